"""Command line: ``casadi-ws equilibrium|solve|compare|reach|follow|study|demo ...``.

Exit codes: 0 success, 1 the equilibrium did not converge or is not admissible (equilibrium), 2 bad input (problem
file, arguments).
Bad input prints one line naming the file and key; ``--debug`` shows the Python traceback instead.
"""

from __future__ import annotations

import argparse
import errno
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
        raise UsageError(f"--u: the problem has {n_u} actuator(s), got {u.size} value(s): {text!r}")
    if not np.all(np.isfinite(u)):
        raise UsageError(f"--u: values must be finite, got {text!r}")
    return u


def _load(path: str | None):
    from .io.problem import default_problem, load_problem

    return default_problem() if path is None else load_problem(path)


def _u_unit(problem) -> str:
    """The unit of u: N for cables, Pa for cavities, "N/Pa" (in input order) for a mix."""
    return "/".join(dict.fromkeys(a.input_unit for a in problem.actuators)) or "N"


def cmd_equilibrium(args) -> int:
    from .fem.model import StaticModel
    from .solvers.admissible import admissible_equilibrium

    problem = _load(args.problem)
    u = _parse_u(args.u, problem.n_u)
    model = StaticModel(problem)
    eq, adm, branched = admissible_equilibrium(model, u)
    states = model.actuator_states(eq.q)
    t = model.intensities(eq.q, u)
    actuators = [{"name": a.name, "kind": a.kind, "control": a.control, "u": float(v), "u_unit": a.input_unit,
                  a.quantity_name: float(st), f"{a.quantity_name}_unit": a.quantity_unit,
                  # the intensity: the tension a displacement-controlled cable carries (0 when slack)
                  ("tension" if a.kind == "cable" else "pressure"): float(ti),
                  ("tension" if a.kind == "cable" else "pressure") + "_unit": a.intensity_unit}
                 for a, v, st, ti in zip(problem.actuators, u, states, t)]
    units = {"tip": "m", "u": _u_unit(problem), "force": "N"}
    checks = adm.to_dict() if adm is not None else {"admissible": False, "stable": None, "violations": []}
    o = model.tip_frame.orientation(eq.q)
    out = {"problem": problem.name, **eq.to_dict(), **checks, "stable_branch": branched, "actuators": actuators,
           "contacts": model.contacts(eq.q), "orientation": {"tilt": o["tilt"], "roll": o["roll"],
                                                              "axis": o["direction"].tolist()},
           "units": units | {"tilt": "deg", "roll": "deg"}}
    print(json.dumps(out, indent=None if args.compact else 2))
    if "self_penetration" in checks["violations"] and problem.self_contact_auto is None:
        print("casadi-ws: the body passes through itself at these inputs: with 'self_contact: auto' in the problem "
              "file it presses on itself instead (docs/problem-format.md)", file=sys.stderr)
    return 0 if eq.converged and checks["admissible"] else 1


def _prepare_out(path: str, overwrite: bool, resume: bool = False) -> tuple[Path, str]:
    """The output directory and what to do there: ``new`` (start), ``resume`` (a checkpoint is there) or
    ``done`` (``--resume`` on a finished result: nothing to compute)."""
    from .runtime.run_state import CHECKPOINT

    out = Path(path)
    if resume:
        if overwrite:
            raise UsageError("--resume and --overwrite contradict each other")
        if (out / CHECKPOINT).is_file():
            return out, "resume"
        if (out / "summary.json").is_file():
            return out, "done"
        print(f"casadi-ws: --resume: no checkpoint in {out} (the run had not written one yet): starting the run",
              file=sys.stderr)
        _writable(out)
        return out, "new"
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise UsageError(f"--out: {out} already holds files; pass --overwrite to replace them or --resume to "
                         f"continue an interrupted run")
    if out.exists() and overwrite:
        (out / CHECKPOINT).unlink(missing_ok=True)
        (out / "summary.json").unlink(missing_ok=True)  # until the new one is written, no complete result is there
    _writable(out)
    return out, "new"


_WRITE_ERRORS = {errno.ENOSPC, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EDQUOT}
"""What a full disk, a file-size limit, a read-only or a forbidden folder raise while files are written."""


def _writable(out: Path) -> None:
    """--out made and written to before any heavy work: a folder that cannot take files is one line."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".casadi-ws-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise UsageError(f"--out: cannot write into {out}: {exc.strerror or exc}") from None


def _print_finished(out: Path) -> int:
    s = json.loads((out / "summary.json").read_text())
    from .workspace.result import failures_text

    why = failures_text(s.get("failures") or {"failed": s["n_failed"]})
    print(f"{out}: the run is complete, nothing to resume: {s['method']}, {s['n_points']} reachable points, "
          f"{why}, {s['time_s']:.1f} s")
    for w in s.get("warnings", []):
        print(f"casadi-ws: warning: {w}", file=sys.stderr)
    return 0


_SOLVE_DEFAULTS = {"method": "forward", "nd": 11, "step": None, "strategy": "uniform", "backward": "reduced",
                   "workers": 1}


def _task(args, problem):
    """The task region: --task-box or --task-points, else the problem file's ``task``."""
    from .workspace.measures import read_task

    if args.task_box is not None and args.task_points is not None:
        raise UsageError("--task-box, --task-points: give one of them")
    try:
        if args.task_box is not None:
            v = [float(x) for x in args.task_box.split(",")]
            if len(v) != 6:
                raise ValueError(f"expected xmin,ymin,zmin,xmax,ymax,zmax, got {args.task_box!r}")
            return read_task(box=[v[:3], v[3:]])
        if args.task_points is not None:
            if not Path(args.task_points).is_file():
                raise ValueError(f"file not found: {args.task_points}")
            return read_task(csv=args.task_points)
    except ValueError as exc:
        flag = "--task-box" if args.task_box is not None else "--task-points"
        raise UsageError(f"{flag}: {exc}") from None
    return problem.task


def _executor(args, problem):
    """A Dask client for --scheduler, else None (the method starts its own workers)."""
    tls = getattr(args, "tls", None)
    if not args.scheduler:
        if tls:
            raise UsageError("--tls: the credentials of a tls:// --scheduler; no --scheduler was given")
        return None
    from .runtime.executor import DaskExecutor, SchedulerError

    security = None
    if args.scheduler.startswith("tls://"):
        if not tls:
            raise UsageError(f"--scheduler {args.scheduler}: a TLS scheduler needs --tls DIR, the folder "
                             f"'casadi-ws cluster-certs' wrote and the scheduler and workers use")
        from .runtime.tls import security as tls_security

        try:
            security = tls_security(tls)
        except ValueError as exc:
            raise UsageError(f"--tls: {exc}") from None
    elif tls:
        raise UsageError(f"--tls: the scheduler {args.scheduler} is not tls:// (start it with --protocol tls)")
    try:
        ex = DaskExecutor(args.scheduler, problem=problem, timeout=5.0, security=security)
    except SchedulerError as exc:
        raise UsageError(f"--scheduler: {exc}") from None
    if not args.quiet:
        print(f"casadi-ws: Dask cluster at {args.scheduler}: {ex.workers} worker(s), dashboard {ex.dashboard}",
              file=sys.stderr)
    return ex


def _orientation(args):
    """--orientation: None (not asked), or the settings of the orientation ranges."""
    if args.orientation is None:
        return None
    from .workspace.orientation import OrientationSettings, parse_orientation

    try:
        axis, cone = parse_orientation("" if args.orientation.strip() == "range" else args.orientation)
    except ValueError as exc:
        raise UsageError(f"--orientation: {exc}") from None
    return OrientationSettings(reference=axis, cone=cone)


def cmd_solve(args) -> int:
    problem = _load(args.problem)
    for key, default in _SOLVE_DEFAULTS.items():  # command line, else the file's workspace section, else default
        if getattr(args, key) is None:
            setattr(args, key, problem.workspace.get(key, default))
    if args.workers < 1:
        raise UsageError(f"--workers: expected an integer >= 1, got {args.workers}")
    if args.shapes is not None and args.shapes < 0:
        raise UsageError(f"--shapes: expected an integer >= 0 (points whose deformed robot the report draws), "
                         f"got {args.shapes}")
    task = _task(args, problem)
    orientation = _orientation(args)
    if args.method == "forward":
        from .workspace.forward import ForwardSettings, forward

        if args.nd < 1:
            raise UsageError(f"--nd: expected an integer >= 1, got {args.nd}")
        from .workspace.forward import grid_inputs

        k = grid_inputs(problem)
        if args.nd ** k > 10**8 and not args.force:
            raise UsageError(f"--nd: {args.nd}^{k} = {args.nd ** k:.3g} equilibria; pass --force to run that many")
        out, mode = _prepare_out(args.out, args.overwrite, args.resume)
        if args.stride is not None and args.stride < 1:
            raise UsageError(f"--stride: expected an integer >= 1, got {args.stride}")
        settings = ForwardSettings(n_d=args.nd, workers=args.workers, progress=not args.quiet,
                                   store_states=args.store_states, checkpoint_every=args.checkpoint_every,
                                   stride=args.stride)
        run = lambda: forward(problem, settings=settings, checkpoint_dir=out, resume=mode == "resume",  # noqa: E731
                              executor=executor)
    else:
        from .workspace.backward import BackwardSettings
        from .workspace.forward_backward import FBSettings, forward_backward

        if args.step is not None and (not args.step > 0 or not np.isfinite(args.step)):
            raise UsageError(f"--step: expected a grid step > 0 in metres, got {args.step}")
        if args.max_cells < 1:
            raise UsageError(f"--max-cells: expected an integer >= 1, got {args.max_cells}")
        out, mode = _prepare_out(args.out, args.overwrite, args.resume)
        settings = FBSettings(step=args.step, strategy=args.strategy, progress=not args.quiet,
                              backward=BackwardSettings(formulation=args.backward), store_states=args.store_states,
                              workers=args.workers, max_cells=args.max_cells)
        settings.boundary.enabled = not args.no_boundary
        run = lambda: forward_backward(problem, settings, checkpoint_dir=out, resume=mode == "resume",  # noqa: E731
                                       executor=executor)
    if mode == "done":
        return _print_finished(out)
    executor = _executor(args, problem)
    try:
        result = run()
    except KeyboardInterrupt:
        print(f"casadi-ws: interrupted; the checkpoint in {out} continues with the same command and --resume",
              file=sys.stderr)
        return 130
    except OSError as exc:  # the checkpoint could not be written: a full disk, a folder gone read-only
        if exc.errno not in _WRITE_ERRORS:
            raise
        print(f"casadi-ws: cannot write the checkpoint into {out}: {exc.strerror or exc}; free the space or give "
              f"another --out, then run the same command with --resume", file=sys.stderr)
        return 2
    finally:
        if executor is not None:
            executor.close()
    from .io.output import measure, write_outputs

    try:
        measure(result, problem, not args.no_boundary, args.step, task)
        if orientation is not None:
            from .runtime.executor import model_for
            from .workspace.orientation import attach, orientation_ranges

            attach(result, orientation_ranges(model_for(problem), result, orientation, step=args.step), task)
        write_outputs(result, problem, out, args.quiet, shapes=args.shapes)
    except KeyboardInterrupt:  # after the run: its result files may be incomplete
        print(f"casadi-ws: interrupted while writing the results into {out}; some files may be missing: run the "
              f"same command with --overwrite to compute them again", file=sys.stderr)
        return 130
    except OSError as exc:  # summary.json is written last: the folder does not pass for a complete result
        if exc.errno not in _WRITE_ERRORS:
            raise
        print(f"casadi-ws: cannot write the results into {out}: {exc.strerror or exc}; no summary.json was "
              f"written (the result is incomplete): free the space, then run the same command with --overwrite",
              file=sys.stderr)
        return 2
    return 0


def cmd_cluster_certs(args) -> int:
    from .runtime.tls import FILES, write_certificates

    out = Path(args.out)
    if args.days < 1:
        raise UsageError(f"--days: expected an integer >= 1, got {args.days}")
    there = [name for name in FILES.values() if (out / name).exists()]
    if there and not args.overwrite:
        raise UsageError(f"--out: {out} already holds {', '.join(there)}; pass --overwrite to replace them (the "
                         f"scheduler and workers started with the old ones will refuse the new)")
    _writable(out)
    paths = write_certificates(out, args.days)
    print(f"wrote {paths['ca']} {paths['cert']} {paths['key']} (valid {args.days} days): copy the folder to each "
          f"machine of the cluster; the key is readable by its owner only")
    return 0


def _result_dir(d) -> Path:
    if not (Path(d) / "summary.json").is_file() or not (Path(d) / "result.npz").is_file():
        raise UsageError(f"{d}: not a result directory (no summary.json and result.npz)")
    return Path(d)


def _problem_of(result, given):
    """The problem a result was computed from: --problem, else the file named in its summary."""
    from .io.problem import BUILT_IN, default_problem

    src = given or result.problem.get("source")
    if not given and src == BUILT_IN:
        return default_problem()
    if not src or not Path(src).is_file():
        raise UsageError(f"--problem: the result's problem file {src!r} is not found; give it with --problem")
    return _load(src)


def cmd_boundary(args) -> int:
    from .io.output import write_outputs
    from .workspace.boundary import KEY_SCALE, BoundarySettings, boundary_of, fold_grid_ok
    from .workspace.measures import measures
    from .workspace.result import load_result

    d = _result_dir(args.result)
    if args.n < 3 or args.n % 2 == 0:
        raise UsageError(f"--n: expected an odd integer >= 3, got {args.n}")
    if not fold_grid_ok(args.fold_n):
        raise UsageError(f"--fold-n: expected an odd integer >= 5 whose n - 1 divides {KEY_SCALE} (5, 7, 9, 11, "
                         f"13, ...), got {args.fold_n}")
    result = load_result(d)
    problem = _problem_of(result, args.problem)
    result.boundary = boundary_of(result, problem, settings=BoundarySettings(n=args.n, fold_n=args.fold_n))
    result.measures = measures(result, task=None) | {k: v for k, v in result.measures.items() if k.startswith("task")}
    write_outputs(result, problem, d, quiet=True)
    b = result.boundary.summary()
    m = result.measures
    print(json.dumps({"boundary": b, "volume": m["volume"], "volume_method": m["volume_method"],
                      **{k: m[k] for k in ("area", "length", "folded", "volume_upper", "volume_lower") if k in m}},
                     indent=2, default=float))
    return 0


def cmd_import_sofa(args) -> int:
    from .io.sofa import import_scene

    scene = Path(args.scene)
    if scene.suffix.lower() not in (".py", ".pyscn", ".scn"):
        raise UsageError(f"{scene}: expected a SOFA scene (.py, .pyscn or .scn), got {scene.suffix or 'no extension'}")
    out = Path(args.out) if args.out else scene.with_suffix(".yaml")
    if not scene.is_file():
        raise UsageError(f"{scene}: scene file not found")
    # the mesh paths are written relative to the output's folder, and checked from there: it must exist
    # (a path through a missing folder, results/../problems, does not resolve)
    out.parent.mkdir(parents=True, exist_ok=True)
    tr = import_scene(scene, out, args.units)
    print(f"wrote {out} ({tr.units} -> SI)")
    for line in tr.notes:
        print(f"  note: {line}")
    for line in tr.untranslated:
        print(f"  not translated: {line}")
    return 0


def cmd_report(args) -> int:
    from .io.report import write_report
    from .workspace.result import load_result

    d = _result_dir(args.result)
    result = load_result(d)
    mesh, obstacles = None, []
    src = args.problem or result.problem.get("source")
    if src and Path(src).is_file():
        problem = _load(src)
        mesh, obstacles = problem.mesh, problem.obstacles
    out = write_report(result, args.out or d / "report.html", mesh, obstacles)
    print(out)
    return 0


def cmd_compare(args) -> int:
    from .workspace.compare import compare
    from .io.plots import three_views
    from .workspace.result import load_result

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


def _parse_point(text: str, flag: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise UsageError(f"{flag}: expected x,y,z in metres, got {text!r}") from None
    if v.size != 3 or not np.all(np.isfinite(v)):
        raise UsageError(f"{flag}: expected three finite numbers x,y,z in metres, got {text!r}")
    return v


def _reach_settings(args):
    from .control.inverse import ReachSettings

    if args.max_du is not None and not args.max_du > 0:
        raise UsageError(f"--max-du: expected a positive number of newtons, got {args.max_du}")
    if not args.regularization >= 0:
        raise UsageError(f"--regularization: expected >= 0, got {args.regularization}")
    return ReachSettings(tolerance=args.tolerance, regularization=args.regularization, max_du=args.max_du,
                         method=args.method)


def cmd_reach(args) -> int:
    from .control.inverse import reach

    problem = _load(args.problem)
    target = _parse_point(args.target, "--target")
    r = reach(problem, target, settings=_reach_settings(args))
    out = {"problem": problem.name, "target": target.tolist(), **r.to_dict()}
    out["units"]["u"] = _u_unit(problem)
    print(json.dumps(out, indent=None if args.compact else 2))
    return 0


def cmd_follow(args) -> int:
    from .control.inverse import follow
    from .io.plots import three_views
    from .workspace.result import WorkspaceResult

    problem = _load(args.problem)
    path = Path(args.targets)
    if not path.is_file():
        raise UsageError(f"--targets: {path}: file not found")
    rows = [ln for ln in path.read_text().splitlines() if ln.strip()]
    try:
        [float(x) for x in rows[0].split(",")]
    except (ValueError, IndexError):
        rows = rows[1:]  # a header line (or nothing)
    try:
        targets = np.array([[float(x) for x in ln.split(",")] for ln in rows])
    except ValueError as exc:
        raise UsageError(f"--targets: {path}: expected lines 'x,y,z' in metres ({exc})") from None
    if targets.ndim != 2 or targets.shape[1] != 3 or len(targets) == 0 or not np.all(np.isfinite(targets)):
        raise UsageError(f"--targets: {path}: expected one or more lines 'x,y,z' in metres")
    out, _ = _prepare_out(args.out, args.overwrite)
    res = follow(problem, targets, _reach_settings(args))
    res.save_csv(out / "follow.csv")
    rest = np.asarray(problem.end_effector, float)
    views = [WorkspaceResult("targets", res.targets, np.zeros((len(targets), 0)), rest_tip=rest),
             WorkspaceResult("reached tips", res.tips, res.u, rest_tip=rest)]
    three_views(views, out / "three_views.png", problem.mesh, title=f"{problem.name}: targets vs reached tips")
    print(f"follow: {int(res.reachable.sum())}/{len(targets)} targets reached, largest error "
          f"{res.errors.max():.3g} m; wrote {out}/follow.csv and three_views.png")
    return 0


def cmd_study(args) -> int:
    from .study import load_study, run_study
    from .study.run import DB

    study = load_study(args.study)
    if args.workers < 1:
        raise UsageError(f"--workers: expected an integer >= 1, got {args.workers}")
    if args.trials is not None:
        if study.method != "optuna":
            raise UsageError("--trials: a grid study runs every design of its grid; --trials is for method: optuna")
        if args.trials < 1:
            raise UsageError(f"--trials: expected an integer >= 1, got {args.trials}")
        from dataclasses import replace as _replace

        study = _replace(study, trials=args.trials)
    out = Path(args.out)
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite contradict each other")
    if args.resume and not (out / DB).is_file():
        print(f"casadi-ws: --resume: no study file in {out}: starting the study", file=sys.stderr)
    replace = not args.resume and out.exists() and any(out.iterdir())
    if replace and not args.overwrite:
        raise UsageError(f"--out: {out} already holds files; pass --overwrite to replace them or --resume to "
                         f"continue an interrupted study")
    if args.scheduler:  # before anything is deleted: an unreachable scheduler must not cost the old results
        executor = _executor(args, None)
    elif args.workers > 1:
        from .runtime.executor import ProcessExecutor

        executor = ProcessExecutor(args.workers)
    else:
        executor = None
    if replace:
        import shutil

        shutil.rmtree(out)
    try:
        result = run_study(study, out, executor=executor, resume=args.resume, progress=not args.quiet)
    except KeyboardInterrupt:
        print(f"casadi-ws: interrupted; the study in {out} continues with the same command and --resume",
              file=sys.stderr)
        return 130
    finally:
        if executor is not None:
            executor.close()
    if not args.quiet:
        failed = len(result.trials) - result.n_complete
        best = result.best
        print(f"study {study.name}: {len(result.trials)} trials, {failed} failed, {result.time_s:.1f} s; "
              + ("no feasible design" if best is None else
                 f"best: trial {best.number} ({', '.join(f'{o.measure} {best.measures[o.measure]:.4g}' for o in study.objectives)})"))
        print(f"wrote {out}/: trials.csv study.png study.json study.db trials/"
              + (" best.yaml best/" if best is not None else ""))
    return 0


def cmd_demo(args) -> int:
    from .workspace.forward import ForwardSettings, forward
    from .io.output import measure, write_outputs
    from .io.problem import default_problem

    problem = default_problem()
    print(f"casadi-ws demo: forward workspace of the built-in '{problem.name}' ({problem.mesh.n_nodes} nodes, "
          f"{problem.mesh.n_tets} tetrahedra, {problem.material.model}, {problem.n_u} cables, "
          f"U = [0, 100] N x [0, 100] N, {args.nd} values per cable)")
    result = forward(problem, settings=ForwardSettings(n_d=args.nd, progress=True))
    measure(result, problem)
    write_outputs(result, problem, _prepare_out(args.out, True)[0], quiet=False)
    return 0


def _solve_parser(sub) -> None:
    s = sub.add_parser("solve", help="estimate the reachable workspace and write result files and plots")
    s.add_argument("problem", help="problem YAML file")
    s.add_argument("--method", choices=["forward", "fb"], default=None,
                   help="forward (grid of U; the default) or fb (forward-backward, grid of the end-effector space)")
    s.add_argument("--nd", type=int, default=None, help="forward: values per actuator, n_d^n_u equilibria (11)")
    s.add_argument("--workers", type=int, default=None, help="parallel processes, forward and fb (1)")
    s.add_argument("--stride", type=int, default=None,
                   help="forward: Newton every STRIDE-th point of a grid line, the others interpolated and "
                        "verified (n_d // 6, or n_d // 10 after a line where interpolation failed often; at most 8; "
                        "1: Newton everywhere)")
    s.add_argument("--step", type=float, default=None, help="fb: grid step s_Ed in metres (default: the robot's reach / 48, rounded; 4 mm on the trunk)")
    s.add_argument("--strategy", choices=["uniform", "relative"], default=None, help="fb: discretisation (uniform)")
    s.add_argument("--backward", choices=["reduced", "ipopt"], default=None, help="fb: backward solver (reduced)")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--overwrite", action="store_true", help="replace the files of an existing output directory")
    s.add_argument("--store-states", action="store_true", help="keep every point's nodal displacements")
    s.add_argument("--shapes", type=int, default=None, metavar="N",
                   help="the report draws the deformed robot at N points spread over the workspace, solved again "
                        "after the run where it kept no states (200; 0: none)")
    s.add_argument("--resume", action="store_true", help="continue the interrupted run whose checkpoint is in --out")
    s.add_argument("--checkpoint-every", type=float, default=30.0,
                   help="forward: seconds between checkpoints (forward-backward: every iteration)")
    s.add_argument("--max-cells", type=int, default=200_000,
                   help="fb: stop after the iteration in which this many grid cells were explored; the result "
                        "keeps what was verified and --resume with a larger budget continues (200000)")
    s.add_argument("--force", action="store_true", help="forward: run even more than 10^8 equilibria")
    s.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on an existing Dask cluster (e.g. tls://host:8786 with --tls, or tcp://127.0.0.1:8786 "
                        "on this machine; workers with --nthreads 1)")
    s.add_argument("--tls", default=None, metavar="DIR",
                   help="the credentials of a tls:// scheduler: the folder casadi-ws cluster-certs wrote")
    s.add_argument("--task-box", default=None, metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="a task region (m): summary.json reports the share of it the workspace reaches")
    s.add_argument("--task-points", default=None, metavar="CSV", help="task points x,y,z (m), instead of a box")
    s.add_argument("--orientation", default=None, metavar="SPEC",
                   help="after the run, the range of tip orientations in each cell: 'range' (tilt from the tip's "
                        "rest axis), or 'axis=[x,y,z],cone=DEG' for the dexterous workspace, where the tip can "
                        "point within DEG of that axis (docs/methods.md \"Orientation\")")
    s.add_argument("--no-boundary", action="store_true",
                   help="do not build the boundary surface (the volume is then the cells')")
    s.set_defaults(func=cmd_solve)


def _inverse_parsers(sub) -> None:
    for name, helptext in (("reach", "cable tensions that bring the tip to a target (inverse model)"),
                           ("follow", "reach a sequence of targets from a CSV file, each warm-started")):
        r = sub.add_parser(name, help=helptext)
        r.add_argument("problem", help="problem YAML file")
        if name == "reach":
            r.add_argument("--target", required=True, help="x,y,z in metres")
            r.add_argument("--compact", action="store_true", help="print the JSON on one line")
            r.set_defaults(func=cmd_reach)
        else:
            r.add_argument("--targets", required=True, help="CSV file of x,y,z rows in metres (header optional)")
            r.add_argument("--out", required=True, help="output directory")
            r.add_argument("--overwrite", action="store_true", help="replace the files of an existing directory")
            r.set_defaults(func=cmd_follow)
        r.add_argument("--tolerance", type=float, default=1e-6, help="reachable if within this distance (m)")
        r.add_argument("--regularization", type=float, default=0.0,
                       help="weight (m^2/N^2) of |u|^2 (reach) or |u - u_previous|^2 (follow)")
        r.add_argument("--max-du", type=float, default=None,
                       help="largest change of each input per solve (in its unit: N, m, Pa or m^3)")
        r.add_argument("--method", choices=("reduced", "ipopt"), default="reduced",
                       help="reduced: Gauss-Newton in the tensions on verified equilibria (fast; IPOPT where it "
                            "stalls); ipopt: the full-space NLP over displacements and tensions")


def _study_parser(sub) -> None:
    st = sub.add_parser("study", help="design study: workspaces of many designs, the best ones (grid or Optuna)")
    st.add_argument("study", help="study YAML file (docs/studies.md)")
    st.add_argument("--out", required=True, help="output directory")
    st.add_argument("--workers", type=int, default=1, help="trials run at once, each in its own process (1)")
    st.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="run the trials on an existing Dask cluster (e.g. tls://host:8786 with --tls, or "
                         "tcp://127.0.0.1:8786 on this machine; workers with --nthreads 1)")
    st.add_argument("--tls", default=None, metavar="DIR",
                    help="the credentials of a tls:// scheduler: the folder casadi-ws cluster-certs wrote")
    st.add_argument("--resume", action="store_true", help="continue the study whose study.db is in --out")
    st.add_argument("--overwrite", action="store_true", help="delete --out and start again")
    st.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    st.add_argument("--trials", type=int, default=None,
                    help="designs to evaluate instead of the file's trials (optuna studies; a quick look, or more "
                         "on --resume)")
    st.set_defaults(func=cmd_study)


def _version() -> str:
    from . import __version__

    return __version__


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="casadi-ws", description="Reachable workspace of soft robots (FEM + CasADi).")
    p.add_argument("--debug", action="store_true", help="show Python tracebacks on errors")
    p.add_argument("--version", action="version", version=f"casadi-ws {_version()}")
    sub = p.add_subparsers(dest="command", required=True)

    e = sub.add_parser("equilibrium", help="solve the static equilibrium for given actuator inputs")
    e.add_argument("problem", help="problem YAML file")
    e.add_argument("--u", required=True,
                   help="the actuators' inputs, comma-separated in the problem's order, each in its own unit: a "
                        "cable's tension in N (its shortening in m with control: displacement), a cavity's "
                        "pressure in Pa (its volume in m^3 with control: volume); e.g. 10,20")
    e.add_argument("--compact", action="store_true", help="print the JSON on one line")
    e.set_defaults(func=cmd_equilibrium)

    _solve_parser(sub)

    b = sub.add_parser("boundary", help="build the boundary surface, volume and area of an existing result")
    b.add_argument("result", help="result directory")
    b.add_argument("--n", type=int, default=5, help="nodes per edge of each face of U, odd (5; forward: its n_d)")
    b.add_argument("--fold-n", type=int, default=9,
                   help="where the map folds: nodes per input of the grid of U whose cells' images make the "
                        "surface, odd (9; a finer forward grid is used as it is)")
    b.add_argument("--problem", default=None, help="the problem file (default: the one named in summary.json)")
    b.set_defaults(func=cmd_boundary)

    im = sub.add_parser("import-sofa", help="write a problem file from a SOFA scene (runs the scene's createScene "
                                            "against a recording stand-in of SOFA's Python API)")
    im.add_argument("scene", help="the scene: .py / .pyscn (Python, executed) or .scn (XML)")
    im.add_argument("--out", default=None, help="the problem file to write (SCENE.yaml)")
    im.add_argument("--units", default=None, help="the scene's unit system: m-kg-s, mm-kg-s, mm-g-s, cm-kg-s "
                                                  "(default: from gravity's magnitude)")
    im.set_defaults(func=cmd_import_sofa)

    rp = sub.add_parser("report", help="an interactive HTML page of a result (self-contained, works offline)")
    rp.add_argument("result", help="result directory")
    rp.add_argument("--out", default=None, help="the page to write (RESULT/report.html)")
    rp.add_argument("--problem", default=None, help="the problem file, for the robot at rest (default: summary's)")
    rp.set_defaults(func=cmd_report)

    _inverse_parsers(sub)

    c = sub.add_parser("compare", help="agreement of two result directories (strict cell recall first, Hausdorff, volumes)")
    c.add_argument("a", help="result directory A (e.g. forward)")
    c.add_argument("b", help="result directory B (e.g. forward-backward)")
    c.add_argument("--step", type=float, default=None, help="grid step for the cell sets (default: B's)")
    c.add_argument("--plot", default=None, help="write the overlaid three views to this PNG")
    c.set_defaults(func=cmd_compare)

    _study_parser(sub)

    cc = sub.add_parser("cluster-certs", help="credentials for a TLS Dask cluster: a private authority and a "
                                              "certificate for its scheduler, workers and clients")
    cc.add_argument("--out", required=True, help="folder to write ca.pem, cluster.pem, cluster-key.pem into")
    cc.add_argument("--days", type=int, default=365, help="days the certificates are valid (365)")
    cc.add_argument("--overwrite", action="store_true", help="replace the credentials already there")
    cc.set_defaults(func=cmd_cluster_certs)

    d = sub.add_parser("demo", help="forward workspace of the built-in default problem (2-cable trunk)")
    d.add_argument("--nd", type=int, default=11, help="values per actuator")
    d.add_argument("--out", default="results/demo", help="output directory (replaced)")
    d.set_defaults(func=cmd_demo)
    return p


def main(argv: list[str] | None = None) -> int:
    from .fem.mesh import MeshError
    from .fem.model import ModelError
    from .io.problem import ProblemError
    from .io.sofa.recorder import SceneError
    from .runtime.executor import StartMethodError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ProblemError, MeshError, ModelError, UsageError, SceneError, StartMethodError) as exc:
        if args.debug:
            raise
        print(f"casadi-ws: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("casadi-ws: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
