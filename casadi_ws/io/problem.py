"""A workspace problem: the robot (mesh, material, boundary, loads), its actuators, and the point of interest.

Built in Python (``Problem(...)``) or read from a YAML file (:func:`load_problem`, format in
``docs/problem-format.md``). Every quantity is in SI units (m, N, Pa, kg/m^3); a mesh file drawn in another
unit is converted by its ``scale``/``units`` key. Reading a file validates it completely before any heavy
work: each mistake raises :class:`ProblemError` naming the file, the key path and what was expected.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..actuation.base import Actuator
from ..actuation.cable import Cable, trunk_cable
from ..fem.materials import FORMULATIONS, HYPERELASTIC_CONSTANTS, MATERIAL_MODELS, Material, hyperelastic
from ..fem.silicones import SILICONES
from ..fem.mesh import (Mesh, MeshError, box_mesh, closest_point_in_tet, embed, load_mesh, quadratic,
                        transform_points, trunk_mesh)
from ..fem.spec import AdmissibilitySettings, AutoSelfContact, ModelSpec, SelfContactPair, SolverSettings
from ..solvers.linear import LINEAR_SOLVERS, available

__all__ = [
    "Problem",
    "ProblemError",
    "SolverSettings",
    "default_problem",
    "load_problem",
    "nodes_in_box",
    "nodes_on_plane",
    "problem_from_dict",
]

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


class ProblemError(ValueError):
    """Invalid problem input. ``str()`` is one line: ``FILE: KEY: what was wrong``."""

    def __init__(self, source: str, key: str, message: str):
        self.source, self.key, self.message = source, key, message
        super().__init__(f"{source}: {key}: {message}" if key else f"{source}: {message}")


@dataclass
class Problem(ModelSpec):
    """A workspace problem: the model's specification (:class:`casadi_ws.fem.spec.ModelSpec`) and what the
    command line and the studies read beside it."""

    workspace: dict = field(default_factory=dict)
    """Defaults for ``casadi-ws solve`` from the file's ``workspace`` section (method, n_d, step, ...)."""
    task: object = None
    """A region the robot should reach (:class:`casadi_ws.workspace.measures.Task`), or None."""

    @property
    def cavities(self) -> list:
        """The actuators that are cavities, in input order."""
        return [a for a in self.actuators if a.kind == "cavity"]

    @property
    def cables(self) -> list[Cable]:
        """The actuators that are cables, in input order."""
        return [a for a in self.actuators if isinstance(a, Cable)]


def nodes_in_box(mesh: Mesh, lower, upper) -> np.ndarray:
    """Indices of the nodes inside the axis-aligned box [lower, upper] (like SOFA's BoxROI)."""
    x = mesh.nodes
    return np.flatnonzero(np.all((x >= np.asarray(lower)) & (x <= np.asarray(upper)), axis=1))


def nodes_on_plane(mesh: Mesh, point, normal, tolerance: float = 1e-9) -> np.ndarray:
    """Indices of the nodes on or behind the plane: (x - point) . n <= tolerance, n the unit normal."""
    n = np.asarray(normal, dtype=float)
    n = n / np.linalg.norm(n)
    return np.flatnonzero((mesh.nodes - np.asarray(point, dtype=float)) @ n <= tolerance)


# ---------------------------------------------------------------------------------------------------------
# YAML reading and validation
# ---------------------------------------------------------------------------------------------------------

_TOP_KEYS = {"name", "description", "mesh", "material", "material_regions", "gravity", "body_force", "fixed", "cables",
             "cavities", "end_effector", "loads", "solver", "workspace", "task", "admissibility", "obstacles",
             "self_contact", "springs", "pressure_loads"}
_MESH_GEN = {"generate", "length", "radius_base", "radius_tip", "resolution", "size", "divisions", "origin",
             "order"}
_MESH_FILE = {"file", "scale", "units", "order", "transform"}
_TRANSFORM = {"rotation", "translation", "scale"}
_CONSTANTS = {"c10", "c01", "c20", "c30", "mu", "alpha"}
_MATERIAL = {"name", "model", "young_modulus", "poisson_ratio", "density", "total_mass", "max_stretch",
             "bulk_modulus", "d1", "formulation", *_CONSTANTS}
_REGION = (_MATERIAL - {"total_mass"}) | {"box"}
_CABLE = {"name", "points", "indices", "pull_point", "trunk_routing", "u_min", "u_max", "stroke_max", "control",
          "spread"}
_CAVITY = {"name", "surface", "enclosing", "u_min", "u_max", "scale", "transform", "volume_max", "volume_max_ratio",
           "embed_tolerance", "control"}
_ADMISSIBILITY = {"stability", "inversion", "self_penetration", "min_det_F", "penetration_depth",
                  "keep_inadmissible"}
_COMPONENTS = {"x": 0, "y": 1, "z": 2}
_ROUTING = {"angle_deg", "kind", "radius", "taper", "z_start", "z_end", "spacing"}
_SOLVER = {"tolerance", "max_iterations", "max_load_steps", "newton", "linear"}
_WORKSPACE = {"method", "n_d", "step", "strategy", "backward", "workers"}

MAX_OUTSIDE_RELATIVE = 0.75
"""Largest distance from the mesh allowed for a cable passage point, in sizes (mean edges) of the element it
is attached to. SOFA's trunks run their cables in grooves just outside the mesh (0.15 and 0.62 element sizes
out on the two shipped ones); a point as far out as the body near it is thick (6.5 mm off the 2-cable
trunk's 5.5 mm-radius tip: 0.89 of its 7 mm elements) is a typo or a unit mistake. Relative to the mesh's
size (5 %, until issue 65) it let that one through: on a long thin robot the mesh's size is its length."""


def _as_number(v):
    """A YAML scalar as a number; PyYAML reads 1.8e7 (no exponent sign) as a string, accept it."""
    if isinstance(v, str):
        try:
            return float(v)
        except ValueError:
            return v
    return v


class _Reader:
    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, message: str):
        raise ProblemError(self.source, key, message)

    def mapping(self, value, key: str, allowed: set[str]) -> dict:
        if not isinstance(value, dict):
            self.fail(key, f"expected a mapping, got {type(value).__name__}")
        for k in value:
            if k not in allowed:
                close = difflib.get_close_matches(str(k), sorted(allowed), n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                self.fail(f"{key}.{k}" if key else str(k),
                          f"unknown key{hint}; expected one of: {', '.join(sorted(allowed))}")
        return value

    def number(self, d: dict, name: str, key: str, default=None, *, lo=None, hi=None, lo_open=False,
               hi_open=False, integer=False):
        path = f"{key}.{name}" if key else name
        if name not in d or d[name] is None:
            if default is None:
                self.fail(path, "missing (a number is required)")
            return default
        v = _as_number(d[name])
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(path, f"expected a number, got {v!r}")
        if not math.isfinite(v):
            self.fail(path, f"expected a finite number, got {v!r}")
        if integer and int(v) != v:
            self.fail(path, f"expected an integer, got {v!r}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            self.fail(path, f"must be {'>' if lo_open else '>='} {lo}, got {v!r}")
        if hi is not None and (v >= hi if hi_open else v > hi):
            self.fail(path, f"must be {'<' if hi_open else '<='} {hi}, got {v!r}")
        return int(v) if integer else float(v)

    def optional(self, d: dict, name: str, key: str, **limits):
        """A number that may be absent (None then), validated like :meth:`number`."""
        return self.number(d, name, key, **limits) if d.get(name) is not None else None

    def flag(self, d: dict, name: str, key: str, default: bool) -> bool:
        v = d.get(name, default)
        if not isinstance(v, bool):
            self.fail(f"{key}.{name}", f"expected true or false, got {v!r}")
        return v

    def vector(self, v, path: str, n: int = 3) -> np.ndarray:
        if not isinstance(v, (list, tuple)) or len(v) != n:
            self.fail(path, f"expected a list of {n} numbers, got {v!r}")
        v = [_as_number(x) for x in v]
        for i, x in enumerate(v):
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                self.fail(f"{path}[{i}]", f"expected a finite number, got {x!r}")
        return np.asarray(v, dtype=float)

    def points(self, v, path: str) -> np.ndarray:
        if not isinstance(v, (list, tuple)) or len(v) == 0:
            self.fail(path, f"expected a list of [x, y, z] points, got {v!r}")
        return np.stack([self.vector(p, f"{path}[{i}]") for i, p in enumerate(v)])


def _read_mesh(r: _Reader, d, base: Path) -> tuple[Mesh, dict]:
    if not isinstance(d, dict):
        r.fail("mesh", "expected a mapping with 'generate' or 'file'")
    order = d.get("order", 1)
    if order not in (1, 2) or isinstance(order, bool):
        r.fail("mesh.order", f"expected 1 (4-node tetrahedra) or 2 (10-node tetrahedra), got {order!r}")
    mesh, info = _read_mesh_cells(r, d, base)
    if order == 2:
        try:
            mesh = quadratic(mesh)
        except MeshError as exc:
            r.fail("mesh.order", str(exc))
    elif mesh.element.order == 2:
        r.fail("mesh.order", f"the file holds 10-node tetrahedra: say 'order: 2' (got {order})")
    return mesh, info


def _read_mesh_cells(r: _Reader, d, base: Path) -> tuple[Mesh, dict]:
    if "file" in d:
        r.mapping(d, "mesh", _MESH_FILE)
        f = d["file"]
        if not isinstance(f, str):
            r.fail("mesh.file", f"expected a path, got {f!r}")
        scale = 1.0
        if "units" in d:
            if d["units"] not in UNITS:
                r.fail("mesh.units", f"expected one of {', '.join(UNITS)}, got {d['units']!r}")
            scale = UNITS[d["units"]]
        if "scale" in d:
            scale = r.number(d, "scale", "mesh", lo=0.0, lo_open=True)
        path = Path(f) if Path(f).is_absolute() else base / f
        transform = _read_transform(r, d.get("transform"), "mesh.transform")
        try:
            return load_mesh(path, scale, transform), {}
        except MeshError as exc:
            r.fail("mesh.file", str(exc))
    r.mapping(d, "mesh", _MESH_GEN)
    try:
        return _generate_mesh(r, d)
    except MeshError as exc:  # e.g. a box so flat that its tetrahedra are degenerate
        r.fail("mesh", str(exc))


def _read_transform(r: _Reader, d, key: str):
    """``transform: {rotation: [rx, ry, rz] (degrees), translation: [x, y, z] (m), scale: s or [sx, sy, sz]}``
    (SOFA's loader data) as a function of (n, 3) points in metres, or None."""
    if d is None:
        return None
    r.mapping(d, key, _TRANSFORM)
    rotation = r.vector(d.get("rotation", [0, 0, 0]), f"{key}.rotation")
    translation = r.vector(d.get("translation", [0, 0, 0]), f"{key}.translation")
    sc = d.get("scale", 1.0)
    scale = r.vector(sc, f"{key}.scale") if isinstance(sc, (list, tuple)) else r.number(d, "scale", key, 1.0)
    if np.any(np.asarray(scale) == 0):
        r.fail(f"{key}.scale", f"must not be zero, got {sc!r}")
    return lambda x: transform_points(x, rotation, translation, scale)


def _generate_mesh(r: _Reader, d) -> tuple[Mesh, dict]:
    kind = d.get("generate")
    if kind == "trunk":
        args = {k: r.number(d, k, "mesh", dflt, lo=0.0, lo_open=True) for k, dflt in
                (("length", 0.195), ("radius_base", 0.013), ("radius_tip", 0.005), ("resolution", 1.0))}
        n_xy = max(2, 2 * int(round(3 * args["resolution"])))
        n_z = max(2, int(round(20 * args["resolution"])))
        _check_size(r, "mesh.resolution", 6 * n_xy * n_xy * n_z)
        return trunk_mesh(**args), args
    if kind == "box":
        size = r.vector(d.get("size", [1, 1, 1]), "mesh.size")
        div = r.vector(d.get("divisions", [2, 2, 2]), "mesh.divisions")
        if np.any(size <= 0):
            r.fail("mesh.size", f"all sizes must be > 0, got {size.tolist()}")
        if np.any(div < 1) or np.any(div != np.round(div)):
            r.fail("mesh.divisions", f"expected positive integers, got {div.tolist()}")
        _check_size(r, "mesh.divisions", 6 * float(np.prod(div)))
        origin = r.vector(d.get("origin", [0, 0, 0]), "mesh.origin")
        return box_mesh(tuple(size), tuple(int(x) for x in div), tuple(origin)), {}
    r.fail("mesh", "expected 'file: PATH' or 'generate: trunk|box'" if kind is None else
           f"mesh.generate: expected 'trunk' or 'box', got {kind!r}")


# Largest generated mesh: beyond this the model would need tens of GB (and hours per solve).
MAX_GENERATED_TETS = 2_000_000


def _check_size(r: _Reader, key: str, n_tets: float) -> None:
    if n_tets > MAX_GENERATED_TETS:
        r.fail(key, f"would generate {n_tets:.3g} tetrahedra, more than {MAX_GENERATED_TETS:.0e}")


def _read_fixed(r: _Reader, d, mesh: Mesh, obstacles=(), held=()):
    """``fixed``: one selection or a list of them; each a box or a plane, optionally with ``components``.
    Returns (fully fixed nodes, [(nodes, components)]). An obstacle the body touches at rest supports it
    along its normal (a block resting on a table): its touching nodes count in the rigid-motion test, as do
    the nodes ``held`` by springs (``springs``: then ``fixed`` may be absent, an empty list)."""
    from ..fem.contact import boundary_nodes

    if isinstance(d, list) and not d and held:
        parts = []
    elif isinstance(d, list):
        if not d:
            r.fail("fixed", "expected a selection or a non-empty list of selections")
        parts = [_read_selection(r, s, mesh, f"fixed[{i}]", alone=False) for i, s in enumerate(d)]
    else:
        parts = [_read_selection(r, d, mesh, "fixed", alone=True)]
    full = np.unique(np.concatenate([n for n, c in parts if c == (0, 1, 2)] + [np.zeros(0, dtype=np.int64)]))
    partial = [(n, c) for n, c in parts if c != (0, 1, 2)]
    # rigid motions are prevented only if no infinitesimal rigid motion leaves every fixed component at 0
    rows = []
    for nodes, comps in [(full, (0, 1, 2))] + partial + [(h, (0, 1, 2)) for h in held]:
        x = mesh.nodes[nodes] - mesh.nodes.mean(0)
        for c in comps:
            modes = np.zeros((len(nodes), 6))
            modes[:, c] = 1.0
            # rotation about axis a moves component c by (e_a x x)_c
            for a in range(3):
                modes[:, 3 + a] = np.cross(np.eye(3)[a], x)[:, c]
            rows.append(modes)
    scale = mesh.characteristic_length()
    nodes = boundary_nodes(mesh) if obstacles else None
    for ob in obstacles:
        dist, nrm, _ = ob.gap(mesh.nodes[nodes])
        touch = dist <= 1e-6 * scale
        x = mesh.nodes[nodes[touch]] - mesh.nodes.mean(0)
        modes = np.column_stack([nrm[touch]] + [np.einsum("ij,ij->i", np.cross(np.eye(3)[a], x), nrm[touch])
                                                for a in range(3)])
        rows.append(modes)
    M = np.vstack(rows) if rows else np.zeros((0, 6))
    M[:, 3:] /= scale
    if M.shape[0] < 6 or np.linalg.svd(M, compute_uv=False)[5] <= 1e-6 * np.sqrt(max(len(M), 1)):
        r.fail("fixed", f"the supports ({full.size} fully fixed node(s), {len(partial)} partial selection(s)) do "
                    f"not prevent rigid motion")
    return full, partial


def _read_selection(r: _Reader, d, mesh: Mesh, key: str, alone: bool):
    """One support; ``alone``: the only one, so a full clamp needs three non-collinear nodes itself (the
    message users of a single box know), else the rank test on all supports together decides."""
    if isinstance(d, dict) and "components" in d:
        comps_raw = d["components"]
        d = {k: v for k, v in d.items() if k != "components"}
        if not isinstance(comps_raw, list) or not comps_raw or \
                any(not isinstance(c, str) or c not in _COMPONENTS for c in comps_raw):
            r.fail(f"{key}.components", f"expected a non-empty list of x, y, z, got {comps_raw!r}")
        comps = tuple(sorted({_COMPONENTS[c] for c in comps_raw}))
    else:
        comps = (0, 1, 2)
    kinds = ("box", "plane", "sphere", "indices")
    if not isinstance(d, dict) or len(d) != 1 or next(iter(d)) not in kinds:
        r.fail(key, f"expected exactly one of 'box: [[xmin, ymin, zmin], [xmax, ymax, zmax]]' (or six numbers), "
                    f"'plane: {{point, normal, tolerance}}', 'sphere: {{center, radius}}' or 'indices: [...]' "
                    f"(and optionally 'components'), got {d!r}")
    if "box" in d:
        lo, hi = _read_box(r, d["box"], f"{key}.box")
        nodes, key = nodes_in_box(mesh, lo, hi), f"{key}.box"
    elif "sphere" in d:
        b = r.mapping(d["sphere"], f"{key}.sphere", {"center", "radius"})
        center = r.vector(b.get("center"), f"{key}.sphere.center")
        radius = r.number(b, "radius", f"{key}.sphere", lo=0.0, lo_open=True)
        nodes, key = np.flatnonzero(np.linalg.norm(mesh.nodes - center, axis=1) <= radius), f"{key}.sphere"
    elif "indices" in d:
        nodes, key = _read_indices(r, d["indices"], mesh, f"{key}.indices"), f"{key}.indices"
    else:
        p = r.mapping(d["plane"], f"{key}.plane", {"point", "normal", "tolerance"})
        point = r.vector(p.get("point"), f"{key}.plane.point")
        normal = r.vector(p.get("normal"), f"{key}.plane.normal")
        if np.linalg.norm(normal) == 0:
            r.fail(f"{key}.plane.normal", "must not be the zero vector")
        tol = r.number(p, "tolerance", f"{key}.plane", 1e-6 * mesh.characteristic_length(), lo=0.0)
        nodes, key = nodes_on_plane(mesh, point, normal, tol), f"{key}.plane"
    if nodes.size == 0:
        lo, hi = mesh.nodes.min(0), mesh.nodes.max(0)
        r.fail(key, f"selects no node (mesh spans {np.round(lo, 6).tolist()} to {np.round(hi, 6).tolist()} m)")
    if alone and comps == (0, 1, 2):
        x = mesh.nodes[nodes] - mesh.nodes[nodes].mean(0)
        sv = np.linalg.svd(x, compute_uv=False) if nodes.size >= 3 else np.zeros(2)
        if nodes.size < 3 or sv[1] <= 1e-6 * mesh.characteristic_length():
            r.fail(key, f"selects {nodes.size} node(s) on a line or fewer: they do not prevent rigid motion")
    return nodes, comps


def _read_box(r: _Reader, b, key: str) -> tuple[np.ndarray, np.ndarray]:
    """A box as ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` or SOFA's six numbers
    ``[xmin, ymin, zmin, xmax, ymax, zmax]``."""
    if isinstance(b, (list, tuple)) and len(b) == 6:
        v = r.vector(b, key, 6)
        lo, hi = v[:3], v[3:]
    elif isinstance(b, (list, tuple)) and len(b) == 2:
        lo, hi = r.vector(b[0], f"{key}[0]"), r.vector(b[1], f"{key}[1]")
    else:
        r.fail(key, f"expected [[xmin, ymin, zmin], [xmax, ymax, zmax]] or [xmin, ymin, zmin, xmax, ymax, zmax], "
                    f"got {b!r}")
    if np.any(lo > hi):
        r.fail(key, f"lower corner {lo.tolist()} exceeds upper corner {hi.tolist()}")
    return lo, hi


def _read_indices(r: _Reader, v, mesh: Mesh, key: str) -> np.ndarray:
    """Point indices of the mesh file (SOFA's ``indices``), as mesh nodes; each must be a point some
    tetrahedron uses."""
    if not isinstance(v, (list, tuple)) or not v or \
            any(isinstance(i, bool) or not isinstance(i, int) or i < 0 for i in v):
        r.fail(key, f"expected a non-empty list of non-negative integers, got {v!r}")
    nodes = mesh.node_of_file_index(v)
    bad = np.flatnonzero(nodes < 0)
    if bad.size:
        n_points = mesh.n_nodes if mesh.file_nodes is None else int(mesh.file_nodes.max()) + 1
        r.fail(f"{key}[{int(bad[0])}]", f"index {v[int(bad[0])]} is not a node of the mesh (the mesh has "
                                        f"{mesh.n_nodes} nodes used by tetrahedra, file points 0..{n_points - 1})")
    return nodes


def _read_cavities(r: _Reader, lst, mesh: Mesh, base: Path) -> list:
    from .cavities import cavity_enclosing, cavity_from_surface

    if not isinstance(lst, list) or not lst:
        r.fail("cavities", "expected a non-empty list of cavities")
    out = []
    for i, c in enumerate(lst):
        key = f"cavities[{i}]"
        r.mapping(c, key, _CAVITY)
        name = str(c.get("name", f"cavity{i + 1}"))
        control = _control(r, c, key, ("pressure", "volume"))
        unit = "m^3" if control == "volume" else "Pa"
        u_min = r.number(c, "u_min", key, 0.0)
        u_max = r.number(c, "u_max", key)
        if u_min > u_max:
            r.fail(f"{key}.u_min", f"lower bound {u_min} {unit} exceeds upper bound u_max = {u_max} {unit}")
        if ("surface" in c) == ("enclosing" in c):
            r.fail(key, "give exactly one of 'surface: FILE' or 'enclosing: [x, y, z]'")
        try:
            if "surface" in c:
                path = base / str(c["surface"])
                if not path.is_file():
                    r.fail(f"{key}.surface", f"file not found: {path}")
                scale = r.number(c, "scale", key, 1.0, lo=0.0, lo_open=True)
                transform = _read_transform(r, c.get("transform"), f"{key}.transform")
                tol = r.optional(c, "embed_tolerance", key, lo=0.0)
                cav = cavity_from_surface(mesh, path, name, u_min, u_max, scale, transform, tol)
            else:
                if "scale" in c:
                    r.fail(f"{key}.scale", "only a surface file has a scale")
                cav = cavity_enclosing(mesh, r.vector(c["enclosing"], f"{key}.enclosing"), name, u_min, u_max)
        except ProblemError:
            raise
        except ValueError as exc:
            r.fail(f"{key}.surface" if "surface" in c else f"{key}.enclosing", str(exc))
        if "volume_max" in c and "volume_max_ratio" in c:
            r.fail(key, "give volume_max (m^3) or volume_max_ratio (of the rest volume), not both")
        cav.volume_max = r.optional(c, "volume_max", key, lo=0.0, lo_open=True)
        ratio = r.optional(c, "volume_max_ratio", key, lo=0.0, lo_open=True)
        if ratio is not None:
            cav.volume_max = ratio * cav.rest_volume()
        cav.control = control
        if cav.volume_max is not None and cav.volume_max <= cav.rest_volume():
            r.fail(f"{key}.volume_max" + ("_ratio" if ratio is not None else ""),
                   f"the limit {cav.volume_max:.6g} m^3 is not above the rest volume {cav.rest_volume():.6g} m^3")
        out.append(cav)
    return out


def _read_cables(r: _Reader, lst, mesh: Mesh) -> list[Cable]:
    if not isinstance(lst, list) or not lst:
        r.fail("cables", "expected a non-empty list of cables")
    cables = []
    for i, c in enumerate(lst):
        key = f"cables[{i}]"
        r.mapping(c, key, _CABLE)
        name = str(c.get("name", f"cable{i + 1}"))
        control = _control(r, c, key, ("force", "displacement"))
        u_min = r.number(c, "u_min", key, 0.0)
        # a tension has a usual default; a stroke depends on the robot's size, so it must be given
        u_max = r.number(c, "u_max", key, 100.0 if control == "force" else None)
        if u_min > u_max:
            r.fail(f"{key}.u_min", f"lower bound {u_min} exceeds upper bound u_max = {u_max}")
        if "trunk_routing" in c:
            if "points" in c:
                r.fail(key, "give either 'points' or 'trunk_routing', not both")
            t = r.mapping(c["trunk_routing"], f"{key}.trunk_routing", _ROUTING)
            kind = t.get("kind", "long")
            if kind not in ("long", "short"):
                r.fail(f"{key}.trunk_routing.kind", f"expected 'long' or 'short', got {kind!r}")
            opts = {k: r.number(t, k, f"{key}.trunk_routing") for k in _ROUTING - {"kind"} if k in t}
            cable = trunk_cable(kind=kind, u_min=u_min, u_max=u_max, name=name,
                                **{"angle_deg": 0.0, **opts})
        else:
            if ("points" in c) == ("indices" in c):
                r.fail(f"{key}.points", "give the passage points, their mesh node 'indices' or a 'trunk_routing'"
                       if "points" not in c else "give either 'points' or 'indices', not both")
            nodes = None
            if "indices" in c:
                nodes = _read_indices(r, c["indices"], mesh, f"{key}.indices")
                pts = mesh.nodes[nodes]
            else:
                pts = r.points(c["points"], f"{key}.points")
            pull = r.vector(c["pull_point"], f"{key}.pull_point") if c.get("pull_point") is not None else None
            if len(pts) < 2 and pull is None:
                r.fail(f"{key}.points", "a cable needs at least two points, or one point and a pull_point")
            cable = Cable(pts, pull, u_min, u_max, name, nodes=nodes)
        emb = embed(mesh, cable.points)
        local = mesh.element_sizes()[emb.tet]
        far = np.flatnonzero(emb.outside > MAX_OUTSIDE_RELATIVE * local)
        if far.size:
            j = int(far[0])
            r.fail(f"{key}.points[{j}]", f"point {np.round(cable.points[j], 6).tolist()} lies "
                   f"{emb.outside[j]:.4g} m outside the body, {emb.outside[j] / local[j]:.2f} of the size of the "
                   f"element nearest to it ({local[j]:.3g} m; allowed: {MAX_OUTSIDE_RELATIVE:g}); check its "
                   f"coordinates and the mesh's units")
        cable.stroke_max = r.optional(c, "stroke_max", key, lo=0.0, lo_open=True)
        cable.spread = r.optional(c, "spread", key, lo=0.0, lo_open=True)
        if cable.spread is not None:
            from ..fem.contact import boundary_nodes

            b = mesh.nodes[boundary_nodes(mesh)]
            gap = [float(np.linalg.norm(b - p, axis=1).min()) for p in cable.points]
            if max(gap) >= cable.spread:
                j = int(np.argmax(gap))
                r.fail(f"{key}.spread", f"no boundary node of the body within {cable.spread:g} m of point {j} "
                                        f"(the nearest is {gap[j]:.3g} m away)")
        cable.control = control
        cables.append(cable)
    return cables


def _control(r: _Reader, c: dict, key: str, allowed: tuple[str, str]) -> str:
    v = c.get("control", allowed[0])
    if v not in allowed:
        r.fail(f"{key}.control", f"expected {allowed[0]} (u is the {'tension' if allowed[0] == 'force' else 'pressure'}) "
                                 f"or {allowed[1]} (u is the {'shortening, m' if allowed[1] == 'displacement' else 'volume growth, m^3'}), got {v!r}")
    return v


def tip_centre(mesh: Mesh, axis: str = "+z") -> np.ndarray:
    """Centre of the mesh's end face along ``axis`` (``+z``, ``-x``, ...): the mean of the nodes farthest
    along it."""
    sign = -1.0 if axis.startswith("-") else 1.0
    c = _COMPONENTS[axis[-1]]
    h = sign * mesh.nodes[:, c]
    top = mesh.nodes[h >= h.max() - 1e-6 * mesh.characteristic_length()]
    out = top.mean(axis=0)
    out[c] = mesh.nodes[np.argmax(h), c]
    return out


_AXES = ("x", "y", "z", "+x", "+y", "+z", "-x", "-y", "-z")


def _read_end_effector(r: _Reader, ee, mesh: Mesh) -> tuple[np.ndarray, np.ndarray | None]:
    """``end_effector``: ``tip`` (the +z end), ``{tip: {axis: -x}}``, a point ``[x, y, z]`` inside the mesh, or
    ``{point: [x, y, z], snap: distance}`` (a point up to ``snap`` metres outside, moved onto the mesh: a
    SOFA effector often sits on the surface, a rounding away from it). A mapping may add ``frame``: three
    points at the tip whose plane carries its orientation (:mod:`casadi_ws.fem.frame`), or ``tip`` (with
    ``tip``: the end face's centre and two of its nodes a quarter turn apart). Returns (point, frame or None)."""
    snap, frame = 0.0, None
    if ee == "tip":
        return tip_centre(mesh), None
    if isinstance(ee, dict) and "tip" in ee:
        r.mapping(ee, "end_effector", {"tip", "frame"})
        t = r.mapping(ee["tip"], "end_effector.tip", {"axis"})
        axis = str(t.get("axis", "+z"))
        if axis not in _AXES:
            r.fail("end_effector.tip.axis", f"expected one of {', '.join(_AXES)}, got {axis!r}")
        point = tip_centre(mesh, axis)
        if ee.get("frame") is not None:
            if ee["frame"] != "tip":
                frame = _read_frame(r, ee["frame"], mesh)
            else:
                try:
                    frame = tip_frame_points(mesh, axis)
                except ValueError as exc:
                    r.fail("end_effector.frame", f"tip: {exc}; give three points [[x, y, z], ...]")
        return point, frame
    if isinstance(ee, dict):
        r.mapping(ee, "end_effector", {"point", "snap", "frame"})
        point = r.vector(ee.get("point"), "end_effector.point")
        snap = r.number(ee, "snap", "end_effector", 0.0, lo=0.0)
        if ee.get("frame") == "tip":
            r.fail("end_effector.frame", "'tip' needs end_effector: {tip: ...}; give three points [[x, y, z], ...]")
        if ee.get("frame") is not None:
            frame = _read_frame(r, ee["frame"], mesh)
    else:
        point = r.vector(ee, "end_effector")
    emb = embed(mesh, point[None])
    out = emb.outside[0]
    if out > max(snap, 1e-6 * mesh.characteristic_length()):
        r.fail("end_effector", f"point {point.tolist()} lies {out:.4g} m outside the mesh"
               + (f" (snap allows {snap:.4g} m)" if snap else " (give {point, snap} to move it onto the mesh)"))
    if out > 0:
        point = closest_point_in_tet(point, mesh.nodes[mesh.corners[emb.tet[0]]])
    return point, frame


def _read_frame(r: _Reader, v, mesh: Mesh) -> np.ndarray:
    """``end_effector.frame``: three points inside the mesh, not on one line."""
    if not (isinstance(v, list) and len(v) == 3):
        r.fail("end_effector.frame", f"expected three points [[x, y, z], [x, y, z], [x, y, z]] or 'tip', got {v!r}")
    P = np.array([r.vector(x, f"end_effector.frame[{i}]") for i, x in enumerate(v)])
    L = mesh.characteristic_length()
    for i, out in enumerate(embed(mesh, P).outside):
        if out > 1e-6 * L:
            r.fail(f"end_effector.frame[{i}]", f"point {P[i].tolist()} lies {out:.4g} m outside the mesh")
    area = np.linalg.norm(np.cross(P[1] - P[0], P[2] - P[0])) / 2
    size = max(np.linalg.norm(P[1] - P[0]), np.linalg.norm(P[2] - P[0]), 1e-300)
    if not area > 0.01 * size**2:
        r.fail("end_effector.frame", f"the three points lie (nearly) on one line (triangle area {area:.3g} m^2): "
                                     f"they must span a plane")
    return P


def tip_frame_points(mesh: Mesh, axis: str = "+z") -> np.ndarray:
    """Three points of the end face along ``axis``: its centre, the face node farthest from it, and the face
    node most nearly a quarter turn from that one about the centre."""
    sign = -1.0 if axis.startswith("-") else 1.0
    c = _COMPONENTS[axis[-1]]
    h = sign * mesh.nodes[:, c]
    face = mesh.nodes[h >= h.max() - 1e-6 * mesh.characteristic_length()]
    centre = tip_centre(mesh, axis)
    r = face - centre
    a = r[np.argmax(np.linalg.norm(r, axis=1))]
    n = np.zeros(3)
    n[c] = 1.0
    b = r[np.argmax(np.cross(a, r) @ n * sign)]
    if not np.linalg.norm(np.cross(a, b)) > 1e-3 * np.linalg.norm(a) ** 2:
        raise ValueError(f"the end face along {axis} has no three nodes spanning a plane")
    return np.array([centre, centre + a, centre + b])


def _read_regions(r: _Reader, lst, mesh: Mesh, material: Material) -> list:
    """``material_regions``: (tetrahedra whose centroid lies in the box, Material) pairs. A region keeps the
    body's law and constants except those it gives; with ``model`` or ``name`` it has a law of its own."""
    regions = []
    lst = lst or []
    if not isinstance(lst, list):
        r.fail("material_regions", "expected a list of {box, and the material keys that differ from the body's}")
    centroids = mesh.nodes[mesh.corners].mean(axis=1)
    for i, g in enumerate(lst):
        key = f"material_regions[{i}]"
        r.mapping(g, key, _REGION)
        lo, hi = _read_box(r, g.get("box"), f"{key}.box")
        tets = np.flatnonzero(np.all((centroids >= lo) & (centroids <= hi), axis=1))
        if tets.size == 0:
            r.fail(f"{key}.box", "holds the centroid of no tetrahedron")
        own = "model" in g or "name" in g
        regions.append((tets, _read_material(r, g, key, mesh, None if own else material)))
    return regions


LOCKING_NU = 0.49
"""Above this Poisson ratio 4-node tetrahedra are refused: they lock (a thick-walled sphere's volume change
under pressure is 77 % low at 0.49, 95 % at 0.499; docs/methods.md "Nearly incompressible silicone"), and
10-node ones take the continuous pressure (``formulation: taylor_hood``) by default."""


def _read_material(r: _Reader, m: dict, key: str, mesh: Mesh, base: Material | None = None) -> Material:
    """A ``material`` mapping (the body's, or a region's over the body's ``base``): a law with E and nu, or
    a strain-energy law with its constants, optionally starting from a named silicone."""
    mat = _read_law(r, m, key, mesh, base)
    if mesh.tets.shape[1] == 4 and mat.poisson_ratio > LOCKING_NU:
        given = next((k for k in ("poisson_ratio", "bulk_modulus", "d1") if k in m), None)
        r.fail(f"{key}.{given}" if given else key,
               f"nu = {mat.poisson_ratio:.4g}: 4-node tetrahedra lock above nu = {LOCKING_NU} (a thick sphere's "
               f"volume change is 95 % low at 0.499); mesh with order: 2, whose pressure formulations do not lock")
    return mat


def _read_law(r: _Reader, m: dict, key: str, mesh: Mesh, base: Material | None) -> Material:
    entry = {}
    if "name" in m:
        name = m["name"]
        if name not in SILICONES:
            close = difflib.get_close_matches(str(name), SILICONES, n=1)
            r.fail(f"{key}.name", f"unknown material {name!r}; expected one of {', '.join(SILICONES)}"
                   + (f" (did you mean '{close[0]}'?)" if close else ""))
        entry = SILICONES[name]
        if "model" in m and m["model"] != entry["model"]:
            r.fail(f"{key}.model", f"{name} is a {entry['model']} fit; give its name or another model, not both")
    model = m.get("model", entry.get("model", base.model if base is not None else "corotational"))
    if model not in MATERIAL_MODELS:
        close = difflib.get_close_matches(str(model), MATERIAL_MODELS, n=1)
        r.fail(f"{key}.model", f"expected one of {', '.join(MATERIAL_MODELS)}, got {model!r}"
               + (f" (did you mean '{close[0]}'?)" if close else ""))
    inherit = base if base is not None and base.model == model else None
    density = r.number(m, "density", key, entry.get("density", inherit.density if inherit else 1000.0), lo=0.0)
    max_stretch = _max_stretch(r, m, key, inherit.max_stretch if inherit else None)
    names = HYPERELASTIC_CONSTANTS.get(model)
    if names is None:
        for k in sorted((_CONSTANTS | {"bulk_modulus", "d1", "formulation"}) & set(m)):
            r.fail(f"{key}.{k}", f"is a constant of the strain-energy laws ({', '.join(HYPERELASTIC_CONSTANTS)}); "
                                 f"{model} takes young_modulus and poisson_ratio")
        return Material(model,
                        r.number(m, "young_modulus", key, inherit.young_modulus if inherit else None, lo=0.0,
                                 lo_open=True),
                        r.number(m, "poisson_ratio", key, inherit.poisson_ratio if inherit else None, lo=-1.0,
                                 hi=0.5, lo_open=True, hi_open=True),
                        density, max_stretch)
    if "young_modulus" in m:
        r.fail(f"{key}.young_modulus", f"{model} is given by its constants ({', '.join(names)}, Pa) and "
                                       f"bulk_modulus, d1 or poisson_ratio, not by young_modulus")
    for k in sorted((_CONSTANTS - set(names)) & set(m)):
        r.fail(f"{key}.{k}", f"is not a constant of {model} (its constants: {', '.join(names)})")
    constants = dict(inherit.constants) if inherit else {k: entry[k] for k in names if k in entry}
    for k in names:
        if k in m:
            constants[k] = _numbers(r, m[k], f"{key}.{k}") if model == "ogden" else r.number(m, k, key)
    if not any(k in m for k in names) and not entry and not inherit:
        r.fail(key, f"{model}: give its constants {', '.join(names)} (Pa), or a named material (name: ...)")
    given = [k for k in ("bulk_modulus", "d1", "poisson_ratio") if k in m]
    if len(given) > 1:
        r.fail(f"{key}.{given[1]}", f"give one of bulk_modulus (Pa), d1 (1/Pa) or poisson_ratio, not {' and '.join(given)}")
    bulk = constants.pop("bulk_modulus", None)
    nu = None
    if given == ["bulk_modulus"]:
        bulk = r.number(m, "bulk_modulus", key, lo=0.0, lo_open=True)
    elif given == ["d1"]:
        bulk = 2.0 / r.number(m, "d1", key, lo=0.0, lo_open=True)
    elif given == ["poisson_ratio"]:
        bulk, nu = None, r.number(m, "poisson_ratio", key, lo=-1.0, hi=0.5, lo_open=True, hi_open=True)
    try:
        mat = hyperelastic(model, bulk, nu, density, max_stretch, **constants)
    except ValueError as exc:
        r.fail(key, str(exc))
    if "formulation" in m or inherit:
        formulation = m.get("formulation", inherit.formulation if inherit else None)
    else:  # chosen by measurement (docs/methods.md): displacement unless nearly incompressible on 10 nodes
        formulation = "taylor_hood" if mat.poisson_ratio >= LOCKING_NU and mesh.tets.shape[1] == 10 else "displacement"
    if formulation not in FORMULATIONS:
        r.fail(f"{key}.formulation", f"expected one of {', '.join(FORMULATIONS)}, got {formulation!r}")
    if formulation == "taylor_hood" and mesh.tets.shape[1] == 4:
        r.fail(f"{key}.formulation", "taylor_hood needs 10-node tetrahedra (mesh order: 2): a linear pressure on "
                                     "4-node ones locks as the displacement element does")
    return replace(mat, formulation=formulation)


def _numbers(r: _Reader, v, path: str) -> tuple:
    """A list of finite numbers (a single number: a list of one)."""
    v = [v] if isinstance(v, (int, float)) and not isinstance(v, bool) else v
    if not isinstance(v, list) or not v or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                  and math.isfinite(x) for x in v):
        r.fail(path, f"expected a list of finite numbers, got {v!r}")
    return tuple(float(x) for x in v)


def _max_stretch(r: _Reader, d: dict, key: str, default):
    v = r.optional(d, "max_stretch", key, lo=1.0, lo_open=True)
    return default if v is None else v


def _read_admissibility(r: _Reader, value) -> AdmissibilitySettings:
    a = r.mapping(value or {}, "admissibility", _ADMISSIBILITY)
    return AdmissibilitySettings(
        r.flag(a, "stability", "admissibility", True), r.flag(a, "inversion", "admissibility", True),
        r.flag(a, "self_penetration", "admissibility", True),
        r.number(a, "min_det_F", "admissibility", 0.1, lo=0.0, hi=1.0, hi_open=True),
        r.number(a, "penetration_depth", "admissibility", 0.01, lo=0.0, hi=0.25, hi_open=True),
        r.flag(a, "keep_inadmissible", "admissibility", False))


_SHAPES = {"plane": {"point", "normal"}, "box": None, "sphere": {"center", "radius"},
           "cylinder": {"a", "b", "radius"}, "surface": {"file", "units", "scale"}}


def _read_obstacles(r: _Reader, lst, mesh: Mesh, base: Path) -> list:
    """``obstacles``: each ``{name, <shape>: ...}`` with one shape of ``_SHAPES``; none may hold a node of the
    body at rest."""
    from ..fem.contact import Obstacle, boundary_nodes
    from ..fem.mesh import read_meshio
    from ..fem.surface import edge_report

    if lst is None:
        return []
    if not isinstance(lst, list):
        r.fail("obstacles", "expected a list of obstacles, each {name, plane|box|sphere|cylinder|surface}")
    out = []
    x = mesh.nodes[boundary_nodes(mesh)]
    tol = 1e-9 * mesh.characteristic_length()
    for i, o in enumerate(lst):
        key = f"obstacles[{i}]"
        r.mapping(o, key, {"name"} | set(_SHAPES))
        shapes = [k for k in o if k in _SHAPES]
        if len(shapes) != 1:
            r.fail(key, f"expected exactly one shape of {', '.join(_SHAPES)}, got {shapes or 'none'}")
        kind, name = shapes[0], str(o.get("name", f"obstacle{i + 1}"))
        k2 = f"{key}.{kind}"
        d = o[kind]
        if kind == "box":
            lo, hi = _read_box(r, d, k2)
            if np.any(lo >= hi):
                r.fail(k2, f"the box is flat: lower {lo.tolist()}, upper {hi.tolist()}")
            params = {"lower": lo, "upper": hi}
        elif kind == "surface":
            r.mapping(d, k2, _SHAPES[kind])
            path = base / str(d.get("file"))
            scale = UNITS[d["units"]] if d.get("units") in UNITS else r.number(d, "scale", k2, 1.0, lo=0.0, lo_open=True)
            try:
                m = read_meshio(path)
            except MeshError as exc:
                r.fail(f"{k2}.file", str(exc))
            tris = np.concatenate([c.data for c in m.cells if c.type == "triangle"] + [np.zeros((0, 3), int)])
            open_edges, same = edge_report(tris) if len(tris) else (1, 0)
            if open_edges or same:
                r.fail(f"{k2}.file", f"{path}: not a closed, consistently oriented triangle surface ({open_edges} open, "
                                     f"{same} misoriented edge(s))")
            params = {"vertices": np.asarray(m.points, float)[:, :3] * scale, "triangles": tris.astype(np.int64)}
        else:
            r.mapping(d, k2, _SHAPES[kind])
            if kind == "plane":
                n = r.vector(d.get("normal"), f"{k2}.normal")
                if not np.linalg.norm(n) > 0:
                    r.fail(f"{k2}.normal", "must not be the zero vector")
                params = {"point": r.vector(d.get("point"), f"{k2}.point"), "normal": n / np.linalg.norm(n)}
            elif kind == "sphere":
                params = {"center": r.vector(d.get("center"), f"{k2}.center"),
                          "radius": r.number(d, "radius", k2, lo=0.0, lo_open=True)}
            else:
                a, b = r.vector(d.get("a"), f"{k2}.a"), r.vector(d.get("b"), f"{k2}.b")
                if not np.linalg.norm(b - a) > 0:
                    r.fail(k2, "its end points a and b coincide")
                params = {"a": a, "b": b, "radius": r.number(d, "radius", k2, lo=0.0, lo_open=True)}
        ob = Obstacle(kind, name, params)
        dist = ob.distance(x)
        if kind == "surface" and np.mean(dist) < 0 and np.all(dist < 0):  # normals inwards: turn the sign
            ob.params["triangles"] = ob.params["triangles"][:, ::-1].copy()
            dist = -dist
        if dist.min() < -tol:
            j = int(np.argmin(dist))
            r.fail(key, f"obstacle {name!r} holds part of the body at rest (a boundary node at "
                        f"{np.round(x[j], 6).tolist()} lies {-dist[j]:.3g} m inside it)")
        centre = {"box": lambda: 0.5 * (params["lower"] + params["upper"]), "sphere": lambda: params["center"],
                  "cylinder": lambda: 0.5 * (params["a"] + params["b"]),
                  "surface": lambda: params["vertices"].mean(axis=0)}.get(kind)
        if centre is not None and embed(mesh, centre()[None]).outside[0] == 0.0:  # wholly inside the body
            r.fail(key, f"obstacle {name!r} lies inside the body at rest (its centre "
                        f"{np.round(centre(), 6).tolist()} is in the mesh)")
        out.append(ob)
    return out


def _read_self_contact(r: _Reader, lst, mesh: Mesh) -> tuple[list, AutoSelfContact | None]:
    """``self_contact``: ``auto`` (or ``{auto: true, distance: m, stiffness: ...}``): wherever the boundary
    meets itself; or a list of declared pairs, each ``{name, points: <selection>, surface: <selection>}``
    (selections as in ``fixed``): the boundary nodes selected by ``points`` may not enter the boundary faces
    whose nodes are all selected by ``surface``. Returns (declared pairs, the auto settings or None)."""
    from ..fem.contact import split_faces
    from ..fem.surface import boundary_faces
    from ..fem.terms import SelfContact

    if lst is None:
        return [], None
    if lst == "auto" or isinstance(lst, dict):
        return [], _read_auto_contact(r, lst, mesh)
    if not isinstance(lst, list):
        r.fail("self_contact", "expected 'auto' (contact wherever the body meets itself) or a list of declared "
                               "pairs {name, points, surface}, each a selection as in 'fixed'")
    faces = boundary_faces(mesh)
    out = []
    for i, s in enumerate(lst):
        key = f"self_contact[{i}]"
        r.mapping(s, key, {"name", "points", "surface", "reach"})
        sel = {}
        for k in ("points", "surface"):
            if k not in s:
                r.fail(f"{key}.{k}", "missing: a selection of the body's boundary (box, sphere, plane or indices)")
            if isinstance(s[k], dict) and "components" in s[k]:
                r.fail(f"{key}.{k}.components", "not used here: contact acts on whole nodes")
            sel[k], _ = _read_selection(r, s[k], mesh, f"{key}.{k}", False)
        points = np.intersect1d(sel["points"], faces)
        tris = faces[np.isin(faces, sel["surface"]).all(axis=1)]
        if points.size == 0:
            r.fail(f"{key}.points", "selects no node on the body's boundary")
        if len(tris) == 0:
            r.fail(f"{key}.surface", "holds no whole boundary face (every node of a face must be selected)")
        shared = np.intersect1d(points, tris)
        if shared.size:
            r.fail(key, f"{shared.size} boundary node(s) are in both 'points' and 'surface': the two regions must "
                        f"be apart")
        name = str(s.get("name", f"self_contact{i + 1}"))
        reach = r.optional(s, "reach", key, lo=0.0, lo_open=True)
        term = SelfContact(name, points, split_faces(tris), mesh.nodes, np.arange(3 * mesh.n_nodes), 1.0, reach)
        inside = np.count_nonzero(np.minimum(term.at(mesh.nodes).g, term.signed_distance(mesh.nodes)) <= 0.0)
        if inside:
            r.fail(key, f"{inside} of its {points.size} points lie on or behind its surface at rest (the points must "
                        f"be outside, on the side the surface faces)")
        out.append(SelfContactPair(name, points, tris, reach))
    return out, None


def _read_auto_contact(r: _Reader, v, mesh: Mesh) -> AutoSelfContact:
    """``self_contact: auto`` or its mapping form; refused where the boundary already meets itself at rest
    closer than the barrier's reach (the barrier would load the body at rest) or passes through itself."""
    from ..fem.collision import collision_surface_of_mesh, rest_clearance
    from ..fem.terms.auto_contact import DISTANCE

    key = "self_contact"
    a = AutoSelfContact()
    if isinstance(v, dict):
        r.mapping(v, key, {"auto", "distance", "stiffness"})
        if v.get("auto") is not True:
            r.fail(f"{key}.auto", "expected true (the mapping form of 'self_contact: auto'); for declared pairs "
                                  "give a list of {name, points, surface}")
        a.distance = r.optional(v, "distance", key, lo=0.0, lo_open=True)
        a.stiffness = r.optional(v, "stiffness", key, lo=0.0, lo_open=True)
    surface = collision_surface_of_mesh(mesh)
    clear, h = rest_clearance(surface, mesh.nodes)
    dhat = a.distance if a.distance else DISTANCE * h
    if not clear > dhat:
        where = "passes through itself" if clear <= 0 else f"has parts {clear:.3g} m apart"
        r.fail(f"{key}.distance" if a.distance else key,
               f"the body's boundary at rest {where}, not farther than the contact distance {dhat:.3g} m: "
               f"give a smaller distance (m) than {max(clear, 0):.3g}" if clear > 0 else
               f"the body's boundary at rest {where}: self-contact cannot start from it (check the mesh)")
    return a


def _read_springs(r: _Reader, lst, mesh: Mesh) -> list:
    """``springs``: each ``{name, nodes: <selection>, stiffness: N/m per node, anchors: [[x, y, z], ...]}``
    (:class:`casadi_ws.fem.terms.springs.Springs`); ``anchors`` one point for every selected node (in the
    order of their indices) or one for all; without it each node is held to its rest position."""
    from ..fem.terms.springs import Springs

    if lst is None:
        return []
    if not isinstance(lst, list) or not lst:
        r.fail("springs", "expected a list of {name, nodes, stiffness, anchors}, 'nodes' a selection as in 'fixed'")
    out = []
    for i, s in enumerate(lst):
        key = f"springs[{i}]"
        r.mapping(s, key, {"name", "nodes", "stiffness", "anchors"})
        if "nodes" not in s:
            r.fail(f"{key}.nodes", "missing: a selection of nodes (box, sphere, plane or indices)")
        if isinstance(s["nodes"], dict) and "components" in s["nodes"]:
            r.fail(f"{key}.nodes.components", "not used here: a spring holds all three components")
        nodes, _ = _read_selection(r, s["nodes"], mesh, f"{key}.nodes", False)
        k = r.number(s, "stiffness", key, lo=0.0, lo_open=True)
        anchors = None
        if s.get("anchors") is not None:
            anchors = r.points(s["anchors"], f"{key}.anchors")
            if len(anchors) == 1:
                anchors = np.repeat(anchors, nodes.size, axis=0)
            elif len(anchors) != nodes.size:
                r.fail(f"{key}.anchors", f"expected one point, or one per selected node ({nodes.size}), got "
                                         f"{len(anchors)}")
        out.append(Springs(nodes, k, anchors, name=str(s.get("name", f"springs{i + 1}"))))
    return out


def _read_pressure_loads(r: _Reader, lst, mesh: Mesh) -> list:
    """``pressure_loads``: each ``{name, surface: <selection>, pressure: Pa}``: a pressure on the boundary faces
    whose nodes are all selected, following them as they move (:class:`casadi_ws.fem.terms.pressure_load.
    PressureLoad`; positive pushes into the body)."""
    from ..fem.surface import boundary_faces
    from ..fem.terms.pressure_load import PressureLoad

    if lst is None:
        return []
    if not isinstance(lst, list) or not lst:
        r.fail("pressure_loads", "expected a list of {name, surface, pressure}, 'surface' a selection as in 'fixed'")
    faces = boundary_faces(mesh)
    out = []
    for i, s in enumerate(lst):
        key = f"pressure_loads[{i}]"
        r.mapping(s, key, {"name", "surface", "pressure"})
        if "surface" not in s:
            r.fail(f"{key}.surface", "missing: a selection of the body's boundary (box, sphere, plane or indices)")
        if isinstance(s["surface"], dict) and "components" in s["surface"]:
            r.fail(f"{key}.surface.components", "not used here: a pressure acts along the surface's normal")
        nodes, _ = _read_selection(r, s["surface"], mesh, f"{key}.surface", False)
        tris = faces[np.isin(faces, nodes).all(axis=1)]
        if len(tris) == 0:
            r.fail(f"{key}.surface", "holds no whole boundary face (every node of a face must be selected)")
        out.append(PressureLoad(tris, r.number(s, "pressure", key), name=str(s.get("name", f"pressure{i + 1}"))))
    return out


_BUILTIN_TERMS = ("elements", "actuators", "intensities", "loads", "obstacles", "pressure")


def _unique_names(r: _Reader, named: list[tuple[str, str]]) -> None:
    """The names of self-contact pairs, springs and pressure loads name the model's terms: each its own."""
    seen: dict[str, str] = {}
    counts: dict[str, int] = {}
    for key, name in named:
        i = counts.get(key, 0)
        counts[key] = i + 1
        where = f"{key}[{i}].name"
        if name in _BUILTIN_TERMS:
            r.fail(where, f"{name!r} is the name of one of the model's own terms; choose another")
        if name in seen:
            r.fail(where, f"{name!r} is already the name of {seen[name]}; give each its own")
        seen[name] = where.removesuffix(".name")


def _read_task(r: _Reader, value, base: Path):
    """``task``: a box or a CSV of points (:class:`casadi_ws.workspace.measures.Task`), or None."""
    if value is None:
        return None
    from ..workspace.measures import read_task

    t = r.mapping(value, "task", {"box", "points"})
    if len(t) != 1:
        r.fail("task", "expected exactly one of 'box: [[xmin, ymin, zmin], [xmax, ymax, zmax]]' or 'points: FILE.csv'")
    try:
        if "box" in t:
            task = read_task(box=t["box"])
        else:
            path = base / str(t["points"])
            if not path.is_file():
                r.fail("task.points", f"file not found: {path}")
            task = read_task(csv=path)
    except ProblemError:
        raise
    except (ValueError, TypeError) as exc:
        r.fail(f"task.{next(iter(t))}", str(exc))
    return task


def problem_from_dict(d: Any, source: str = "<dict>", base: Path | None = None) -> Problem:
    """Validate a problem given as plain data (as read from YAML) and build it."""
    r = _Reader(source)
    base = base or Path.cwd()
    if not isinstance(d, dict):
        r.fail("", f"expected a mapping at the top level, got {type(d).__name__}")
    r.mapping(d, "", _TOP_KEYS)
    for k in ("mesh", "material") + (() if d.get("springs") else ("fixed",)):
        if k not in d:
            r.fail(k, "missing (required)")
    if "cables" not in d and "cavities" not in d:
        r.fail("cables", "missing: a problem needs cables, cavities or both")
    mesh, _ = _read_mesh(r, d["mesh"], base)

    m = r.mapping(d["material"], "material", _MATERIAL)
    if "density" in m and "total_mass" in m:
        r.fail("material.total_mass", "give density (kg/m^3) or total_mass (kg), not both")
    material = _read_material(r, m, "material", mesh)
    if "total_mass" in m:
        # SOFA's UniformMass totalMass: spread here by volume (a consistent mass), not equally per node
        material = replace(material, density=r.number(m, "total_mass", "material", lo=0.0) / float(mesh.volumes().sum()))
    regions = _read_regions(r, d.get("material_regions"), mesh, material)
    gravity = r.vector(d["gravity"], "gravity") if d.get("gravity") is not None else np.zeros(3)
    body_force = r.vector(d["body_force"], "body_force") if d.get("body_force") is not None else np.zeros(3)
    obstacles = _read_obstacles(r, d.get("obstacles"), mesh, base)
    springs = _read_springs(r, d.get("springs"), mesh)
    held = [t.nodes for t in springs]
    fixed, partial_fixed = _read_fixed(r, d.get("fixed", []), mesh, obstacles, held)
    cables = _read_cables(r, d["cables"], mesh) if "cables" in d else []
    cavities = _read_cavities(r, d["cavities"], mesh, base) if "cavities" in d else []

    end_effector, tip_frame = _read_end_effector(r, d.get("end_effector", "tip"), mesh)

    loads = []
    lst = d.get("loads") or []
    if not isinstance(lst, list):
        r.fail("loads", "expected a list of {point, force}")
    for i, ld in enumerate(lst):
        r.mapping(ld, f"loads[{i}]", {"point", "force"})
        loads.append((r.vector(ld.get("point"), f"loads[{i}].point"),
                      r.vector(ld.get("force"), f"loads[{i}].force")))

    s = r.mapping(d.get("solver") or {}, "solver", _SOLVER)
    solver = SolverSettings(r.number(s, "tolerance", "solver", 1e-8, lo=0.0, lo_open=True),
                            r.number(s, "max_iterations", "solver", 30, lo=1, integer=True),
                            r.number(s, "max_load_steps", "solver", 64, lo=1, integer=True),
                            s.get("newton", "builtin"), s.get("linear", "auto"))
    if solver.newton not in ("builtin", "rootfinder"):
        r.fail("solver.newton", f"expected builtin or rootfinder, got {solver.newton!r}")
    if solver.linear not in LINEAR_SOLVERS:
        r.fail("solver.linear", f"expected one of {', '.join(LINEAR_SOLVERS)}, got {solver.linear!r}")
    if not available(solver.linear):
        r.fail("solver.linear", f"{solver.linear} is not installed here (pip install 'casadi-ws[fast]' brings "
               "pypardiso and MKL, on x86-64); 'auto' uses it where it is and SuperLU elsewhere")
    w = r.mapping(d.get("workspace") or {}, "workspace", _WORKSPACE)
    workspace = {}
    if "method" in w:
        if w["method"] not in ("forward", "fb"):
            r.fail("workspace.method", f"expected 'forward' or 'fb', got {w['method']!r}")
        workspace["method"] = w["method"]
    if "n_d" in w:
        workspace["nd"] = r.number(w, "n_d", "workspace", lo=1, integer=True)
    if "step" in w:
        workspace["step"] = r.number(w, "step", "workspace", lo=0.0, lo_open=True)
    for key, allowed in (("strategy", ("uniform", "relative")), ("backward", ("reduced", "ipopt"))):
        if key in w:
            if w[key] not in allowed:
                r.fail(f"workspace.{key}", f"expected one of {', '.join(allowed)}, got {w[key]!r}")
            workspace[key] = w[key]
    if "workers" in w:
        workspace["workers"] = r.number(w, "workers", "workspace", lo=1, integer=True)
    task = _read_task(r, d.get("task"), base)
    admissibility = _read_admissibility(r, d.get("admissibility"))
    name = str(d.get("name", Path(source).stem))
    self_contact, self_contact_auto = _read_self_contact(r, d.get("self_contact"), mesh)
    terms = springs + _read_pressure_loads(r, d.get("pressure_loads"), mesh)
    _unique_names(r, [("self_contact", p.name) for p in self_contact] +
                  [("springs" if t in springs else "pressure_loads", t.name) for t in terms])
    return Problem(mesh, material, fixed, cables + cavities, end_effector, gravity, loads, solver, name=name,
                   source=source, regions=regions, partial_fixed=partial_fixed, admissibility=admissibility,
                   obstacles=obstacles, self_contact=self_contact, self_contact_auto=self_contact_auto, terms=terms,
                   workspace=workspace, task=task, tip_frame=tip_frame, body_force=body_force)


def read_yaml(path: str | Path, what: str = "problem file", error=None):
    """The data of a YAML file; a missing or malformed file is ``error`` (a ProblemError class) naming it."""
    import yaml

    error = error or ProblemError
    path = Path(path)
    if not path.is_file():
        raise error(str(path), "", f"{what} not found")
    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise error(str(path), "", f"malformed YAML: {where}{getattr(exc, 'problem', exc)}") from None


def load_problem(path: str | Path) -> Problem:
    """Read and validate a YAML problem file."""
    path = Path(path)
    return problem_from_dict(read_yaml(path), str(path), path.parent)


BUILT_IN = "<built-in trunk_2cables>"
"""The source a result of the built-in problem names (``casadi-ws demo``): commands that read a result's problem
build it again from :data:`DEFAULT_PROBLEM`."""

DEFAULT_PROBLEM = {
    "name": "trunk_2cables",
    "description": "Trunk-like robot with two long cables 90 degrees apart (paper, Section 6.1).",
    "mesh": {"generate": "trunk", "length": 0.195, "radius_base": 0.013, "radius_tip": 0.005,
             "resolution": 1.0},
    "material": {"model": "corotational", "young_modulus": 1.8e7, "poisson_ratio": 0.45, "density": 1100.0},
    "gravity": [0.0, -9.81, 0.0],
    "fixed": {"box": [[-0.02, -0.02, -0.001], [0.02, 0.02, 0.02]]},
    "cables": [
        {"name": "long0", "trunk_routing": {"angle_deg": 0, "kind": "long"}, "u_min": 0, "u_max": 100},
        {"name": "long90", "trunk_routing": {"angle_deg": 90, "kind": "long"}, "u_min": 0, "u_max": 100},
    ],
    "end_effector": "tip",
}


def default_problem() -> Problem:
    """The built-in default problem: the 2-cable trunk of the paper (same as problems/trunk_2cables.yaml)."""
    return problem_from_dict(DEFAULT_PROBLEM, BUILT_IN)
