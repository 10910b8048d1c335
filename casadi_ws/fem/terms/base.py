"""The protocol every term of the model follows (:class:`Term`), and the smoothed Fischer-Burmeister function
its complementarity rows use."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["Term", "fischer_burmeister"]


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
