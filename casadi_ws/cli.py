"""Command line: ``casadi-ws equilibrium|demo ...``.

Exit codes: 0 success, 1 a solve did not converge (equilibrium), 2 bad input (problem file, arguments).
Bad input prints one line naming the file and key; ``--debug`` shows the Python traceback instead.
"""

from __future__ import annotations

import argparse
import json
import sys

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


def cmd_demo(args) -> int:
    import time

    from .equilibrium import solve_equilibrium
    from .model import StaticModel
    from .problem import default_problem

    t0 = time.perf_counter()
    problem = default_problem()
    model = StaticModel(problem)
    t1 = time.perf_counter()
    print(f"casadi-ws demo: {problem.name}, {problem.mesh.n_nodes} nodes, {problem.mesh.n_tets} tetrahedra, "
          f"{problem.material.model} material, {problem.n_u} cables (model built in {t1 - t0:.2f} s)")
    for u in ([0.0, 0.0], [50.0, 0.0], [50.0, 50.0], [100.0, 100.0]):
        t = time.perf_counter()
        eq = solve_equilibrium(model, u)
        print(f"  u = {u} N -> tip = {np.round(eq.tip, 5).tolist()} m, {eq.status_name}, "
              f"{eq.iterations} Newton iterations, residual {eq.residual:.1e}, {time.perf_counter() - t:.2f} s")
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

    d = sub.add_parser("demo", help="run the built-in default problem (2-cable trunk)")
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
