"""The protocol every term of the model follows (:class:`Term`), and the complementarity rows shared by the
prescribed actuators and contact.

The model is the sum of its terms (:class:`casadi_ws.fem.model.StaticModel`): each one gives its own forces,
its rows and unknowns if it has any, its entries of the tangent, its share of the Hessian of lam . R, what it
holds in the stability test, how far a Newton step may go and what it reports. A term works in one of three
phases of the residual, in the order the model registers them:

- ``internal``: the body's own forces (the elements, springs), summed first (:meth:`Term.forces`);
- ``applied``: loads (actuators' intensities, gravity and point loads, pressure on a face): summed next, they
  are the scale a residual is judged against (:meth:`Term.forces`); R = internal + applied on the free dofs;
- ``rows``: terms that change R afterwards and may own rows and unknowns (prescribed quantities, contact, the
  continuous pressure) (:meth:`Term.residual`); the forces of those marked ``applied`` join the scale.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

__all__ = ["Evaluation", "Term", "complementarity", "fischer_burmeister", "held_block", "point_pairs",
           "tangent_data"]


def fischer_burmeister(a, b, eps):
    """(phi, dphi/da, dphi/db, d2phi/da2, d2phi/dadb, d2phi/db2) of the smoothed Fischer-Burmeister function
    phi(a, b) = a + b - sqrt(a^2 + b^2 + eps^2), zero iff a, b >= 0 and a b = eps^2 / 2."""
    rho = np.sqrt(a * a + b * b + eps**2)
    r3 = rho**3
    return (a + b - rho, 1 - a / rho, 1 - b / rho, -(b * b + eps**2) / r3, a * b / r3, -(a * a + eps**2) / r3)


def complementarity(a, b, eps, unilateral=True) -> tuple:
    """The row of an intensity a (a cable's tension, a contact force) and its gap b (kappa times the distance
    from its constraint), with its first and second derivatives (as :func:`fischer_burmeister`): where
    ``unilateral`` (a cable, a contact point) phi(a, b) = 0 holds a >= 0, b >= 0, a b = eps^2 / 2; elsewhere
    (a chamber's volume) the row is b = 0."""
    fb = fischer_burmeister(a, b, eps)
    if unilateral is True or np.all(unilateral):
        return fb
    one, zero = np.ones_like(a), np.zeros_like(a)
    return tuple(np.where(unilateral, f, bil) for f, bil in zip(fb, (b, zero, one, zero, zero, zero)))


def point_pairs(pt: np.ndarray):
    """Every pair (e1, e2) of entries that belong to one point (entries sorted by point)."""
    count = np.bincount(pt) if pt.size else np.zeros(0, dtype=np.int64)
    start = np.cumsum(count) - count
    tot = count[pt]
    e1 = np.repeat(np.arange(pt.size), tot)
    e2 = start[pt[e1]] + (np.arange(e1.size) - np.repeat(np.cumsum(tot) - tot, tot))
    return e1, e2


def held_block(coef, pt, fpos, val, pairs, n) -> sp.csc_matrix:
    """sum_i coef_i g_i g_i^T on n dofs, g_i given by its nonzeros (point ``pt``, free dof ``fpos``, ``val``)
    and ``pairs`` (e1, e2) of entries of one point: what the stability test adds for a row it holds (a taut
    cable, a pressing contact point: coef = 1e3 kappa dphi/db, 1000x stiffer than the row's own scale)."""
    e1, e2 = pairs
    return sp.csc_matrix((coef[pt[e1]] * val[e1] * val[e2], (fpos[e1], fpos[e2])), shape=(n, n))


def tangent_data(model, data: np.ndarray | None) -> np.ndarray:
    """``data``, or the zeros of the pattern's values (nnz + 1) where it is None (:meth:`Term.add_tangent`)."""
    return np.zeros(model.nnz + 1) if data is None else data


@dataclass
class Evaluation:
    """One state at which the model is evaluated, and what its terms share between its residual and tangent
    there (``memo``, per term)."""

    q: np.ndarray
    u: np.ndarray
    load: float = 1.0
    tangent: bool = False
    """Whether the tangent is wanted too (terms then compute what the two share once)."""
    with_scale: bool = False
    """Whether the residual's scale is wanted (the internal terms then give ``force_norm``)."""
    force_norm: float = 0.0
    """The norm of the unassembled element forces (set by :class:`casadi_ws.fem.terms.elements.Elements`)."""
    memo: dict = field(default_factory=dict)


class Term:
    """One term of the model (see the module). ``n_rows`` unknowns and rows of its own (``rows``, a slice of
    the free dofs, and ``state``, a slice of the full state, set by the model from its dof map)."""

    name = ""
    """Unique among a model's terms with rows: the name of its block of the state."""
    phase = "rows"
    """``internal``, ``applied`` or ``rows`` (see the module)."""
    applied = True
    """(Phase ``rows``) whether its nodal forces count as applied loads in the residual's scale (contact
    forces do)."""
    n_rows = 0
    negatives = None
    """How many negative eigenvalues its block adds to a stable tangent when it keeps the tangent symmetric
    (0 for most; a saddle point's rows: the pressure's n_rows), so that the stability test reads them off the
    pivots; None when it does not (contact rows, follower loads): the test then factorises the stiffness it
    holds."""
    rows = slice(0, 0)
    state = slice(0, 0)
    grows = False
    """Whether its pattern grows with the state (:meth:`casadi_ws.fem.model.StaticModel.grow_pattern`)."""
    contact = False
    """Whether its rows are contact points (:meth:`casadi_ws.fem.model.StaticModel.contact_terms`: Newton's
    contact safeguards, the contact reports)."""

    @property
    def tangent_from_residual(self) -> bool:
        """Whether its tangent is built with its residual (:meth:`residual` returns what :meth:`tangent`
        needs): the model's ``tangent`` then evaluates R too. Phase ``rows`` terms do by default."""
        return self.phase == "rows"

    # ---------------------------------------------------------------- building, in this order
    def prepare(self, model) -> None:
        """The mesh, the supports (``model.free_mech``) and the terms before it are known: set ``n_rows``
        here where it depends on them."""

    def setup(self, model, pos: np.ndarray) -> None:
        """The dof map is known (``rows``, ``state``, ``model.n_dof``); ``pos`` maps a dof to its free position
        (-1 fixed). Build what the evaluation needs."""

    def pattern(self, model, pos: np.ndarray) -> np.ndarray:
        """Keys (column * n_free + row) of every tangent entry it may ever give."""
        return np.zeros(0, dtype=np.int64)

    def attach(self, model, slots: np.ndarray) -> None:
        """The positions in the tangent's data of the keys :meth:`pattern` gave, in their order."""

    def ready(self, model) -> None:
        """The model is assembled: what needs its tangent (a prescribed quantity's stiffness at rest)."""

    # ---------------------------------------------------------------- evaluation
    def forces(self, model, s: Evaluation) -> np.ndarray | None:
        """(Phases ``internal`` and ``applied``) its forces on all dofs (n_dof,), or None for none."""
        return None

    def residual(self, model, q, u, R):
        """(Phase ``rows``) add its forces to the nodal rows of R (free dofs), set its own rows; return what
        :meth:`tangent` needs."""
        return None

    def tangent(self, model, cache) -> tuple[np.ndarray, np.ndarray]:
        """(keys, values) of dR/dq it contributes (keys a subset of :meth:`pattern`; repeated keys add)."""
        return np.zeros(0, dtype=np.int64), np.zeros(0)

    def add_tangent(self, model, s: Evaluation, cache, data: np.ndarray | None) -> np.ndarray | None:
        """``data`` with its entries of K added: the values on the pattern (length nnz + 1: the last entry
        collects those of fixed dofs), None where no term has given any yet (the first may then return its own
        array: the elements' 1.4 MB on the trunk are not added to zeros). Default: :meth:`tangent`'s
        (keys, values) at their slots."""
        keys, values = self.tangent(model, cache)
        if keys.size:
            data = tangent_data(model, data)
            data[: model.nnz] += np.bincount(model.slots(keys), weights=values, minlength=model.nnz)
        return data

    def input_jacobian(self, model, s: Evaluation, dRdu: np.ndarray) -> None:
        """Change dR/du (n_free, n_u) by its share (in place)."""

    def hessian(self, model, q, u, lam) -> sp.csc_matrix | None:
        """Its share of d(K^T lam)/dq on the free dofs (lam on the free dofs), or None."""
        return None

    def add_hessian(self, model, s: Evaluation, lam, Hqq, Hqu):
        """(Hqq, Hqu) with its share of the second derivatives of lam . R added: d(K^T lam)/dq (sparse) and
        d(dR/du^T lam)/dq (dense, n_free x n_u). Default: :meth:`hessian`'s, added to Hqq."""
        H = self.hessian(model, s.q, s.u, lam)
        return (Hqq if H is None else (Hqq + H).tocsc()), Hqu

    def held(self, model, q, u) -> sp.csc_matrix | None:
        """What the stability test holds on the nodal free dofs (a matrix added to K), or None."""
        return None

    cut_judged = False
    """Whether a Newton step its :meth:`step_limit` cut is still judged by the monotonicity test (and halved
    where it fails): a barrier's energy sees the contact the cut step lands in, so its residual means something.
    False: the cut step is taken as it is (a complementarity row's residual beyond the contact's switch means
    little)."""

    def step_limit(self, model, q, dq) -> float:
        """The share of a Newton step dq (free dofs) it allows."""
        return 1.0

    def admits(self, model, q) -> bool:
        """Whether the state q may start a Newton solve (a predictor's guess may not, e.g. a boundary already
        through itself where a barrier holds it apart)."""
        return True

    def report(self, model, q) -> list[dict]:
        """What it reports at the state q (``contacts`` of an equilibrium): a dict per item, or none."""
        return []

    # ---------------------------------------------------------------- the patterns the CasADi Functions declare
    def input_pattern(self, model) -> dict[int, np.ndarray] | None:
        """For the inputs whose column of dR/du it decides, {input: its free rows}; None: it decides none."""
        return None

    def hessian_pattern(self, model) -> tuple[np.ndarray, np.ndarray]:
        """(rows, columns) of the entries of d(K^T lam)/dq it may give beyond K's pattern."""
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
