"""The workspace result shared by all methods, its files, and loading it back.

A :class:`WorkspaceResult` holds the reachable end-effector points (each a verified equilibrium: relative
residual below tolerance and u inside U), their inputs, optionally their nodal states, the failures
(kept apart, never mixed in), counters, timings per phase, and the problem and settings used.

Files written by :meth:`WorkspaceResult.save` into a directory:

``summary.json``  method, n_points, n_failed and ``failures`` (prefiltered / not_reached / failed: what the
                  rows of failures.csv mean), time_s, settings, counters, timings, problem description,
                  measures (volume from the boundary surface, cell_volume, area, ...), the boundary's summary
``points.csv``    one row per reachable point: x, y, z (m), u1..un (N), stable, admissible (0/1), violations
                  (bit mask: ``summary.json``'s ``violation_bits``), then the maps (:mod:`.maps`): effort,
                  steerability, compliance, tilt, and each actuator's state state1..n
``failures.csv``  one row per failed point. Forward: u1..un, status, reason, residual. Forward-backward:
                  target_x, target_y, target_z (m), status, reason, closest_x, closest_y, closest_z (the tip
                  of the verified answer the backward solve returned, empty if it had none)
``result.npz``    all arrays (points, u, failures, states if kept, cells for forward-backward, maps,
                  boundary_vertices / _triangles / _u)
``points.vtu``    the points as VTK vertices with u, flags and maps as point data (with the orientation ranges:
                  tilt_min, tilt_max, dexterous, also in points.csv and cells.vtu)
``cells.vtu``     forward-backward only: the reached grid cells as hexahedra, with the maps as cell data
``dexterous.vtu`` with ``--orientation ...,cone=c``: the cells where the tip can point within the cone
``boundary.vtu``  the boundary surface (:mod:`.boundary`) as triangles (2 inputs: the workspace surface and
``boundary.stl``  its boundary curve as lines); STL for CAD. Every mesh file is VTK XML unstructured grid,
                  which both ParaView and meshio read (meshio does not read PolyData, .vtp)
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..solvers.admissible import VIOLATIONS
from ..status import Status
from .interval import default_step
from .maps import MAPS

__all__ = ["FAILURE_WARNING", "WorkspaceResult", "describe", "load_result"]

ORIENTATION_MAPS = ("tilt_min", "tilt_max", "dexterous")
"""Per point, where the orientation ranges were computed: the smallest and largest angle (deg) of the tip's axis
from the reference with the tip in the point's cell, and whether the cell is in the dexterous workspace (1/0)."""

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
    boundary: object = None
    """The boundary surface (:class:`casadi_ws.workspace.boundary.Boundary`), if built."""

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
        """Every target or input with no reported point (:meth:`failures` says why)."""
        return int(self.failed_status.shape[0])

    def failures(self) -> dict:
        """The rows of failures.csv by what they mean: ``prefiltered`` (forward-backward: not solved, the
        linearised closest point lies outside the target's cell: most are outside the workspace),
        ``not_reached`` (solved: the verified closest point lies outside the cell, or the solve stopped for
        that reason), ``failed`` (no verified equilibrium: what the warnings count)."""
        codes = np.asarray(self.failed_status, dtype=int)
        pre = int(np.count_nonzero(codes == Status.PREFILTERED))
        missed = int(np.count_nonzero(np.isin(codes, (Status.NOT_REACHED, Status.GAVE_UP))))
        return {"prefiltered": pre, "not_reached": missed, "failed": int(codes.size) - pre - missed}

    def failures_line(self) -> str:
        """``12 failed`` or, where some rows are not failures, ``226 prefiltered, 9 not reached, 2 failed``."""
        return failures_text(self.failures())

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
            if excluded.get("self_penetration"):
                w.append(f"{excluded['self_penetration']} of them pass through themselves: with 'self_contact: auto' "
                         f"in the problem file the body presses on itself instead (docs/problem-format.md)")
        if self.counters.get("path_dependent"):
            w.append(f"{self.counters['path_dependent']} equilibria depend on the path the inputs take (the robot "
                     f"loaded from a neighbouring point and from rest settles differently: buckling, snap-through or "
                     f"contact that holds); the one reached from rest is reported (docs/methods.md \"One answer per "
                     f"input\")")
        fold = getattr(self.boundary, "fold", None)
        if fold:
            vol = self.measures.get("volume")
            w.append("the map from inputs to tip folds over itself (det dp/du changes sign; inputs near the fold: "
                     + ", ".join("(" + ", ".join(f"{x:.3g}" for x in u) + ")" for u in fold.get("inputs", [])[:3])
                     + "): " + (f"the volume {vol * 1e6:.4g} cm^3 is that of the union of the images of U's grid "
                                f"cells" + _bounds_words(self.measures) if vol is not None else "no volume")
                     + " (docs/methods.md \"Folds\")")
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
            "failures": self.failures(),
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
            "boundary": self.boundary.summary() if self.boundary is not None else None,
            "units": {"points": "m", "u": "/".join(dict.fromkeys(a.get("unit", "N") for a in
                                                                  self.problem.get("actuators", []))) or "N",
                      "time_s": "s", "volume": "m^3", "area": "m^2"},
        }

    def save(self, directory: str | Path, summary: bool = True) -> Path:
        """The result files in ``directory``; ``summary.json``, which marks a result complete (what reads a
        result looks for it), last (``summary`` False: not at all, the caller writes more files first and
        then :meth:`write_summary`)."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        (d / "summary.json").unlink(missing_ok=True)  # an older result's: until this one is whole, none is there
        self._save_points_csv(d / "points.csv")
        self._save_failures_csv(d / "failures.csv")
        arrays = dict(points=self.points, u=self.u, failed_u=self.failed_u, failed_status=self.failed_status,
                      failed_residual=self.failed_residual, rest_tip=self.rest_tip,
                      **{f"extra_{k}": v for k, v in self.arrays.items()})
        if self.states is not None:
            arrays["states"] = self.states
        arrays.update(stable=self.stable, admissible=self.admissible, violations=self._violations())
        b = self.boundary
        if b is not None:
            arrays.update(boundary_vertices=b.vertices, boundary_triangles=b.triangles, boundary_u=b.u,
                          boundary_curve=np.zeros(0, int) if b.curve is None else b.curve)
        np.savez_compressed(d / "result.npz", **arrays)
        self._save_points(d / "points.vtu")
        if "cells_centres" in self.arrays and len(self.arrays["cells_centres"]):
            self._save_cells(d / "cells.vtu")
        if "dexterous_centres" in self.arrays:
            self._save_cells(d / "dexterous.vtu", self.arrays["dexterous_centres"], with_data=False)
        if b is not None and len(b.triangles):
            self._save_boundary(d)
        if summary:
            self.write_summary(d)
        return d

    def write_summary(self, directory: str | Path) -> None:
        """``summary.json``, whole or not at all (written beside and renamed): the mark of a complete result."""
        d = Path(directory)
        part = d / "summary.json.partial"
        part.write_text(json.dumps(self.summary(), indent=2, default=_json_default) + "\n")
        os.replace(part, d / "summary.json")

    def maps(self) -> dict:
        """The point maps (:mod:`casadi_ws.workspace.maps`) as arrays, NaN where not computed; with the
        orientation ranges (:mod:`.orientation`) their :data:`ORIENTATION_MAPS` too."""
        k, n_u = self.n_points, (self.u.shape[1] if self.u.ndim == 2 else 0)
        out = {name: np.asarray(self.arrays.get(f"map_{name}", np.full(k, np.nan)), float)
               for name in MAPS + self._orientation_maps()}
        for key in ("states", "intensities"):
            out[key] = np.asarray(self.arrays.get(f"map_{key}", np.full((k, n_u), np.nan)), float).reshape(k, n_u)
        return out

    def _save_failures_csv(self, path: Path) -> None:
        reason = [Status(int(c)).label if int(c) in Status._value2member_map_ else str(int(c))
                  for c in self.failed_status]
        k = self.n_failed
        if self.method == "forward-backward":
            closest = np.asarray(self.arrays.get("failed_closest", np.full((k, 3), np.nan))).reshape(k, 3)
            head = "target_x,target_y,target_z,status,reason,closest_x,closest_y,closest_z"
            rows = [",".join([*(f"{v:.10g}" for v in t), str(int(c)), r,
                              *("" if not np.isfinite(v) else f"{v:.10g}" for v in cl)])
                    for t, c, r, cl in zip(self.failed_u.reshape(k, 3), self.failed_status, reason, closest)]
        else:
            nf = self.failed_u.shape[1] if self.failed_u.ndim == 2 else 0
            head = ",".join([f"u{i + 1}" for i in range(nf)] + ["status", "reason", "residual"])
            rows = [",".join([*(f"{v:.10g}" for v in uu), str(int(c)), r, f"{res:.3g}"])
                    for uu, c, r, res in zip(self.failed_u.reshape(k, nf), self.failed_status, reason,
                                             self.failed_residual)]
        path.write_text("\n".join([head, *rows]) + "\n")

    def _point_data(self) -> dict:
        data = {"stable": self.stable.astype(np.uint8), "admissible": self.admissible.astype(np.uint8)}
        for i in range(self.u.shape[1] if self.u.ndim == 2 else 0):
            data[f"u{i + 1}"] = self.u[:, i]
        maps = self.maps()
        for name in MAPS + self._orientation_maps():
            data[name] = maps[name]
        for i in range(maps["states"].shape[1]):
            data[f"state{i + 1}"] = maps["states"][:, i]
            data[f"intensity{i + 1}"] = maps["intensities"][:, i]
        return data

    def _save_points_csv(self, path: Path) -> None:
        """x, y, z (m), u1..un, then stable, admissible (0/1) and the violations' bit mask (all numbers, so
        any CSV reader takes the file; bit i is ``VIOLATIONS[i]``, listed in summary.json), then the maps."""
        n_u = self.u.shape[1] if self.u.ndim == 2 else 0
        maps = self.maps()
        extra = self._orientation_maps()
        head = ",".join(["x", "y", "z"] + [f"u{i + 1}" for i in range(n_u)] + ["stable", "admissible", "violations"]
                        + list(MAPS) + [f"state{i + 1}" for i in range(n_u)]
                        + [f"intensity{i + 1}" for i in range(n_u)] + list(extra))
        data = np.hstack([self.points, self.u.reshape(self.n_points, n_u), self.stable[:, None],
                          self.admissible[:, None], self._violations()[:, None],
                          np.column_stack([maps[name] for name in MAPS]), maps["states"], maps["intensities"],
                          np.array([maps[name] for name in extra]).T.reshape(self.n_points, len(extra))])
        np.savetxt(path, data, delimiter=",", header=head, comments="",
                   fmt=["%.10g"] * (3 + n_u) + ["%d"] * 3 + ["%.6g"] * (len(MAPS) + n_u) + ["%.10g"] * n_u
                   + ["%.6g"] * len(extra))

    def _orientation_maps(self) -> tuple:
        """The orientation ranges' columns the result has (:data:`ORIENTATION_MAPS`, after
        :func:`casadi_ws.workspace.orientation.orientation_ranges`)."""
        return tuple(n for n in ORIENTATION_MAPS if f"map_{n}" in self.arrays)

    def _save_cells(self, path: Path, centres=None, with_data: bool = True) -> None:
        """The reached cells (forward-backward's W_E; or the cells at ``centres``, e.g. the dexterous workspace's)
        as hexahedra, the cell's point's maps as cell data."""
        import meshio

        c = np.asarray(self.arrays["cells_centres"] if centres is None else centres, float).reshape(-1, 3)
        step = self.arrays.get("cell_step", np.nan)
        if centres is not None or not np.isfinite(float(step)):
            step = self.measures.get("orientation", {}).get("cell_step", step)
        h = 0.5 * float(step)
        # VTK hexahedron order: the bottom face counter-clockwise, then the top face
        corners = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                            [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], float) * h
        pts = (c[:, None, :] + corners[None]).reshape(-1, 3)
        data = {k: [np.asarray(v, float)] for k, v in self._point_data().items()} \
            if with_data and len(c) == self.n_points else {}
        meshio.write(path, meshio.Mesh(pts, [("hexahedron", np.arange(len(pts)).reshape(-1, 8))], cell_data=data))

    def _save_points(self, path: Path) -> None:
        import meshio

        pts = self.points if self.n_points else np.zeros((0, 3))
        meshio.write(path, meshio.Mesh(pts, [("vertex", np.arange(len(pts))[:, None])],
                                       point_data={k: np.asarray(v, float) for k, v in self._point_data().items()}))

    def _save_boundary(self, d: Path) -> None:
        import meshio

        b = self.boundary
        cells = [("triangle", b.triangles)]
        if b.curve is not None and len(b.curve):
            ring = np.append(b.curve, b.curve[0])
            cells.append(("line", np.column_stack([ring[:-1], ring[1:]])))
        point_data = {f"u{i + 1}": b.u[:, i] for i in range(b.u.shape[1])}
        if b.violations is not None:
            point_data["admissible"] = (b.violations == 0).astype(float)
        meshio.write(d / "boundary.vtu", meshio.Mesh(b.vertices, cells, point_data=point_data))
        meshio.write(d / "boundary.stl", meshio.Mesh(b.vertices, [("triangle", b.triangles)]), binary=True)


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
        measures=summary.get("measures") or {}, boundary=_load_boundary(summary.get("boundary"), a))


def _load_boundary(info, a):
    if not info or "boundary_vertices" not in a:
        return None
    from .boundary_data import Boundary

    curve = a.get("boundary_curve")
    return Boundary(a["boundary_vertices"], a["boundary_triangles"], a["boundary_u"], info["method"],
                    closed=info["closed"], volume=info["volume"], volume_error=info["volume_error"],
                    area=info["area"], tolerance=info["tolerance"], failed=info.get("failed_nodes", 0),
                    curve=curve if curve is not None and len(curve) else None, notes=info.get("notes", []),
                    fold=info.get("fold", {}))


def _bounds_words(m: dict) -> str:
    lo, hi = m.get("volume_lower"), m.get("volume_upper")
    if lo is not None and hi is not None:
        return f", between {lo * 1e6:.4g} and {hi * 1e6:.4g} cm^3"
    return f", at most {hi * 1e6:.4g} cm^3" if hi is not None else ""


def failures_text(f: dict) -> str:
    """:meth:`WorkspaceResult.failures` (or a summary's ``failures``) in words; zero counts left out but
    ``failed``'s."""
    return ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in f.items() if v or k == "failed")


def describe(problem, model) -> dict:
    """Plain-data description of what was solved, for result files."""
    return {
        "name": problem.name, "source": problem.source, "n_nodes": problem.mesh.n_nodes,
        "n_tets": problem.mesh.n_tets, "element": problem.mesh.element.name, "n_free_dofs": model.n_free,
        "material": asdict(problem.material), "n_u": model.n_u,
        "actuators": [{"name": a.name, "kind": a.kind, "unit": a.input_unit} for a in model.actuators],
        "u_min": model.u_min.tolist(), "u_max": model.u_max.tolist(),
        "end_effector": np.asarray(problem.end_effector).tolist(), "tolerance": problem.solver.tolerance,
        "admissibility": asdict(problem.admissibility), "default_step": default_step(model),
        "obstacles": [{"name": o.name, "kind": o.kind} for o in problem.obstacles],
        "gravity": np.asarray(getattr(problem, "gravity", np.zeros(3)), float).tolist(),
    }
