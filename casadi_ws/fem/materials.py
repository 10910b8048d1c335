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
            Q = _polar_rotation(F)
            grad = ca.mtimes(Q.T, F) - ca.SX.eye(3)  # displacement gradient in the rotated frame
            eps = 0.5 * (grad + grad.T)
            sigma = lam * ca.trace(eps) * ca.SX.eye(3) + 2 * mu * eps
            f = f + w * ca.mtimes(G, ca.mtimes(Q, sigma).T)  # rows: w (Q sigma) g_a
        return f
    if model == "neohookean":
        return sum(_neohookean_force(u, G, w, mu, lam) for G, w in zip(Gs, ws))
    raise ValueError(f"unknown material model {model!r}; expected one of {MATERIAL_MODELS}")


def _neohookean_force(u, G, V0, mu, lam):
    F = ca.SX.eye(3) + ca.mtimes(u.T, G)
    J = ca.det(F)
    Finv_T = ca.inv(F).T
    P = mu * (F - Finv_T) + lam * ca.log(J) * Finv_T
    return V0 * ca.mtimes(G, P.T)


def element_functions(model: str, element: ElementType = TET4, hessian: bool = True) -> dict[str, ca.Function]:
    """SX functions of one element of type ``element`` for the material ``model``.

    Returns ``force`` (f_e, n_dof), ``stiffness`` (vec of df_e/dx_e, n_dof^2, column-major) and
    ``hessian_vector`` (vec of d(K_e^T lam_e)/du_e, n_dof^2: the element's share of the Hessian of
    lam^T f_int, needed by the full-space NLP; only with ``hessian``: for a corotational 10-node element its
    graph takes seconds to build). Inputs: u_e (n_dof), X_e (n_dof, relative to node 0),
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
        Hv = ca.jacobian(ca.mtimes(K.T, lam_e), xv)
        out["hessian_vector"] = ca.Function(f"{tag}_hessian_vector", ins + [lam_e],
                                            [ca.densify(ca.reshape(Hv, nd * nd, 1))], names + ["lam"], ["H"])
    return out


def rest_geometry(X: np.ndarray, element: ElementType = TET4) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature weights in m^3 (m, n_qp) and shape-function gradients (m, n_qp, n_nodes, 3) of the
    elements ``X`` (m, n_nodes, 3); for the linear tetrahedron the weight is the volume."""
    return element.rest_geometry(X)
