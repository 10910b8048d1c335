"""The body against itself: a pair of its regions that may meet (:class:`SelfContact`)."""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from .contact import ContactGeometry, ContactTerm

__all__ = ["MLS_SLOTS", "SelfContact"]


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
    from ..kernels import ElementBatch

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

        from ..contact import _barycentric

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
