"""The workspace result shared by all methods, its files, and loading it back.

A :class:`WorkspaceResult` holds the reachable end-effector points (each a verified equilibrium: relative
residual below tolerance and u inside U), their inputs, optionally their nodal states, the failures
(kept apart, never mixed in), counters, timings per phase, and the problem and settings used.

Files written by :meth:`WorkspaceResult.save` into a directory:

``summary.json``  method, n_points, n_failed, time_s, settings, counters, timings, problem description
``points.csv``    one row per reachable point: x, y, z (m), u1..un (N), stable, admissible (0/1), violations
                  (bit mask: ``summary.json``'s ``violation_bits``)
``failures.csv``  one row per failed point: u1..un, status, residual
``result.npz``    all arrays (points, u, failures, states if kept, cells for forward-backward)
``points.vtp``    the points as VTK PolyData with u as point data: opens in ParaView
``cells.vtu``     forward-backward only: the reached grid cells as VTK voxels
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..solvers.admissible import VIOLATIONS

__all__ = ["FAILURE_WARNING", "WorkspaceResult", "describe", "load_result"]

FAILURE_WARNING = 0.05
"""Share of failed solves above which the summary carries a warning."""


@dataclass
class WorkspaceResult:
    method: str
    """``forward`` or ``forward-backward``."""
    points: np.ndarray
    """Reachable end-effector positions (k, 3), metres."""
    u: np.ndarray
    """Inputs of the reachable points (k, n_u), N."""
    failed_u: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    """Inputs (or targets, for forward-backward) whose solve failed (f, n_u or 3)."""
    failed_status: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    """:class:`casadi_ws.status.Status` code of each failure."""
    failed_residual: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Relative residual reached by each failure."""
    states: np.ndarray | None = None
    """Nodal displacements of the reachable points (k, 3n), if kept."""
    violations: np.ndarray | None = None
    """Admissibility violations of each reported point, a bit mask (k,) (:mod:`casadi_ws.solvers.admissible`;
    0: admissible). Non-zero only for points kept by ``keep_inadmissible``; None: not checked."""
    counters: dict = field(default_factory=dict)
    """solves, newton_iterations, factorizations, ... (method-specific)."""
    timings: dict = field(default_factory=dict)
    """Seconds per phase; ``total`` is the whole run."""
    settings: dict = field(default_factory=dict)
    """The method's settings, as plain data."""
    problem: dict = field(default_factory=dict)
    """Name, source, mesh size, material, bounds: enough to say what was solved."""
    rest_tip: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """End-effector position at rest (u = 0, no load), metres."""
    arrays: dict = field(default_factory=dict)
    """Further method-specific arrays (e.g. the forward-backward cells), saved in result.npz."""
    measures: dict = field(default_factory=dict)
    """Volume, area, extents, task share (:func:`casadi_ws.workspace.measures.measures`), if computed."""

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def admissible(self) -> np.ndarray:
        """Whether each reported point passed every admissibility check, (k,)."""
        return self._violations() == 0

    @property
    def stable(self) -> np.ndarray:
        """Whether each reported point's tangent is positive definite, (k,)."""
        return (self._violations() & 1) == 0

    def _violations(self) -> np.ndarray:
        return np.zeros(self.n_points, dtype=np.int64) if self.violations is None else np.asarray(self.violations)

    @property
    def n_failed(self) -> int:
        return int(self.failed_status.shape[0])

    def warnings(self) -> list[str]:
        """Plain-language warnings about the run (e.g. many failed points)."""
        w = []
        solves = self.counters.get("solves", self.counters.get("backward_solves", 0))
        failed = self.n_failed if self.method == "forward" else self.counters.get("backward_failed", 0)
        if solves and failed / solves > FAILURE_WARNING:
            w.append(f"{failed} of {solves} solves failed ({100 * failed / solves:.0f} %, above "
                     f"{100 * FAILURE_WARNING:.0f} %): the estimate may miss parts of the workspace; see failures.csv")
        excluded = {k: v for k, v in self.counters.get("excluded", {}).items() if v}
        if excluded:
            w.append(f"{len(self.arrays.get('excluded_violations', []))} verified equilibria were not admissible and "
                     f"are not reported ({', '.join(f'{k}: {v}' for k, v in excluded.items())}); see "
                     f"result.npz's excluded_* arrays")
        if self.counters.get("stopped_at_max_cells"):
            w.append(f"the exploration stopped at its budget of {self.settings.get('max_cells')} explored cells "
                     f"(--max-cells): the result holds what was verified so far; the same command with --resume "
                     f"and a larger --max-cells continues it")
        return w

    def summary(self) -> dict:
        return {
            "method": self.method,
            "n_points": self.n_points,
            "n_failed": self.n_failed,
            "n_excluded": int(len(self.arrays.get("excluded_violations", []))),
            "excluded_by_check": self.counters.get("excluded", {}),
            "n_inadmissible_kept": int(np.count_nonzero(self._violations())),
            "violation_bits": {name: 1 << i for i, name in enumerate(VIOLATIONS)},
            "warnings": self.warnings(),
            "time_s": float(self.timings.get("total", float("nan"))),
            "settings": self.settings,
            "counters": self.counters,
            "timings": self.timings,
            "problem": self.problem,
            "rest_tip": self.rest_tip.tolist(),
            "bounding_box": ([self.points.min(0).tolist(), self.points.max(0).tolist()]
                             if self.n_points else None),
            "measures": self.measures,
            "units": {"points": "m", "u": "/".join(dict.fromkeys(a.get("unit", "N") for a in
                                                                  self.problem.get("actuators", []))) or "N",
                      "time_s": "s", "volume": "m^3", "area": "m^2"},
        }

    def save(self, directory: str | Path) -> Path:
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        (d / "summary.json").write_text(json.dumps(self.summary(), indent=2, default=_json_default) + "\n")
        self._save_points_csv(d / "points.csv")
        nf = self.failed_u.shape[1] if self.failed_u.ndim == 2 else 0
        fh = ",".join([f"u{i + 1}" for i in range(nf)] + ["status", "residual"])
        np.savetxt(d / "failures.csv", np.hstack([self.failed_u.reshape(self.n_failed, nf),
                                                  self.failed_status[:, None], self.failed_residual[:, None]]),
                   delimiter=",", header=fh, comments="", fmt="%.10g")
        arrays = dict(points=self.points, u=self.u, failed_u=self.failed_u, failed_status=self.failed_status,
                      failed_residual=self.failed_residual, rest_tip=self.rest_tip,
                      **{f"extra_{k}": v for k, v in self.arrays.items()})
        if self.states is not None:
            arrays["states"] = self.states
        arrays.update(stable=self.stable, admissible=self.admissible, violations=self._violations())
        np.savez_compressed(d / "result.npz", **arrays)
        self._save_vtp(d / "points.vtp")
        if "cells_centres" in self.arrays and len(self.arrays["cells_centres"]):
            self._save_cells(d / "cells.vtu")
        return d

    def _save_points_csv(self, path: Path) -> None:
        """x, y, z (m), u1..un, then stable, admissible (0/1) and the violations' bit mask (all numbers, so
        any CSV reader takes the file; bit i is ``VIOLATIONS[i]``, listed in summary.json)."""
        n_u = self.u.shape[1] if self.u.ndim == 2 else 0
        head = ",".join(["x", "y", "z"] + [f"u{i + 1}" for i in range(n_u)] + ["stable", "admissible", "violations"])
        data = np.hstack([self.points, self.u.reshape(self.n_points, n_u), self.stable[:, None],
                          self.admissible[:, None], self._violations()[:, None]])
        np.savetxt(path, data, delimiter=",", header=head, comments="", fmt=["%.10g"] * (3 + n_u) + ["%d"] * 3)

    def _save_cells(self, path: Path) -> None:
        """The reached cells as VTK voxels (forward-backward's W_E)."""
        import pyvista as pv

        c = np.asarray(self.arrays["cells_centres"])
        h = 0.5 * float(self.arrays["cell_step"])
        corners = np.array([[i, j, k] for k in (-1, 1) for j in (-1, 1) for i in (-1, 1)], float) * h
        pts = (c[:, None, :] + corners[None]).reshape(-1, 3)
        conn = np.arange(len(pts)).reshape(-1, 8)
        grid = pv.UnstructuredGrid({pv.CellType.VOXEL: conn}, pts)
        grid.cell_data["u_norm"] = np.linalg.norm(self.u, axis=1) if self.u.size else np.zeros(len(c))
        grid.save(str(path))

    def _save_vtp(self, path: Path) -> None:
        import pyvista as pv

        cloud = pv.PolyData(self.points if self.n_points else np.zeros((0, 3)))
        cloud.point_data["stable"] = self.stable.astype(np.uint8)
        cloud.point_data["admissible"] = self.admissible.astype(np.uint8)
        for i in range(self.u.shape[1] if self.u.ndim == 2 else 0):
            cloud.point_data[f"u{i + 1}"] = self.u[:, i]
        cloud.save(str(path))


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def load_result(directory: str | Path) -> WorkspaceResult:
    """Read a result written by :meth:`WorkspaceResult.save`."""
    d = Path(directory)
    summary = json.loads((d / "summary.json").read_text())
    with np.load(d / "result.npz") as z:
        a = {k: z[k] for k in z.files}
    return WorkspaceResult(
        method=summary["method"], points=a["points"], u=a["u"], failed_u=a["failed_u"],
        failed_status=a["failed_status"], failed_residual=a["failed_residual"], states=a.get("states"),
        violations=a.get("violations"),
        counters=summary["counters"], timings=summary["timings"], settings=summary["settings"],
        problem=summary["problem"], rest_tip=a["rest_tip"],
        arrays={k[len("extra_"):]: v for k, v in a.items() if k.startswith("extra_")},
        measures=summary.get("measures") or {})


def describe(problem, model) -> dict:
    """Plain-data description of what was solved, for result files."""
    return {
        "name": problem.name, "source": problem.source, "n_nodes": problem.mesh.n_nodes,
        "n_tets": problem.mesh.n_tets, "element": problem.mesh.element.name, "n_free_dofs": model.n_free,
        "material": asdict(problem.material), "n_u": model.n_u,
        "actuators": [{"name": a.name, "kind": a.kind, "unit": a.input_unit} for a in model.actuators],
        "u_min": model.u_min.tolist(), "u_max": model.u_max.tolist(),
        "end_effector": np.asarray(problem.end_effector).tolist(), "tolerance": problem.solver.tolerance,
        "admissibility": asdict(problem.admissibility),
    }
