"""Translate a recorded SOFA scene graph (:mod:`.recorder`) into a casadi-ws problem, in SI units.

The rules, one per SOFA component (docs/sofa.md lists them with what each becomes):

- the body is the node holding a ``TetrahedronFEMForceField`` (or ``TetrahedronHyperelasticityFEMForceField``);
  its mesh comes from the node's mesh loader (``MeshVTKLoader``, ``MeshGmshLoader``, ...), placed by the
  loader's ``rotation``/``translation``/``scale``/``scale3d``;
- fixed nodes: ``FixedConstraint``/``FixedProjectiveConstraint`` indices, stiff ``RestShapeSpringsForceField``
  points, ``PartialFixed(Projective)Constraint`` with its directions; indices given as a link to a
  ``BoxROI``/``SphereROI`` are selected here as SOFA would (bounds inclusive, in the scene's units);
- cables: a ``CableConstraint``/``CableActuator`` on the points of its node's ``MechanicalObject``
  (``indices``, ``pullPoint``, ``hasPullPoint``); ``valueType`` force: tension bounds ``minForce``/``maxForce``;
  displacement (SOFA's default): ``control: displacement``, shortening bounds ``-maxNegativeDisp`` and
  ``maxPositiveDisp``;
- cavities: a ``SurfacePressureConstraint`` on its node's surface loader (vertices embedded like SOFA's
  barycentric mapping), bounds ``minPressure``/``maxPressure``, or with ``valueType`` volumeGrowth
  ``control: volume`` and ``minVolumeGrowth``/``maxVolumeGrowth``;
- soft supports: a ``RestShapeSpringsForceField`` softer than :data:`STIFF_SPRINGS` becomes ``springs`` (N/m);
- loads: ``ConstantForceField`` on the body's points becomes ``loads``; ``SurfacePressureForceField`` on a
  surface of the body's points ``pressure_loads`` (sign turned to casadi-ws's: positive pushes in);
- the end effector: the first ``PositionEffector`` point, else the centre of the body's far end;
- mass: ``UniformMass`` ``totalMass``/``vertexMass``, ``MeshMatrixMass``/``DiagonalMass`` ``massDensity``;
- units: from gravity's magnitude (9.81: m-kg-s, 9810: mm-kg-s) unless given.

Everything else is listed, one line per component type, as not translated.
"""

from __future__ import annotations

import itertools

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .api import Data, Node, Object, SceneError
from .recorder import record

__all__ = ["UNIT_SYSTEMS", "Translation", "import_scene", "translate"]

UNITS_TOLERANCE = 0.10
"""Gravity within this share of 9.81, 981 or 9810 picks m, cm or mm (SoftRobots' scenes carry -9180 for -9810:
SOFA runs them as written; the note says so)."""

UNIT_SYSTEMS = {"m-kg-s": (1.0, 1.0), "mm-kg-s": (1e-3, 1.0), "mm-g-s": (1e-3, 1e-3), "cm-kg-s": (1e-2, 1.0)}
"""Unit systems of SOFA scenes: (metres per length unit, kilograms per mass unit); seconds throughout."""

_LOADERS = ("MeshVTKLoader", "MeshGmshLoader", "MeshSTLLoader", "MeshOBJLoader", "MeshExtendedVTKLoader",
            "MeshXspLoader", "MeshOffLoader", "GIDMeshLoader", "MeshGmshLoader")
_FEM = ("TetrahedronFEMForceField", "TetrahedronHyperelasticityFEMForceField", "FastTetrahedralCorotationalForceField",
        "TetrahedralCorotationalFEMForceField")
_CABLES = ("CableConstraint", "CableActuator")
_CAVITIES = ("SurfacePressureConstraint", "SurfacePressureActuator")
_FIXED = ("FixedConstraint", "FixedProjectiveConstraint", "RestShapeSpringsForceField",
          "PartialFixedConstraint", "PartialFixedProjectiveConstraint")
_MASSES = ("UniformMass", "MeshMatrixMass", "DiagonalMass")
# components whose content is translated through another (a topology read by the body, a mapping that
# embeds a cable's points, a selection a constraint links to)
_ABSORBED = ("MechanicalObject", "MeshTopology", "TetrahedronSetTopologyContainer",
             "TetrahedronSetGeometryAlgorithms", "TriangleSetTopologyContainer", "BarycentricMapping", "BoxROI",
             "SphereROI", "PositionEffector", "RequiredPlugin") + _LOADERS
_KINDS = (
    ("dynamics or solver (casadi-ws solves the static equilibrium itself)",
     ("Solver", "AnimationLoop", "ConstraintCorrection", "ODESolver")),
    ("visual only", ("Ogl", "Visual", "Light", "Camera", "BackgroundSetting", "SceneFrame")),
    ("changes the topology during a simulation (the mesh is kept as loaded)", ("TopologyModifier",
                                                                               "TopologicalMapping")),
    ("collision detection (casadi-ws's contact is the problem's obstacles and self_contact, translated from the "
     "scene's fixed objects and self-collision where it says so)", ("Collision", "Contact", "Pipeline", "Intersection",
                                                  "BroadPhase", "NarrowPhase", "BruteForce", "MinDistance",
                                                  "Proximity")),
)


@dataclass
class Translation:
    """What :func:`translate` made of a scene: the problem as plain data, and what it says about it."""

    problem: dict
    """The problem file's content (SI units), as :func:`casadi_ws.io.problem.problem_from_dict` reads it."""
    comments: dict = field(default_factory=dict)
    """Comment for a top-level key or a list entry (``cables[0]``), for the written file."""
    notes: list[str] = field(default_factory=list)
    """What was translated approximately or assumed, one line each."""
    untranslated: list[str] = field(default_factory=list)
    """What was not translated, one line per component type."""
    units: str = "m-kg-s"


def _flat_points(v) -> np.ndarray:
    """SOFA's vector data: a flat or nested list of numbers (SofaPython3 flattens), as (n, 3)."""
    if isinstance(v, Data):
        v = v.value
    if isinstance(v, str):
        v = [float(x) for x in v.replace(",", " ").split()]
    flat = []

    def walk(x):
        if isinstance(x, (list, tuple, np.ndarray)):
            for y in x:
                walk(y)
        else:
            flat.append(float(x))

    walk(v)
    if len(flat) % 3:
        raise ValueError(f"{len(flat)} numbers are not a list of 3-D points")
    return np.asarray(flat, dtype=float).reshape(-1, 3)


def _floats(v) -> np.ndarray:
    """SOFA's numeric data (a number, a list, nested or a string) as a flat float array."""
    if isinstance(v, Data):
        v = v.value
    if isinstance(v, str):
        v = v.replace(",", " ").split()
    return np.asarray(v if isinstance(v, (list, tuple, np.ndarray)) else [v], dtype=float).ravel()


def _ints(v) -> list[int]:
    if isinstance(v, str):
        v = v.replace(",", " ").split()
    if isinstance(v, (int, float)):
        v = [v]
    return [int(float(x)) for x in np.asarray(v, dtype=object).ravel()]


def _bool(v, default: bool) -> bool:
    if v is None:
        return default
    if isinstance(v, str):
        return v.strip().lower() not in ("0", "false", "no", "")
    return bool(v)


def _num(v, default=None):
    if v is None:
        return default
    if isinstance(v, str):
        v = float(v.split()[0])
    if isinstance(v, (list, tuple)):
        v = v[0]
    return float(v)


class _Scene:
    def __init__(self, root: Node, path: Path):
        self.root, self.path, self.dir = root, path, path.resolve().parent
        self.nodes = list(root.walk())

    def fail(self, message: str):
        raise SceneError(f"{self.path}: {message}")

    def find(self, link, here: Node) -> Object | None:
        """The object a link names (``@name``, ``@name.data``, ``@../name``, ``@/a/b/name``)."""
        if isinstance(link, Data):
            return link.owner if isinstance(link.owner, Object) else None
        if not isinstance(link, str) or not link.startswith("@"):
            return None
        head, _, last = link[1:].rpartition("/")  # '@../roi.indices': the data name follows the last '.'
        target = f"{head}/{last.split('.')[0]}" if head or link[1:].startswith("/") else last.split(".")[0]
        parts = [p for p in target.split("/") if p]
        node = self.root if target.startswith("/") else here
        for p in parts[:-1]:
            node = node.parent if p == ".." else (node.getChild(p) if p != "." else node)
            if node is None:
                return None
        name = parts[-1] if parts else ""
        for n in [node] + ([] if target.startswith("/") or len(parts) > 1 else list(_ancestors(node))):
            o = n.getObject(name)
            if o is not None:
                return o
        return None


def _ancestors(node: Node):
    while node.parent is not None:
        node = node.parent
        yield node


def _objects(node: Node, types: tuple) -> list[Object]:
    return [o for o in node.objects if o.type in types]


def _loader_points(scene: _Scene, loader: Object, length: float):
    """The points (scene units, transformed as the loader says) and the file of a mesh loader."""
    from ...fem.mesh import read_meshio

    f = loader.data.get("filename")
    if not f:
        scene.fail(f"{loader.type} '{loader.name}' at {loader.path()} has no filename")
    file = Path(str(f))
    file = file if file.is_absolute() else scene.dir / file
    if not file.is_file():
        scene.fail(f"{loader.type} '{loader.name}': mesh file not found: {file}")
    m = read_meshio(file)
    return np.asarray(m.points, float)[:, :3], file, _transform(loader), m


def _transform(loader: Object) -> dict:
    """The loader's placement as the problem format's ``transform`` (scale dimensionless, translation in
    scene units until converted)."""
    t = {}
    rot = loader.data.get("rotation")
    if rot is not None and np.any(_flat_points(rot)):
        t["rotation"] = _flat_points(rot)[0].tolist()
    tr = loader.data.get("translation")
    if tr is not None and np.any(_flat_points(tr)):
        t["translation"] = _flat_points(tr)[0].tolist()
    sc = loader.data.get("scale3d", loader.data.get("scale"))
    if sc is not None:
        s = np.atleast_1d(np.asarray(_flat_points(sc) if np.size(sc) == 3 else [_num(sc)], dtype=float)).ravel()
        if np.any(s != 1.0):
            t["scale"] = float(s[0]) if s.size == 1 or np.all(s == s[0]) else s.tolist()
    return t


def _apply(t: dict, x: np.ndarray) -> np.ndarray:
    from ...fem.mesh import transform_points

    return transform_points(x, t.get("rotation", (0, 0, 0)), t.get("translation", (0, 0, 0)), t.get("scale", 1.0))


def _units(scene: _Scene, units: str | None, notes: list) -> str:
    g = scene.root.data.get("gravity")
    if units is not None:
        if units not in UNIT_SYSTEMS:
            scene.fail(f"--units: expected one of {', '.join(UNIT_SYSTEMS)}, got {units!r}")
        return units
    mag = float(np.linalg.norm(_flat_points(g)[0])) if g is not None else None
    if not mag:  # gravity unset (SOFA's default -9.81 in whatever units) or zero: it says nothing
        return _units_from_body(scene, notes, "gravity is not set" if g is None else "gravity is zero")
    for name, expect in (("m-kg-s", 9.81), ("mm-kg-s", 9810.0), ("cm-kg-s", 981.0)):
        if abs(mag - expect) <= UNITS_TOLERANCE * expect:
            off = abs(mag - expect) / expect
            typo = f", {off:.0%} off {expect:g}: a typo?" if off > 0.02 else ""
            notes.append(f"units {name} (from gravity's magnitude {mag:g}{typo}); masses read as "
                         f"{'kg' if UNIT_SYSTEMS[name][1] == 1 else 'g'} (--units mm-g-s if the scene uses grams)")
            return name
    scene.fail(f"cannot tell the units from gravity's magnitude {mag:g} (9.81: m, 9810: mm); give --units")


PLAUSIBLE_SIZE = (0.005, 2.0)
"""Body sizes (m) and Young's moduli (Pa, below) a soft robot has: with gravity unset or zero, the unit systems
that make the body's extent and modulus fall in both are candidates, and the one whose size is nearest 10 cm
is taken (SoftRobots' Bunny: 10 units, E 18000 -> cm-kg-s, 10 cm and 1.8 MPa)."""
PLAUSIBLE_MODULUS = (1e3, 1e8)


def _units_from_body(scene: _Scene, notes: list, why: str) -> str:
    bodies = [n for n in scene.nodes if _objects(n, _FEM) and not any(_objects(a, _FEM) for a in _ancestors(n))]
    loaders = [o for o in (bodies[0].objects if bodies else []) if o.type in _LOADERS and o.data.get("filename")]
    if not loaders:  # nothing to go on; what is missing is said next
        notes.append(f"{why}: units m-kg-s assumed (--units to change)")
        return "m-kg-s"
    pts = _loader_points(scene, loaders[0], 1.0)[0]
    extent = float(np.ptp(pts, axis=0).max()) * float(np.max(_transform(loaders[0]).get("scale", 1.0)))
    fem = _objects(bodies[0], _FEM)[0]
    E = _num(fem.data.get("youngModulus"), None) if fem.type != "TetrahedronHyperelasticityFEMForceField" else None
    fits = []
    for name in ("m-kg-s", "cm-kg-s", "mm-kg-s"):
        L, M = UNIT_SYSTEMS[name]
        size, modulus = extent * L, None if E is None else E * M / L
        if PLAUSIBLE_SIZE[0] <= size <= PLAUSIBLE_SIZE[1] and (
                modulus is None or PLAUSIBLE_MODULUS[0] <= modulus <= PLAUSIBLE_MODULUS[1]):
            fits.append((abs(np.log(size / 0.1)), name, size, modulus))
    if not fits:
        scene.fail(f"{why}, and the body's extent {extent:g} (youngModulus {E}) fits no unit system of a soft "
                   f"robot ({PLAUSIBLE_SIZE[0]:g}-{PLAUSIBLE_SIZE[1]:g} m, {PLAUSIBLE_MODULUS[0]:g}-"
                   f"{PLAUSIBLE_MODULUS[1]:g} Pa); give --units")
    _, name, size, modulus = min(fits)
    said = f"a body {size:.3g} m across" + (f", E = {modulus:.3g} Pa" if modulus is not None else "")
    notes.append(f"{why}: units {name} taken from the body ({said}; "
                 f"{'also fits: ' + ', '.join(f[1] for f in sorted(fits)[1:]) + '; ' if len(fits) > 1 else ''}"
                 f"--units to change)")
    return name


def translate(path: str | Path, units: str | None = None, out_dir: str | Path | None = None) -> Translation:
    """The problem a SOFA scene describes (see the module's docstring for the rules).

    ``out_dir``: where the problem file will live (its mesh paths are written relative to it).
    """
    path = Path(path)
    sc = _Scene(record(path), path)
    sc.out_dir = Path(out_dir) if out_dir is not None else Path.cwd()
    sc.tr = tr = Translation({}, units="")
    stubbed = sc.root.__dict__.get("stubbed") or []
    if stubbed:
        tr.notes.append(f"run as stubs (unknown to the SOFA stand-in; what they build is not translated): "
                        f"{', '.join(stubbed)}")
    tr.units = _units(sc, units, tr.notes)
    sc.length, M = UNIT_SYSTEMS[tr.units]
    sc.mass, sc.force, sc.stress = M, M * sc.length, M / sc.length  # kg, N, Pa per scene unit
    sc.used = set()
    tr.problem["name"] = path.stem
    tr.problem["description"] = f"Imported from the SOFA scene {path.name} by casadi-ws import-sofa."
    _body_mesh(sc)
    _material(sc)
    g = sc.root.data.get("gravity")
    # unset, SOFA's default (0, -9.81, 0) is in the scene's units, as SOFA runs it
    tr.problem["gravity"] = ((_flat_points(g)[0] if g is not None else np.array([0, -9.81, 0])) * sc.length).tolist()
    _fixed(sc)
    _actuators(sc)
    _loads(sc)
    _obstacles(sc)
    _self_collision(sc)
    _effector(sc)
    tr.untranslated = _leftovers(sc, sc.used)
    _open_strokes(sc)
    from ..problem import ProblemError, problem_from_dict

    try:  # the file written must load: a rule that made a bad problem is the importer's bug, said as such
        problem_from_dict(tr.problem, f"{path} (translated)", sc.out_dir)
    except ProblemError as exc:
        sc.fail(f"the translated problem is invalid: {exc.key}: {exc.message}")
    return tr


def _body_mesh(sc: _Scene) -> None:
    """The body (a node with a FEM force field under no other such node: one below a body is a layer of
    it) and its mesh: ``sc.body``, ``sc.X`` (its points in scene units, placed as SOFA's MechanicalObject
    holds them), ``sc.in_tets`` (the points some tetrahedron uses)."""
    tr, L = sc.tr, sc.length
    bodies = [n for n in sc.nodes if _objects(n, _FEM) and not any(_objects(a, _FEM) for a in _ancestors(n))]
    if not bodies:
        sc.fail("no node holds a TetrahedronFEMForceField (or TetrahedronHyperelasticityFEMForceField): no "
                "deformable body to translate")
    sc.body, sc.others = bodies[0], bodies[1:]
    groups = sc.body.__dict__.get("rigidified")
    if groups:
        tr.notes.append(f"stlib3 Rigidify makes {sum(map(len, groups))} points of {sc.body.path()} rigid in "
                        f"{len(groups)} group(s): not modelled, those parts stay elastic here")
        sc.used.update(id(o) for o in sc.body.objects if o.type == "SubsetMultiMapping")
    if len(bodies) > 1:
        tr.notes.append(f"{len(bodies)} deformable bodies; translated the first, {sc.body.path()} (the others: "
                        f"{', '.join(b.path() for b in bodies[1:])})")
    loaders = [o for o in sc.body.objects if o.type in _LOADERS and o.data.get("filename")]
    if not loaders:
        sc.fail(f"body node {sc.body.path()} has no mesh loader with a filename")
    loader = loaders[0]
    pts, mesh_file, transform, raw = _loader_points(sc, loader, L)
    sc.in_tets = np.zeros(len(pts), bool)
    tets = [np.asarray(c.data)[:, :4] for c in raw.cells if c.type in ("tetra", "tetra10")]
    for t in tets:
        sc.in_tets[t.ravel()] = True
    sc.tets = np.concatenate(tets) if tets else None
    sc.used.add(id(loader))
    mesh = {"file": os.path.relpath(mesh_file.resolve(), sc.out_dir.resolve()), "scale": L}
    if transform:
        t = dict(transform)
        if "translation" in t:
            t["translation"] = [x * L for x in t["translation"]]
        mesh["transform"] = t
    sc.X = _apply(transform, pts) if transform else pts
    placed = _state_placement(sc)
    if placed:
        if transform:
            # the loader's placement, then the MechanicalObject's: one transform of the problem format is one
            # placement, so the mesh file's points are written already placed by the first
            sc.fail(f"{loader.path()} and the MechanicalObject of {sc.body.path()} both place the body: "
                    f"combine them in one of the two")
        sc.X = _apply(placed, pts)
        t = dict(placed)
        if "translation" in t:
            t["translation"] = [x * L for x in t["translation"]]
        mesh["transform"] = t
        tr.notes.append(f"the body's MechanicalObject places its mesh ({', '.join(sorted(placed))}): applied")
    tr.problem["mesh"] = mesh
    tr.comments["mesh"] = f"{loader.type} '{loader.name}' ({tr.units.split('-')[0]} -> m)"


def _state_placement(sc: _Scene) -> dict:
    """The body MechanicalObject's own placement of the positions it takes from the topology (SOFA's
    ``rx, ry, rz`` / ``rotation`` in degrees, ``dx, dy, dz`` / ``translation``, ``scale3d``), as a transform."""
    mo = next((o for o in sc.body.objects if o.type == "MechanicalObject"), None)
    if mo is None:
        return {}
    d = mo.data
    t = {}
    rot = [_num(d.get(k), 0.0) for k in ("rx", "ry", "rz")]
    if d.get("rotation") is not None:
        rot = _flat_points(d["rotation"])[0].tolist()
    if any(rot):
        t["rotation"] = rot
    tr = [_num(d.get(k), 0.0) for k in ("dx", "dy", "dz")]
    if d.get("translation") is not None:
        tr = _flat_points(d["translation"])[0].tolist()
    if any(tr):
        t["translation"] = tr
    if d.get("scale3d") is not None:
        s = _flat_points(d["scale3d"])[0]
        if np.any(s != 1.0):
            t["scale"] = float(s[0]) if np.all(s == s[0]) else s.tolist()
    return t


def _material(sc: _Scene) -> None:
    """The body's law and constants, its mass, and the layers on its sub-topologies."""
    tr, body, stress, notes = sc.tr, sc.body, sc.stress, sc.tr.notes
    fem = _objects(body, _FEM)[0]
    sc.used.add(id(fem))
    if fem.type == "TetrahedronHyperelasticityFEMForceField":
        law = str(fem.data.get("materialName", "NeoHookean"))
        if law.lower() not in ("neohookean", "stablenehookean", "stableneohookean"):
            sc.fail(f"{fem.type} materialName {law!r}: only NeoHookean is available here")
        ps = fem.data.get("ParameterSet")
        p = np.asarray([float(x) for x in ps.replace(",", " ").split()] if isinstance(ps, str)
                       else np.ravel(ps if ps is not None else []), dtype=float)
        if p.size < 2 or np.any(p[:2] <= 0):
            sc.fail(f"{fem.type} '{fem.name}': ParameterSet {ps!r}: expected mu and K, both > 0")
        mu, K = p[0] * stress, p[1] * stress
        E, nu = 9 * K * mu / (3 * K + mu), (3 * K - 2 * mu) / (2 * (3 * K + mu))
        material = {"model": "neohookean", "young_modulus": float(f"{E:.6g}"), "poisson_ratio": float(f"{nu:.6g}")}
        tr.comments["material"] = f"{fem.type} NeoHookean mu = {p[0]:g}, K = {p[1]:g}"
    else:
        method = str(fem.data.get("method", "large"))
        model = "linear" if method == "small" else "corotational"
        E = _num(fem.data.get("youngModulus"), 5000.0)
        nu = _num(fem.data.get("poissonRatio"), 0.45)
        if isinstance(fem.data.get("youngModulus"), (list, tuple)) and len(fem.data["youngModulus"]) > 1:
            notes.append(f"{fem.name}: youngModulus per element; the first value, {E:g}, is used for the body")
        if fem.type != "TetrahedronFEMForceField":
            notes.append(f"{fem.type} translated as a corotational law")
        material = {"model": model, "young_modulus": float(f"{E * stress:.6g}"), "poisson_ratio": nu}
        tr.comments["material"] = (f"{fem.type} method {method!r} -> {model}; youngModulus {E:g} "
                                   f"({'kPa' if stress == 1e3 else f'x {stress:g} Pa'})")
    masses = _objects(body, _MASSES)
    if masses:
        mass, M, L = masses[0], sc.mass, sc.length
        sc.used.add(id(mass))
        if mass.data.get("totalMass") is not None:
            material["total_mass"] = _num(mass.data["totalMass"]) * M
        elif mass.data.get("vertexMass") is not None:
            material["total_mass"] = _num(mass.data["vertexMass"]) * M * len(sc.X)
        elif mass.data.get("massDensity") is not None:
            material["density"] = _num(mass.data["massDensity"]) * M / L ** 3
        if mass.type == "UniformMass":
            notes.append("UniformMass: its total mass is spread by volume (a consistent mass), not equally per node")
    tr.problem["material"] = material
    regions = _layers(sc, body, fem, material, stress, sc.used, notes)
    if regions:
        tr.problem["material_regions"] = regions
        tr.comments["material_regions"] = "force fields on sub-topologies (stiff layers): their stiffness adds to the body's"


STIFF_SPRINGS = 1e3
"""A ``RestShapeSpringsForceField`` stiffer than this many times the stiffness of a boundary node (E times the
mesh's mean edge) holds its nodes as a support (stlib3's ``FixedBox``: 1e12); a softer one is ``springs``."""


def _fixed(sc: _Scene) -> None:
    """The supports on the body's node or a child of it (stlib3's FixedBox adds a node with a BoxROI and
    springs): ``sc.fixed`` as (entry, comment) pairs, and the soft springs as ``springs`` entries."""
    tr, fixed, springs = sc.tr, [], []
    for node, o in [(n, o) for n in sc.body.walk() for o in _objects(n, _FIXED)]:
        sc.used.add(id(o))
        key = "points" if o.type == "RestShapeSpringsForceField" else "indices"
        sel = o.data.get(key)
        idx, how = _selection(sc, node, sel, sc.X, sc.used)
        if idx is None:
            if sel is None and o.type == "RestShapeSpringsForceField":
                sc.fail(f"{o.type} '{o.name}' holds every node (no points): nothing would move")
            sc.fail(f"{o.type} '{o.name}': cannot resolve its {key} {sel!r}")
        entry = {"indices": [k for k in idx if k < len(sc.in_tets) and sc.in_tets[k]]}  # SOFA holds unused points too
        if not entry["indices"]:
            sc.fail(f"{o.type} '{o.name}' at {node.path() or '/'}: {how or 'its selection'} holds no point of the "
                    f"body (the body spans {np.round(sc.X.min(0), 3).tolist()} to {np.round(sc.X.max(0), 3).tolist()} "
                    f"in scene units)")
        dirs = o.data.get("fixedDirections")
        if o.type.startswith("PartialFixed") and dirs is not None:
            comps = [c for c, d in zip("xyz", _ints(dirs)) if d]
            if comps != ["x", "y", "z"]:
                entry["components"] = comps
        if o.type == "RestShapeSpringsForceField":
            k = _spring_stiffness(sc, o)
            if k is not None:
                springs.append(({"name": o.name, "nodes": entry, "stiffness": k}, f"{o.type} '{o.name}': {how}"))
                continue
            tr.notes.append(f"{o.type} '{o.name}' (stiffness {o.data.get('stiffness', '?')}, over {STIFF_SPRINGS:g} "
                            f"times a boundary node's) translated as fixed nodes")
        fixed.append((entry, f"{o.type} '{o.name}': {how}"))
    if not fixed and not springs:
        bodies = {id(b) for b in [sc.body, *sc.others]}
        touches = [n.path() for n in sc.nodes if _objects(n, _COLLISION_MODELS) and not any(
            id(a) in bodies for a in [n, *_ancestors(n)])]
        hint = (f" (it only rests on {', '.join(touches[:2])} by contact: a robot held by contact alone, one that "
                f"rolls or walks, is not modelled)" if touches else "")
        sc.fail(f"no FixedConstraint, RestShapeSpringsForceField or PartialFixedConstraint on {sc.body.path()}: the "
                f"body is not held{hint}")
    if fixed:
        tr.problem["fixed"] = [e for e, _ in fixed]
        for i, (_, c) in enumerate(fixed):
            tr.comments[f"fixed[{i}]"] = c
    if springs:
        tr.problem["springs"] = [e for e, _ in springs]
        for i, (_, c) in enumerate(springs):
            tr.comments[f"springs[{i}]"] = c
    sc.fixed = fixed + [(e["nodes"], c) for e, c in springs]


def _spring_stiffness(sc: _Scene, o: Object) -> float | None:
    """A RestShapeSpringsForceField's stiffness in N/m if it holds softly, None if it is a support (see
    :data:`STIFF_SPRINGS`); one value per point is averaged, with a note."""
    k = _floats(o.data.get("stiffness", 1.0))
    if k.size > 1 and np.ptp(k) > 1e-9 * abs(k).max():
        sc.tr.notes.append(f"RestShapeSpringsForceField '{o.name}': one stiffness per point, their mean used")
    k_si = float(k.mean()) * sc.mass  # N/m per (scene force / scene length) = kg/s^2
    E = sc.tr.problem["material"]["young_modulus"]
    h = _mean_edge(sc.X[sc.tets] if sc.tets is not None else sc.X) * sc.length
    return None if k_si >= STIFF_SPRINGS * E * h else float(f"{k_si:.6g}")


def _mean_edge(corners: np.ndarray) -> float:
    """The mean edge of tetrahedra (m, 4, 3), or a size scale of a point cloud (k, 3)."""
    if corners.ndim == 2:
        return float(np.linalg.norm(np.ptp(corners, axis=0))) / max(len(corners) ** (1 / 3), 1.0)
    pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    return float(np.mean([np.linalg.norm(corners[:, a] - corners[:, b], axis=1) for a, b in pairs]))


def _actuators(sc: _Scene) -> None:
    tr, cables, cavities = sc.tr, [], []
    sc.open_strokes = []
    # the actuators of the translated body are in its subtree; another body's (a gripper's other fingers)
    # are listed, not translated (an actuator outside every body's subtree is the body's)
    own = [n for n in sc.body.walk()]
    others = [n for n in sc.nodes if n not in own and _objects(n, _CABLES + _CAVITIES)]
    elsewhere = [n for n in others if any(_objects(a, _FEM) for a in [n, *_ancestors(n)])]
    for n in elsewhere:
        for o in _objects(n, _CABLES + _CAVITIES):
            sc.used.add(id(o))
            tr.notes.append(f"{o.type} '{o.name}' at {n.path()} acts on another body: not translated")
    for node in [n for n in sc.nodes if n not in elsewhere]:
        for o in _objects(node, _CABLES):
            sc.used.add(id(o))
            cables.append(_cable(sc, node, o, sc.body, sc.X, sc.length, sc.force, tr.notes, tr, len(cables), sc.used,
                                 sc.open_strokes))
        for o in _objects(node, _CAVITIES):
            sc.used.add(id(o))
            cavities.append(_cavity(sc, node, o, sc.length, sc.stress, tr.notes, tr, len(cavities), sc.out_dir,
                                    sc.used))
    if not cables and not cavities:
        sc.fail("no CableConstraint or SurfacePressureConstraint: nothing actuates the robot")
    if cables:
        tr.problem["cables"] = cables
    if cavities:
        tr.problem["cavities"] = cavities


def _loads(sc: _Scene) -> None:
    """``ConstantForceField`` on the body's points: ``loads`` (a force on each point: ``forces`` one per index,
    ``force`` the same on each, ``totalForce`` shared equally); ``SurfacePressureForceField`` on a surface whose
    vertices are the body's points: ``pressure_loads``."""
    tr, L, X = sc.tr, sc.length, sc.X
    loads, pressures = [], []
    for o in _objects(sc.body, ("ConstantForceField",)):
        idx = _ints(o.data["indices"]) if o.data.get("indices") is not None else np.flatnonzero(sc.in_tets).tolist()
        if any(i >= len(X) for i in idx):
            sc.fail(f"ConstantForceField '{o.name}': an index is beyond the body's {len(X)} points")
        if o.data.get("forces") is not None:
            f = _flat_points(o.data["forces"])
            f = np.repeat(f, len(idx), axis=0) if len(f) == 1 else f
        elif o.data.get("totalForce") is not None:
            f = np.repeat(_flat_points(o.data["totalForce"]) / len(idx), len(idx), axis=0)
        elif o.data.get("force") is not None:
            f = np.repeat(_flat_points(o.data["force"]), len(idx), axis=0)
        else:
            continue
        if len(f) != len(idx):
            sc.fail(f"ConstantForceField '{o.name}': {len(f)} forces for {len(idx)} indices")
        sc.used.add(id(o))
        loads += [{"point": (X[i] * L).tolist(), "force": (fi * sc.force).tolist()} for i, fi in zip(idx, f)
                  if np.any(fi) and sc.in_tets[i]]
        tr.comments["loads"] = f"ConstantForceField '{o.name}' ({len(idx)} points)"
    for node in sc.body.walk():
        for o in _objects(node, ("SurfacePressureForceField",)):
            entry = _surface_pressure(sc, node, o)
            if entry is not None:
                sc.used.add(id(o))
                pressures.append(entry)
    if loads:
        tr.problem["loads"] = loads
    if pressures:
        tr.problem["pressure_loads"] = pressures


def _surface_pressure(sc: _Scene, node: Node, o: Object) -> dict | None:
    """A SurfacePressureForceField's surface (its node's loader, else the body's boundary: ``triangleIndices``
    not translated) as the body's nodes, and its pressure in the problem's sign: SOFA pushes along each
    triangle's winding normal, casadi-ws into the body."""
    from ...fem.mesh import Mesh
    from ...fem.surface import boundary_faces

    if sc.tets is None:
        return None
    loaders = [x for x in node.objects if x.type in _LOADERS and x.data.get("filename")]
    if not loaders or node is sc.body:
        sc.tr.notes.append(f"SurfacePressureForceField '{o.name}': only one on a surface loader of its own is "
                           "translated; not translated")
        return None
    ld = loaders[0]
    sc.used.add(id(ld))
    pts, _, _, raw = _loader_points(sc, ld, sc.length)
    tris = np.concatenate([np.asarray(c.data)[:, :3] for c in raw.cells if c.type == "triangle"] +
                          [np.zeros((0, 3), dtype=np.int64)])
    size = float(np.linalg.norm(np.ptp(sc.X, axis=0)))
    d = np.linalg.norm(pts[:, None, :] - sc.X[None, :, :], axis=2) if len(pts) * len(sc.X) < 5e7 else None
    if d is None or len(tris) == 0:
        sc.fail(f"SurfacePressureForceField '{o.name}': its surface {ld.name} has no triangles or is too large")
    near = d.argmin(axis=1)
    if np.any(d[np.arange(len(pts)), near] > 1e-6 * size):
        sc.fail(f"SurfacePressureForceField '{o.name}': the vertices of {ld.name} are not points of the body (a "
                f"pressure on an embedded surface is not translated)")
    faces = near[tris]
    mesh = Mesh(sc.X, sc.tets)
    outward = boundary_faces(mesh)
    key = {tuple(sorted(f)): f for f in outward.tolist()}
    same = []
    for f in faces.tolist():
        b = key.get(tuple(sorted(f)))
        if b is None:
            sc.fail(f"SurfacePressureForceField '{o.name}': a triangle of {ld.name} is not on the body's boundary")
        same.append(any(f == b[k:] + b[:k] for k in range(3)))
    if 0 < sum(same) < len(same):
        sc.fail(f"SurfacePressureForceField '{o.name}': the triangles of {ld.name} are not wound alike")
    p = _num(o.data.get("pressure"), 0.0) * sc.stress
    if o.data.get("pulseMode") is not None and _bool(o.data.get("pulseMode"), False):
        sc.tr.notes.append(f"SurfacePressureForceField '{o.name}': pulseMode ignored (a constant pressure)")
    return {"name": o.name, "surface": {"indices": sorted(set(np.unique(faces).tolist()))},
            "pressure": float(f"{(-p if same[0] else p):.6g}")}


_ODE = ("EulerImplicitSolver", "EulerExplicitSolver", "RungeKutta4Solver", "RungeKutta2Solver", "StaticSolver",
        "NewmarkImplicitSolver", "CentralDifferenceSolver", "BDFOdeSolver", "VariationalSymplecticSolver",
        "NewtonRaphsonSolver")
_COLLISION_MODELS = ("TriangleCollisionModel", "LineCollisionModel", "PointCollisionModel", "SphereCollisionModel")


def _obstacles(sc: _Scene) -> None:
    """Rigid objects and collision surfaces outside the deformable bodies: a fixed one (stlib3's
    ``isAStaticObject``, a ``FixedConstraint``, collision models with ``moving``/``simulated`` off, or nothing
    integrating it) becomes an obstacle the body may touch but not enter (frictionless); one that moves (a
    cube to grasp) is listed, one line each."""
    bodies = {id(b) for b in [sc.body, *sc.others]}
    out = []
    for n in sc.nodes:
        if any(id(a) in bodies or "rigidify_of" in a.__dict__ for a in [n, *_ancestors(n)]) or any(
                id(a) in sc.__dict__.get("_obstacle_ids", ()) for a in _ancestors(n)):
            continue
        rigid = [o for o in _objects(n, ("MechanicalObject",)) if str(o.data.get("template", "")).startswith("Rigid")]
        models = [o for c in [n, *n.children] for o in _objects(c, _COLLISION_MODELS)]
        if not rigid and not (models and _objects(n, _LOADERS) and not any("Mapping" in o.type for o in n.objects)):
            continue
        sc.__dict__.setdefault("_obstacle_ids", set()).add(id(n))
        info = n.__dict__.get("rigid") or {}
        off = models and all(not _bool(o.data.get("simulated"), True) or not _bool(o.data.get("moving"), True)
                             for o in models)
        integrated = any(_objects(a, _ODE) for a in [n, *_ancestors(n)])
        static = info.get("static") or _objects(n, _FIXED) or off or not integrated
        if not static:
            sc.tr.notes.append(f"rigid object {n.path()} moves (something integrates it): a free object is not "
                               f"modelled, not translated")
            _absorb(sc, n)
            continue
        why, shape = _obstacle_shape(sc, n, info)
        if shape is None:
            sc.tr.notes.append(f"fixed object {n.path()}: {why}; not translated as an obstacle")
        else:
            shape = {"name": n.name, **shape}
            ok = _obstacle_clear(sc, shape)
            if ok is True:
                out.append(shape)
                sc.tr.notes.append(f"fixed object {n.path()} -> obstacle {n.name!r} ({why}; frictionless contact)")
            else:
                sc.tr.notes.append(f"fixed object {n.path()}: {ok}; not translated as an obstacle")
        _absorb(sc, n)
    if out:
        sc.tr.problem["obstacles"] = out
        sc.tr.comments["obstacles"] = "fixed rigid objects and collision surfaces of the scene"


_PIPELINE = ("CollisionPipeline", "DefaultPipeline", "BruteForceBroadPhase", "BruteForceDetection",
             "BVHNarrowPhase", "ParallelBruteForceBroadPhase", "ParallelBVHNarrowPhase", "CollisionResponse",
             "DefaultContactManager", "RuleBasedContactManager", "LocalMinDistance", "MinProximityIntersection",
             "NewProximityIntersection", "DiscreteIntersection")


def _self_collision(sc: _Scene) -> None:
    """A collision surface of the body with ``selfCollision`` on, in a scene with a collision pipeline, is SOFA
    letting the body press on itself: ``self_contact: auto`` (found as it moves, never passing through itself).
    Collision models of the body without it: SOFA lets the body pass through itself, which casadi-ws would
    too; the note says how to forbid it."""
    mine = [o for n in sc.body.walk() for o in _objects(n, _COLLISION_MODELS)]
    if not mine:
        return
    pipeline = [o for n in sc.nodes for o in n.objects if o.type in _PIPELINE]
    selfish = [o for o in mine if _bool(o.data.get("selfCollision"), False)] or _facing_parts(sc.body)
    if selfish and pipeline:
        sc.tr.problem["self_contact"] = "auto"
        sc.tr.comments["self_contact"] = (f"{selfish[0].type} '{selfish[0].name}' selfCollision at "
                                          f"{selfish[0].path()}: the body presses on itself (barrier, frictionless)")
        sc.tr.notes.append(f"self-collision of {sc.body.path()} (selfCollision on {len(selfish)} collision models) "
                           f"-> self_contact: auto, frictionless; the contact distance and stiffness are casadi-ws's "
                           f"own (docs/problem-format.md), not SOFA's alarmDistance/contactDistance")
        sc.used.update(id(o) for o in mine + pipeline)
    elif selfish:
        sc.tr.notes.append(f"{selfish[0].path()} asks for selfCollision but the scene has no collision pipeline: "
                           f"SOFA detects no contact, so neither does the problem (add self_contact: auto to forbid "
                           f"the body passing through itself)")
    else:
        sc.tr.notes.append(f"the collision models of {sc.body.path()} have selfCollision off: in SOFA the body may pass "
                           f"through itself; add self_contact: auto if it curls onto itself")


def _facing_parts(body: Node) -> list:
    """Collision models of the body on two different nodes (two surfaces, each mapped on it) whose groups do
    not share a number: SOFA lets them collide (the Trunk tutorial's ``addCollisionModel(selfCollision=True)``
    puts its two collision meshes in groups 0 and 1)."""
    parts = [(n, o) for n in body.walk() for o in _objects(n, _COLLISION_MODELS)]
    for (na, a), (nb, b) in itertools.combinations(parts, 2):
        if na is not nb and not set(_ints(a.data.get("group", []))) & set(_ints(b.data.get("group", []))):
            return [a, b]
    return []


def _absorb(sc: _Scene, node: Node) -> None:
    for m in node.walk():
        for o in m.objects:
            sc.used.add(id(o))


def _obstacle_shape(sc: _Scene, n: Node, info: dict) -> tuple[str, dict | None]:
    """The obstacle (SI) a fixed object makes: stlib3's Floor a plane, its Cube a box, its Sphere a sphere (SOFA's
    own meshes, ``mesh/floor.obj`` ..., are not needed); otherwise a flat collision mesh a plane."""
    from ...fem.mesh import transform_points

    L = sc.length
    kind = info.get("shape")
    t, r, s = (np.asarray(info.get(k, d), float) for k, d in (("translation", [0, 0, 0]),
                                                              ("rotation", [0, 0, 0]), ("scale", 1.0)))
    if kind == "floor":
        normal = np.round(transform_points(np.array([[0.0, 1.0, 0.0]]), r)[0], 12) + 0.0
        return "stlib3 Floor: a plane", {"plane": {"point": (t * L).tolist(), "normal": normal.tolist()}}
    if kind in ("cube", "sphere") and np.any(r):
        return f"a rotated stlib3 {kind.capitalize()}", None
    if kind == "cube":  # SOFA's mesh/cube.obj spans [-1, 1]^3
        return "stlib3 Cube: a box", {"box": [((t - s) * L).tolist(), ((t + s) * L).tolist()]}
    if kind == "sphere":
        return "stlib3 Sphere: a sphere", {"sphere": {"center": (t * L).tolist(), "radius": float(s * L)}}
    loaders = [o for c in [n, *n.children] for o in _objects(c, _LOADERS) if o.data.get("filename")]
    if not loaders:
        return "no mesh loader gives its shape", None
    f = Path(str(loaders[0].data["filename"]))
    if not (f if f.is_absolute() else sc.dir / f).is_file():
        return f"its mesh {f} is not found", None
    pts = _loader_points(sc, loaders[0], L)[0]
    tf = _transform(loaders[0])
    x = (_apply(tf, pts) if tf else pts) * L
    c = x.mean(axis=0)
    _, sv, vt = np.linalg.svd(x - c, full_matrices=False)
    if sv[-1] > 1e-6 * sv[0]:
        return "its collision mesh is not flat (only flat ones become obstacles, as planes)", None
    return f"a flat collision mesh ({loaders[0].type} '{loaders[0].name}'): a plane", {
        "plane": {"point": c.tolist(), "normal": (np.round(vt[-1], 12) + 0.0).tolist()}}


def _obstacle_clear(sc: _Scene, shape: dict):
    """True when the body at rest lies clear of the obstacle (a plane's normal turned towards the body), else
    why not."""
    from ...fem.contact import Obstacle, boundary_nodes
    from ...fem.mesh import Mesh

    if sc.tets is None:
        return "the body has no tetrahedra to check it against"
    mesh = Mesh(sc.X * sc.length, sc.tets, str(sc.path))
    x = mesh.nodes[boundary_nodes(mesh)]
    if "plane" in shape:
        p, nrm = np.asarray(shape["plane"]["point"]), np.asarray(shape["plane"]["normal"], float)
        side = (x - p) @ nrm
        if side.min() < 0 < side.max():
            return "its plane cuts the body at rest"
        if side.max() <= 0:
            shape["plane"]["normal"] = (-nrm).tolist()
        return True
    kind = next(iter(k for k in shape if k != "name"))
    params = ({"lower": np.asarray(shape["box"][0]), "upper": np.asarray(shape["box"][1])} if kind == "box" else
              {"center": np.asarray(shape["sphere"]["center"]), "radius": shape["sphere"]["radius"]})
    d = Obstacle(kind, "", params).distance(x)
    return True if d.min() > 0 else "it holds or overlaps the body at rest"


def _effector(sc: _Scene) -> None:
    """The first PositionEffector's point, else the centre of the body's end farthest from its support."""
    tr, X = sc.tr, sc.X
    eff = [(n, o) for n in sc.nodes for o in _objects(n, ("PositionEffector",))]
    for n, o in eff:
        goal = o.data.get("effectorGoal")
        if goal is not None:  # a link to a goal node, or coordinates
            tr.notes.append(f"PositionEffector '{o.name}' at {o.path()}: its effectorGoal (SOFA's inverse target) is "
                            f"not translated; casadi-ws reach --target X,Y,Z (m) solves for one")
    for n, o in eff[1:]:
        tr.notes.append(f"PositionEffector '{o.name}' at {o.path()}: only the first effector is the end effector")
    if eff:
        n, o = eff[0]
        mo = _objects(n, ("MechanicalObject",))
        p = _flat_points(mo[0].data.get("position"))[_ints(o.data.get("indices", [0]))[0]] if mo else None
        if p is not None:
            size = float(np.linalg.norm(X.max(0) - X.min(0)))
            tr.problem["end_effector"] = {"point": (p * sc.length).tolist(), "snap": 0.01 * size * sc.length}
            tr.comments["end_effector"] = f"PositionEffector '{o.name}' (moved onto the mesh if within 1 % of its size)"
            return
    held = [np.asarray(e["indices"]) for e, _ in sc.fixed if "components" not in e] or \
        [np.asarray(e["indices"]) for e, _ in sc.fixed]
    axis = _far_axis(X, np.unique(np.concatenate(held)))
    tr.problem["end_effector"] = {"tip": {"axis": axis}}
    tr.comments["end_effector"] = f"no PositionEffector: the centre of the body's end farthest from its support ({axis})"


def _open_strokes(sc: _Scene) -> None:
    """A stroke the scene leaves open (no maxPositiveDisp): 10 % of the cable's rest length, in a note."""
    for i, name in sc.open_strokes:
        c = sc.tr.problem["cables"][i]
        pts = np.asarray(c["points"]) if "points" in c else sc.X[np.asarray(c["indices"])] * sc.length
        line = np.vstack([c["pull_point"], pts]) if "pull_point" in c else pts
        length = float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
        c["u_max"] = float(f"{0.1 * length:.4g}")
        sc.tr.notes.append(f"cable {name}: no maxPositiveDisp in the scene: a stroke of 10 % of its rest length "
                           f"({c['u_max'] * 1e3:.4g} mm) assumed, edit u_max")


def _lame(E, nu):
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


def _layers(scene, body, fem, material, stress, used, notes) -> list[dict]:
    """A second TetrahedronFEMForceField on a sub-topology of the body (its tetrahedra a BoxROI's
    ``tetrahedraInROI``: a strain-limiting layer) adds its stiffness there: a material region, one per box,
    whose Lame parameters are the sums (exact for linear and corotational laws). A box holds the
    tetrahedra whose centroid is in it, as BoxROI's tetrahedraInROI and material_regions both decide."""
    regions = []
    for node in list(body.walk())[1:]:
        for o in _objects(node, _FEM):
            used.add(id(o))
            topo = next((t for t in node.objects if t.type in _ABSORBED and t.type != "MechanicalObject"
                         and any(str(t.data.get(k, "")).endswith("tetrahedraInROI") for k in ("tetrahedra", "tetras"))),
                        None)
            link = None if topo is None else next(str(topo.data[k]) for k in ("tetrahedra", "tetras")
                                                  if str(topo.data.get(k, "")).endswith("tetrahedraInROI"))
            roi = scene.find(link, node) if link else None
            if roi is None or roi.type != "BoxROI":
                notes.append(f"{o.type} '{o.name}' at {node.path()}: its tetrahedra are not a BoxROI's "
                             f"tetrahedraInROI, so it is not translated (a second force field on a sub-topology)")
                continue
            used.add(id(topo))
            used.add(id(roi))
            E2, nu2 = _num(o.data.get("youngModulus"), 5000.0) * stress, _num(o.data.get("poissonRatio"), 0.45)
            mu, lam = (a + b for a, b in zip(_lame(material["young_modulus"], material["poisson_ratio"]), _lame(E2, nu2)))
            E, nu = mu * (3 * lam + 2 * mu) / (lam + mu), lam / (2 * (lam + mu))
            for b in _flat_points(roi.data.get("box", [])).reshape(-1, 6):
                regions.append({"box": (b * scene.length).reshape(2, 3).tolist(), "young_modulus": float(f"{E:.6g}"),
                                "poisson_ratio": float(f"{nu:.6g}")})
            notes.append(f"{o.type} '{o.name}' at {node.path()} on BoxROI '{roi.name}': a layer of E = {E2:.4g} Pa, "
                         f"nu = {nu2:g} added to the body's there (E = {E:.4g} Pa, nu = {nu:.4g})")
    return regions


def _far_axis(X: np.ndarray, fixed_idx: np.ndarray) -> str:
    fixed_idx = np.asarray(fixed_idx, dtype=np.int64)
    d = X.mean(0) - X[fixed_idx].mean(0)
    c = int(np.argmax(np.abs(d)))
    return ("+" if d[c] >= 0 else "-") + "xyz"[c]


def _selection(scene: _Scene, body: Node, sel, X: np.ndarray, used: set):
    """(file point indices, how they were chosen) of a constraint's ``indices``/``points``: a list, or a
    link to a BoxROI/SphereROI evaluated on the body's points (scene units, SOFA's inclusive bounds)."""
    obj = scene.find(sel, body)
    if obj is None and isinstance(sel, Data) and sel.value is not None:
        sel = sel.value
    if obj is None and sel is not None and not isinstance(sel, str) or (isinstance(sel, str) and not sel.startswith("@")):
        try:
            idx = _ints(sel)
        except (TypeError, ValueError):
            return None, ""
        return idx, f"{len(idx)} indices"
    if obj is None:
        return None, ""
    used.add(id(obj))
    if obj.type == "BoxROI":
        flat = _flat_points(obj.data.get("box", [])).reshape(-1, 6)
        flat = np.hstack([np.minimum(flat[:, :3], flat[:, 3:]), np.maximum(flat[:, :3], flat[:, 3:])])  # as SOFA
        mask = np.zeros(len(X), bool)
        for b in flat:
            mask |= np.all((X >= b[:3]) & (X <= b[3:]), axis=1)
        boxes = "; ".join(str([float(f"{x:g}") for x in b]) for b in flat)
        return np.flatnonzero(mask).tolist(), f"BoxROI '{obj.name}' box {boxes} (scene units): {int(mask.sum())} nodes"
    if obj.type == "SphereROI":
        c = _flat_points(obj.data.get("centers"))
        r = np.atleast_1d(np.asarray(obj.data.get("radii"), dtype=float)).ravel()
        mask = np.zeros(len(X), bool)
        for k, ck in enumerate(c):
            mask |= np.linalg.norm(X - ck, axis=1) <= r[min(k, r.size - 1)]
        return np.flatnonzero(mask).tolist(), f"SphereROI '{obj.name}' (scene units): {int(mask.sum())} nodes"
    return None, ""


def _cable(scene, node, o, body, X, L, force, notes, tr, i, used, disp) -> dict:
    name = o.data.get("name", f"cable{i + 1}")
    name = node.name if name in ("cable", "aCableActuator", "CableConstraint") and node.name not in ("cable",) else str(name)
    entry: dict = {"name": str(name)}
    comment = [f"{o.type} '{o.name}' at {node.path()}"]
    idx = _ints(o.data["indices"]) if o.data.get("indices") is not None else None
    centers = o.data.get("centers")
    if centers is not None:
        # SOFA attaches the cable at the surface vertex closest to each centre and, with method sphere or
        # geodesic, spreads its force over the vertices within the centre's radius
        entry["points"] = [[float(f"{x * L:.9g}") for x in p] for p in _flat_points(centers)]
        method = str(o.data.get("method", "point"))
        if method in ("sphere", "geodesic"):
            radii = _floats(o.data.get("radii", [1.0]))
            entry["spread"] = float(f"{radii.max() * L:.9g}")
            notes.append(f"cable {name}: its force spread over the body's surface within {radii.max() * L * 1e3:.3g} "
                         f"mm of each centre (method {method}"
                         f"{': the straight distance stands for the geodesic one' if method == 'geodesic' else ''}"
                         f"{'; the largest of its radii' if radii.size > 1 and np.ptp(radii) > 0 else ''})")
        comment.append(f"centers ({method})")
        for m in _objects(node, ("MechanicalObject",)) + _objects(node, _LOADERS):
            used.add(id(m))
    elif node is body:
        if idx is None:
            scene.fail(f"{o.type} '{o.name}' on the body has no indices")
        entry["indices"] = idx
    else:
        mo = _objects(node, ("MechanicalObject",))
        if not mo or mo[0].data.get("position") is None:
            scene.fail(f"{o.type} '{o.name}': its node {node.path()} has no MechanicalObject with positions")
        used.add(id(mo[0]))
        P = _flat_points(mo[0].data["position"])
        placed = _transform(mo[0])  # a MechanicalObject's own rotation/translation/scale (PullingCable's)
        if placed:
            P = _apply(placed, P)
        idx = list(range(len(P))) if idx is None else idx
        if max(idx) >= len(P):
            scene.fail(f"{o.type} '{o.name}': index {max(idx)} but its MechanicalObject has {len(P)} points")
        if len(idx) < len(P):
            comment.append(f"points {idx[0]}..{idx[-1]} of {len(P)}")
        entry["points"] = [[float(f"{x * L:.9g}") for x in p] for p in P[idx]]
    if _bool(o.data.get("hasPullPoint"), True):
        pull = o.data.get("pullPoint")
        if pull is None:
            notes.append(f"cable {name}: hasPullPoint without a pullPoint: SOFA's default (0, 0, 0) used")
            pull = [0, 0, 0]
        entry["pull_point"] = [float(f"{x * L:.9g}") for x in _flat_points(pull)[0]]
    value_type = str(o.data.get("valueType", "displacement"))
    if value_type == "force":
        lo, hi = _num(o.data.get("minForce"), 0.0), _num(o.data.get("maxForce"))
        if hi is None:
            hi = 1.0 / force
            notes.append(f"cable {name}: force-controlled with no maxForce: u_max set to 1 N, edit it")
        entry["u_min"], entry["u_max"] = max(lo, 0.0) * force, hi * force
    else:
        # SOFA's default: the input is the cable's shortening; maxPositiveDisp bounds it, maxNegativeDisp
        # bounds its lengthening
        entry["control"] = "displacement"
        dmax, dneg = _num(o.data.get("maxPositiveDisp")), _num(o.data.get("maxNegativeDisp"), 0.0)
        entry["u_min"] = -dneg * L if dneg else 0.0
        entry["u_max"] = None if dmax is None else dmax * L
        if dmax is None:
            disp.append((i, name))
        comment.append(f"maxPositiveDisp {o.data.get('maxPositiveDisp', 'unset')}")
        min_force = _num(o.data.get("minForce"))
        if min_force not in (None, 0.0):
            notes.append(f"cable {name}: minForce {min_force:g}: a cable here never pushes and goes slack at zero "
                         f"tension (minForce 0)")
    tr.comments[f"cables[{i}]"] = "; ".join(comment)
    return entry


def _cavity(scene, node, o, L, stress, notes, tr, i, out_dir, used) -> dict:
    name = str(o.data.get("name", node.name))
    loaders = [x for x in node.objects if x.type in _LOADERS and x.data.get("filename")]
    if not loaders:
        scene.fail(f"{o.type} '{o.name}': its node {node.path()} has no surface loader (MeshSTLLoader, ...)")
    ld = loaders[0]
    used.add(id(ld))
    pts, file, t, raw = _loader_points(scene, ld, L)
    entry: dict = {"name": node.name if name == o.type else name,
                   "surface": os.path.relpath(file.resolve(), Path(out_dir).resolve()), "scale": L}
    if t:
        if "translation" in t:
            t["translation"] = [x * L for x in t["translation"]]
        entry["transform"] = t
    _embed_tolerance(scene, entry, _apply(t, pts) if t else pts, L, notes)
    value_type = str(o.data.get("valueType", "pressure"))
    if value_type == "volumeGrowth":
        # the input is the chamber's volume growth (scene length units cubed), the pressure an unknown
        entry["control"] = "volume"
        lo, hi = _num(o.data.get("minVolumeGrowth"), 0.0), _num(o.data.get("maxVolumeGrowth"))
        if hi is None:
            # SOFA leaves the growth unbounded; a workspace needs a box: half the chamber's rest volume, said
            hi = 0.5 * _rest_volume(scene, o, pts, raw)
            notes.append(f"cavity {entry['name']}: no maxVolumeGrowth in the scene: u_max set to half its rest "
                         f"volume ({hi * L**3 * 1e9:.4g} mm^3), edit it")
        entry["u_min"], entry["u_max"] = lo * L**3, hi * L**3
    else:
        lo, hi = _num(o.data.get("minPressure"), 0.0), _num(o.data.get("maxPressure"))
        if hi is None:
            hi = 1e4 / stress
            notes.append(f"cavity {entry['name']}: no maxPressure in the scene: u_max set to 10 kPa, edit it")
        entry["u_min"], entry["u_max"] = lo * stress, hi * stress
    tr.comments[f"cavities[{i}]"] = f"{o.type} '{o.name}' at {node.path()}, surface {ld.type} '{ld.name}'"
    return entry


EMBED_SLACK = 0.05
"""A cavity surface up to this share of the body's size (its bounding-box diagonal) outside it is embedded as
SOFA's barycentric mapping does (extrapolated); the problem format's default allows 1 %."""


def _embed_tolerance(scene: _Scene, entry: dict, pts: np.ndarray, L: float, notes: list) -> None:
    from ...fem.mesh import Mesh, embed

    if scene.tets is None:
        return
    mesh = Mesh(scene.X, scene.tets, str(scene.path))
    h, out = mesh.characteristic_length(), embed(mesh, pts).outside
    if 0.01 * h < out.max() <= EMBED_SLACK * h:
        entry["embed_tolerance"] = float(f"{1.05 * out.max() * L:.3g}")
        notes.append(f"cavity {entry['name']}: {int((out > 0.01 * h).sum())} surface vertices lie up to "
                     f"{out.max() * L * 1e3:.3g} mm outside the body; embedded as SOFA's barycentric mapping does "
                     f"(embed_tolerance {entry['embed_tolerance']:g} m)")


def _rest_volume(scene: _Scene, o: Object, pts: np.ndarray, raw) -> float:
    """The volume a cavity's surface encloses (scene units cubed), whichever way its triangles turn."""
    from ...actuation.cavity import surface_volume

    tris = [np.asarray(c.data) for c in raw.cells if c.type in ("triangle", "triangle6")]
    if not tris:
        scene.fail(f"{o.type} '{o.name}': its surface has no triangles")
    return abs(float(sum(surface_volume(pts, t) for t in tris)))


def _leftovers(scene: _Scene, used: set) -> list[str]:
    """One line per component type that was not translated."""
    groups: dict[str, list[str]] = {}
    others = {id(b): b for b in getattr(scene, "others", [])}
    bodies: dict[str, list[str]] = {}  # another body: one line, its component types
    for n in scene.nodes:
        other = next((a for a in [n, *_ancestors(n)] if id(a) in others), None)
        for o in n.objects:
            if other is not None:
                bodies.setdefault(other.path(), []).append(o.type)
                continue
            if id(o) in used or o.type in _ABSORBED:
                continue
            if o.type == "Controller":
                label = f"controller {type(o).__name__} (Python code SOFA runs during a simulation)"
            else:
                label = next((f"{o.type}: {why}" for why, words in _KINDS if any(w in o.type for w in words)),
                             f"{o.type}: unknown to the importer")
            groups.setdefault(label, []).append(o.path())
    return [f"{label} at {', '.join(paths)}" for label, paths in groups.items()] + [
        f"another deformable body at {path} ({len(kinds)} components: {', '.join(sorted(set(kinds)))})"
        for path, kinds in bodies.items()]


def _yaml(v) -> str:
    def clean(x):
        if isinstance(x, dict):
            return {k: clean(y) for k, y in x.items()}
        if isinstance(x, (list, tuple, np.ndarray)):
            return [clean(y) for y in x]
        if isinstance(x, (np.integer,)):
            return int(x)
        if isinstance(x, (float, np.floating)):
            return float(f"{float(x):.10g}")
        return x

    return json.dumps(clean(v))


def write_problem(tr: Translation, out: str | Path, scene: str) -> None:
    """The commented problem file of a translation."""
    lines = [f"# Imported from the SOFA scene {scene} by casadi-ws import-sofa: SI units (m, N, Pa, kg).",
             f"# Scene units: {tr.units}."]
    if tr.notes:
        lines.append("# Notes:")
        lines += [f"#   {n}" for n in tr.notes]
    if tr.untranslated:
        lines.append("# Not translated:")
        lines += [f"#   {n}" for n in tr.untranslated]
    for key, value in tr.problem.items():
        if key in tr.comments:
            lines.append(f"# {tr.comments[key]}")
        if isinstance(value, list) and value and isinstance(value[0], dict):
            lines.append(f"{key}:")
            for i, item in enumerate(value):
                c = tr.comments.get(f"{key}[{i}]")
                if c:
                    lines.append(f"  # {c}")
                lines.append(f"  - {_yaml(item)}")
        else:
            lines.append(f"{key}: {_yaml(value)}")
    Path(out).write_text("\n".join(lines) + "\n")


def import_scene(scene: str | Path, out: str | Path, units: str | None = None) -> Translation:
    """Translate ``scene`` and write the problem file ``out``; returns the translation."""
    out = Path(out)
    tr = translate(scene, units, out.parent if str(out.parent) else Path.cwd())
    write_problem(tr, out, Path(scene).name)
    return tr
