"""Command line: ``casadi-ws equilibrium|solve|compare|demo ...``.

Exit codes: 0 success, 1 a solve did not converge (equilibrium), 2 bad input (problem file, arguments).
Bad input prints one line naming the file and key; ``--debug`` shows the Python traceback instead.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["main"]


class UsageError(ValueError):
    pass


def _parse_u(text: str, n_u: int) -> np.ndarray:
    try:
        u = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise UsageError(f"--u: expected {n_u} comma-separated numbers, got {text!r}") from None
    if u.size != n_u:
        raise UsageError(f"--u: the problem has {n_u} cable(s), got {u.size} value(s): {text!r}")
    if not np.all(np.isfinite(u)):
        raise UsageError(f"--u: values must be finite, got {text!r}")
    return u


def _load(path: str | None):
    from .problem import default_problem, load_problem

    return default_problem() if path is None else load_problem(path)


def cmd_equilibrium(args) -> int:
    from .equilibrium import solve_equilibrium
    from .model import StaticModel

    problem = _load(args.problem)
    u = _parse_u(args.u, problem.n_u)
    model = StaticModel(problem)
    eq = solve_equilibrium(model, u)
    out = {"problem": problem.name, **eq.to_dict(), "units": {"tip": "m", "u": "N"}}
    print(json.dumps(out, indent=None if args.compact else 2))
    return 0 if eq.converged else 1


def _prepare_out(path: str, overwrite: bool) -> Path:
    out = Path(path)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise UsageError(f"--out: {out} already holds files; pass --overwrite to replace them")
    out.mkdir(parents=True, exist_ok=True)
    return out


def write_outputs(result, problem, out: Path, quiet: bool = False) -> None:
    """Result files plus the three-view and 3-D pictures into ``out``."""
    from .plots import three_views, workspace_3d

    result.save(out)
    three_views(result, out / "three_views.png", problem.mesh, title=f"{problem.name}: {result.method} workspace")
    workspace_3d(result, out / "workspace_3d.png", problem.mesh, title=f"{problem.name}: {result.method}")
    if not quiet:
        s = result.summary()
        print(f"{result.method}: {s['n_points']} reachable points, {s['n_failed']} failed, {s['time_s']:.1f} s")
        extra = " cells.vtu" if (out / "cells.vtu").exists() else ""
        print(f"wrote {out}/: summary.json points.csv failures.csv result.npz points.vtp{extra} (ParaView) "
              f"three_views.png workspace_3d.png")


def cmd_solve(args) -> int:
    problem = _load(args.problem)
    if args.method == "forward":
        from .forward import ForwardSettings, forward

        if args.nd < 1:
            raise UsageError(f"--nd: expected an integer >= 1, got {args.nd}")
        out = _prepare_out(args.out, args.overwrite)
        settings = ForwardSettings(n_d=args.nd, workers=args.workers, progress=not args.quiet,
                                   store_states=args.store_states)
        result = forward(problem, settings=settings)
    else:
        from .backward import BackwardSettings
        from .forward_backward import FBSettings, forward_backward

        if not args.step > 0:
            raise UsageError(f"--step: expected a grid step > 0 in metres, got {args.step}")
        out = _prepare_out(args.out, args.overwrite)
        settings = FBSettings(step=args.step, strategy=args.strategy, progress=not args.quiet,
                              backward=BackwardSettings(formulation=args.backward), store_states=args.store_states,
                              workers=args.workers)
        result = forward_backward(problem, settings)
    write_outputs(result, problem, out, args.quiet)
    return 0


def cmd_compare(args) -> int:
    from .compare import compare
    from .plots import three_views
    from .result import load_result

    results = []
    for d in (args.a, args.b):
        if not (Path(d) / "summary.json").is_file():
            raise UsageError(f"{d}: not a result directory (no summary.json)")
        results.append(load_result(d))
    report = compare(*results, step=args.step)
    print(json.dumps(report, indent=2))
    if args.plot:
        three_views(results, args.plot, title="forward (blue) vs forward-backward (gray cells, red points)")
    return 0


def cmd_demo(args) -> int:
    from .forward import ForwardSettings, forward
    from .problem import default_problem

    problem = default_problem()
    print(f"casadi-ws demo: forward workspace of the built-in '{problem.name}' ({problem.mesh.n_nodes} nodes, "
          f"{problem.mesh.n_tets} tetrahedra, {problem.material.model}, {problem.n_u} cables, "
          f"U = [0, 100] N x [0, 100] N, {args.nd} values per cable)")
    result = forward(problem, settings=ForwardSettings(n_d=args.nd, progress=True))
    write_outputs(result, problem, _prepare_out(args.out, True), quiet=False)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="casadi-ws", description="Reachable workspace of soft robots (FEM + CasADi).")
    p.add_argument("--debug", action="store_true", help="show Python tracebacks on errors")
    sub = p.add_subparsers(dest="command", required=True)

    e = sub.add_parser("equilibrium", help="solve the static equilibrium for given cable tensions")
    e.add_argument("problem", help="problem YAML file")
    e.add_argument("--u", required=True, help="cable tensions in N, comma-separated, e.g. 10,20")
    e.add_argument("--compact", action="store_true", help="print the JSON on one line")
    e.set_defaults(func=cmd_equilibrium)

    s = sub.add_parser("solve", help="estimate the reachable workspace and write result files and plots")
    s.add_argument("problem", help="problem YAML file")
    s.add_argument("--method", choices=["forward", "fb"], default="forward",
                   help="forward (grid of U) or fb (forward-backward, grid of the end-effector space)")
    s.add_argument("--nd", type=int, default=11, help="forward: values per actuator (n_d^n_u equilibria)")
    s.add_argument("--workers", type=int, default=1, help="parallel processes (forward and fb)")
    s.add_argument("--step", type=float, default=0.004, help="fb: grid step s_Ed in metres")
    s.add_argument("--strategy", choices=["uniform", "relative"], default="uniform", help="fb: discretisation")
    s.add_argument("--backward", choices=["reduced", "ipopt"], default="reduced", help="fb: backward solver")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--overwrite", action="store_true", help="replace the files of an existing output directory")
    s.add_argument("--store-states", action="store_true", help="keep every point's nodal displacements")
    s.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    s.set_defaults(func=cmd_solve)

    c = sub.add_parser("compare", help="agreement of two result directories (coverage, precision, Hausdorff)")
    c.add_argument("a", help="result directory A (e.g. forward)")
    c.add_argument("b", help="result directory B (e.g. forward-backward)")
    c.add_argument("--step", type=float, default=None, help="grid step for the cell sets (default: B's)")
    c.add_argument("--plot", default=None, help="write the overlaid three views to this PNG")
    c.set_defaults(func=cmd_compare)

    d = sub.add_parser("demo", help="forward workspace of the built-in default problem (2-cable trunk)")
    d.add_argument("--nd", type=int, default=11, help="values per cable")
    d.add_argument("--out", default="results/demo", help="output directory (replaced)")
    d.set_defaults(func=cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    from .mesh import MeshError
    from .problem import ProblemError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ProblemError, MeshError, UsageError) as exc:
        if args.debug:
            raise
        print(f"casadi-ws: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("casadi-ws: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
