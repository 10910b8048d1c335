"""One trial of a study: build the design's problem, compute its workspace, measure it.

:func:`run_trial` runs wherever the executor puts it (this process, a pool process, a Dask worker): it
receives plain data and returns plain data and a :class:`~casadi_ws.workspace.result.WorkspaceResult`;
it never raises for a bad design, it reports it.
"""

from __future__ import annotations

import time
import traceback
from pathlib import Path

import numpy as np

from ..io.problem import ProblemError, problem_from_dict

__all__ = ["run_trial"]


def _workspace(problem, w: dict):
    from ..fem.model import StaticModel

    model = StaticModel(problem)
    if w["method"] == "forward":
        from ..workspace.forward import ForwardSettings, forward

        return forward(problem, model=model, settings=ForwardSettings(n_d=w.get("n_d", 11), progress=False))
    from ..workspace.backward import BackwardSettings
    from ..workspace.forward_backward import FBSettings, forward_backward

    settings = FBSettings(step=w.get("step"), strategy=w.get("strategy", "uniform"), progress=False,
                          backward=BackwardSettings(formulation=w.get("backward", "reduced")))
    return forward_backward(problem, settings, model=model)


def run_trial(data: dict, base_dir: str, source: str, workspace: dict, needed: list, target=None,
              reach_tolerance: float = 1e-4) -> dict:
    """``{"status": "complete" | "failed", "reason", "measures", "time_s", "result"}`` of one design."""
    from ..workspace.measures import measures

    t0 = time.perf_counter()
    try:
        problem = problem_from_dict(data, source, Path(base_dir))
    except ProblemError as exc:
        return {"status": "failed", "reason": f"invalid design: {exc.key}: {exc.message}", "measures": {},
                "time_s": time.perf_counter() - t0, "result": None}
    try:
        result = _workspace(problem, workspace)
        step = workspace.get("step")
        m = measures(result, step=step, task=problem.task)
        result.measures = m
        # a study's "volume" objective falls back to the cells' where there is no closed surface (study/spec.py)
        out = {"volume": m["volume"] if m["volume"] is not None else m["cell_volume"], "cells": m["cells"],
               "area": m.get("area"), "task_share": m.get("task_share")}
        if m["extents"] is not None:
            ext = np.subtract(m["extents"][1], m["extents"][0])
            out.update(extent_x=float(ext[0]), extent_y=float(ext[1]), extent_z=float(ext[2]))
        if target is not None and any(k.startswith("reach_") for k in needed):
            from ..control.inverse import ReachSettings, reach

            r = reach(problem, target, settings=ReachSettings(tolerance=reach_tolerance))
            out.update(reach_tension=float(np.max(np.abs(r.u))), reach_error=float(r.error))
        if result.n_points == 0:
            return {"status": "failed", "reason": "no verified equilibrium: the workspace is empty",
                    "measures": out, "time_s": time.perf_counter() - t0, "result": result}
        missing = [k for k in needed if out.get(k) is None or not np.isfinite(out[k])]
        if missing:
            return {"status": "failed", "reason": f"measure(s) {', '.join(missing)} undefined for this design",
                    "measures": out, "time_s": time.perf_counter() - t0, "result": result}
        return {"status": "complete", "reason": "", "measures": out, "time_s": time.perf_counter() - t0,
                "result": result}
    except Exception as exc:  # noqa: BLE001 - a failed run is a result of the study, recorded with its reason
        last = traceback.extract_tb(exc.__traceback__)[-1]
        return {"status": "failed", "reason": f"{type(exc).__name__}: {exc} ({Path(last.filename).name}:{last.lineno})",
                "measures": {}, "time_s": time.perf_counter() - t0, "result": None}
