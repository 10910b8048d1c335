"""Constitutive laws of a linear tetrahedron, written once per element in CasADi SX.

Each law is a function of one element only:

    f_e = element_force(u_e, X_e, G_e, p_e)

with ``u_e`` the displacements of the 4 nodes (12), ``X_e`` their rest positions relative to the first
node (12), ``G_e`` the rest gradients of the 4 shape functions (4x3, row-major, 12) and
``p_e = [V0, mu, lambda]``. Displacements and element-local coordinates, not absolute positions: x - X
would lose ~1e-16 |X| to round-off, which under small loads is larger than the residual tolerance. Rest
quantities are inputs, not constants, so one small SX graph serves every element: it is then mapped over
the mesh and assembled with constant index maps (see :mod:`casadi_ws.fem.model`). Building the stiffness by AD
through an MX map of the whole mesh is ~100x slower; differentiating this 12-input SX graph is cheap.

Laws
----
``linear``        small-strain Hooke, f = Ke (x - X).
``corotational``  SOFA TetrahedronFEMForceField "large": the element frame is built from edges ab and ac by
                  Gram-Schmidt, and f = R^T Ke_loc (R x - R0 X), i.e. Ke applied in the rotated frame.
``neohookean``    compressible, W = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

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
    ex = x[1, :] - x[0, :]
    ey = x[2, :] - x[0, :]
    ez = ca.cross(ex, ey)
    ey = ca.cross(ez, ex)
    ex = ex / ca.norm_2(ex)
    ey = ey / ca.norm_2(ey)
    ez = ez / ca.norm_2(ez)
    return ca.vertcat(ex, ey, ez)


def _element_force(model: str, u, X, G, V0, mu, lam):
    if model == "linear":
        return _linear_force(u, G, V0, mu, lam)
    if model == "corotational":
        Q = ca.mtimes(_frame(X + u).T, _frame(X))  # rotation rest -> current
        d = ca.mtimes(X, Q - ca.SX.eye(3)) + ca.mtimes(u, Q)  # rows: Q^T x_a - X_a
        return ca.mtimes(_linear_force(d, G, V0, mu, lam), Q.T)  # rows: Q f_a
    if model == "neohookean":
        F = ca.SX.eye(3) + ca.mtimes(u.T, G)
        J = ca.det(F)
        Finv_T = ca.inv(F).T
        P = mu * (F - Finv_T) + lam * ca.log(J) * Finv_T
        return V0 * ca.mtimes(G, P.T)
    raise ValueError(f"unknown material model {model!r}; expected one of {MATERIAL_MODELS}")


def element_functions(model: str) -> dict[str, ca.Function]:
    """SX functions of one element for ``model``.

    Returns ``force`` (f_e, 12), ``stiffness`` (vec of df_e/dx_e, 144, column-major) and
    ``hessian_vector`` (vec of d(K_e^T lam_e)/du_e, 144: the element's share of the Hessian of lam^T f_int,
    needed by the full-space NLP). Inputs: u_e (12), X_e (12, relative to node 0), G_e (12),
    p_e = [V0, mu, lambda] (3).
    Node-major layout: entry 3*a + i is coordinate i of node a.
    """
    xv = ca.SX.sym("u", 12)
    Xv = ca.SX.sym("X", 12)
    Gv = ca.SX.sym("G", 12)
    p = ca.SX.sym("p", 3)
    lam_e = ca.SX.sym("lam", 12)
    x = ca.reshape(xv, 3, 4).T
    X = ca.reshape(Xv, 3, 4).T
    G = ca.reshape(Gv, 3, 4).T
    f = ca.densify(ca.reshape(_element_force(model, x, X, G, p[0], p[1], p[2]).T, 12, 1))
    K = ca.jacobian(f, xv)
    Hv = ca.jacobian(ca.mtimes(K.T, lam_e), xv)
    ins = [xv, Xv, Gv, p]
    names = ["u", "X", "G", "p"]
    return {
        "force": ca.Function(f"{model}_force", ins, [f], names, ["f"]),
        "stiffness": ca.Function(f"{model}_stiffness", ins, [ca.densify(ca.reshape(K, 144, 1))], names, ["K"]),
        "hessian_vector": ca.Function(
            f"{model}_hessian_vector", ins + [lam_e], [ca.densify(ca.reshape(Hv, 144, 1))], names + ["lam"], ["H"]
        ),
    }


def rest_geometry(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rest volumes (m,) and shape-function gradients (m, 4, 3) of tetrahedra ``X`` (m, 4, 3)."""
    Dm = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2)  # columns = edges
    V0 = np.linalg.det(Dm) / 6.0
    Dinv = np.linalg.inv(Dm)  # rows: gradients of shape functions 1..3
    G = np.empty((X.shape[0], 4, 3))
    G[:, 1:] = Dinv
    G[:, 0] = -Dinv.sum(axis=1)
    return V0, G
