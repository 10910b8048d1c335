"""Sparse factorisations of the tangent K: the LU behind every Newton step, sensitivity and stability test.

The factorisation is most of an equilibrium's cost (16 of 22 s of one equilibrium of the 18k-dof trunk with
SuperLU), so it is chosen by name (problem file ``solver.linear``), each backend behind one interface: a
factorisation object with ``solve(b)`` (vectors or matrices, in double precision), ``negative_pivots()``
(K's inertia where the backend knows it, else None), ``single`` and ``K`` (factors in single precision and the
matrix to refine against).

==========  ===================================================================================================
name        backend
==========  ===================================================================================================
superlu     SciPy's SuperLU (always installed): LU in symmetric mode, the minimum-degree ordering of the first
            factorisation of a pattern reused, diagonal pivots where it can (then its pivots are the inertia)
pardiso     Intel MKL PARDISO (``pip install casadi-ws[fast]``: pypardiso, which brings MKL; x86-64 only):
            ordering (METIS or AMD, the smaller factors) and symbolic analysis once per pattern (up to 64
            live factorisations share it), numeric factorisations after (Newton's in single precision where a
            symmetric K's pivots and a probe solve allow, else in double); a symmetric K gets a Bunch-Kaufman
            L D L^T, or Cholesky in single precision where it should be positive definite (half the work of an
            LU, its inertia exact unless a pivot was perturbed), an unsymmetric one an LU (no
            inertia: the stability test reads the symmetric part's, else eigenvalues). A numerically singular K
            is factorised with perturbed pivots instead of refused: Newton's residual test still decides
auto        where PARDISO is installed: PARDISO for a symmetric K (10-node corotational and every hyperelastic
            law) and for Newton's LU of an unsymmetric one (the 4-node corotational tangent, 0.5 %
            unsymmetric); SuperLU for an unsymmetric K whose inertia is asked for (its diagonal pivots);
            else SuperLU
==========  ===================================================================================================
"""

from __future__ import annotations

import contextlib
import ctypes
import weakref

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

__all__ = ["LINEAR_SOLVERS", "SINGLE_PRECISION_PROBE", "available", "choose", "factorize", "one_mkl_thread",
           "solver_of", "symmetric_part_positive_definite"]

LINEAR_SOLVERS = ("auto", "superlu", "pardiso")
"""The names ``solver.linear`` accepts."""


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


def factorize(K, single: bool = False, pivot_threshold: float = 0.01, reuse_ordering: bool = True,
              solver: str = "superlu", negatives: int | None = 0, inertia: bool = True) -> object:
    """LU of K by ``solver`` (a name of :data:`LINEAR_SOLVERS` resolved by :func:`choose`); with ``single``,
    in single precision where that is accurate enough (Newton's choice).

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
    ``negatives``: how many negative pivots K has where it is stable, by design (a saddle point's pressure
    rows), or None if that is not known; PARDISO's single-precision L D L^T is kept only with that many.
    ``inertia`` False (Newton's): under ``auto`` an unsymmetric K gets PARDISO's LU, which has no inertia
    (2.5x faster than SuperLU's in single precision at 2646 dofs); the stability test then reads the
    symmetric part's (:func:`symmetric_part_positive_definite`). True: SuperLU, whose pivots it reads.
    ``reuse_ordering`` False: a one-off matrix (the stability test's held stiffness, whose pattern follows
    the contact set), ordered for itself and not cached, so it does not evict the tangent's ordering.
    """
    K = K.tocsc() if not sp.isspmatrix_csc(K) else K
    if solver == "pardiso" or (solver == "auto" and not _MISSING):
        lu = _pardiso_factorize(K, reuse_ordering, unsymmetric=solver == "pardiso" or not inertia,
                                single=single and negatives is not None, negatives=negatives or 0,
                                check=solver == "auto")
        if lu is not None:
            return lu
    # K is structurally symmetric and nearly numerically symmetric: symmetric mode with a small pivot
    # threshold keeps the fill-reducing ordering of A + A^T (measured ~10 % faster than COLAMD here).
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


_MISSING: list = []


def available(name: str) -> bool:
    """Whether the backend ``name`` can run in this installation."""
    if name != "pardiso":
        return name in LINEAR_SOLVERS
    if _MISSING:
        return False
    try:
        _mkl()
    except (ImportError, OSError):
        _MISSING.append(True)
        return False
    return True


def choose(name: str) -> str:
    """What ``name`` means in this installation: ``auto`` stays ``auto`` (per matrix, as the module's table says:
    PARDISO for a symmetric K and for Newton's LU of an unsymmetric one, SuperLU for an unsymmetric K whose
    inertia is asked for) where PARDISO is installed, and is ``superlu`` where it is not."""
    if name == "auto" and not available("pardiso"):
        return "superlu"
    return name


def solver_of(model) -> str:
    """The backend of ``model``'s factorisations: its problem's ``solver.linear``, by :func:`choose`."""
    return choose(model.spec.solver.linear if model is not None else "auto")


# ---- PARDISO -------------------------------------------------------------------------------------------

MAX_FACTORS = 64
"""Numeric factorisations kept at once per symbolic analysis (PARDISO's maxfct); a 65th gets a new analysis.
Each slot costs memory only while a factorisation lives in it."""

SYMMETRY_TOLERANCE = 1e-10
"""K is factorised as symmetric when max |K - K^T| is below this share of max |K| (the 10-node corotational
tangent measures ~1e-16; the 4-node one 5e-3, which goes to SuperLU under ``auto``)."""

_LIB: list = []


def _mkl_rt() -> str | None:
    """The mkl_rt library where pip's ``mkl`` wheel puts it (this environment's lib directory), or None.

    Why: pypardiso looks for it with ``find_library`` and then a recursive glob of the whole environment, at
    its import: 0.37 s of every process's start (the main one's and each worker's), before its first
    factorisation. Given the path (``PYPARDISO_MKL_RT``), it loads it at once."""
    import glob
    import sys

    for pattern in ("lib/libmkl_rt.so*", "lib/libmkl_rt*.dylib", "Library/bin/mkl_rt*.dll"):
        found = sorted(glob.glob(f"{sys.prefix}/{pattern}"), key=len)
        if found:
            return found[0]
    return None


def _mkl():
    """MKL's ``pardiso`` entry point, from the mkl_rt that pypardiso finds."""
    if not _LIB:
        import os

        # Intel's OpenMP threads spin 200 ms after each parallel region by default, holding the core that the
        # element kernels' threads (:mod:`casadi_ws.fem.kernels`) need next; read when the runtime starts
        os.environ.setdefault("KMP_BLOCKTIME", "0")
        if "PYPARDISO_MKL_RT" not in os.environ and (path := _mkl_rt()) is not None:
            os.environ["PYPARDISO_MKL_RT"] = path
        import pypardiso

        lib = pypardiso.PyPardisoSolver().libmkl
        f = lib.pardiso
        i32 = ctypes.POINTER(ctypes.c_int32)
        f.argtypes = [ctypes.POINTER(ctypes.c_int64), i32, i32, i32, i32, i32, ctypes.c_void_p, i32, i32, i32, i32,
                      i32, i32, ctypes.c_void_p, ctypes.c_void_p, i32]
        f.restype = None
        lib.MKL_Get_Max_Threads.restype = ctypes.c_int
        lib.MKL_Set_Num_Threads_Local.restype = ctypes.c_int
        lib.MKL_Set_Num_Threads_Local.argtypes = [ctypes.c_int]
        _LIB.extend([f, lib.MKL_Get_Max_Threads, lib.MKL_Set_Num_Threads_Local])
        if _ONE_THREAD:  # loaded inside one_mkl_thread: the outermost scope restores MKL's own setting
            _ONE_THREAD[0] = _LIB[2](1)
    return _LIB[0]


_ONE_THREAD: list = []
"""The MKL thread settings that :func:`one_mkl_thread` scopes restore, innermost last (None: nothing)."""


@contextlib.contextmanager
def one_mkl_thread():
    """MKL's PARDISO on one thread (of this thread) in the enclosed code.

    Why not threadpoolctl's limit alone (:func:`casadi_ws.runtime.executor.one_blas_thread`): it reaches the
    libraries loaded when it is entered, and MKL is loaded on first use, mostly inside. MKL then ran on every
    core in a one-worker run: a solve with 2-10 right-hand sides took 1.3-1.8 ms against 0.6-1.7 ms on one
    thread (the 4-cable trunk's K, waking the other thread), and its factors differed in their last bits
    from those of a pool's workers (one thread each), so a one-worker run was not the same as a pool's."""
    _ONE_THREAD.append(_LIB[2](1) if _LIB else None)
    try:
        yield
    finally:
        previous = _ONE_THREAD.pop()
        if previous is not None and _LIB:
            _LIB[2](previous)


class _Pattern:
    """What PARDISO needs of one sparsity pattern of K (CSC, sorted, structurally symmetric): its upper
    triangle as 0-based CSR arrays and the gather that fills it, and the map of K's entries to K^T's."""

    def __init__(self, K):
        self.indptr, self.indices, self.n = K.indptr.copy(), K.indices.copy(), K.shape[0]
        tag = sp.csc_matrix((np.arange(1, K.nnz + 1, dtype=float), K.indices, K.indptr), shape=K.shape)
        T = tag.T.tocsc()
        T.sort_indices()
        same = np.array_equal(T.indptr, K.indptr) and np.array_equal(T.indices, K.indices)
        self.transpose = T.data.astype(np.int64) - 1 if same else None  # None: not structurally symmetric
        self.sample = np.arange(0, K.nnz, 8)
        self.sample_t = None if self.transpose is None else self.transpose[self.sample]
        # K's CSC arrays read as CSR are K^T's rows; where K = K^T, its upper triangle is the entries of row i
        # with column >= i
        col = np.repeat(np.arange(self.n), np.diff(K.indptr))
        # a diagonally dominant matrix of the pattern (a graph Laplacian plus the identity) for the analysis
        self.canonical = np.where(K.indices == col, np.diff(K.indptr)[col].astype(float), -1.0)
        upper = K.indices >= col
        self.upper = np.flatnonzero(upper)
        # K^T's entries at the upper triangle's: (K + K^T) / 2 there is gathered from half of K's entries
        self.upper_t = None if self.transpose is None else self.transpose[self.upper]
        self.u_indptr = np.concatenate([[0], np.cumsum(np.bincount(col[upper], minlength=self.n))]).astype(np.int32)
        self.u_indices = K.indices[upper].astype(np.int32)
        self.f_indptr, self.f_indices = K.indptr.astype(np.int32), K.indices.astype(np.int32)
        self.probe = np.random.default_rng(0).standard_normal(self.n)  # fixed: results never depend on chance
        self.analyses: dict = {}

    def matches(self, K) -> bool:
        return (K.indptr.shape == self.indptr.shape and K.indices.shape == self.indices.shape
                and np.array_equal(K.indptr, self.indptr) and np.array_equal(K.indices, self.indices))

    def symmetric(self, data) -> bool:
        """Whether K = K^T to :data:`SYMMETRY_TOLERANCE` of its largest entry, judged on a fixed eighth of its
        entries (a law or term that makes K unsymmetric does so all over it; the whole test cost 23 ms at 18k
        dofs)."""
        if self.transpose is None:
            return False
        a, b = data[self.sample], data[self.sample_t]
        return bool(np.max(np.abs(a - b)) <= SYMMETRY_TOLERANCE * np.max(np.abs(a)))


_ORDERING_CODES = {"metis": 2, "amd": 0}
"""PARDISO's iparm[1] for the fill-reducing orderings :meth:`_Analysis._ordered` chooses between."""


class _Analysis:
    """One PARDISO handle: the ordering and symbolic analysis of a pattern in one mode (symmetric
    indefinite or unsymmetric), and up to ``slots`` numeric factorisations sharing it.

    ``cholesky``: a symmetric K is factorised as positive definite (PARDISO's Cholesky, L L^T), not as
    indefinite with Bunch and Kaufman's 1x1 and 2x2 pivots. Why: the same factors in about half the time
    (measured in single precision, one thread, the same ordering: K_s 4.3 -> 2.2 ms at 2646 dofs, 12.5 -> 6.8 ms
    at 4374 dofs, 119 -> 64 ms at 18252, the solves no slower), and a K that is stable with no negative pivot by
    design is positive definite. Where it is not, PARDISO stops at the first pivot that is not positive (its
    error -4, raised as singular): a single-precision factorisation is then refused and redone in double
    precision, whose analysis keeps Bunch and Kaufman's pivots and counts the negative ones.
    """

    def __init__(self, pattern: _Pattern, symmetric: bool, slots: int, threads: int, single: bool = False,
                 cholesky: bool = False, orderings: tuple = ("metis", "amd")):
        self.n, self.slots, self.single = pattern.n, slots, single
        self.mtype = (2 if cholesky else -2) if symmetric else 11
        self.indptr, self.indices = ((pattern.u_indptr, pattern.u_indices) if symmetric
                                     else (pattern.f_indptr, pattern.f_indices))
        self.dtype = np.float32 if single else np.float64
        iparm = np.zeros(64, np.int32)
        iparm[0] = 1  # these settings, not the defaults
        iparm[9] = 8 if symmetric else 13  # pivot perturbation 1e-8 / 1e-13 (PARDISO's defaults per type)
        iparm[10] = iparm[12] = 0  # no scaling or matching: they would follow the analysed values
        iparm[11] = 0 if symmetric else 2  # the CSC arrays read as CSR are K^T: solve the transposed system
        iparm[20] = 1  # Bunch-Kaufman pivoting (symmetric indefinite)
        iparm[27] = int(single)
        iparm[34] = 1  # 0-based indices
        # conditional numerical reproducibility: without it, with 2 threads, the same K gave factors differing
        # in the last bits from run to run, which chord-Newton amplified (27 iterations or 71 from rest on the
        # 10-node trunk, in consecutive runs); with it, runs with the same thread count agree bit for bit
        iparm[33] = threads
        self.iparm = iparm
        self.free = list(range(slots, 0, -1))
        self.live = True
        # the analysis depends on the values it is given (measured: the same K solved with analyses of two other
        # tangents differs by 3e-12), so it gets the pattern's fixed ones, not the first matrix's: a result must
        # not depend on which factorisation of the pattern came first in this process (a worker's history)
        canonical = np.ascontiguousarray(pattern.canonical[pattern.upper] if symmetric else pattern.canonical,
                                         dtype=self.dtype)
        self.pt = self._ordered(canonical, orderings)
        if not pattern.analyses:  # the pattern's first analysis: the factors' size is known, none is made yet
            try:
                fits_in_memory(self.n, self.factor_sizes[self.ordering], np.dtype(self.dtype).itemsize)
            except ValueError:
                self._release(self.pt)
                raise

    def _ordered(self, canonical, orderings) -> np.ndarray:
        """The handle of the analysis whose factors have fewer nonzeros, of METIS's nested dissection and
        AMD's minimum degree (PARDISO's count; the other analysis is released).

        Why both: neither wins at every size. Measured on the trunks' tangents (single precision, one thread):
        at 2646 dofs AMD's factors are 0.90 of METIS's and factorise in 0.81 of the time (LU 5.6 -> 4.5 ms), at
        4374 dofs 0.96 and 0.85, at 18252 dofs METIS's are 0.94 of AMD's and factorise in 0.86 of the time.
        The factors' size decides and the analysis is deterministic: every process picks the same one."""
        handles, self.factor_sizes = {}, {}
        for ordering in orderings:
            self.pt = np.zeros(64, np.int64)
            self.iparm[1], self.iparm[17] = _ORDERING_CODES[ordering], -1
            self.call(1, 11, canonical)
            handles[ordering], self.factor_sizes[ordering] = self.pt, int(self.iparm[17])
        self.ordering = min(orderings, key=self.factor_sizes.get)
        self.iparm[1] = _ORDERING_CODES[self.ordering]
        for ordering, pt in handles.items():
            if ordering != self.ordering:
                self._release(pt)
        return handles[self.ordering]

    def _release(self, pt) -> None:
        self.pt, keep = pt, self.pt
        try:
            self.call(1, -1, np.zeros(len(self.indices), self.dtype))
        finally:
            self.pt = keep

    def call(self, mnum: int, phase: int, data, b=None):
        nrhs = 1 if b is None or b.ndim == 1 else b.shape[1]
        b = np.zeros(self.n, self.dtype) if b is None else np.asfortranarray(b, dtype=self.dtype)
        x = np.zeros_like(b)
        err = ctypes.c_int32(0)
        i32 = ctypes.c_int32
        fixed = self.__dict__.get("_fixed")
        if fixed is None:  # the arguments that never change, made once (~10 us a call, ~36000 calls a 4-cable run)
            p32 = ctypes.POINTER(i32)
            fixed = self._fixed = (i32(self.slots), i32(self.mtype), i32(self.n), self.indptr.ctypes.data_as(p32),
                                   self.indices.ctypes.data_as(p32), self.iparm.ctypes.data_as(p32), i32(0))
        slots, mtype, n, indptr, indices, iparm, msglvl = fixed
        _mkl()(self.pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)), ctypes.byref(slots), ctypes.byref(i32(mnum)),
               ctypes.byref(mtype), ctypes.byref(i32(phase)), ctypes.byref(n), data.ctypes.data, indptr, indices,
               None, ctypes.byref(i32(nrhs)), iparm, ctypes.byref(msglvl), b.ctypes.data, x.ctypes.data,
               ctypes.byref(err))
        if err.value == -4:  # zero pivot: singular, as SuperLU says it
            raise RuntimeError("Factor is exactly singular (PARDISO error -4)")
        if err.value != 0:
            raise RuntimeError(f"PARDISO error {err.value} in phase {phase}")
        return x

    def release(self, slot: int) -> None:
        # the slot is refactorised in place by its next user (PARDISO's phase 22 on the same mnum), not freed:
        # the free slots are reused last-in first-out, so the memory held is that of the most factorisations
        # alive at once, as before, and a release (phase 0, 0.3 ms at 4k dofs) is saved per factorisation
        if self.live:
            self.free.append(slot)

    def __del__(self):
        if self.live and _LIB:
            self.live = False
            try:
                self.call(1, -1, np.zeros(len(self.indices), self.dtype))
            except Exception:  # noqa: BLE001
                pass


class _PardisoLU:
    """A numeric factorisation in one slot of an analysis (freed with this object); in single precision, K is
    kept to refine against (as :class:`_PermutedLU` does)."""

    def __init__(self, analysis: _Analysis, data, K=None):
        self.analysis, self.data = analysis, np.ascontiguousarray(data, dtype=analysis.dtype)
        self.single = analysis.single
        self.K = K if analysis.single else None
        self.slot = analysis.free.pop()
        try:
            analysis.call(self.slot, 22, self.data)
        except BaseException:
            analysis.free.append(self.slot)
            self.slot = None
            raise
        # (a Cholesky factorisation that succeeds had only positive pivots)
        self.perturbed, self._negative = int(analysis.iparm[13]), 0 if analysis.mtype == 2 else int(analysis.iparm[22])
        # with perturbed pivots the factors are of a nearby matrix, and their inertia may not be K's
        self.inertia_known = analysis.mtype in (-2, 2) and self.perturbed == 0
        weakref.finalize(self, analysis.release, self.slot)

    def negative_pivots(self) -> int | None:
        return self._negative if self.inertia_known else None

    def solve(self, b):
        b = np.asarray(b)
        return np.ascontiguousarray(self.analysis.call(self.slot, 33, self.data, b), dtype=float)


_PATTERNS: list[_Pattern] = []


def _threads() -> int:
    """MKL's threads now: 1 in the methods (:func:`one_mkl_thread`, in
    :func:`casadi_ws.runtime.executor.one_blas_thread`, and their workers), the cores otherwise. Results are
    bit-reproducible for a given count."""
    _mkl()
    return max(1, int(_LIB[1]()))


MEMORY_SHARE = 0.8
"""The most of the memory available one factorisation's factors may take (PARDISO's analysis counts their
nonzeros before any is made); beyond, the model is refused (:func:`fits_in_memory`)."""


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (MemAvailable of /proc/meminfo); None where unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def fits_in_memory(n: int, factor_nonzeros: int, itemsize: int) -> None:
    """Refuse, in one line (a ModelError: exit 2 on the command line), a tangent whose factors would not fit:
    a mesh too big for the machine, said before the first factorisation (which would exhaust the memory, swap
    for hours or be killed) with the estimate and the limit. Only PARDISO's analysis gives the size in advance;
    with SuperLU there is no such check."""
    avail = available_memory()
    need = factor_nonzeros * itemsize
    if avail is not None and need > MEMORY_SHARE * avail:
        from ..fem.spec import ModelError

        raise ModelError(f"the mesh is too big for this machine's memory: one factorisation of its tangent ({n} "
                         f"unknowns; {factor_nonzeros:.3g} nonzeros in its factors, by PARDISO's analysis) needs "
                         f"{need / 2**30:.3g} GiB, more than {100 * MEMORY_SHARE:.0f} % of the "
                         f"{avail / 2**30:.3g} GiB available: coarsen the mesh or use a machine with more memory")


def _analysis(pattern: _Pattern, symmetric: bool, single: bool = False, cholesky: bool = False) -> _Analysis:
    key = (symmetric, _threads(), single, symmetric and cholesky)
    a = pattern.analyses.get(key)
    if a is None or not a.free:
        a = pattern.analyses[key] = _Analysis(pattern, symmetric, MAX_FACTORS, key[1], single, key[3])
    return a


def _single(pattern: _Pattern, K, data, symmetric: bool, negatives: int = 0):
    """K's L D L^T (symmetric) or LU in single precision, or None where it cannot be trusted: a perturbed
    pivot, another count of negative pivots than ``negatives`` (those of a stable saddle point: the inertia
    the stability test reads, which round-off could decide, a double-precision factorisation settles), or a
    probe solve off by more than :data:`SINGLE_PRECISION_PROBE`.

    Why the pivots are checked as well as the probe: on a nearly incompressible K (nu = 0.499, mean
    dilatation) PARDISO's single precision passed the probe (error 0.019) with two spurious negative pivots,
    and Newton stalled on it."""
    try:
        lu = _PardisoLU(_analysis(pattern, symmetric, single=True, cholesky=negatives == 0), data, K)
    except RuntimeError:
        return None
    if lu.perturbed or (symmetric and lu.negative_pivots() != negatives):
        return None
    x = lu.solve(K @ pattern.probe)
    if not np.linalg.norm(x - pattern.probe) < SINGLE_PRECISION_PROBE * np.linalg.norm(pattern.probe):
        return None
    return lu


def symmetric_part_positive_definite(K) -> bool | None:
    """Whether K's symmetric part (K + K^T) / 2 is positive definite, by PARDISO's Cholesky in single precision,
    or its L D L^T in double where that fails; None where PARDISO is not installed, K's pattern is not
    symmetric, or a pivot of the double-precision one is perturbed or zero.

    Why: where it is, every eigenvalue of K has a positive real part (Re lambda = v* K_s v / |v|^2 for
    K v = lambda v), so an unsymmetric K (the 4-node corotational tangent) whose Newton LU has no inertia is
    stable. 2.2 ms at 2646 dofs by Cholesky in single precision (4.3 ms with Bunch and Kaufman's pivots,
    8-9 ms for SuperLU's LU, whose pivots were read before); where it is not positive definite the stability
    test computes K's eigenvalues nearest zero.
    """
    if not available("pardiso"):
        return None
    K = K.tocsc() if not sp.isspmatrix_csc(K) else K
    if not K.has_sorted_indices:
        K = K.sorted_indices()
    pattern = _pattern_of(K, True)
    if pattern.transpose is None:
        return None
    data = 0.5 * (K.data[pattern.upper] + K.data[pattern.upper_t])
    for single in (True, False):
        try:
            n = _PardisoLU(_analysis(pattern, True, single, cholesky=single), data).negative_pivots()
        except RuntimeError:  # a pivot of Cholesky's not positive, or a zero one: not known to be definite
            n = None
        if n == 0:
            return True
    return None if n is None else False


def _pattern_of(K, reuse: bool) -> _Pattern:
    for pattern in _PATTERNS if reuse else ():
        if pattern.matches(K):
            return pattern
    pattern = _Pattern(K)
    if reuse:
        _PATTERNS.insert(0, pattern)
        del _PATTERNS[4:]
    return pattern


def _pardiso_factorize(K, reuse_ordering: bool, unsymmetric: bool = True, single: bool = False,
                       negatives: int = 0, check: bool = False):
    """PARDISO's factorisation of K; None if K is unsymmetric and ``unsymmetric`` is False (such a K then goes
    to SuperLU, whose diagonal pivots the stability test reads; PARDISO's LU has no inertia), or with
    ``check`` (``auto``) if PARDISO is not installed. With ``single``, in single precision where
    :func:`_single` trusts it."""
    if not K.has_sorted_indices:
        K = K.sorted_indices()
    pattern = _pattern_of(K, reuse_ordering)
    symmetric = pattern.symmetric(K.data)
    # (asked only once PARDISO would factorise K: loading MKL costs ~0.6 s per process)
    if not (symmetric or unsymmetric) or (check and not available("pardiso")):
        return None
    data = K.data[pattern.upper] if symmetric else K.data
    if not reuse_ordering:  # a one-off matrix: its own analysis, freed with its factorisation
        # (METIS alone: a second analysis would double the cost of a matrix factorised once)
        return _PardisoLU(_Analysis(pattern, symmetric, 1, _threads(), orderings=("metis",)), data)
    if single:
        lu = _single(pattern, K, data, symmetric, negatives)
        if lu is not None:
            return lu
    return _PardisoLU(_analysis(pattern, symmetric), data)
