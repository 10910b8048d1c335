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

import numpy as np
import scipy.sparse as sp

from ..contact import ContactSet
from .base import Term, complementarity, held_block, point_pairs as _pairs

__all__ = ["ContactGeometry", "ContactTerm", "ObstacleContact"]


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


class ContactTerm(Term):
    """Contact points with normal forces as unknowns and Fischer-Burmeister rows (see the module)."""

    contact = True

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
        fb = complementarity(lam, self.kappa * geo.g, self.eps)
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

    def held(self, model, q, u):
        """The points that press, held 1000x stiffer than kappa along their gradients."""
        geo = self.geometry(model, q)
        pb = complementarity(self.forces(q), self.kappa * geo.g, self.eps)[2]
        pt, fpos, val = geo.entries
        pairs = geo.pairs if geo.pairs is not None else _pairs(pt)
        return held_block(1e3 * self.kappa * pb, pt, fpos, val, pairs, model.n_free_mech)

    def hessian(self, model, q, u, lam):
        """lam_i phi(a_i, kappa g_i(q)) exactly; -a_i lam . dg_i/dq without its third derivatives of the
        distance (zero on flat obstacles)."""
        kap = self.kappa
        geo = self.geometry(model, q)
        a = self.forces(q)
        _, pa, pb, paa, pab, pbb = complementarity(a, kap * geo.g, self.eps)
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
        self.contact_set = contact
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
        g, nrm, H = self.contact_set.gaps(model.positions(q))
        pt, coord, w, fpos = self._ce
        e1, e2 = self._cp
        d2g = w[e1] * w[e2] * H[pt[e1], coord[e1], coord[e2]]
        return ContactGeometry(g, nrm, (pt, fpos, w * nrm[pt, coord]), (pt[e1], fpos[e1], fpos[e2], d2g), self._cp)

    @property
    def multistable(self) -> np.ndarray:
        planes = np.array([ob.kind == "plane" for ob in self.contact_set.obstacles], dtype=bool)
        return ~planes[self.contact_set.obstacle]

    def report(self, model, q) -> list[dict]:
        """Per obstacle: name, kind, the force [fx, fy, fz] (N) it exerts, points pressing, penetration (m)."""
        geo = self.geometry(model, q)
        lam, on = self.forces(q), self.in_contact(model, q)
        out = []
        for k, ob in enumerate(self.contact_set.obstacles):
            i = self.contact_set.obstacle == k
            out.append({"name": ob.name, "kind": ob.kind, "force": (lam[i] @ geo.normal[i]).tolist(),
                        "points": int(np.count_nonzero(on & i)),
                        "penetration": float(max(0.0, -geo.g[i].min())) if i.any() else 0.0})
        return out
