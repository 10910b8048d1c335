"""A workspace result as the files a user opens: result files, ParaView scene, pictures."""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["measure", "write_outputs"]


def measure(result, problem, boundary: bool = True, step=None, task=None) -> None:
    """Give a finished run its boundary (a forward grid's from its own nodes; forward-backward builds its own
    while it runs) and its measures (:func:`casadi_ws.workspace.measures.measures`), in place."""
    from ..workspace.measures import measures

    if result.method == "forward" and boundary:
        from ..workspace.boundary import boundary_of

        result.boundary = boundary_of(result, problem)
    result.measures = measures(result, step=step, task=task)


def write_outputs(result, problem, out, quiet: bool = True, boundary: bool = True, shapes: int | None = None) -> None:
    """Everything ``casadi-ws solve`` writes, into the directory ``out``: the result files, the ParaView scene,
    the three-view and 3-D pictures and the interactive report; a result without measures gets them first
    (:func:`measure`, the boundary too unless ``boundary`` is False). The one call a script needs after
    ``forward`` or ``forward_backward``; ``quiet`` False prints the summary lines the command prints.

    ``shapes``: of how many points (spread over them; default :data:`~casadi_ws.io.report.MAX_SHAPES`, fewer
    for a robot with a large boundary: :data:`~casadi_ws.io.report.SHAPE_BYTES`) the report draws the deformed
    robot; where the run kept no states they are solved again here, each from the
    nearest one solved before it, and kept where the tip is the reported point (the time is
    ``timings['shapes']``, the count ``counters['shapes']``)."""
    from .plots import three_views, workspace_3d
    from .report import MAX_SHAPES, shape_count, shape_points, write_report
    from .scene import write_scene

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if not result.measures:
        measure(result, problem, boundary)
    limit = shape_count(problem.mesh, MAX_SHAPES if shapes is None else shapes)
    states = _shape_states(result, problem, limit, shape_points)
    result.save(out, summary=False)  # summary.json, the mark of a complete result, after every other file
    scene = write_scene(problem, out)
    three_views(result, out / "three_views.png", problem.mesh, title=f"{problem.name}: {result.method} workspace")
    workspace_3d(result, out / "workspace_3d.png", problem.mesh, title=f"{problem.name}: {result.method}")
    write_report(result, out / "report.html", problem.mesh, getattr(problem, "obstacles", []), states)
    result.write_summary(out)
    for w in result.warnings():
        print(f"casadi-ws: warning: {w}", file=sys.stderr)
    if not quiet:
        s = result.summary()
        per_cell = s["counters"].get("factorizations_per_cell")
        print(f"{result.method}: {s['n_points']} reachable points, {result.failures_line()}, {s['time_s']:.1f} s"
              + (f", {per_cell:.2f} LU factorisations per reached cell" if per_cell is not None else ""))
        o, dx = result.measures.get("orientation"), result.measures.get("dexterous")
        if o and o.get("solved"):
            print(f"orientation: {o['solved']} of {o['cells']} cells, tilt from {o['tilt_min_deg']:.1f} to "
                  f"{o['tilt_max_deg']:.1f} deg, widest range in one cell {o['widest_range_deg']:.1f} deg "
                  f"({o['time_s']:.1f} s)")
        if dx:
            print(f"dexterous (within {dx['cone_deg']:g} deg of {dx['axis']}): {dx['cells']} cells, "
                  f"{dx['cell_volume'] * 1e6:.4g} cm^3 of cells ({100 * dx['share']:.0f} % of the workspace's)"
                  + (f", {100 * dx['task_share']:.0f} % of the task" if dx.get("task_share") is not None else ""))
        if "shapes" in result.timings:
            print(f"report: the robot deformed at {result.counters['shapes']} points, solved again in "
                  f"{result.timings['shapes']:.1f} s (--shapes)")
        extra = "".join(f" {f}" for f in ("cells.vtu", "dexterous.vtu", "boundary.vtu", "boundary.stl")
                        if (out / f).exists())
        m = result.measures
        if m.get("volume") is not None and m.get("volume_method") == "boundary":
            how = "the union of U's grid cells' images: the map folds" if m.get("folded") else "boundary surface"
            print(f"volume {m['volume'] * 1e6:.4g} cm^3 ({how}, +-{m['volume_error'] * 1e6:.2g}); "
                  f"the cells cover {m['cell_volume'] * 1e6:.4g} cm^3")
        elif m.get("area") is not None:
            print(f"area {m['area'] * 1e4:.4g} cm^2 (two inputs: the workspace is a surface)")
        elif m.get("length") is not None:
            print(f"length {m['length'] * 1e3:.4g} mm (one input: the workspace is a curve)")
        print(f"wrote {out}/: summary.json points.csv failures.csv result.npz points.vtu{extra} "
              f"{' '.join(scene)} (ParaView) three_views.png workspace_3d.png report.html")


def _shape_states(result, problem, limit, shape_points):
    """(point indices, nodal states) for the report's deformed robots: the run's own where it kept them, else
    solved again (:func:`casadi_ws.workspace.states.states_at`); None where none are asked for."""
    import time

    import numpy as np

    pick = shape_points(result, limit)
    if not len(pick):
        return np.zeros(0, dtype=int), np.zeros((0, 0))
    if result.states is not None:
        return pick, np.asarray(result.states)[pick]
    from ..runtime.executor import model_for
    from ..workspace.states import states_at

    t = time.perf_counter()
    found, Q = states_at(model_for(problem), result, pick)
    result.timings["shapes"] = time.perf_counter() - t
    result.counters["shapes"] = int(len(found))
    return found, Q
