"""What "verified" means beyond the residual: the configurations a robot can actually take.

A converged equilibrium (relative residual below tolerance, u in U: :mod:`.equilibrium`) is *admissible* when
none of these checks fails; each failure has a name, and the names form one vocabulary for every method,
result file and summary (``VIOLATIONS``):

==================  =============================================================================
name                the equilibrium is refused when
==================  =============================================================================
unstable            the tangent K on the free dofs is not positive definite: for a symmetric K
                    (linear, neo-Hookean laws; the actuators' terms are Hessians) it has a negative
                    eigenvalue; for the corotational law, whose K is not symmetric, its eigenvalue of
                    smallest real part is negative
inverted            det F at some quadrature point is below ``min_det_F`` (default 0.1)
self_penetration    a boundary sample of the deformed body (a boundary node, mid-edge nodes of
                    10-node meshes included, or a boundary face's centroid) lies inside a tetrahedron
                    that does not touch it, deeper than ``penetration_depth`` in barycentric terms,
                    whatever their distance at rest
stroke              a cable shortened by more than its ``stroke_max``
volume              a cavity's volume exceeds its ``volume_max``
stretch             a principal stretch exceeds the material's ``max_stretch``
obstacle            a boundary node lies inside one of the problem's ``obstacles`` (contact forces are not
                    modelled yet: such a state is excluded, not pushed back)
==================  =============================================================================

How stability is decided, cheaply: the LU that Newton already holds (SuperLU, symmetric mode, diagonal
pivots) is, when SuperLU swapped no rows, the L D U of K; the count of negative pivots is then the number of
negative eigenvalues of a symmetric K (Sylvester's law of inertia), read off U's diagonal in ~0.3 ms. When
the count is not zero, or rows were swapped, or K is not symmetric and the count is not zero, the
eigenvalues of K nearest zero are computed by shift-invert (ARPACK) with a double-precision LU of K at the
point itself, and the decision is the sign of the smallest real part among them. A tangent bordered by
contact or prescribed-quantity rows is judged on the stiffness with them held (:meth:`StaticModel.
stability_matrix`); one bordered by the continuous pressure's unknowns (a symmetric saddle point) is
stable iff it has exactly one negative pivot per pressure unknown (Haynsworth's inertia; such models
factorise with diagonal pivots, see :attr:`StaticModel.pivot_threshold`). Arrays store violations
as a bit mask (bit i: ``VIOLATIONS[i]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse.linalg as sla

from ..fem.spec import AdmissibilitySettings

__all__ = ["Admissibility", "AdmissibilitySettings", "VIOLATIONS", "admissibility", "admissible_equilibrium", "decode", "encode",
           "penetrating_samples", "smallest_eigenvalues", "stable_branch"]

VIOLATIONS = ("unstable", "inverted", "self_penetration", "stroke", "volume", "stretch", "obstacle")
"""The names of the admissibility checks, in the order of their bits in stored masks."""


@dataclass
class Admissibility:
    """The admissibility checks of one converged equilibrium."""

    violations: tuple[str, ...] = ()
    """Names from ``VIOLATIONS`` of the checks that failed; empty: admissible."""
    stable: bool = True
    """K positive definite (see the module's table); True when the check is off."""
    negative_pivots: int | None = None
    """Negative pivots of the LU of K (None: rows were swapped, or the check is off)."""
    smallest_eigenvalue: float | None = None
    """Smallest real part among K's eigenvalues nearest zero (N/m), computed only when the pivots do not
    settle stability."""
    min_det_F: float = float("nan")
    """Smallest det F over the quadrature points."""
    max_stretch: float = float("nan")
    """Largest principal stretch over the quadrature points (computed where a ``max_stretch`` is set)."""
    penetrating: int = 0
    """Boundary samples inside the body."""
    unstable_mode: np.ndarray | None = field(default=None, repr=False)
    """The eigenvector (free dofs) of the negative eigenvalue, when one was computed."""

    @property
    def admissible(self) -> bool:
        return not self.violations

    @property
    def mask(self) -> int:
        return encode(self.violations)

    def to_dict(self) -> dict:
        return {"admissible": self.admissible, "stable": self.stable, "violations": list(self.violations),
                "min_det_F": self.min_det_F,
                "max_stretch": self.max_stretch if np.isfinite(self.max_stretch) else None,
                "negative_pivots": self.negative_pivots, "smallest_eigenvalue": self.smallest_eigenvalue,
                "penetrating_samples": self.penetrating}


def encode(names) -> int:
    """The bit mask of violation names."""
    return sum(1 << VIOLATIONS.index(n) for n in names)


def decode(mask: int) -> tuple[str, ...]:
    """The violation names of a bit mask."""
    return tuple(n for i, n in enumerate(VIOLATIONS) if int(mask) >> i & 1)


def admissibility(model, q: np.ndarray, u: np.ndarray, fac=None, K=None,
                  settings: AdmissibilitySettings | None = None, inherited: bool = False) -> Admissibility:
    """Every check of the module's table at the equilibrium (q, u).

    ``fac``: an LU of K at q (or at the last Newton iterate before q), whose pivots decide stability when
    they can; without it K is factorised here. ``inherited``: stability and self-penetration are known to
    pass from the points around it (a forward point interpolated between Newton points of its grid line
    that passed them), so only the cheap checks run.
    """
    s = settings or model.spec.admissibility
    out = Admissibility()
    names = []
    out.min_det_F = float(model.jacobians(q).min())
    if s.inversion and not out.min_det_F > s.min_det_F:
        names.append("inverted")
    if s.stability and "inverted" not in names:
        stable = True
        if not inherited:
            stable, out.negative_pivots, out.smallest_eigenvalue, out.unstable_mode = _stability(model, q, u, fac, K)
        out.stable = bool(stable)
        if not out.stable:
            names.insert(0, "unstable")
    elif "inverted" in names:
        out.stable = False  # an inverted element has no meaningful tangent
    if s.self_penetration and not inherited:
        out.penetrating = int(penetrating_samples(model, q, s.penetration_depth).size)
        if out.penetrating:
            names.append("self_penetration")
    names += _state_limits(model, q, out)
    if _inside_obstacle(model, q):
        names.append("obstacle")
    out.violations = tuple(n for n in VIOLATIONS if n in names)
    return out


def _inside_obstacle(model, q) -> bool:
    """A boundary node of the deformed body lies inside an obstacle (deeper than 1e-9 of the mesh's size)."""
    obstacles = model.spec.obstacles
    if not obstacles:
        return False
    from ..fem.contact import boundary_nodes

    nodes = model.cache.get("boundary_nodes", lambda: boundary_nodes(model.mesh))
    x = model.positions(q)[nodes]
    tol = 1e-9 * model.mesh.characteristic_length()
    return any(float(o.distance(x).min()) < -tol for o in obstacles)


def _state_limits(model, q, out: Admissibility) -> list[str]:
    names = []
    lo, hi, what = model.quantity_limits
    if what:
        Q = model.actuator_states(q)
        slack = 1e-9 * np.maximum(np.abs(Q), 1e-30)
        for a in np.flatnonzero((Q < lo - slack) | (Q > hi + slack)):
            names.append(what[a])
    limit = model.max_stretch  # per element, inf where the material sets none
    if np.isfinite(limit).any():  # the largest principal stretch: sqrt of C's largest eigenvalue
        F = model.deformation_gradients(q)
        C = np.matmul(np.swapaxes(F, -1, -2), F)
        lam = np.sqrt(np.maximum(np.linalg.eigvalsh(C)[..., -1], 0.0))  # (m, n_qp)
        out.max_stretch = float(lam.max())
        if np.any(lam.max(axis=1) > limit * (1 + 1e-12)):
            names.append("stretch")
    return names


def _stability(model, q, u, fac, K):
    """(stable, negative pivots, smallest eigenvalue or None, its mode or None); see the module."""
    from .equilibrium import Factorization, designed_negatives, factorize, tangent_factorization
    from .linear import solver_of, symmetric_part_positive_definite

    designed = designed_negatives(model)
    solver = solver_of(model)
    held = designed is None
    if held:
        # prescribed quantities and contacts border K (a saddle point, whose pivots say nothing): judge the stiffness
        # with them held instead (:meth:`StaticModel.stability_matrix`)
        K = model.stability_matrix(q, u)
        fac = Factorization(factorize(K, reuse_ordering=False, solver=solver), q.copy())
    elif fac is None or _stale(fac.q, q):
        fac = tangent_factorization(model, q, u)
    expected = 0 if held else designed
    n_neg = fac.negative_pivots()
    if n_neg is None and not held and not expected:
        # Newton's LU of an unsymmetric K (PARDISO's) has no inertia: a positive definite symmetric part
        # proves every eigenvalue's real part positive
        Ks = fac.K if fac.K is not None else (K if K is not None else model.tangent(q, u))
        if symmetric_part_positive_definite(Ks):
            return True, 0, None, None
    if n_neg is None and expected:
        # Newton's LU swapped rows; the saddle point of an energy is quasi-definite where it is stable (its
        # stiffness block positive definite, the pressure block negative), and such a matrix has an L D L^T
        # in any order: factorised with diagonal pivots, its pivots are its inertia
        fac = Factorization(factorize(model.tangent(q, u), pivot_threshold=0.0, solver=solver),
                            q.copy())
        n_neg = fac.negative_pivots()
    if n_neg == expected:
        # a symmetric saddle point (the pressure unknowns) whose own block holds exactly its negative
        # eigenvalues: by Haynsworth's inertia the rest, its Schur complement, is positive definite
        return True, 0, None, None
    if expected:  # the saddle's pivots did not settle it: the Schur complement's do
        K = model.stability_matrix(q, u)
        fac = Factorization(factorize(K, reuse_ordering=False, solver=solver), q.copy())
        n_neg = fac.negative_pivots()
        if n_neg == 0:
            return True, 0, None, None
    vals, vecs = smallest_eigenvalues(model, q, u, K)
    k = int(np.argmin(vals.real))
    lam = float(vals[k].real)
    mode = None
    if lam < 0:
        mode = np.zeros(model.n_free)
        mode[: vecs.shape[0]] = vecs[:, k].real
    return lam >= 0.0, n_neg, lam, mode


STALE = 0.01
"""An LU computed at a state farther than this (relative, max-norm of the displacements) from the point is
not used for its stability: Newton's chord steps reuse an LU over several iterates, and a column loaded from
rest reuses the LU of the unloaded, stable state up to the straight, unstable one."""


def _stale(q_lu: np.ndarray, q: np.ndarray) -> bool:
    return bool(np.abs(q - q_lu).max() > STALE * max(np.abs(q).max(), 1e-300))


def smallest_eigenvalues(model, q, u, K=None, k: int = 6):
    """The ``k`` eigenvalues of K (free dofs) nearest zero and their vectors, by shift-invert with a
    double-precision LU of K at (q, u)."""
    from .equilibrium import factorize
    from .linear import solver_of

    if K is None:
        K = model.tangent(q, u)
    lu = factorize(K, single=False, solver=solver_of(model))
    n = K.shape[0]
    k = min(k, n - 2)
    op = sla.LinearOperator(K.shape, matvec=lu.solve, dtype=float)
    v0 = np.random.default_rng(0).standard_normal(n)  # fixed: results never depend on chance
    vals, vecs = sla.eigs(K, k=k, sigma=0.0, OPinv=op, which="LM", v0=v0, tol=1e-8)
    return vals, vecs


def penetrating_samples(model, q: np.ndarray, depth: float = 0.01) -> np.ndarray:
    """Indices of the boundary samples (see :func:`_samples`) lying inside a tetrahedron that does not
    touch them, in the deformed configuration q, whatever their distance at rest.

    First the deformed boundary is asked whether it passes through itself at all (an edge crossing a
    triangle it shares no vertex with: :func:`casadi_ws.fem.collision.surface_crosses`, ~1 ms). A sample
    inside a tetrahedron away from it takes the surface near it inside the body, so where the surface does
    not cross itself no sample can be inside (all elements positively oriented: an inverted one is the
    ``inverted`` check's). Else every sample is tested: candidates are the samples within each
    tetrahedron's circumscribing ball about its centroid (KD-trees, one per class of tetrahedra of similar
    size, so a graded mesh's large elements do not widen the search of its small ones); the test is on
    barycentric coordinates in the straight tetrahedron of the corners.
    """
    from scipy.spatial import cKDTree

    from ..fem.collision import surface_crosses

    x = model.positions(q)
    if not surface_crosses(model, x):
        return np.zeros(0, dtype=np.int64)
    S = _samples(model)
    tets = model.mesh.tets
    c0, c1, c2, c3 = (x[tets[:, a]] for a in range(4))  # curved 10-node elements judged by their corners
    centre = 0.25 * (c0 + c1 + c2 + c3)
    radius = np.sqrt(np.max([np.einsum("ij,ij->i", c - centre, c - centre) for c in (c0, c1, c2, c3)], axis=0))
    radius *= 1 + 1e-9
    corners = np.stack([c0, c1, c2, c3], axis=1)
    pts = S.W @ x
    samples = cKDTree(pts)
    si, ti = [], []
    size_class = np.floor(np.log2(radius / radius.max())).astype(int)
    for c in np.unique(size_class):
        tets = np.flatnonzero(size_class == c)
        pairs = samples.sparse_distance_matrix(cKDTree(centre[tets]), float(radius[tets].max()),
                                               output_type="ndarray")
        t = tets[pairs["j"]]
        keep = pairs["v"] <= radius[t]
        si.append(pairs["i"][keep].astype(np.int64))
        ti.append(t[keep])
    si, ti = np.concatenate(si), np.concatenate(ti)
    p = pts[si]
    keep = np.all((p >= corners.min(axis=1)[ti]) & (p <= corners.max(axis=1)[ti]), axis=1)
    si, ti = si[keep], ti[keep]
    keep = ~_member(si * model.mesh.n_tets + ti, S.touching)
    si, ti = si[keep], ti[keep]
    if si.size == 0:
        return np.zeros(0, dtype=np.int64)
    T = np.stack([corners[ti, 1] - corners[ti, 0], corners[ti, 2] - corners[ti, 0],
                  corners[ti, 3] - corners[ti, 0]], axis=2)
    ok = np.abs(np.linalg.det(T)) > 0
    lam = np.full((si.size, 3), -1.0)
    lam[ok] = np.linalg.solve(T[ok], (pts[si] - corners[ti, 0])[ok][..., None])[..., 0]
    bary = np.column_stack([1.0 - lam.sum(axis=1), lam])
    inside = np.all(bary > depth, axis=1)
    return np.unique(si[inside])


def _member(keys: np.ndarray, sorted_keys: np.ndarray) -> np.ndarray:
    i = np.minimum(np.searchsorted(sorted_keys, keys), max(sorted_keys.size - 1, 0))
    return sorted_keys[i] == keys if sorted_keys.size else np.zeros(keys.size, dtype=bool)


@dataclass
class _Samples:
    W: object
    """(s, n) sparse: sample positions from the node positions."""
    touching: np.ndarray
    """Sorted keys s * n_tets + e of the (sample, tetrahedron) pairs that touch at rest: not checked."""


def _samples(model) -> _Samples:
    """The boundary nodes and the boundary faces' centroids, built once per model."""
    return model.cache.get("penetration_samples", lambda: _build_samples(model))


def _build_samples(model) -> _Samples:
    import scipy.sparse as sp

    from ..fem.surface import boundary_faces

    mesh = model.mesh
    faces = boundary_faces(mesh)
    nodes = np.unique(faces)
    n, m, s_nodes = mesh.n_nodes, mesh.n_tets, nodes.size
    rows = np.concatenate([np.arange(s_nodes), np.repeat(s_nodes + np.arange(len(faces)), 3)])
    cols = np.concatenate([nodes, faces[:, :3].ravel()])
    vals = np.concatenate([np.ones(s_nodes), np.full(3 * len(faces), 1.0 / 3.0)])
    W = sp.csr_matrix((vals, (rows, cols)), shape=(s_nodes + len(faces), n))
    # a sample touches the tetrahedra that hold any node it is made of; on 10-node meshes also their
    # neighbours, whose straight corner tetrahedra a curved face next to them may enter
    node_tets = sp.csr_matrix((np.ones(mesh.tets.size), (mesh.tets.ravel(), np.repeat(np.arange(m), mesh.tets.shape[1]))),
                              shape=(n, m))
    touch = (W != 0).astype(float) @ node_tets
    if mesh.tets.shape[1] == 10:
        touch = touch @ (node_tets.T @ node_tets)
    touch = touch.tocoo()
    keys = np.unique(touch.row.astype(np.int64) * m + touch.col)
    return _Samples(W, keys)


def stable_branch(model, q: np.ndarray, u: np.ndarray, mode: np.ndarray, tol: float | None = None,
                  imperfection: float = 0.05, max_steps: int = 40):
    """A stable equilibrium at u near the unstable one q, found as a real column with an imperfection
    buckles: a small force along the unstable mode (``imperfection`` x the load) is applied from rest, which
    follows the stable branch, and then removed in adaptive steps, each Newton from the last. Both signs of
    the mode are tried. Returns a converged, stable :class:`.equilibrium.Equilibrium`, or None.
    """
    from .equilibrium import CONVERGED, solve_equilibrium

    F0 = model.F
    scale = max(float(np.linalg.norm(F0[model.free])),
                float(np.linalg.norm(model.actuation_rows(q).T @ model.intensities(q, u))))
    direction = np.zeros(model.n_dof)
    direction[model.free] = mode / np.linalg.norm(mode)
    no_penetration = AdmissibilitySettings(self_penetration=False, inversion=False)
    try:
        for sign in (1.0, -1.0):
            eps, step, steps = imperfection, 0.5 * imperfection, 0
            model.F = F0 + sign * eps * scale * direction
            eq = solve_equilibrium(model, u, tol=tol)  # from rest, by continuation if need be
            while eq.converged and eps > 0 and steps < max_steps:
                steps += 1
                e = max(eps - step, 0.0)
                model.F = F0 + sign * e * scale * direction
                nxt = solve_equilibrium(model, u, q0=eq.q, u0=u, guess=eq.q, tol=tol, continuation=False)
                if nxt.converged:
                    eq, eps, step = nxt, e, min(2 * step, e if e > 0 else step)
                else:
                    step *= 0.25
            if eq.converged and eps == 0 and np.abs(eq.q - q).max() > 1e-6 * max(np.abs(q).max(), 1e-300):
                model.F = F0
                if admissibility(model, eq.q, u, eq.factorization, settings=no_penetration).stable:
                    return eq
    finally:
        model.F = F0
    return None


def admissible_equilibrium(model, u, **kwargs):
    """:func:`.equilibrium.solve_equilibrium` (settled on the path from rest where contact could hold the body in
    more than one way: :func:`.equilibrium.settle`), then every admissibility check; an unstable equilibrium is
    replaced by a stable one at the same u where :func:`stable_branch` finds it (a column loaded above its
    buckling load comes out buckled). Returns (Equilibrium, Admissibility or None if not converged,
    whether the stable branch was taken)."""
    from .equilibrium import settle, solve_equilibrium

    eq = solve_equilibrium(model, u, **kwargs)
    q0 = kwargs.get("q0")
    eq = settle(model, eq, np.zeros(model.n_dof) if q0 is None else q0)  # where contact could hold it two ways
    if not eq.converged:
        return eq, None, False
    adm = admissibility(model, eq.q, eq.u, eq.factorization)
    if "unstable" in adm.violations and adm.unstable_mode is not None:
        alt = stable_branch(model, eq.q, eq.u, adm.unstable_mode)
        if alt is not None:
            return alt, admissibility(model, alt.q, alt.u, alt.factorization), True
    return eq, adm, False
