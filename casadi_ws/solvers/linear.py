"""Sparse factorisations of the tangent K: the LU behind every Newton step, sensitivity and stability test.

The factorisation is most of an equilibrium's cost; this module is where it is chosen and kept.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

__all__ = ["SINGLE_PRECISION_PROBE", "factorize"]


class _Ordering:
    """A fill-reducing ordering of one sparsity pattern, computed once and reused.

    SuperLU recomputes its minimum-degree ordering at every factorisation (~12 % of its time at 2646
    dofs); K's pattern never changes in a model, so the ordering of its first factorisation is applied as
    a symmetric permutation (a gather of K's nonzeros) and SuperLU told to keep it.
    """

    def __init__(self, K, perm_c):
        self.indptr, self.indices = K.indptr.copy(), K.indices.copy()
        self.p = np.argsort(perm_c)  # row/column k of the permuted matrix is K's p[k]
        n = K.shape[0]
        tag = sp.csc_matrix((np.arange(1, K.nnz + 1, dtype=float), K.indices, K.indptr), shape=K.shape)
        Kp = tag[self.p][:, self.p].tocsc()
        Kp.sort_indices()
        self.gather = Kp.data.astype(np.int64) - 1
        self.p_indptr, self.p_indices, self.n = Kp.indptr, Kp.indices, n
        self.probe = np.random.default_rng(0).standard_normal(n)  # fixed: results never depend on chance

    def matches(self, K) -> bool:
        return (K.indptr.shape == self.indptr.shape and K.indices.shape == self.indices.shape
                and np.array_equal(K.indptr, self.indptr) and np.array_equal(K.indices, self.indices))

    def permute(self, K):
        return sp.csc_matrix((K.data[self.gather], self.p_indices, self.p_indptr), shape=(self.n, self.n))


class _PermutedLU:
    """SuperLU of P K P^T behind the interface of SuperLU of K (``solve`` of vectors and matrices, in
    double precision whatever the factors' precision)."""

    def __init__(self, lu, p, K=None):
        self.lu, self.p = lu, p
        self.single = K is not None  # factors in single precision, K kept to refine against
        self.K = K

    def negative_pivots(self) -> int | None:
        if not np.array_equal(self.lu.perm_r, self.lu.perm_c):  # diagonal pivots: P K P^T = L U
            return None
        return int(np.count_nonzero(self.lu.U.diagonal() < 0))

    def solve(self, b):
        x = np.empty(b.shape)
        x[self.p] = self.lu.solve(np.ascontiguousarray(b[self.p], dtype=np.float32 if self.single else float))
        return x


_ORDERINGS: list[_Ordering] = []


SINGLE_PRECISION_PROBE = 3e-2
"""A single-precision LU is kept when it solves K x = K v for the fixed random v to this relative error
(else K is factorised in double precision)."""


def factorize(K, single: bool = False, pivot_threshold: float = 0.01, reuse_ordering: bool = True) -> object:
    """LU of K; with ``single``, in single precision where that is accurate enough (Newton's choice).

    Why single: the factorisation is most of an equilibrium's cost, and in float32 it takes ~26 % less
    time on the trunk (~30 % on the 10-node trunk and the PneuNets finger). Newton loses nothing: its
    chord steps contract by the LU's relative error, measured at 0.002-0.1 (spectral radius of
    I - LU^-1 K; the probe's error is about half of it) on every shipped problem, and the residual it is
    verified on is computed in double precision. Sensitivities refine their solves against K
    (:class:`Factorization`). A probe solve with a fixed vector falls back to double precision when its
    error is above ``SINGLE_PRECISION_PROBE``, and so does a matrix singular in single precision.

    ``pivot_threshold``: SuperLU's diag_pivot_thresh (a row is swapped in when the diagonal is below this
    share of its column's largest entry); 0 keeps the diagonal pivots unless one is exactly zero, so that
    the LU is an L D L^T of a symmetric K and its pivots give K's inertia (the stability test's use).
    ``reuse_ordering`` False: a one-off matrix (the stability test's held stiffness, whose pattern follows
    the contact set), ordered for itself and not cached, so it does not evict the tangent's ordering.
    """
    # K is structurally symmetric and nearly numerically symmetric: symmetric mode with a small pivot
    # threshold keeps the fill-reducing ordering of A + A^T (measured ~10 % faster than COLAMD here).
    K = K.tocsc() if not sp.isspmatrix_csc(K) else K
    opts = dict(diag_pivot_thresh=pivot_threshold, options={"SymmetricMode": True})
    if not (reuse_ordering and K.has_sorted_indices):
        return _PermutedLU(sla.splu(K, permc_spec="MMD_AT_PLUS_A", **opts), np.arange(K.shape[0]))
    for o in _ORDERINGS:
        if o.matches(K):
            break
    else:
        # the first time: the ordering only; the factorisation below is the same as every later one, so a
        # result does not depend on which factorisation of the pattern came first in this process
        o = _Ordering(K, sla.splu(K, permc_spec="MMD_AT_PLUS_A", **opts).perm_c)
        _ORDERINGS.insert(0, o)
        del _ORDERINGS[4:]  # a few models per process (a design study's worker builds many)
    Kp = o.permute(K)
    if single:
        try:
            lu = sla.splu(Kp.astype(np.float32), permc_spec="NATURAL", **opts)
        except RuntimeError:  # singular in single precision: double may still factorise it
            lu = None
        if lu is not None:
            x = lu.solve((Kp @ o.probe).astype(np.float32))
            if np.linalg.norm(x - o.probe) < SINGLE_PRECISION_PROBE * np.linalg.norm(o.probe):
                return _PermutedLU(lu, o.p, K)
    return _PermutedLU(sla.splu(Kp, permc_spec="NATURAL", **opts), o.p)
