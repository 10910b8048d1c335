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
    n_rows = 0
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
    curvature: tuple
    """(point, free row, free column, value): the nonzeros of d2g/dq2."""
    pairs: tuple | None = None
    """(e1, e2): every pair of entries of one point (computed if None)."""


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
        cp, r, c, d2g = geo.curvature
        col, row = self._keys(model, pt, fpos)
        j = self.rows.start + np.arange(self.n_rows)
        keys = np.concatenate([col, row, j * n + j, c * n + r])
        vals = np.concatenate([-kap * val, fb[2][pt] * kap * val, kap * fb[1], -lam[cp] * d2g])
        return keys, vals

    def contact_forces(self, model, q) -> np.ndarray:
        """sum_i lambda_i dg_i/dq on the free dofs."""
        geo = self.geometry(model, q)
        pt, fpos, val = geo.entries
        return np.bincount(fpos, weights=self.forces(q)[pt] * val, minlength=model.n_free)

    def in_contact(self, model, q) -> np.ndarray:
        """(k,) bool: the points that press (their row depends more on the gap than on the force)."""
        return self.forces(q) > self.kappa * np.maximum(self.geometry(model, q).g, 0.0)

    def step_limit(self, model, q, dq) -> float:
        """No point now apart ends deeper inside than it is outside now, or than 1 % of an element
        (linearised): a full step from far away ignores the contact and lands deep inside, where the rows
        are far from their solution. At least 1e-2."""
        geo = self.geometry(model, q)
        pt, fpos, val = geo.entries
        g = geo.g
        dg = np.bincount(pt, weights=val * dq[fpos], minlength=self.n_rows)
        depth = np.maximum(g, 0.01 * self.h)
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
        cp, r, c, d2g = geo.curvature
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


@lru_cache(maxsize=None)
def _gap_functions() -> list[ca.Function]:
    """The distance of a point s from a triangle's plane (signed, n by the right-hand rule), from the line
    through its first edge, and from its first vertex, each with its gradient and Hessian over
    x = [s, a, b, c] (12)."""
    x = ca.SX.sym("x", 12)
    s, a, b, c = x[0:3], x[3:6], x[6:9], x[9:12]
    n = ca.cross(b - a, c - a)
    out = []
    for name, g in (("plane", ca.dot(n, s - a) / ca.norm_2(n)),
                    ("edge", ca.norm_2(ca.cross(s - a, b - a)) / ca.norm_2(b - a)),
                    ("vertex", ca.norm_2(s - a))):
        H = ca.densify(ca.reshape(ca.hessian(g, x)[0], 144, 1))
        out.append(ca.Function(f"{name}_gap", [x], [g, ca.gradient(g, x), H]))
    return out


class SelfContact(ContactTerm):
    """A pair of the body's own regions that may meet: the boundary nodes ``points`` may not enter the
    boundary triangles ``triangles`` (node indices, oriented out of the body; a 10-node face is split into
    four through its mid-edge nodes).

    Each point's gap is its signed distance from the surface (libigl's AABB tree on the current positions)
    less a radius rho = 1e-4 h: the distance to the closest triangle's plane, edge or vertex, a smooth
    function of the point and that triangle's nodes, so the force lambda_i acts on the point and, spread over
    the triangle's nodes, back on the surface (forces and moments balance exactly: the gap does not change
    under a rigid motion). The sign is that of the way to the point along the normal of the triangle there
    best aligned with it. rho rounds the triangles, as for a triangle-surface obstacle: a point held on a bare
    edge or vertex has a cone of normals and Newton stalls; held rho away it has one. A point whose closest
    point is on the surface's rim (an edge of one triangle only) is apart at its distance: the surface ends
    there.
    The pattern holds every point against every node of the surface, so the pair's size, not its motion,
    bounds the cost (keep the regions to the parts that can meet)."""

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
        self._vertex_tris = [[] for _ in range(self.master.size)]
        for t, abc in enumerate(self.tri):
            for v in abc:
                self._vertex_tris[v].append(t)
        x = nodes[self.master]
        self.h = float(np.mean(np.linalg.norm(x[edges[:, 0]] - x[edges[:, 1]], axis=1)))
        self.kappa = float(young_modulus * self.h)
        self.eps = 1e-8 * self.kappa * self.h
        self._pdofs = pos[3 * self.points[:, None] + np.arange(3)]  # (k, 3) free positions, -1 fixed
        self._mdofs = pos[3 * self.master[:, None] + np.arange(3)]
        self._maps = [f.map(self.n_rows) for f in _gap_functions()]
        self.rho = 1e-4 * self.h
        self.reach = 3.0 * self.h if reach is None else float(reach)
        """How far (m) from the spot it faces at rest a point may slide on the surface and still be held: its
        candidate triangles are those with a node within ``reach`` of its closest point at rest."""
        self._candidates(nodes)

    def _candidates(self, nodes):
        """Each point's candidate triangles (as sorted keys point * n_triangles + triangle) and nodes."""
        import igl
        from scipy.spatial import cKDTree

        V = nodes[self.master]
        _, I0, C0 = igl.point_mesh_squared_distance(nodes[self.points], V, self.tri)
        near = cKDTree(V).query_ball_point(C0, self.reach)
        nt = len(self.tri)
        keys, self._cand_nodes = [], []
        for i, vs in enumerate(near):
            tris = np.unique(np.concatenate([[I0[i]]] + [self._vertex_tris[v] for v in vs]).astype(np.int64))
            keys.append(i * nt + tris)
            self._cand_nodes.append(np.unique(self.tri[tris]))
        self._cand = np.concatenate(keys)

    def pattern(self, model, pos):
        n, k = model.n_free, self.n_rows
        j = self.rows.start + np.arange(k)
        keys = [j * n + j]
        for i in range(k):
            d = self._pdofs[i][self._pdofs[i] >= 0]
            md = self._mdofs[self._cand_nodes[i]].ravel()
            every = np.concatenate([d, md[md >= 0]])
            keys += [j[i] * n + every, every * n + j[i], (d[:, None] * n + every[None, :]).ravel(),
                     (every[:, None] * n + d[None, :]).ravel()]
        t = self._mdofs[self.tri].reshape(-1, 9)  # (t, 9) the dofs of each triangle
        rr, cc = np.repeat(t, 9, axis=1), np.tile(t, (1, 9))
        ok = (rr >= 0) & (cc >= 0)
        keys.append(cc[ok] * n + rr[ok])
        return np.unique(np.concatenate(keys))

    def _closest(self, P, V):
        """Per point: the triangle, its nodes ordered with the closest feature first, the feature (0 face,
        1 edge, 2 vertex), the sign, whether the point is apart at its distance (beyond the rim, or slid beyond
        its reach), the distance and the closest point."""
        import igl

        from .contact import _barycentric

        sqd, I, C = igl.point_mesh_squared_distance(P, V, self.tri)
        I = np.asarray(I, dtype=np.int64).copy()
        order = self.tri[I].copy()
        on = _barycentric(C, V[order]) > 1e-9
        kind = 3 - on.sum(axis=1)
        sign = np.ones(len(P))
        apart = np.zeros(len(P), dtype=bool)
        for i in np.flatnonzero(kind > 0):
            feature = order[i][on[i]]
            if len(feature) == 2 and tuple(sorted(feature)) in self._rim_edges or \
                    len(feature) == 1 and feature[0] in self._rim_vertices:
                apart[i] = True
                continue
            cand = set(self._vertex_tris[feature[0]])
            for v in feature[1:]:
                cand &= set(self._vertex_tris[v])
            cand = np.array(sorted(cand))
            a, b, c = (V[self.tri[cand, m]] for m in range(3))
            nrm = np.cross(b - a, c - a)
            nrm /= np.linalg.norm(nrm, axis=1)[:, None]
            along = nrm @ (P[i] - C[i])
            best = np.argmax(np.abs(along))
            I[i], sign[i] = cand[best], (1.0 if along[best] >= 0 else -1.0)
            if abs(along[best]) >= (1 - 1e-9) * np.linalg.norm(P[i] - C[i]):
                # straight above the triangle's edge or corner: its plane (a flat surface has no rounded
                # edge there; the edge's curvature 1/rho would stiffen the point sideways)
                kind[i], sign[i], order[i] = 0, 1.0, self.tri[I[i]]
                continue
            rest = [v for v in self.tri[I[i]] if v not in feature]
            order[i] = list(feature) + rest
        key = np.arange(len(P)) * len(self.tri) + I
        k = np.minimum(np.searchsorted(self._cand, key), self._cand.size - 1)
        self.beyond_reach = (self._cand[k] != key) & ~apart
        return order, kind, sign, apart | self.beyond_reach, np.sqrt(sqd), C

    def geometry(self, model, q) -> ContactGeometry:
        return self.at(model.positions(q))

    def at(self, x: np.ndarray) -> ContactGeometry:
        """The geometry at the nodal positions x (n, 3)."""
        P, V = x[self.points], x[self.master]
        T, kind, sign, apart, dist, C = self._closest(P, V)
        X = np.hstack([P, V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]]).T
        g, grad, hess = (np.choose(kind[None, :], parts) for parts in
                         zip(*[[np.asarray(v) for v in f(X)] for f in self._maps]))
        g, grad, hess = sign * g.ravel() - self.rho, (sign * grad).T, (sign * hess).T
        if apart.any():
            d = np.maximum(dist[apart], 1e-300)
            g[apart] = d - self.rho
            grad[apart] = 0.0
            grad[apart, :3] = (P[apart] - C[apart]) / d[:, None]
            hess[apart] = 0.0
        k = self.n_rows
        dofs = np.hstack([self._pdofs, self._mdofs[T[:, 0]], self._mdofs[T[:, 1]], self._mdofs[T[:, 2]]])  # (k, 12)
        pt = np.repeat(np.arange(k), 12)
        keep = dofs.ravel() >= 0
        entries = (pt[keep], dofs.ravel()[keep], grad.ravel()[keep])
        r, c = np.repeat(dofs, 12, axis=1), np.tile(dofs, (1, 12))
        ok = ((r >= 0) & (c >= 0)).ravel()
        curvature = (np.repeat(np.arange(k), 144)[ok], r.ravel()[ok], c.ravel()[ok], hess.ravel()[ok])
        return ContactGeometry(g, grad[:, :3], entries, curvature)

    def report(self, model, q) -> list[dict]:
        """One entry: the name, kind ``self``, the force [fx, fy, fz] (N) the surface exerts on the points
        (the points exert the opposite on the surface), points pressing, the largest penetration (m)."""
        geo = self.geometry(model, q)
        lam = self.forces(q)
        return [{"name": self.name, "kind": "self", "force": (lam @ geo.normal).tolist(),
                 "points": int(np.count_nonzero(self.in_contact(model, q))),
                 "penetration": float(max(0.0, -geo.g.min())) if self.n_rows else 0.0,
                 "beyond_reach": int(np.count_nonzero(self.beyond_reach))}]
