"""The linear solvers behind every factorisation (solvers/linear.py): each backend against the others and
against dense linear algebra (solutions, inertia), their bookkeeping, and the problem file's choice.

PARDISO comes with the test install (``make test`` installs the ``fast`` extra); SuperLU is always there, and
its cases run without PARDISO too (only the PARDISO cases skip, saying why).
References are dense solves and dense eigenvalues of the same matrix, never an earlier output.
"""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import REPO, small_trunk
from test_admissible import P_EULER, column

import casadi_ws as cw
import casadi_ws.solvers.linear as linear
from casadi_ws.io.problem import ProblemError, SolverSettings
from casadi_ws.solvers.admissible import admissibility
from casadi_ws.solvers.linear import factorize

needs_pardiso = pytest.mark.skipif(not linear.available("pardiso"),
                                   reason="PARDISO (pypardiso) not installed: make test installs it")
"""Only the PARDISO cases: the SuperLU ones run wherever the package does (a plain install has no pypardiso)."""
SOLVERS = ["superlu", pytest.param("pardiso", marks=needs_pardiso)]


def _symmetric(n=600, shift=0.0, seed=3):
    A = sp.random(n, n, density=0.01, random_state=seed)
    A = (A + A.T + 4.0 * sp.eye(n) - shift * sp.eye(n)).tocsc()
    A.sort_indices()
    return A


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("single", [False, True])
def test_solutions_match_a_dense_solve(solver, single):
    A = _symmetric()
    b = np.random.default_rng(0).standard_normal((A.shape[0], 3))
    ref = np.linalg.solve(A.toarray(), b)
    lu = factorize(A, single, solver=solver)
    tol = 1e-4 if lu.single else 1e-10  # single precision: the caller refines against lu.K
    assert np.linalg.norm(lu.solve(b) - ref) < tol * np.linalg.norm(ref)
    assert np.linalg.norm(lu.solve(b[:, 0]) - ref[:, 0]) < tol * np.linalg.norm(ref[:, 0])
    assert lu.single == (lu.K is not None)


@pytest.mark.parametrize("solver", SOLVERS)
def test_the_inertia_of_an_indefinite_symmetric_matrix(solver):
    A = _symmetric(shift=3.0)
    expected = int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))
    assert 0 < expected < A.shape[0]
    assert factorize(A, pivot_threshold=0.0, solver=solver).negative_pivots() == expected


@needs_pardiso
def test_pardisos_single_precision_is_kept_only_without_a_negative_pivot():
    """Newton's single-precision L D L^T: kept for a positive definite K; where a pivot is negative (the
    inertia the stability test reads, which round-off could decide) K is factorised again in double."""
    B = _symmetric(shift=-2.0)
    assert np.linalg.eigvalsh(B.toarray())[0] > 0
    assert factorize(B, single=True, solver="pardiso").single
    A = _symmetric(shift=3.0)
    lu = factorize(A, single=True, solver="pardiso")
    assert not lu.single and lu.K is None
    assert lu.negative_pivots() == int(np.count_nonzero(np.linalg.eigvalsh(A.toarray()) < 0))


def _grid_laplacian(n):
    """The 7-point Laplacian of an n^3 grid plus the identity: a 3-D mesh's pattern, where nested dissection
    makes smaller factors than minimum degree once the grid is large."""
    d = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    i = sp.eye(n)
    A = (sp.kron(sp.kron(d, i), i) + sp.kron(sp.kron(i, d), i) + sp.kron(sp.kron(i, i), d) + sp.eye(n**3)).tocsc()
    A.sort_indices()
    return A


@needs_pardiso
@pytest.mark.parametrize("make", [lambda: _symmetric(), lambda: _grid_laplacian(14)], ids=["random", "grid"])
def test_the_ordering_with_the_smaller_factors_is_chosen(make):
    A = make()
    lu = factorize(A, single=True, solver="pardiso")
    a = lu.analysis
    assert set(a.factor_sizes) == {"metis", "amd"}
    assert a.factor_sizes[a.ordering] == min(a.factor_sizes.values())
    b = np.random.default_rng(0).standard_normal(A.shape[0])
    ref = np.linalg.solve(A.toarray(), b)
    assert np.linalg.norm(lu.solve(b) - ref) < 1e-4 * np.linalg.norm(ref)
    again = linear._Analysis(linear._Pattern(A), True, 1, linear._threads(), True, True)
    assert again.ordering == a.ordering and again.factor_sizes == a.factor_sizes  # every process picks the same


@needs_pardiso
def test_single_precision_is_cholesky_only_where_no_negative_pivot_is_designed():
    """Cholesky (half the time of Bunch-Kaufman's L D L^T) for a K that should be positive definite; a saddle
    point's designed negative pivots, and the double-precision fallback, keep Bunch-Kaufman's, and an
    indefinite K that Cholesky refuses is counted by it."""
    B = _symmetric(shift=-2.0)
    lu = factorize(B, single=True, solver="pardiso")
    assert lu.single and lu.analysis.mtype == 2 and lu.negative_pivots() == 0
    saddle = _symmetric(shift=3.0)
    expected = int(np.count_nonzero(np.linalg.eigvalsh(saddle.toarray()) < 0))
    lu = factorize(saddle, single=True, solver="pardiso", negatives=expected)
    assert lu.analysis.mtype == -2 and lu.negative_pivots() == expected
    lu = factorize(saddle, single=True, solver="pardiso")
    assert not lu.single and lu.analysis.mtype == -2 and lu.negative_pivots() == expected
    assert factorize(B, single=False, solver="pardiso").analysis.mtype == -2


@pytest.mark.parametrize("solver", SOLVERS)
def test_an_unsymmetric_matrix_gets_an_lu(solver):
    """PARDISO's LU has no inertia to give; SuperLU's diagonal pivots are read for one."""
    A = _symmetric()
    A = (A + sp.triu(A, 1).multiply(0.3)).tocsc()  # same pattern, unsymmetric values
    A.sort_indices()
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    lu = factorize(A, solver=solver)
    assert np.linalg.norm(A @ lu.solve(b) - b) < 1e-10 * np.linalg.norm(b)
    if solver == "pardiso":
        assert lu.negative_pivots() is None


@needs_pardiso
def test_more_live_factorisations_than_one_analysis_holds():
    A = _symmetric(200)
    b = np.ones(A.shape[0])
    lus = [factorize(A * (1 + k), solver="pardiso") for k in range(linear.MAX_FACTORS + 3)]
    for k in (0, linear.MAX_FACTORS - 1, linear.MAX_FACTORS + 2):
        assert np.allclose((A * (1 + k)) @ lus[k].solve(b), b, atol=1e-10)
    analysis = lus[0].analysis
    del lus
    assert len(analysis.free) == analysis.slots  # every slot released with its factorisation


@pytest.mark.parametrize("solver", SOLVERS)
def test_the_pivots_count_the_negative_eigenvalues_of_a_column_above_euler(solver):
    pb = column(3.0)
    pb.solver = dataclasses.replace(pb.solver, linear=solver)
    m = cw.StaticModel(pb)
    eq = cw.solve_equilibrium(m, np.zeros(0))
    adm = admissibility(m, eq.q, eq.u, eq.factorization)
    K = m.residual_and_tangent(eq.q, eq.u)[1].toarray()
    assert adm.negative_pivots == np.count_nonzero(np.linalg.eigvalsh(0.5 * (K + K.T)) < 0) == 2
    assert not adm.stable and P_EULER > 0


@needs_pardiso
@pytest.mark.parametrize("factor, stable", [(0.9, True), (1.1, False)])
def test_the_taylor_hood_columns_stability_is_the_same_with_both_solvers(factor, stable):
    """A saddle-point tangent (pressure unknowns): its inertia from PARDISO's L D L^T and from SuperLU's
    diagonal pivots, either side of Euler's load."""
    for solver in ("superlu", "pardiso"):
        pb = column(factor, "taylor_hood")
        pb.solver = dataclasses.replace(pb.solver, linear=solver)
        m = cw.StaticModel(pb)
        eq = cw.solve_equilibrium(m, np.zeros(0))
        assert eq.converged and linear.solver_of(m) == solver
        assert admissibility(m, eq.q, eq.u, eq.factorization).stable is stable


@needs_pardiso
def test_the_trunks_equilibrium_is_the_same_with_both_solvers():
    tips = {}
    for solver in ("superlu", "pardiso"):
        pb = small_trunk()
        pb.solver = SolverSettings(linear=solver)
        m = cw.StaticModel(pb)
        eq = cw.solve_equilibrium(m, np.array([60.0, 30.0]))
        assert eq.converged and linear.solver_of(m) == solver
        tips[solver] = eq.tip
    assert np.linalg.norm(tips["superlu"] - tips["pardiso"]) < 1e-9


@needs_pardiso
def test_auto_for_symmetric_and_unsymmetric_tangents(monkeypatch):
    """The 10-node corotational tangent is symmetric: PARDISO's L D L^T and its inertia. The 4-node one is
    unsymmetric: Newton gets PARDISO's LU (no inertia; the stability test reads the symmetric part's), a
    factorisation that asks for the inertia gets SuperLU's LU, whose pivots say it."""
    for order in (1, 2):
        pb = small_trunk()
        if order == 2:
            from casadi_ws.fem.mesh import quadratic
            pb.mesh = quadratic(pb.mesh)
        m = cw.StaticModel(pb)
        eq = cw.solve_equilibrium(m, np.array([60.0, 30.0]))
        assert linear.solver_of(m) == "auto" and type(eq.factorization.lu).__name__ == "_PardisoLU"
        assert eq.factorization.negative_pivots() == (None if order == 1 else 0)
        K = m.residual_and_tangent(eq.q, eq.u)[1]
        assert type(factorize(K, solver="auto")).__name__ == ("_PermutedLU" if order == 1 else "_PardisoLU")
        assert factorize(K, solver="auto").negative_pivots() == 0
        adm = admissibility(m, eq.q, eq.u, eq.factorization)
        assert adm.stable and adm.negative_pivots == 0 and adm.smallest_eigenvalue is None  # no eigenvalues needed
    monkeypatch.setattr(linear, "available", lambda name: name != "pardiso")
    assert linear.choose("auto") == "superlu"


@pytest.mark.parametrize("shift, expected", [(-2.0, True), (3.0, False)])
def test_the_symmetric_part_test_against_dense_eigenvalues(shift, expected):
    A = _symmetric(shift=shift)
    A = (A + sp.triu(A, 1).multiply(0.1)).tocsc()  # unsymmetric values, symmetric pattern
    A.sort_indices()
    S = 0.5 * (A + A.T).toarray()
    assert (np.linalg.eigvalsh(S)[0] > 0) == expected
    # (without PARDISO it says nothing, None, and the stability test computes eigenvalues instead)
    assert linear.symmetric_part_positive_definite(A) == (expected if linear.available("pardiso") else None)


def test_the_problem_files_solver_linear(tmp_path, monkeypatch):
    d = dict(cw.io.problem.DEFAULT_PROBLEM)
    d["solver"] = {"linear": "superlu"}
    assert cw.problem_from_dict(d, "p.yaml").solver.linear == "superlu"
    d["solver"] = {"linear": "umfpack"}
    with pytest.raises(ProblemError, match=r"^p\.yaml: solver\.linear: expected one of auto, superlu, pardiso"):
        cw.problem_from_dict(d, "p.yaml")
    import casadi_ws.io.problem as problem_module

    monkeypatch.setattr(problem_module, "available", lambda name: name != "pardiso")
    d["solver"] = {"linear": "pardiso"}
    with pytest.raises(ProblemError, match=r"solver\.linear: pardiso is not installed here"):
        cw.problem_from_dict(d, "p.yaml")


def test_without_pypardiso_the_package_runs_on_superlu(tmp_path):
    """A plain install (no ``fast`` extra): pypardiso cannot be imported, ``auto`` is SuperLU."""
    block = tmp_path / "pypardiso.py"
    block.write_text("raise ImportError('not installed')\n")
    code = ("import numpy as np, casadi_ws as cw\n"
            "from casadi_ws.solvers.linear import available\n"
            "m = cw.StaticModel(cw.default_problem())\n"
            "from casadi_ws.solvers.linear import solver_of\n"
            "print(available('pardiso'), solver_of(m), cw.solve_equilibrium(m, np.array([10.0, 0.0])).converged)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                         env={**__import__("os").environ, "PYTHONPATH": str(tmp_path)}, timeout=300)
    assert out.stdout.split() == ["False", "superlu", "True"], out.stderr[-2000:]


def test_without_pypardiso_this_modules_superlu_cases_run_and_pass(tmp_path):
    """This module again, with pypardiso not importable (a plain install): its SuperLU cases run and pass, only
    the PARDISO ones skip (the module as a whole used to skip there)."""
    (tmp_path / "pypardiso.py").write_text("raise ImportError('not installed')\n")
    here = __import__("pathlib").Path(__file__)
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-p", "no:cacheprovider", str(here),
                          "-k", "not this_modules_superlu_cases and not without_pypardiso_the_package"],
                         capture_output=True, text=True, cwd=here.parent.parent, timeout=600,
                         env={**__import__("os").environ, "PYTHONPATH": str(tmp_path)})
    summary = out.stdout.strip().splitlines()[-1]
    passed = int(summary.split(" passed")[0].split()[-1])
    assert out.returncode == 0 and "failed" not in summary and passed >= 8, out.stdout[-2000:]


@needs_pardiso
def test_a_workers_history_does_not_change_a_factorisation():
    """The analysis is computed from the pattern's fixed values, so the same K solves to the same bits
    whichever tangent of the pattern was factorised first (a Dask task re-run in another worker)."""
    A = _symmetric(300)
    b = np.ones(A.shape[0])
    out = []
    for first in (A, A * 3.0 + sp.eye(A.shape[0]) * 7.0):
        linear._PATTERNS.clear()
        factorize(first.tocsc(), solver="pardiso")
        out.append(factorize(A, solver="pardiso").solve(b))
    np.testing.assert_array_equal(out[0], out[1])


@needs_pardiso
def test_the_methods_run_pardiso_on_one_thread_though_mkl_is_loaded_inside_them():
    """threadpoolctl's limit reaches only the libraries loaded before it; MKL loads on first use, inside
    a method: :func:`casadi_ws.solvers.linear.one_mkl_thread` limits it then, and restores it after."""
    code = ("import os, scipy.sparse as sp\n"
            "os.environ.pop('MKL_NUM_THREADS', None); os.environ.pop('OMP_NUM_THREADS', None)\n"
            "from casadi_ws.solvers import linear\n"
            "from casadi_ws.runtime.executor import one_blas_thread\n"
            "A = (sp.random(60, 60, density=0.1, random_state=1) + 10 * sp.eye(60)).tocsc(); A = (A + A.T).tocsc()\n"
            "with one_blas_thread():\n"
            "    with one_blas_thread():\n"
            "        linear.factorize(A, solver='pardiso')\n"
            "        inside = linear._threads()\n"
            "    nested = linear._threads()\n"
            "print(inside, nested, linear._threads())\n")
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("MKL_NUM_THREADS", "OMP_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    default = subprocess.run([sys.executable, "-c", "from casadi_ws.solvers import linear; print(linear._threads())"],
                             capture_output=True, text=True, env=env, timeout=120)
    assert out.stdout.split() == ["1", "1", default.stdout.strip()], out.stderr[-2000:]


def test_the_methods_keep_numpy_arrays_in_small_pages_and_restore_the_setting():
    """:func:`casadi_ws.runtime.executor.small_pages`: NumPy's huge-page requests off inside a method (first
    touches stalled seconds on fragmented memory), back on after; left alone where the environment sets it."""
    code = ("from numpy._core import multiarray as m\n"
            "from casadi_ws.runtime.executor import small_pages\n"
            "with small_pages():\n"
            "    inside = m._set_madvise_hugepage(False)\n"
            "    m._set_madvise_hugepage(inside)\n"
            "print(inside, m._set_madvise_hugepage(True))\n")
    env = {k: v for k, v in __import__("os").environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.stdout.split() == ["False", "True"], out.stderr[-2000:]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env=env | {"NUMPY_MADVISE_HUGEPAGE": "1"})
    assert out.stdout.split() == ["True", "True"], out.stderr[-2000:]


@needs_pardiso
def test_a_mesh_too_big_for_the_memory_is_refused_before_the_first_factorisation(monkeypatch, capsys):
    """Issue 66: PARDISO's analysis counts the factors' nonzeros before any factorisation; where they would
    take more than MEMORY_SHARE of the memory available (here made 1 MB), the command says so in one line --
    the estimate and the limit -- and exits 2 instead of exhausting the machine. The estimate is the analysis's
    own count (iparm 18), checked against the factors' size on a matrix whose factors are known: a diagonal."""
    from casadi_ws.cli import main

    monkeypatch.setattr(linear, "available_memory", lambda: 2**20)
    assert main(["equilibrium", "--u", "10,0", str(REPO / "problems" / "trunk_2cables.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "too big for this machine's memory" in err[0] and "GiB available" in err[0]
    monkeypatch.setattr(linear, "available_memory", lambda: 10 * 2**30)
    n = 500
    lu = factorize(sp.eye(n, format="csc") * 2.0, solver="pardiso")
    assert n <= lu.analysis.factor_sizes[lu.analysis.ordering] <= n + 1  # a diagonal's n entries (PARDISO: n + 1)
