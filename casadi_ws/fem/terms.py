"""Terms of the residual that bring their own unknowns and rows: contact with obstacles and self-contact.

The model's residual on the free dofs is the elements' forces, the actuators' and the loads', and then the
sum over its registered terms (:attr:`casadi_ws.fem.model.StaticModel.terms`). A term adds forces to the
nodal rows, owns a block of unknowns and of rows at the end of the state, and gives each piece once: its
residual, its tangent's entries on the model's fixed pattern, its share of the Hessian of lam . R (the NLPs),
what it holds in the stability test, and how far a Newton step may go. Newton, the sensitivities, the
CasADi Functions and the admissibility checks iterate over the terms; a new kind of contact or constraint is
a new term and its problem-file reader, nothing else.

A contact term is a set of points, each with a gap g_i(q) (m; > 0 apart) and a normal force lambda_i >= 0
(held in the state as lambda_i / kappa, a length), and one smoothed Fischer-Burmeister row
phi(lambda_i, kappa g_i(q)) = 0 (Signorini's conditions; docs/methods.md "Contact"). The nodal rows get
-lambda_i dg_i/dq. A subclass gives the geometry: g, the normal, the nonzeros of dg/dq and of d2g/dq2.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .contact import ContactSet

__all__ = ["ContactGeometry", "ContactTerm", "ObstacleContact", "SelfContact", "Term", "fischer_burmeister"]


def fischer_burmeister(a, b, eps):
    """(phi, dphi/da, dphi/db, d2phi/da2, d2phi/dadb, d2phi/db2) of the smoothed Fischer-Burmeister function
    phi(a, b) = a + b - sqrt(a^2 + b^2 + eps^2), zero iff a, b >= 0 and a b = eps^2 / 2."""
    rho = np.sqrt(a * a + b * b + eps**2)
    r3 = rho**3
    return (a + b - rho, 1 - a / rho, 1 - b / rho, -(b * b + eps**2) / r3, a * b / r3, -(a * a + eps**2) / r3)


class Term:
    """One registered term: ``n_rows`` unknowns and rows of its own (``rows``, a slice of the free dofs, and
    ``state``, a slice of the full state, set when the model registers it)."""

    name = ""
    applied = True
    """Whether its nodal forces count as applied loads in the residual's scale (contact forces do)."""
    n_rows = 0
    negatives = None
    """How many negative eigenvalues its block adds to a stable tangent when its rows keep the tangent
    symmetric (a saddle point's: the pressure's n_rows), so that the stability test reads them off the
    pivots; None when they do not (contact rows): the test then factorises the stiffness it holds."""
    rows = slice(0, 0)
    state = slice(0, 0)

    def pattern(self, model, pos: np.ndarray) -> np.ndarray:
        """Keys (column * n_free + row) of every tangent entry it may ever give; ``pos`` maps a dof to its
        free position (-1 fixed)."""
        raise NotImplementedError

    def residual(self, model, q, u, R):
        """Add its forces to the nodal rows of R (free dofs), set its own rows; return what :meth:`tangent`
        needs."""
        raise NotImplementedError

    def tangent(self, model, cache) -> tuple[np.ndarray, np.ndarray]:
        """(keys, values) of dR/dq it contributes (keys a subset of :meth:`pattern`; repeated keys add)."""
        raise NotImplementedError

    def hessian(self, model, q, u, lam) -> sp.csc_matrix:
        """Its share of d(K^T lam)/dq on the free dofs (lam on the free dofs)."""
        raise NotImplementedError

    def held(self, model, q) -> sp.csc_matrix | None:
        """What the stability test holds on the nodal free dofs (a matrix added to K), or None."""
        return None

    def step_limit(self, model, q, dq) -> float:
        """The share of a Newton step dq (free dofs) it allows."""
        return 1.0


@dataclass
class ContactGeometry:
    """A contact term's geometry at one state."""

    g: np.ndarray
    """(k,) gaps (m)."""
    normal: np.ndarray
    """(k, 3) the direction each point's force pushes it (N per N of lambda)."""
    entries: tuple
    """(point, free dof, value): the nonzeros of dg/dq, grouped by point."""
    curvature: object
    """(point, free row, free column, value): the nonzeros of d2g/dq2, or a function returning them (called
    once, when the tangent or the Hessian first needs them: :meth:`second`)."""
    pairs: tuple | None = None
    """(e1, e2): every pair of entries of one point (computed if None)."""

    def second(self) -> tuple:
        if callable(self.curvature):
            self.curvature = self.curvature()
        return self.curvature


def _pairs(pt: np.ndarray):
    """Every pair (e1, e2) of entries that belong to one point (entries sorted by point)."""
    count = np.bincount(pt) if pt.size else np.zeros(0, dtype=np.int64)
    start = np.cumsum(count) - count
    tot = count[pt]
    e1 = np.repeat(np.arange(pt.size), tot)
    e2 = start[pt[e1]] + (np.arange(e1.size) - np.repeat(np.cumsum(tot) - tot, tot))
    return e1, e2


class ContactTerm(Term):
    """Contact points with normal forces as unknowns and Fischer-Burmeister rows (see the module)."""

    kappa: float
    """Stiffness scale (N/m) of the rows: E h, the stiffness of a boundary node of size h."""
    eps: float
    """Smoothing of the rows (N): 1e-8 kappa h."""
    h: float
    """The mean edge of the boundary faces (m)."""

    def geometry(self, model, q) -> ContactGeometry:
        raise NotImplementedError

    def forces(self, q) -> np.ndarray:
        """lambda (k,), N."""
        return self.kappa * q[self.state]

    def _keys(self, model, pt, fpos):
        j = self.rows.start + pt
        return j * model.n_free + fpos, fpos * model.n_free + j

    def residual(self, model, q, u, R):
        geo = self.geometry(model, q)
        lam = self.forces(q)
        pt, fpos, val = geo.entries
        R -= np.bincount(fpos, weights=lam[pt] * val, minlength=R.size)
        fb = fischer_burmeister(lam, self.kappa * geo.g, self.eps)
        R[self.rows] = fb[0]
        return geo, lam, fb

    def tangent(self, model, cache):
        geo, lam, fb = cache
        kap, n = self.kappa, model.n_free
        pt, fpos, val = geo.entries
        cp, r, c, d2g = geo.second()
        col, row = self._keys(model, pt, fpos)
        j = self.rows.start + np.arange(self.n_rows)
        keys = np.concatenate([col, row, j * n + j, c * n + r])
        vals = np.concatenate([-kap * val, fb[2][pt] * kap * val, kap * fb[1], -lam[cp] * d2g])
        return keys, vals

    @property
    def multistable(self) -> np.ndarray:
        """(k,) bool: the points whose contact can hold the body in one of several equilibria at the same
        inputs: the region such a point may occupy is not convex (outside a curved or faceted obstacle, or
        the body itself), so which points press can depend on the path (docs/methods.md "One answer per
        input"). Outside a plane it is a half-space: one equilibrium whatever the path."""
        return np.ones(self.n_rows, dtype=bool)

    def contact_forces(self, model, q) -> np.ndarray:
        """sum_i lambda_i dg_i/dq on the free dofs."""
        geo = self.geometry(model, q)
        pt, fpos, val = geo.entries
        return np.bincount(fpos, weights=self.forces(q)[pt] * val, minlength=model.n_free)

    def in_contact(self, model, q) -> np.ndarray:
        """(k,) bool: the points that press (their row depends more on the gap than on the force)."""
        return self.forces(q) > self.kappa * np.maximum(self.geometry(model, q).g, 0.0)

    dive = True
    """Whether a point far apart may end as deep inside as it was outside (else 1 % of an element at most)."""

    def step_limit(self, model, q, dq) -> float:
        """No point now apart ends deeper inside than it is outside now (:attr:`dive`), or than 1 % of an
        element (linearised): a full step from far away ignores the contact and lands deep inside, where the
        rows are far from their solution. At least 1e-2."""
        geo = self.geometry(model, q)
        pt, fpos, val = geo.entries
        g = geo.g
        dg = np.bincount(pt, weights=val * dq[fpos], minlength=self.n_rows)
        depth = np.maximum(g, 0.01 * self.h) if self.dive else np.full_like(g, 0.01 * self.h)
        hit = (g > 0) & (g + dg < -depth)
        if not hit.any():
            return 1.0
        return float(max(1e-2, np.min((g[hit] + depth[hit]) / -dg[hit])))

    def held(self, model, q):
        """The points that press, held 1000x stiffer than kappa along their gradients."""
        geo = self.geometry(model, q)
        pb = fischer_burmeister(self.forces(q), self.kappa * geo.g, self.eps)[2]
        pt, fpos, val = geo.entries
        e1, e2 = geo.pairs if geo.pairs is not None else _pairs(pt)
        n = model.n_free_mech
        return sp.csc_matrix((1e3 * self.kappa * pb[pt[e1]] * val[e1] * val[e2], (fpos[e1], fpos[e2])), shape=(n, n))

    def hessian(self, model, q, u, lam):
        """lam_i phi(a_i, kappa g_i(q)) exactly; -a_i lam . dg_i/dq without its third derivatives of the
        distance (zero on flat obstacles)."""
        kap = self.kappa
        geo = self.geometry(model, q)
        a = self.forces(q)
        _, pa, pb, paa, pab, pbb = fischer_burmeister(a, kap * geo.g, self.eps)
        pt, fpos, val = geo.entries
        cp, r, c, d2g = geo.second()
        e1, e2 = geo.pairs if geo.pairs is not None else _pairs(pt)
        mu = lam[self.rows]
        j = self.rows.start + pt
        jc = self.rows.start + cp
        jj = self.rows.start + np.arange(self.n_rows)
        # (q, q): mu_i kappa (pb_i d2g_i + pbb_i kappa dg_i dg_i^T)
        qq_c = mu[cp] * kap * pb[cp] * d2g
        qq_g = mu[pt[e1]] * pbb[pt[e1]] * kap * kap * val[e1] * val[e2]
        # (q, force_i): -kappa d2g_i lam_m + mu_i phi_ab kappa^2 dg_i/dq
        qs_c = -kap * d2g * lam[c]
        qs_g = mu[pt] * pab[pt] * kap * kap * val
        rows = np.concatenate([r, fpos[e1], r, fpos, jc, j, jj])
        cols = np.concatenate([c, fpos[e2], jc, j, r, fpos, jj])
        vals = np.concatenate([qq_c, qq_g, qs_c, qs_g, qs_c, qs_g, mu * paa * kap * kap])
        return sp.csc_matrix((vals, (rows, cols)), shape=(model.n_free, model.n_free))


class ObstacleContact(ContactTerm):
    """The body's contact points against the rigid obstacles (:class:`casadi_ws.fem.contact.ContactSet`)."""

    name = "obstacles"

    def __init__(self, contact: ContactSet, pos):
        self.contact = contact
        self.kappa, self.eps, self.h = contact.kappa, contact.eps, contact.h
        self.n_rows = contact.n
        # the nonzeros of the points' gradients: point, coordinate, weight, free dof (fixed ones dropped)
        Wc = contact.W.tocoo()
        order = np.lexsort((Wc.col, Wc.row))
        pt, node, w = np.repeat(Wc.row[order], 3), np.repeat(Wc.col[order], 3), np.repeat(Wc.data[order], 3)
        coord = np.tile(np.arange(3), order.size)
        fpos = pos[3 * node + coord]
        keep = fpos >= 0
        self._ce = (pt[keep], coord[keep], w[keep], fpos[keep].astype(np.int64))
        self._cp = _pairs(self._ce[0])

    def pattern(self, model, pos):
        pt, _, _, fpos = self._ce
        e1, e2 = self._cp
        col, row = self._keys(model, pt, fpos)
        j = self.rows.start + np.arange(self.n_rows)
        n = model.n_free
        return np.concatenate([col, row, j * n + j, fpos[e2] * n + fpos[e1]])

    def geometry(self, model, q) -> ContactGeometry:
        g, nrm, H = self.contact.gaps(model.positions(q))
        pt, coord, w, fpos = self._ce
        e1, e2 = self._cp
        d2g = w[e1] * w[e2] * H[pt[e1], coord[e1], coord[e2]]
        return ContactGeometry(g, nrm, (pt, fpos, w * nrm[pt, coord]), (pt[e1], fpos[e1], fpos[e2], d2g), self._cp)

    @property
    def multistable(self) -> np.ndarray:
        planes = np.array([ob.kind == "plane" for ob in self.contact.obstacles], dtype=bool)
        return ~planes[self.contact.obstacle]

    def report(self, model, q) -> list[dict]:
        """Per obstacle: name, kind, the force [fx, fy, fz] (N) it exerts, points pressing, penetration (m)."""
        geo = self.geometry(model, q)
        lam, on = self.forces(q), self.in_contact(model, q)
        out = []
        for k, ob in enumerate(self.contact.obstacles):
            i = self.contact.obstacle == k
            out.append({"name": ob.name, "kind": ob.kind, "force": (lam[i] @ geo.normal[i]).tolist(),
                        "points": int(np.count_nonzero(on & i)),
                        "penetration": float(max(0.0, -geo.g[i].min())) if i.any() else 0.0})
        return out


MLS_SLOTS = 10
"""Triangles a point's surface is fitted to, at most: those whose centroids lie within one mean edge h,
nearest first (4 to 10 at the surface of the shipped gripper's 10-node mesh; a dropped farthest one weighs
little, its centroid near the edge of the support)."""


@lru_cache(maxsize=None)
def _mls_gap(second: bool):
    """The gap of a point P from the surface fitted to up to MLS_SLOTS triangles near it, with its gradient
    (and with ``second`` its Hessian) over x = [P, the triangles' corners] (3 + 9 MLS_SLOTS), as an
    :class:`casadi_ws.fem.kernels.ElementBatch` (inputs x, used, r^2).

    Triangle k (corners a, b, c, centroid m_k, area vector A_k) weighs w_k = (1 - |P - m_k|^2 / r^2)^3 within
    r (zero beyond, twice differentiable there); the surface near P is the plane through the weighted
    centroid x = sum w |A| m / sum w |A| with normal n = sum w A / |sum w A|, and g = n . (P - x). A flat
    surface gives the exact distance; a kinked one (a vertex dented under a point) a smooth normal."""
    from .kernels import ElementBatch

    K = MLS_SLOTS
    x = ca.SX.sym("x", 3 + 9 * K)
    used = ca.SX.sym("used", K)  # 1 for a triangle, 0 for an empty slot
    r2 = ca.SX.sym("r2")
    P = x[0:3]
    normal, weight, centre = 0, 0, 0
    for k in range(K):
        a, b, c = (x[3 + 9 * k + 3 * j: 6 + 9 * k + 3 * j] for j in range(3))
        m = (a + b + c) / 3
        A = 0.5 * ca.cross(b - a, c - a)
        w = used[k] * ca.fmax(0, 1 - ca.sumsqr(P - m) / r2) ** 3
        normal += w * A
        weight += w * ca.norm_2(A)
        centre += w * ca.norm_2(A) * m
    g = ca.dot(normal / ca.norm_2(normal), P - centre / weight)
    out = [g, ca.gradient(g, x)]
    if second:
        out.append(ca.densify(ca.reshape(ca.hessian(g, x)[0], (3 + 9 * K) ** 2, 1)))
    # the Hessian's C takes gcc ~80 s; on CasADi's machine it costs ~1.4 ms per point near the surface, once
    # per tangent: far below a factorisation
    return ElementBatch(ca.Function("mls_gap2" if second else "mls_gap1", [x, used, r2], out),
                        "casadi" if second else "auto")


class SelfContact(ContactTerm):
    """A pair of the body's own regions that may meet: the boundary nodes ``points`` may not enter the
    boundary triangles ``triangles`` (node indices, oriented out of the body; a 10-node face is split into
    four through its mid-edge nodes).

    A point near the surface (a triangle's centroid within one mean edge h) measures its gap from the
    surface fitted to the triangles there (:func:`_mls_gap`): a smooth function of the point and those
    triangles' nodes, so the force lambda_i acts on the point and, spread over the nodes, back on the
    surface (forces and moments balance exactly: the gap does not change under a rigid motion). A point
    farther away is apart at its distance (libigl's AABB tree); so is one whose closest point is on the
    surface's rim (an edge of one triangle only: the surface ends there). The closest plane of a triangle
    mesh would not do: a point pressing on a vertex dents the surface into a cone whose faces take turns
    being closest, the normal jumps between them and Newton cycles (it did, on the shipped gripper).

    The pattern holds each point against every node within ``reach`` of the spot it faces at rest; a point
    that slides farther is not held and is counted (``beyond_reach``)."""

    dive = False  # a body diving into itself brings many points in that Newton then releases one by one

    def __init__(self, name: str, points: np.ndarray, triangles: np.ndarray, nodes: np.ndarray, pos: np.ndarray,
                 young_modulus: float, reach: float | None = None):
        self.name = name
        self.points = np.asarray(points, dtype=np.int64)
        self.master, tri = np.unique(np.asarray(triangles, dtype=np.int64), return_inverse=True)
        self.tri = tri.reshape(-1, 3)
        self.n_rows = self.points.size
        edges = np.sort(np.concatenate([self.tri[:, [0, 1]], self.tri[:, [1, 2]], self.tri[:, [2, 0]]]), axis=1)
        e, count = np.unique(edges, axis=0, return_counts=True)
        self._rim_edges = {tuple(x) for x in e[count == 1]}
        self._rim_vertices = set(e[count == 1].ravel().tolist())
        x = nodes[self.master]
        self.h = float(np.mean(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)))
        self.kappa = float(young_modulus * self.h)
        self.eps = 1e-8 * self.kappa * self.h
        self._pdofs = pos[3 * self.points[:, None] + np.arange(3)]  # (k, 3) free positions, -1 fixed
        self._mdofs = pos[3 * self.master[:, None] + np.arange(3)]
        self.reach = 2.0 * self.h if reach is None else float(reach)
        """How far (m) from the spot it faces at rest a point may slide on the surface and still be held."""
        self.beyond_reach = np.zeros(self.n_rows, dtype=bool)
        self._candidates(nodes)

    def _candidates(self, nodes):
        """Each point's candidate triangles (those with a node within ``reach`` of its closest point at rest,
        and that one) as pairs (point, triangle) sorted by point, and their nodes."""
        import igl
        from scipy.spatial import cKDTree

        V = nodes[self.master]
        _, I0, C0 = igl.point_mesh_squared_distance(nodes[self.points], V, self.tri)
        near = cKDTree(V).query_ball_point(C0, self.reach)
        self._vertex_tris = vertex_tris = [[] for _ in range(self.master.size)]
        for t, abc in enumerate(self.tri):
            for v in abc:
                vertex_tris[v].append(t)
        pts, tris, self._cand_nodes = [], [], []
        for i, vs in enumerate(near):
            t = np.unique(np.concatenate([[I0[i]]] + [vertex_tris[v] for v in vs]).astype(np.int64))
            pts.append(np.full(t.size, i))
            tris.append(t)
            self._cand_nodes.append(np.unique(self.tri[t]))
        self._cand_pt, self._cand_tri = np.concatenate(pts), np.concatenate(tris)
        self._cand = self._cand_pt * len(self.tri) + self._cand_tri
        # each point's support radius: h, or less where more than MLS_SLOTS triangles would lie within it at
        # rest (a triangle left out of the slots while it still weighs would make the gap jump)
        m = V[self.tri].mean(axis=1)
        d = np.linalg.norm(m[self._cand_tri] - C0[self._cand_pt], axis=1)
        self.radius = np.full(self.n_rows, self.h)
        for i in range(self.n_rows):
            di = np.sort(d[self._cand_pt == i])
            if di.size > MLS_SLOTS:
                self.radius[i] = min(self.h, 0.5 * (di[MLS_SLOTS - 1] + di[MLS_SLOTS]))

    def pattern(self, model, pos):
        n, k = model.n_free, self.n_rows
        j = self.rows.start + np.arange(k)
        keys = [j * n + j]
        for i in range(k):
            d = np.concatenate([self._pdofs[i], self._mdofs[self._cand_nodes[i]].ravel()])
            d = d[d >= 0]
            keys += [j[i] * n + d, d * n + j[i], (d[:, None] * n + d[None, :]).ravel()]
        return np.unique(np.concatenate(keys))

    def _apart(self, P, V):
        """(distance, closest point, closest triangle, apart): apart where the closest point is on the rim or
        beyond reach."""
        import igl

        from .contact import _barycentric

        sqd, I, C = igl.point_mesh_squared_distance(P, V, self.tri)
        I = np.asarray(I, dtype=np.int64).copy()
        on = _barycentric(C, V[self.tri[I]]) > 1e-9
        apart = np.zeros(len(P), dtype=bool)
        for i in np.flatnonzero(on.sum(axis=1) < 3):
            feature = self.tri[I[i]][on[i]]
            apart[i] = len(feature) == 2 and tuple(sorted(feature)) in self._rim_edges or \
                len(feature) == 1 and feature[0] in self._rim_vertices
            # on an edge or a corner: the triangle there whose normal points most nearly at the point (above
            # a body's edge a point faces the top, not the side it would slide down)
            cand = np.array(sorted(set.intersection(*[set(self._vertex_tris[v]) for v in feature])))
            T = V[self.tri[cand]]
            n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
            I[i] = cand[np.argmax((n / np.linalg.norm(n, axis=1)[:, None]) @ (P[i] - C[i]))]
        key = np.arange(len(P)) * len(self.tri) + I
        k = np.minimum(np.searchsorted(self._cand, key), self._cand.size - 1)
        self.beyond_reach = (self._cand[k] != key) & ~apart
        return np.sqrt(sqd), C, I, apart | self.beyond_reach

    def _slots(self, P, V, I):
        """(k, MLS_SLOTS) the candidate triangles whose centroids lie within its radius of each point and that face
        the way its closest triangle I does (within 60 degrees: a dent is smoothed, an edge of the body is
        not rounded off), nearest first (-1: empty)."""
        T = V[self.tri]
        m = T.mean(axis=1)
        n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        n /= np.linalg.norm(n, axis=1)[:, None]
        d2 = np.einsum("ij,ij->i", P[self._cand_pt] - m[self._cand_tri], P[self._cand_pt] - m[self._cand_tri])
        facing = np.einsum("ij,ij->i", n[self._cand_tri], n[I[self._cand_pt]]) > 0.5
        inside = np.flatnonzero((d2 < self.radius[self._cand_pt] ** 2) & facing)
        order = inside[np.lexsort((d2[inside], self._cand_pt[inside]))]
        pt = self._cand_pt[order]
        first = np.searchsorted(pt, pt)  # where each point's run starts
        rank = np.arange(pt.size) - first
        keep = rank < MLS_SLOTS
        slots = -np.ones((self.n_rows, MLS_SLOTS), dtype=np.int64)
        slots[pt[keep], rank[keep]] = self._cand_tri[order[keep]]
        return slots

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Each point's distance from the surface at the nodal positions x, negative behind it (the side its
        closest triangle faces away from)."""
        P, V = x[self.points], x[self.master]
        dist, C, I, _ = self._apart(P, V)
        T = V[self.tri[I]]
        n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
        return np.where(np.einsum("ij,ij->i", n, P - C) < 0, -dist, dist)

    def geometry(self, model, q) -> ContactGeometry:
        return self.at(model.positions(q))

    def at(self, x: np.ndarray) -> ContactGeometry:
        """The geometry at the nodal positions x (n, 3); its curvature is computed when first asked for."""
        P, V = x[self.points], x[self.master]
        dist, C, I, apart = self._apart(P, V)
        slots = self._slots(P, V, I)
        near = np.flatnonzero((slots[:, 0] >= 0) & ~apart)
        k, nx = self.n_rows, 3 + 9 * MLS_SLOTS
        g = dist.copy()
        normal = (P - C) / np.maximum(dist, 1e-300)[:, None]
        # a point slid beyond its reach and behind the surface: its (negative) distance, so that verification
        # fails rather than the point passing unseen
        if self.beyond_reach.any():
            behind = self.beyond_reach & (self.signed_distance(x) < 0)
            g[behind] *= -1.0
            normal[behind] *= -1.0
        # points apart: their distance, moved by the point alone
        far = np.setdiff1d(np.arange(k), near)
        pt_e = [np.repeat(far, 3)]
        dof_e = [self._pdofs[far].ravel()]
        val_e = [normal[far].ravel()]
        curv = [np.zeros(0, dtype=np.int64)] * 3 + [np.zeros(0)]
        curvature = (lambda: curv)
        if near.size:
            s = slots[near]
            filled = np.where(s >= 0, s, s[:, :1])  # empty slots repeat the first triangle, unweighted
            corners = self.tri[filled]  # (b, K, 3)
            X = np.hstack([P[near], V[corners].reshape(near.size, -1)])
            used = (s >= 0).astype(float)
            r2 = self.radius[near, None] ** 2
            gn, grad = _mls_gap(False)(X, used, r2)
            g[near] = gn.ravel()
            normal[near] = grad[:, :3]
            dofs = np.hstack([self._pdofs[near], np.where((s >= 0)[:, :, None, None],
                                                          self._mdofs[corners], -1).reshape(near.size, -1)])
            pt = np.repeat(near, nx)
            ok = dofs.ravel() >= 0
            pt_e.append(pt[ok])
            dof_e.append(dofs.ravel()[ok])
            val_e.append(grad.ravel()[ok])

            def curvature():
                hess = _mls_gap(True)(X, used, r2)[2]
                r, c = np.repeat(dofs, nx, axis=1), np.tile(dofs, (1, nx))
                ok = ((r >= 0) & (c >= 0)).ravel()
                return np.repeat(near, nx * nx)[ok], r.ravel()[ok], c.ravel()[ok], hess.ravel()[ok]
        pt, dof, val = np.concatenate(pt_e), np.concatenate(dof_e), np.concatenate(val_e)
        keep = dof >= 0
        order = np.argsort(pt[keep], kind="stable")
        entries = (pt[keep][order], dof[keep][order], val[keep][order])
        return ContactGeometry(g, normal, entries, curvature)

    def report(self, model, q) -> list[dict]:
        """One entry: the name, kind ``self``, the force [fx, fy, fz] (N) the surface exerts on the points
        (the points exert the opposite on the surface), points pressing, the largest penetration (m), and the
        points that slid beyond ``reach``."""
        geo = self.geometry(model, q)
        lam = self.forces(q)
        return [{"name": self.name, "kind": "self", "force": (lam @ geo.normal).tolist(),
                 "points": int(np.count_nonzero(self.in_contact(model, q))),
                 "penetration": float(max(0.0, -geo.g.min())) if self.n_rows else 0.0,
                 "beyond_reach": int(np.count_nonzero(self.beyond_reach))}]
