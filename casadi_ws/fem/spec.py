"""The model's own specification: what a :class:`casadi_ws.fem.model.StaticModel` is built from.

Typed dataclasses, in the model's layer: the body (mesh, materials, regions), its supports, the actuators, the
loads, the end effector, the obstacles and the self-contact pairs, and the settings of the solves and of the
admissibility checks. :class:`casadi_ws.io.problem.Problem` (a problem file, or one built in Python) *is* a
ModelSpec with what only the command line and the studies read beside it (``workspace``, ``task``); the layers
below ``io`` read a ModelSpec's fields and nothing else (tests/test_architecture.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .contact import Obstacle
from .materials import Material
from .mesh import Mesh

__all__ = ["AdmissibilitySettings", "AutoSelfContact", "ModelError", "ModelSpec", "SelfContactPair",
           "SolverSettings", "ranged_inputs"]


def ranged_inputs(u_min, u_max) -> np.ndarray:
    """Indices of the inputs with a range (u_max > u_min): an input held at one value (a cable kept at its rest
    length) still acts, but is no dimension of the box U (the forward grid, the boundary's faces, the measures)."""
    return np.flatnonzero(np.asarray(u_max, float) > np.asarray(u_min, float))


class ModelError(ValueError):
    """A problem that reads well but cannot make a model; ``str()`` is one line naming the file and key."""


@dataclass
class SolverSettings:
    """Settings of the equilibrium (Newton) solve."""

    tolerance: float = 1e-8
    """Relative residual ||R|| / ||H^T u + F|| under which an equilibrium counts as verified."""
    max_iterations: int = 30
    """Newton iterations per solve (each load step of a continuation counts separately)."""
    max_load_steps: int = 64
    """Continuation steps allowed when a direct Newton solve fails."""
    newton: str = "builtin"
    """``builtin`` (Newton reusing LU factorisations across iterations and points: the faster) or
    ``rootfinder`` (casadi.rootfinder's Newton with MUMPS on the same residual Function)."""
    linear: str = "auto"
    """The sparse factorisation of the tangent (:mod:`casadi_ws.solvers.linear`): ``auto`` (PARDISO where
    installed, else SuperLU), ``superlu`` or ``pardiso``."""


@dataclass
class AdmissibilitySettings:
    """Which checks run and their tolerances (problem file: ``admissibility:``)."""

    stability: bool = True
    """Refuse equilibria whose tangent is not positive definite (see :mod:`casadi_ws.solvers.admissible`)."""
    inversion: bool = True
    """Refuse equilibria with det F below ``min_det_F`` at some quadrature point."""
    self_penetration: bool = True
    """Refuse equilibria whose deformed boundary passes through the body."""
    min_det_F: float = 0.1
    """Floor of det F (volume ratio) at every quadrature point: below it an element counts as inverted
    (no law here is meant for a tenfold volumetric compression of a rubber)."""
    penetration_depth: float = 0.01
    """A boundary sample counts as inside a tetrahedron when all four of its barycentric coordinates there
    exceed this (1 %: the margin that keeps a curved 10-node face's samples, judged against the straight
    tetrahedron of its corners, out of their neighbours)."""
    keep: bool = False
    """Keep inadmissible equilibria among the reported points, marked (``--keep-inadmissible``); by
    default they are counted and kept apart."""


@dataclass
class SelfContactPair:
    """Two regions of the body that may meet: the boundary nodes ``points`` may not enter the boundary
    ``faces`` (problem file: ``self_contact:``)."""

    name: str
    points: np.ndarray
    """Boundary node indices."""
    faces: np.ndarray
    """Boundary faces (k, 3) or (k, 6) node indices, oriented out of the body."""
    reach: float | None = None
    """How far (m) a point may slide along the surface and stay paired with its triangles (default: two mean
    edges of the surface, :class:`casadi_ws.fem.terms.SelfContact`)."""


@dataclass
class AutoSelfContact:
    """Self-contact found as the body deforms (problem file: ``self_contact: auto``;
    :class:`casadi_ws.fem.terms.AutoSelfContact`)."""

    distance: float | None = None
    """dhat (m): the barrier acts on pairs of the boundary closer than this; None: 0.1 % of the boundary's mean
    edge. It bounds the gap a pressing contact keeps (the geometric error of the contact)."""
    stiffness: float | None = None
    """The barrier's stiffness kappa (N/m); None: a pair's stiffness at half its reach is 1000 times a boundary
    node's, E h (:data:`casadi_ws.fem.terms.auto_contact.STIFFNESS`)."""


@dataclass
class ModelSpec:
    """What a static model is built from (SI units: m, N, Pa, kg/m^3)."""

    mesh: Mesh
    """The body at rest."""
    material: Material
    fixed_nodes: np.ndarray
    """Indices of the nodes held fixed (zero displacement)."""
    actuators: list
    """The actuators (:class:`casadi_ws.actuation.base.Actuator`: cables, then cavities, in file order); the
    input vector u holds their inputs in this order."""
    end_effector: np.ndarray
    """Rest position of the point of interest (3,), embedded in the mesh."""
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Gravitational acceleration (3,), m/s^2."""
    point_loads: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    """(point, force) pairs: constant forces in N on embedded points."""
    solver: SolverSettings = field(default_factory=SolverSettings)
    name: str = "problem"
    source: str = "<python>"
    """Where it was read from (a file's path): error messages name it."""
    regions: list[tuple[np.ndarray, Material]] = field(default_factory=list)
    """Parts of the body of another material: (tetrahedron indices, Material) pairs, later ones win. A
    region may have a law of its own (a strain-limiting layer of a stiffer silicone)."""
    partial_fixed: list[tuple[np.ndarray, tuple[int, ...]]] = field(default_factory=list)
    """Further supports holding only some components of some nodes: (node indices, components 0/1/2)
    pairs (SOFA's PartialFixedConstraint: symmetry planes, rollers)."""
    admissibility: AdmissibilitySettings = field(default_factory=AdmissibilitySettings)
    """Which admissibility checks run on every reported equilibrium, and their tolerances."""
    obstacles: list[Obstacle] = field(default_factory=list)
    """Rigid, fixed obstacles the body may not enter."""
    self_contact: list[SelfContactPair] = field(default_factory=list)
    """Pairs of the body's regions that may meet."""
    self_contact_auto: AutoSelfContact | None = None
    """Self-contact wherever the boundary meets itself (None: off; the ``self_penetration`` audit then
    refuses states that pass through themselves)."""
    tip_frame: np.ndarray | None = None
    """Three points (3, 3) at the tip whose plane carries its orientation (:mod:`casadi_ws.fem.frame`); None:
    the tip elements' rotation."""
    body_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """A force per unit volume (3,), N/m^3, uniform over the body (a load field that is not weight: a magnetic
    or buoyant body, a manufactured solution's source), as consistent nodal loads."""
    terms: list = field(default_factory=list)
    """Terms added to those the fields above make (:mod:`casadi_ws.fem.terms`): a problem file's ``springs``
    and ``pressure_loads``, or a user's own :class:`casadi_ws.fem.terms.Term`. Each model works on a copy."""

    def fixed_dofs(self) -> np.ndarray:
        """Mask (n_nodes, 3) of the displacement components held at zero."""
        mask = np.zeros((self.mesh.n_nodes, 3), dtype=bool)
        mask[np.asarray(self.fixed_nodes, dtype=np.int64)] = True
        for nodes, comps in self.partial_fixed:
            mask[np.ix_(np.asarray(nodes, dtype=np.int64), list(comps))] = True
        return mask

    @property
    def n_u(self) -> int:
        return len(self.actuators)

    @property
    def u_min(self) -> np.ndarray:
        return np.array([a.u_min for a in self.actuators], dtype=float)

    @property
    def u_max(self) -> np.ndarray:
        return np.array([a.u_max for a in self.actuators], dtype=float)
