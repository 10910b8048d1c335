"""Sensitivities of an equilibrium (first and second derivatives of q(u)) and the bounded linear
least-squares step built on them."""

from __future__ import annotations

import numpy as np

__all__ = ["TangentProducts", "bounded_step", "closest_to_box", "curvature", "distance_below", "input_range",
           "limited_step", "second_order", "sensitivity", "tip_compliance"]


def sensitivity(model, q, fac, K=None, compliance: bool = False, joint: bool = False) -> tuple:
    """(A, S): A = C K^-1 H^T (3 x n_u), S = K^-1 H^T = dq/du on the free dofs (n_free x n_u); with
    ``compliance``, (A, S, G), G = C K_f^-1 C^T the tip's compliance (:func:`casadi_ws.workspace.maps.point_maps`)
    for the matrix K_f that ``fac`` factorised, solved with S's solves (the factors are read once for both). A
    single-precision ``fac`` leaves G 1-5 % off (measured on the trunks: the soft directions are those it
    solves worst), so G is refined once against K_f (then within 0.3 % on the 10-node trunk, 1e-4 on the 4-node
    one), in the same solve as S's first refinement.

    ``K``: the tangent at q, when ``fac`` was computed near q but not at it: iterative refinement then
    brings S to K's own (an LU one Newton iterate away leaves A ~1 % off; the predictors built on S need
    it closer, see :func:`curvature`). Without it, a single-precision ``fac`` is refined against its own
    matrix (its round-off leaves A 0.4-2 % off on the trunk; after two steps, ~1e-6). ``joint`` (with ``K``):
    one step that refines S and G together against K instead (:func:`_joint`; the forward maps).
    """
    H = model.actuation_matrix(q)  # (n_u, n_free), H = -dL/dq
    if not model.n_u:
        out = np.zeros((3, 0)), np.zeros((model.n_free, 0))
        return (*out, tip_compliance(model, fac)) if compliance else out
    HT = np.ascontiguousarray(H.T)
    # one solve with n_u right-hand sides reads the factors once (they do not fit in cache)
    n_u, kept = model.n_u, getattr(fac, "K", None)
    if compliance:
        CT = model.C_free.T.toarray()
        X = fac.solve(np.hstack([HT, CT]))
        S, Y = X[:, :n_u], X[:, n_u:]
    else:
        S = fac.solve(HT)
    if joint and K is not None:
        return _joint(model, q, fac, K, HT, S, CT if compliance else None, Y if compliance else None)
    K, steps = _refinement(fac, K)
    for k in range(steps):
        if compliance and k == 0 and kept is not None:
            D = fac.solve(np.hstack([HT - K @ S, CT - kept @ Y]))
            S, Y = S + D[:, :n_u], Y + D[:, n_u:]
        else:
            S = S + fac.solve(HT - K @ S)
    S = _taut(model, q, fac, S)
    # (C order, as a checkpoint restores it: the products with S then round the same way after a resume)
    S = np.ascontiguousarray(S)
    return (model.C_free @ S, S, model.C_free @ Y) if compliance else (model.C_free @ S, S)


def _joint(model, q, fac, K, HT, S, CT, Y):
    """:func:`sensitivity`'s (A, S[, G]) with one refinement step of S and G together against ``K``. Why: the
    forward maps take a double-precision LU of the tangent one Newton step before the state they are wanted at
    (~1e-9 away), and one step takes the error of both to round-off; the single-precision path refines G only
    once, ~1e-4 off, which put a serial and a 2-worker run's compliances 8e-5 apart."""
    B = HT if CT is None else np.hstack([HT, CT])
    X = S if CT is None else np.hstack([S, Y])
    X = X + fac.solve(B - K @ X)
    n_u = HT.shape[1]
    S = np.ascontiguousarray(_taut(model, q, fac, X[:, :n_u]))
    return (model.C_free @ S, S) if CT is None else (model.C_free @ S, S, model.C_free @ X[:, n_u:])


def tip_compliance(model, fac) -> np.ndarray:
    """G = C K_f^-1 C^T (3 x 3) for the matrix K_f that ``fac`` factorised; refined once against it when ``fac``
    is in single precision (see :func:`sensitivity`)."""
    CT = model.C_free.T.toarray()
    Y = fac.solve(CT)
    kept = getattr(fac, "K", None)
    if kept is not None:
        Y = Y + fac.solve(CT - kept @ Y)
    return model.C_free @ Y


def _taut(model, q, fac, S):
    """The columns of slack cables (displacement-controlled, no tension) replaced by their sensitivity once
    taut: a slack cable moves nothing until its motor has taken up the slack, then pulls like a taut one;
    the zero column the tangent gives would hide that from the interval box and the Gauss-Newton step
    (:func:`input_range` says from where the column applies). Woodbury's identity on the slack rows of the
    tangent: M = K + E W^T, M^-1 B = Y - Z (I + W^T Z)^-1 W^T Y, Y = K^-1 B, Z = K^-1 E."""
    rows = model.taut_rows(q) if hasattr(model, "taut_rows") else []
    if not rows:
        return S
    n = model.n_free
    E = np.zeros((n, len(rows)))
    W = np.column_stack([w for _, _, w in rows])
    B = np.zeros((n, len(rows)))
    for c, (a, j, _) in enumerate(rows):
        E[j, c] = 1.0
        B[j, c] = model.kappa[j - model.n_free_mech]  # -dR/du of a taut cable's row
    Y, Z = fac.solve(B), fac.solve(E)
    X = Y - Z @ np.linalg.solve(np.eye(len(rows)) + W.T @ Z, W.T @ Y)
    S = S.copy()
    for c, (a, _, _) in enumerate(rows):
        S[:, a] = X[:, c]
    return S


def input_range(model, q, u):
    """(lo, hi, offset): the input steps that move the tip from the equilibrium (q, u), with their
    sensitivities from :func:`sensitivity`. Usually lo = u_min - u, hi = u_max - u, offset 0. A slack cable
    moves nothing until its motor has taken up the slack sigma = s(q) - u (s its shortening now), and
    slackening it further moves nothing either: its steps are measured from there, lo = 0,
    hi = u_max - s, and an effective step d > 0 is the input step sigma + d (:func:`applied_step`)."""
    lo, hi = model.u_min - u, model.u_max - u
    offset = np.zeros(model.n_u)
    slack = model.slack(q) if hasattr(model, "slack") else np.zeros(model.n_u, dtype=bool)
    if slack.any():
        s = model.sign * (model.actuator_states(q) - model.rest_quantities)
        offset[slack] = np.maximum(s[slack] - u[slack], 0.0)
        lo = np.where(slack, 0.0, lo)
        hi = np.where(slack, np.maximum(model.u_max - u - offset, 0.0), hi)
    return lo, hi, offset


def applied_step(du, offset):
    """The input step that makes the effective step ``du`` of :func:`input_range`: slack taken up first."""
    return du + np.where(du > 0, offset, 0.0)


class TangentProducts:
    """K @ V for the tangent K at the equilibrium (q, u), by forward differences of the residual, without
    assembling K: what the refinement of S and Q needs from the tangent at a reached configuration.

    Why: a residual costs 1/10 (4-node) to 1/16 (10-node tetrahedra) of the residual and assembled tangent
    (``ElementType.tangent_cost``), and the refinement needs 2 n_u + n_u (n_u + 1) / 2 products. The step
    moves the state by 1e-8 of the body's size along each column: the products err by ~1e-7 relative,
    where the refinement brings S from ~1 % off to ~1e-4.
    """

    def __init__(self, model, q, u):
        self.model, self.q, self.u = model, q, u
        self.R0 = model.residual(q, u)
        self.h = 1e-8 * max(float(np.ptp(model.mesh.nodes, axis=0).max()), 1e-3)

    def __matmul__(self, V):
        V = np.asarray(V, dtype=float)
        cols = V.reshape(V.shape[0], -1)
        out = np.zeros(cols.shape)
        for k in range(cols.shape[1]):
            size = float(np.abs(cols[:, k]).max())
            if not size > 0:
                continue
            eps = self.h / size
            qp = self.q.copy()
            qp[self.model.free] += eps * cols[:, k]
            out[:, k] = (self.model.residual(qp, self.u) - self.R0) / eps
        return out.reshape(V.shape)


def _refinement(fac, K):
    """(matrix, steps) of the iterative refinement of solves with ``fac``: against ``K`` if given, else
    against the matrix a single-precision LU keeps; two steps after a single-precision LU (its error
    contracts by ~0.01-0.1 per step), one otherwise, none without a matrix."""
    kept = getattr(fac, "K", None)
    K = K if K is not None else kept
    return K, 0 if K is None else (2 if kept is not None else 1)


def curvature(model, q, u, S, fac, tip_step: float, K=None) -> np.ndarray:
    """Q: the second derivatives d2q/du_i du_j (i <= j, row-major; n_u(n_u+1)/2 x n_free, float32) of
    the equilibrium path at (q, u), so that q(u + du) = q + S du + Q(du, du)/2 + O(|du|^3).

    Why: the linear predictor q + S du stretches the elements that rotate (by ~theta^2), which in a slender
    body leaves a relative residual ~1 for a one-cell move; an LU at that state has a tangent ~50 % off
    the answer's, so Newton needs a second LU. With the second-order term the residual is ~4e-3 and one LU
    suffices (docs/methods.md). Differentiating R(q(u), u) = 0 twice: K Q(d, d) = -D2R[(S d, d)]^2, the
    second directional derivative along the path's tangent, taken by central differences
    R(q + S d, u + d) + R(q - S d, u - d) (odd orders cancel; one-sided ones were useless), with input
    increments that move the tip by a tenth of ``tip_step`` (the step of the grid the predictor serves;
    0.01-0.25 of it measured the same); pairs by polarisation. (The -2 R(q, u) of the second difference is
    left out: at a verified equilibrium it is below the tolerance, ~1e-6 of the term.) n_u(n_u+1)
    residuals and one solve, plus one refinement step against ``K`` (as in :func:`sensitivity`; without
    it the errors of Q and of the LU at its predictor feed each other from one configuration to the
    next). A non-finite Q (degenerate increments) is returned as zeros, i.e. the linear predictor.
    float32: a predictor needs no more, and it halves what travels between processes and what a
    checkpoint holds.
    """
    K, _ = _refinement(fac, K)
    n = S.shape[1]
    reach = np.linalg.norm(model.C_free @ S, axis=0)  # tip movement per unit input
    span = model.u_max - model.u_min
    span = np.where(np.isfinite(span) & (span > 0), span, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.minimum(0.1 * tip_step / reach, 0.1 * span)
    h = np.where(np.isfinite(h) & (h > 0), h, 1e-3 * span)

    def second_difference(d):
        dq = S @ d
        qp, qm = q.copy(), q.copy()
        qp[model.free] += dq
        qm[model.free] -= dq
        return model.residual(qp, u + d) + model.residual(qm, u - d)

    # a slack cable's column is its taut one (see _taut), which a small step does not follow: no curvature
    slack = model.slack(q) if hasattr(model, "slack") else np.zeros(n, dtype=bool)
    zero = np.zeros(S.shape[0])
    diag = [zero if slack[i] else second_difference(h[i] * np.eye(n)[i]) for i in range(n)]
    cols = []
    for i in range(n):
        for j in range(i, n):
            if slack[i] or slack[j]:
                cols.append(zero)
            elif i == j:
                cols.append(diag[i] / h[i] ** 2)
            else:
                d = np.zeros(n)
                d[i], d[j] = h[i], h[j]
                cols.append((second_difference(d) - diag[i] - diag[j]) / (2.0 * h[i] * h[j]))
    if not cols:
        return np.zeros((0, S.shape[0]), dtype=np.float32)
    B = np.column_stack(cols)
    Q = -fac.solve(B)
    if K is not None:
        Q = Q - fac.solve(B + K @ Q)
    if not np.all(np.isfinite(Q)):
        Q = np.zeros_like(Q)
    return np.ascontiguousarray(Q.T, dtype=np.float32)


def second_order(Q: np.ndarray, du: np.ndarray) -> np.ndarray:
    """Q(du, du) / 2 on the free dofs: the second-order term of the predictor q + S du (see :func:`curvature`)."""
    n = du.size
    i, j = np.triu_indices(n)
    w = np.where(i == j, 0.5, 1.0) * du[i] * du[j]
    return w @ Q.astype(float) if Q.size else np.zeros(Q.shape[1])


def bounded_step(A: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """du minimising |A du - r| with lo <= du <= hi (bounded linear least squares).

    An active-set method (Lawson and Hanson's, with both bounds) for the few actuators of a robot: it
    costs ~50 us where scipy's ``lsq_linear`` costs ~0.8 ms, and the method calls it for every target.
    Where the minimiser is not unique (more actuators than 3), the free part is the least-norm one.
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[1]
    lo, hi = np.asarray(lo, dtype=float), np.minimum(np.maximum(hi, lo), np.inf)
    free = hi > lo
    first = None
    if n and free.all():
        # the first least-squares problem of the loop below, on its own: most targets are met inside the box
        # (the exploration's neighbouring cells), and the loop's set-up costs more than this solve
        first = np.linalg.lstsq(A, r, rcond=None)[0]
        if np.all(first >= lo) and np.all(first <= hi):
            return first
    x = np.clip(np.zeros(n), lo, hi)
    if n == 0:
        return x
    tol = 1e-12 * max(1.0, float(np.abs(A.T @ r).max()) if r.size else 1.0)
    for _ in range(10 * n + 10):
        # inner loop: least squares on the free variables, stepping back to the box when it leaves it
        for _ in range(n + 1):
            if not free.any():
                break
            z = x.copy()
            if first is not None:  # all free, x = 0: r - A[:, ~free] @ x[~free] is r
                z[free], first = first, None
            else:
                z[free] = np.linalg.lstsq(A[:, free], r - A[:, ~free] @ x[~free], rcond=None)[0]
            if np.all(z[free] >= lo[free]) and np.all(z[free] <= hi[free]):
                x = z
                break
            d = z - x
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(d < 0, (lo - x) / d, np.where(d > 0, (hi - x) / d, np.inf))
            t = np.where(free, t, np.inf)
            k = int(np.argmin(t))
            x = np.clip(x + max(0.0, min(1.0, t[k])) * d, lo, hi)
            x[k] = lo[k] if d[k] < 0 else hi[k]
            free[k] = False
        # KKT at the bounds: a fixed variable whose gradient points into the box is freed
        g = A.T @ (A @ x - r)
        want = np.where(~free & (x <= lo) & (hi > lo), -g, 0.0) + np.where(~free & (x >= hi) & (hi > lo), g, 0.0)
        k = int(np.argmax(want))
        if want[k] <= tol:
            return x
        free[k] = True
    return x


def distance_below(A: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray, y: np.ndarray) -> float:
    """A lower bound on the Euclidean distance from r to the set {A du : lo <= du <= hi}: the distance from r
    to the plane normal to y that has the whole set on its other side (-inf or nan, no bound, where the set is
    unbounded along y). With y = r - A du at :func:`bounded_step`'s answer it is that distance, to rounding;
    with any other y it is still a bound, so a caller can rely on it whether or not the active-set loop
    converged."""
    norm = float(np.linalg.norm(y))
    if norm == 0.0:
        return 0.0
    g = np.asarray(A, dtype=float).T @ y
    with np.errstate(invalid="ignore"):
        support = float(np.sum(np.where(g > 0, g * hi, g * lo)))  # max of y . A du over the box
    return (float(y @ r) - support) / norm


def closest_to_box(A: np.ndarray, r: np.ndarray, lo: np.ndarray, hi: np.ndarray, half_width: float):
    """du (lo <= du <= hi) bringing A du as near as possible to the box r +- half_width (a grid cell around
    r), with the distance left: min |A du - (r + w)| over du and |w_i| <= half_width, a bounded linear
    least-squares problem in (du, w). Where A du can enter the box the minimiser is not unique: the
    least-norm one is the smallest input change that does. Returns ``(du, gap)``, gap the infinity-norm
    distance from A du to the box (0 inside it)."""
    A = np.asarray(A, dtype=float)
    n = A.shape[1]
    h = np.full(3, float(half_width))
    x = bounded_step(np.hstack([A, -np.eye(3)]), r, np.concatenate([lo, -h]), np.concatenate([hi, h]))
    du = x[:n]
    gap = max(0.0, float(np.abs(A @ du - r).max()) - half_width)
    return du, gap


def limited_step(A, r, lo, hi, G, g_lo, g_hi, du):
    """``du`` (a step within lo <= du <= hi), or, if it breaks a linearised state limit g_lo <= G du <= g_hi
    (rows: the limited actuators' quantities, G = dQ/du), the closest step that keeps them: min |A du - r|
    over the box and the limits (SLSQP, a few actuators only; called only when a limit is hit)."""
    G = np.atleast_2d(np.asarray(G, dtype=float))
    if G.size == 0:
        return du
    slack = 1e-9 * np.maximum(1.0, np.abs(G).sum(axis=1) * np.abs(du).max())
    if np.all(G @ du >= g_lo - slack) and np.all(G @ du <= g_hi + slack):
        return du
    from scipy.optimize import minimize

    cons = [{"type": "ineq", "fun": (lambda x, i=i: G[i] @ x - g_lo[i]), "jac": (lambda x, i=i: G[i])}
            for i in range(G.shape[0]) if np.isfinite(g_lo[i])]
    cons += [{"type": "ineq", "fun": (lambda x, i=i: g_hi[i] - G[i] @ x), "jac": (lambda x, i=i: -G[i])}
             for i in range(G.shape[0]) if np.isfinite(g_hi[i])]
    res = minimize(lambda x: 0.5 * float(np.sum((A @ x - r) ** 2)), np.zeros_like(du),
                   jac=lambda x: A.T @ (A @ x - r), bounds=list(zip(lo, hi)), constraints=cons, method="SLSQP",
                   options={"ftol": 1e-14, "maxiter": 200})
    return np.clip(res.x, lo, hi)
