"""The body against itself wherever it meets itself (:class:`AutoSelfContact`, problem file ``self_contact:
auto``): contact found as the body deforms, held by a smooth barrier.

Which parts of the boundary touch is not declared: at every state a bounding-volume hierarchy over the
deformed boundary triangles gives the point-triangle and edge-edge pairs closer than the barrier's reach
``dhat`` (the IPC Toolkit, ``ipctk``; pairs that share a vertex are never pairs). Each pair adds the barrier
energy kappa b(d) (IPC's clamped log barrier, b = -(d - dhat)^2 log(d / dhat) for d < dhat, zero beyond, in
physical units) of its distance d; the term adds its gradient to R and its exact Hessian to K. The barrier
grows without bound as d -> 0, so a surface never passes through itself as long as Newton's steps do not
jump across it: each step is cut to :data:`CCD_SHARE` of the first time of contact along it (continuous
collision detection), as IPC does. The state then keeps a gap below dhat where the body presses on itself: the
geometric error of the contact, stated with each result (``dhat`` defaults to :data:`DISTANCE` of the boundary's mean edge).

The pairs change with the state, and with them the entries of K: the model's pattern grows by the blocks of
every pair found within :data:`PATTERN_REACH` of the mean edge (never shrinks), and the factorisations then redo their
symbolic analysis once (:meth:`casadi_ws.fem.model.StaticModel.grow_pattern`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .base import Term

__all__ = ["AutoSelfContact", "PATTERN_REACH"]

PATTERN_REACH = 0.1
"""Pairs closer than this share of the boundary's mean edge join the pattern before they press, so the
pattern grows a few times along a path rather than at every Newton step."""

DISTANCE = 1e-3
"""The default dhat, as a share of the boundary's mean edge: the largest gap a pressing contact keeps, so the
geometric error of the contact (1e-2 moved the stacked cantilevers' contact force by 2 %)."""

STIFFNESS = 1e3
"""kappa: a pair's stiffness at half the barrier's reach, in boundary-node stiffnesses E h."""

CCD_SHARE = 0.8
"""Share of the first time of contact a Newton step may go where two parts of the boundary are already within
:data:`LANDING` of dhat (IPC's choice: what is left keeps d > 0)."""

LANDING = 0.5
"""A step that would bring two parts of the boundary closer than this share of dhat stops where they are that
far apart: inside the barrier's reach, so the next Newton step sees the contact. (Cut at CCD_SHARE of the time
of contact instead, a Newton step that does not see the contact yet shrank the gap about 3x per iteration, each
with a fresh LU, until it came within dhat; the pinch gripper at 1.5 N per cable took 478 iterations.)"""

MAX_PAIRS = 20
"""Most pairs within the barrier's reach per boundary vertex before the search is refused as exploding (a
surface pressed flat on itself has a few: the SOFA Trunk's disks at 97.8 % of a cable 34 pairs over 2000
vertices; more means the reach spans whole elements of a collapsing body, and the LU would go dense)."""


class AutoSelfContact(Term):
    """Self-contact found as the body deforms, held by a barrier (see the module)."""

    name = "self_contact"
    phase = "rows"
    applied = True
    contact = True
    negatives = 0  # a potential's Hessian: the tangent stays symmetric where the rest is
    n_rows = 0
    grows = True

    def __init__(self, young_modulus: float, distance: float | None = None, stiffness: float | None = None):
        self.young_modulus = float(young_modulus)
        self.distance = distance
        """dhat (m): the barrier acts on pairs closer than this; None: :data:`DISTANCE` of the boundary's mean
        edge."""
        self.stiffness = stiffness
        """kappa (N/m, the physical barrier's): None for STIFFNESS E h / b''(dhat / 2), a pair's stiffness at
        half its reach STIFFNESS times a boundary node's."""

    # ---------------------------------------------------------------- building
    def setup(self, model, pos):
        import ipctk

        from ..collision import collision_surface, mean_edge

        # its CCD warns on stderr where a pair starts closer than the distance asked for: not news here
        ipctk.set_logger_level(ipctk.LoggerLevel.error)
        self.surface = s = collision_surface(model)
        dofs = 3 * s.nodes[:, None] + np.arange(3)
        self._fpos = pos[dofs.ravel()]  # free position of each surface dof (vertex-major), -1 fixed
        X = model.mesh.nodes[s.nodes]
        self.h = mean_edge(s, model.mesh.nodes)
        self.dhat = float(self.distance) if self.distance else DISTANCE * self.h
        kappa = self.stiffness if self.stiffness else STIFFNESS * self.young_modulus * self.h / _unit_stiffness(self.dhat)
        self.kappa = float(kappa)
        self.barrier = ipctk.BarrierPotential(self.dhat, self.kappa, True)
        self._known = sp.csr_matrix((s.nodes.size, s.nodes.size), dtype=bool)
        self._grow_known(model, np.asfortranarray(X))

    def _grow_known(self, model, V) -> bool:
        """Adds to the known vertex pairs those of every pair within the pattern's reach at V; whether any
        was new. (The pairs are read off a barrier's Hessian over that reach: ipctk's collision objects are
        not to be held from Python, whose wrappers free them twice.)"""
        import ipctk

        reach = max(PATTERN_REACH * self.h, 2 * self.dhat)
        col = ipctk.NormalCollisions()
        col.build(self.surface.mesh, V, reach)
        if not len(col):
            return False
        H = ipctk.BarrierPotential(reach, 1.0, True).hessian(col, self.surface.mesh, V).tocoo()
        n = self.surface.nodes.size
        new = sp.csr_matrix((np.ones(H.nnz, dtype=bool), (H.row // 3, H.col // 3)), shape=(n, n))
        grown = (self._known + new).astype(bool)
        if grown.nnz == self._known.nnz:
            return False
        self._known = grown
        return True

    def pattern(self, model, pos):
        k = self._known.tocoo()
        a = (3 * k.row[:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2).ravel()
        b = (3 * k.col[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1).ravel()
        fa, fb = self._fpos[a], self._fpos[b]
        ok = (fa >= 0) & (fb >= 0)
        return fb[ok].astype(np.int64) * model.n_free + fa[ok]

    # ---------------------------------------------------------------- evaluation
    def _collisions(self, model, q):
        import ipctk

        V = self.surface.vertices(model.positions(q))
        col = ipctk.NormalCollisions()
        col.build(self.surface.mesh, V, self.dhat)
        if len(col) > MAX_PAIRS * self.surface.nodes.size:
            from ..spec import ModelError

            raise ModelError(f"self_contact: {len(col)} pairs of the boundary closer than its contact distance "
                             f"{self.dhat:.3g} m, more than {MAX_PAIRS} per boundary vertex: the candidate search "
                             f"explodes (the body collapses onto itself, or the distance spans whole elements); "
                             f"give a smaller self_contact.distance")
        self._last = (q.copy(), len(col))
        return V, col

    def _pressing(self, model, q) -> bool:
        """Whether any pair is within dhat at q: the last residual's search where it was at this q (Newton's
        step limit follows the residual of the same iterate), else a new one."""
        last = getattr(self, "_last", None)
        if last is not None and np.array_equal(last[0], q):
            return last[1] > 0
        return len(self._collisions(model, q)[1]) > 0

    def residual(self, model, q, u, R):
        V, col = self._collisions(model, q)
        if not len(col):
            return None
        if self._grow_known(model, V):
            model.grow_pattern()
        g = self.barrier.gradient(col, self.surface.mesh, V)
        ok = self._fpos >= 0
        R += np.bincount(self._fpos[ok], weights=g[ok], minlength=R.size)
        return V, col

    def tangent(self, model, cache):
        if cache is None:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        V, col = cache
        H = self.barrier.hessian(col, self.surface.mesh, V).tocoo()
        fr, fc = self._fpos[H.row], self._fpos[H.col]
        ok = (fr >= 0) & (fc >= 0)
        return fc[ok].astype(np.int64) * model.n_free + fr[ok], H.data[ok]

    def held(self, model, q, u):
        return None  # its stiffness is in K already

    cut_judged = True

    def step_limit(self, model, q, dq) -> float:
        """The share of the step that brings no two parts of the boundary closer than LANDING dhat, or where
        some are that close already, CCD_SHARE of the first time of contact (1 where neither binds)."""
        import ipctk

        x0 = model.positions(q)
        d = np.zeros(model.n_dof)
        d[model.free] = dq
        x1 = x0 + d[: model.n_mech].reshape(-1, 3)
        s = self.surface
        V0, V1 = s.vertices(x0), s.vertices(x1)
        if not self._pressing(model, q):  # nothing presses yet: stop where the first pair comes within reach
            land = ipctk.compute_collision_free_stepsize(s.mesh, V0, V1, LANDING * self.dhat)
            if land >= 1.0:
                return 1.0
            if land > 1e-6:
                return float(land)
        toi = ipctk.compute_collision_free_stepsize(s.mesh, V0, V1)
        return 1.0 if toi >= 1.0 else CCD_SHARE * float(toi)

    def admits(self, model, q) -> bool:
        """Whether q may start a Newton solve: its boundary does not pass through itself (the barrier only
        sees distances, so from a state already through itself it would hold the surfaces crossed)."""
        from ..collision import surface_crosses

        return not surface_crosses(model, model.positions(q))

    # ---------------------------------------------------------------- what it reports
    def contact_forces(self, model, q) -> np.ndarray:
        """The barrier's forces on the free dofs (-gradient)."""
        V, col = self._collisions(model, q)
        out = np.zeros(model.n_free)
        if len(col):
            g = self.barrier.gradient(col, self.surface.mesh, V)
            ok = self._fpos >= 0
            out -= np.bincount(self._fpos[ok], weights=g[ok], minlength=model.n_free)
        return out

    def in_contact(self, model, q) -> np.ndarray:
        """(s,) bool: the boundary vertices of a pair within dhat (pressed by the barrier)."""
        V, col = self._collisions(model, q)
        if not len(col):
            return np.zeros(self.surface.nodes.size, dtype=bool)
        g = self.barrier.gradient(col, self.surface.mesh, V).reshape(-1, 3)
        return np.any(g != 0.0, axis=1)

    @property
    def multistable(self) -> np.ndarray:
        """Every vertex: a body pressing on its own faceted boundary can rest in more than one way at the same
        inputs (measured on SoftRobots' Finger curled onto its base: loading in tenths, in halves and unloading
        from beyond end up to 53 um apart), so the path from rest decides
        (:func:`casadi_ws.solvers.equilibrium.settle`)."""
        return np.ones(self.surface.nodes.size, dtype=bool)

    def report(self, model, q) -> list[dict]:
        """One entry: name ``self_contact``, kind ``self``, ``force`` the force (N) the body presses on itself
        with (half the sum of the barrier's nodal force magnitudes: each pair pushes its two sides apart
        equally; a body pressing on itself exerts no net force on itself), ``points`` the pairs within dhat,
        ``gap`` the smallest distance (m) and ``dhat``."""
        V, col = self._collisions(model, q)
        if not len(col):
            return [{"name": self.name, "kind": "self", "force": 0.0, "points": 0, "penetration": 0.0,
                     "gap": None, "dhat": self.dhat}]
        g = self.barrier.gradient(col, self.surface.mesh, V).reshape(-1, 3)
        gap = float(np.sqrt(col.compute_minimum_distance(self.surface.mesh, V)))  # ipctk: squared
        return [{"name": self.name, "kind": "self", "force": float(0.5 * np.linalg.norm(g, axis=1).sum()),
                 "points": int(len(col)), "penetration": 0.0, "gap": gap, "dhat": self.dhat}]


def _unit_stiffness(dhat: float) -> float:
    """d2/dd2 of the physical barrier with kappa = 1 at d = dhat / 2 (a point above a triangle)."""
    import ipctk

    V = np.asfortranarray(np.array([[0.0, 0.0, 0.0], [10 * dhat, 0.0, 0.0], [0.0, 10 * dhat, 0.0],
                                    [2 * dhat, 2 * dhat, 0.5 * dhat]]))
    F = np.array([[0, 1, 2]], dtype=np.int32)
    mesh = ipctk.CollisionMesh(V, ipctk.edges(F), F)
    col = ipctk.NormalCollisions()
    col.build(mesh, V, dhat)
    H = ipctk.BarrierPotential(dhat, 1.0, True).hessian(col, mesh, V)
    return float(H.toarray()[-1, -1])
