"""Constitutive laws, written once per element in CasADi SX on an element type's quadrature.

Each law is a function of one element only:

    f_e = element_force(u_e, X_e, G_e, p_e)

with ``u_e`` the displacements of the element's nodes (n_dof = 3 n_nodes), ``X_e`` their rest positions
relative to the first node (n_dof), ``G_e`` the rest gradients of the shape functions at each quadrature
point (n_qp x n_nodes x 3, row-major) and ``p_e = [w_1 .. w_nqp, mu, lambda]`` with w_k the quadrature
weights in m^3 (for the linear tetrahedron: its volume). The sizes come from the
:class:`casadi_ws.fem.elements.ElementType`. Displacements and element-local coordinates, not absolute
positions: x - X would lose ~1e-16 |X| to round-off, which under small loads is larger than the residual
tolerance. Rest quantities are inputs, not constants, so one small SX graph serves every element: it is
then evaluated over the mesh and assembled with constant index maps (see :mod:`casadi_ws.fem.model`).
Building the stiffness by AD through an MX map of the whole mesh is ~100x slower; differentiating this
small SX graph is cheap.

Laws
----
``linear``        small-strain Hooke, f = Ke (x - X).
``corotational``  SOFA TetrahedronFEMForceField "large": the element frame is built from the corner edges
                  ab and ac by Gram-Schmidt, and f = R^T Ke_loc (R x - R0 X), i.e. Ke applied in the
                  rotated frame. A quadratic element takes the rotation at each quadrature point: the
                  polar rotation of the deformation gradient there.
``neohookean``    compressible, W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .elements import TET4, ElementType

__all__ = ["MATERIAL_MODELS", "Material", "element_functions", "lame"]

MATERIAL_MODELS = ("linear", "corotational", "neohookean")


@dataclass(frozen=True)
class Material:
    """Material of the whole body (SI units)."""

    model: str = "corotational"
    """One of ``linear``, ``corotational``, ``neohookean``."""
    young_modulus: float = 1.8e7
    """Young's modulus E in Pa."""
    poisson_ratio: float = 0.45
    """Poisson ratio nu, in (-1, 0.5)."""
    density: float = 1000.0
    """Mass density in kg/m^3 (used for gravity only)."""
    max_stretch: float | None = None
    """Largest principal stretch the material takes before it tears (an admissibility limit); None: none."""

    @property
    def lame(self) -> tuple[float, float]:
        return lame(self.young_modulus, self.poisson_ratio)


def lame(E: float, nu: float) -> tuple[float, float]:
    """(mu, lambda) from Young's modulus and Poisson ratio."""
    mu = E / (2.0 * (1.0 + nu))
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return mu, lam


def _linear_force(d, G, V0, mu, lam):
    """Small-strain force of displacements ``d`` (4x3, a row per node)."""
    grad = ca.mtimes(d.T, G)  # du_i/dX_j
    eps = 0.5 * (grad + grad.T)
    sigma = lam * ca.trace(eps) * ca.SX.eye(3) + 2 * mu * eps
    return V0 * ca.mtimes(G, sigma)  # 4x3, row a = V0 sigma g_a


def _frame(x):
    """SOFA's 'large' element frame: rows are the local axes built from edges ab, ac."""
    return _frame_of_edges(x[1, :] - x[0, :], x[2, :] - x[0, :])


def _frame_of_edges(ex, ey):
    """Rows: the axes built from two edge vectors (rows) by Gram-Schmidt."""
    ez = ca.cross(ex, ey)
    ey = ca.cross(ez, ex)
    ex = ex / ca.norm_2(ex)
    ey = ey / ca.norm_2(ey)
    ez = ez / ca.norm_2(ez)
    return ca.vertcat(ex, ey, ez)


def _polar_rotation(F, iterations: int = 5):
    """The rotation of the polar decomposition F = R U, by Newton's iteration R <- (R + R^-T) / 2 from F.
    It converges quadratically: from a strain of 10 % five steps reach round-off. R^-T is the cofactor
    matrix over the determinant (cheap in SX, unlike a general inverse)."""
    R = F
    for _ in range(iterations):
        c0, c1, c2 = R[:, 0], R[:, 1], R[:, 2]
        cof = ca.horzcat(ca.cross(c1, c2), ca.cross(c2, c0), ca.cross(c0, c1))
        R = 0.5 * (R + cof / ca.dot(c0, ca.cross(c1, c2)))
    return R


def _polar_corotational_stress(F, mu, lam):
    """First Piola-Kirchhoff stress Q sigma(sym(Q^T F) - I) with Q the polar rotation of F."""
    Q = _polar_rotation(F)
    grad = ca.mtimes(Q.T, F) - ca.SX.eye(3)  # displacement gradient in the rotated frame
    eps = 0.5 * (grad + grad.T)
    return ca.mtimes(Q, lam * ca.trace(eps) * ca.SX.eye(3) + 2 * mu * eps)


def _neohookean_stress(F, mu, lam):
    """First Piola-Kirchhoff stress of the compressible neo-Hookean law."""
    Finv_T = ca.inv(F).T
    return mu * (F - Finv_T) + lam * ca.log(ca.det(F)) * Finv_T


def _hessian_vector_by_quadrature_point(stress, u, lam_e, Gs, ws, mu, lam):
    """d(K_e^T lam_e)/du_e for a law P(F) summed over quadrature points, built in F-space.

    f_e = sum_k w_k G_k P(F_k)^T, so K_e^T lam_e = sum_k w_k G_k (dg_k/dF)^T with g_k = Lam_k : P(F) and
    Lam_k = lam_e^T G_k, and its derivative is sum_k w_k B_k^T (d2 g_k/dF2) B_k with B_k = dvec(F_k)/du_e.
    Differentiating the element's 30 outputs twice through the polar iteration instead made 166 MB of C for
    a corotational 10-node element, too large to compile; this is 2.8 MB and equal to round-off (and the
    neo-Hookean graph builds in a fraction of the time).
    """
    Fv, Lv = ca.SX.sym("F", 9), ca.SX.sym("Lam", 9)
    m, l = ca.SX.sym("mu"), ca.SX.sym("lam")
    g = ca.dot(Lv, ca.vec(stress(ca.reshape(Fv, 3, 3), m, l)))
    d2g = ca.Function("d2g", [Fv, Lv, m, l], [ca.hessian(g, Fv)[0]])
    nn = u.shape[0]
    H = 0
    for G, w in zip(Gs, ws):
        F = ca.SX.eye(3) + ca.mtimes(u.T, G)
        B = ca.SX.zeros(9, 3 * nn)  # vec(F)[i + 3 J] = sum_b u[b, i] G[b, J]; u_e[3 b + i] = u[b, i]
        for b in range(nn):
            for i in range(3):
                for J in range(3):
                    B[i + 3 * J, 3 * b + i] = G[b, J]
        N = d2g(ca.vec(F), ca.vec(ca.mtimes(lam_e.T, G)), mu, lam)
        H = H + w * ca.mtimes(B.T, ca.mtimes(N, B))
    return H


def _element_force(model: str, u, X, Gs, ws, mu, lam):
    """Nodal forces (n_nodes x 3) summed over the quadrature points (gradients ``Gs``, weights ``ws``)."""
    if model == "linear":
        return sum(_linear_force(u, G, w, mu, lam) for G, w in zip(Gs, ws))
    if model == "corotational" and len(Gs) == 1:
        Q = ca.mtimes(_frame(X + u).T, _frame(X))  # rotation rest -> current
        d = ca.mtimes(X, Q - ca.SX.eye(3)) + ca.mtimes(u, Q)  # rows: Q^T x_a - X_a
        return ca.mtimes(sum(_linear_force(d, G, w, mu, lam) for G, w in zip(Gs, ws)), Q.T)  # rows: Q f_a
    if model == "corotational":
        # a curved (quadratic) element turns by different amounts across it: the rotation is taken at each
        # quadrature point, as the polar rotation of the deformation gradient there (an edge-based frame
        # would lag the material by O(strain), which biases the rotated-back force by O(strain) relative)
        f = 0
        for G, w in zip(Gs, ws):
            F = ca.SX.eye(3) + ca.mtimes(u.T, G)
            f = f + w * ca.mtimes(G, _polar_corotational_stress(F, mu, lam).T)  # rows: w P g_a
        return f
    if model == "neohookean":
        return sum(_neohookean_force(u, G, w, mu, lam) for G, w in zip(Gs, ws))
    raise ValueError(f"unknown material model {model!r}; expected one of {MATERIAL_MODELS}")


def _neohookean_force(u, G, V0, mu, lam):
    F = ca.SX.eye(3) + ca.mtimes(u.T, G)
    return V0 * ca.mtimes(G, _neohookean_stress(F, mu, lam).T)


def element_functions(model: str, element: ElementType = TET4, hessian: bool = True) -> dict[str, ca.Function]:
    """SX functions of one element of type ``element`` for the material ``model``.

    Returns ``force`` (f_e, n_dof), ``stiffness`` (vec of df_e/dx_e, n_dof^2, column-major) and
    ``hessian_vector`` (vec of d(K_e^T lam_e)/du_e, n_dof^2: the element's share of the Hessian of
    lam^T f_int, needed by the full-space NLP; only with ``hessian``). Inputs: u_e (n_dof), X_e (n_dof, relative to node 0),
    G_e (n_qp * n_dof), p_e = [w_1 .. w_nqp, mu, lambda]. Node-major layout: entry 3*a + i is coordinate
    i of node a.
    """
    nd, nn, nq = element.n_dof, element.n_nodes, element.n_qp
    xv = ca.SX.sym("u", nd)
    Xv = ca.SX.sym("X", nd)
    Gv = ca.SX.sym("G", nq * nd)
    p = ca.SX.sym("p", nq + 2)
    lam_e = ca.SX.sym("lam", nd)
    x = ca.reshape(xv, 3, nn).T
    X = ca.reshape(Xv, 3, nn).T
    Gs = [ca.reshape(Gv[k * nd:(k + 1) * nd], 3, nn).T for k in range(nq)]
    ws = [p[k] for k in range(nq)]
    f = ca.densify(ca.reshape(_element_force(model, x, X, Gs, ws, p[nq], p[nq + 1]).T, nd, 1))
    K = ca.jacobian(f, xv)
    ins = [xv, Xv, Gv, p]
    names = ["u", "X", "G", "p"]
    tag = f"{element.name}_{model}" if element is not TET4 else model  # tet4 keeps its compiled kernels' names
    out = {
        "force": ca.Function(f"{tag}_force", ins, [f], names, ["f"]),
        "stiffness": ca.Function(f"{tag}_stiffness", ins, [ca.densify(ca.reshape(K, nd * nd, 1))], names, ["K"]),
    }
    if hessian:
        stress = {"corotational": _polar_corotational_stress, "neohookean": _neohookean_stress}.get(model)
        if stress is not None and nq > 1:  # (a 4-node corotational element turns with its edges, not F)
            Hv = _hessian_vector_by_quadrature_point(stress, x, ca.reshape(lam_e, 3, nn).T, Gs, ws, p[nq],
                                                     p[nq + 1])
        else:
            Hv = ca.jacobian(ca.mtimes(K.T, lam_e), xv)
        out["hessian_vector"] = ca.Function(f"{tag}_hessian_vector", ins + [lam_e],
                                            [ca.densify(ca.reshape(Hv, nd * nd, 1))], names + ["lam"], ["H"])
    return out


def rest_geometry(X: np.ndarray, element: ElementType = TET4) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature weights in m^3 (m, n_qp) and shape-function gradients (m, n_qp, n_nodes, 3) of the
    elements ``X`` (m, n_nodes, 3); for the linear tetrahedron the weight is the volume."""
    return element.rest_geometry(X)
