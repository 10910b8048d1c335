"""Constitutive laws, written once per element in CasADi SX on an element type's quadrature.

Each law is a function of one element only:

    f_e = element_force(u_e, X_e, G_e, p_e)

with ``u_e`` the displacements of the element's nodes (n_dof = 3 n_nodes), ``X_e`` their rest positions
relative to the first node (n_dof), ``G_e`` the rest gradients of the shape functions at each quadrature
point (n_qp x n_nodes x 3, row-major) and ``p_e = [w_1 .. w_nqp, mu, lambda]`` (or a strain-energy law's
constants, see below) with w_k the quadrature
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

The silicone laws are strain-energy densities in Abaqus' convention (the one datasheets and published fits
use), with I1b = J^(-2/3) I1 and I2b = J^(-4/3) I2 the invariants of the isochoric part and K the bulk
modulus (Abaqus' D1 = 2 / K):

``mooney_rivlin``  W = C10 (I1b - 3) + C01 (I2b - 3) + K/2 (J - 1)^2;    mu0 = 2 (C10 + C01)
``yeoh``           W = sum_i Ci0 (I1b - 3)^i (i = 1..3) + K/2 (J - 1)^2;  mu0 = 2 C10
``ogden``          W = sum_i 2 mu_i / alpha_i^2 (l1b^a_i + l2b^a_i + l3b^a_i - 3) + K/2 (J - 1)^2;  mu0 = sum mu_i
                   with lkb the isochoric principal stretches. They are the square roots of the eigenvalues of
                   Cb = J^(-2/3) C, from the trigonometric closed form with two regularisations (see
                   :func:`_isochoric_eigenvalues`): smooth where eigenvalues coincide (at rest, in uniaxial
                   tension), with exact derivatives of that smooth function, and within ~1e-7 of the exact
                   energy and stress.

Their parameters are [constants..., K]; the others' are [mu, lambda] (Lame, from E and nu).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .elements import TET4, ElementType

__all__ = ["HYPERELASTIC_CONSTANTS", "MATERIAL_MODELS", "Material", "element_functions", "hyperelastic", "lame"]

HYPERELASTIC_CONSTANTS = {"mooney_rivlin": ("c10", "c01"), "yeoh": ("c10", "c20", "c30"), "ogden": ("mu", "alpha")}
"""The constants of each strain-energy law, in the order of the kernel's parameters; K follows them. Ogden's
are lists of N terms: mu_i (Pa) and alpha_i (dimensionless)."""
MAX_OGDEN_TERMS = 6
FORMULATIONS = ("displacement", "mixed", "taylor_hood")
MATERIAL_MODELS = ("linear", "corotational", "neohookean", *HYPERELASTIC_CONSTANTS)


@dataclass(frozen=True)
class Material:
    """Material of the whole body (SI units)."""

    model: str = "corotational"
    """One of :data:`MATERIAL_MODELS`."""
    young_modulus: float = 1.8e7
    """Young's modulus E in Pa. For a strain-energy law: the small-strain modulus its constants give,
    9 K mu0 / (3 K + mu0) (set by :func:`hyperelastic`)."""
    poisson_ratio: float = 0.45
    """Poisson ratio nu, in (-1, 0.5). For a strain-energy law: its small-strain value,
    (3 K - 2 mu0) / (2 (3 K + mu0))."""
    density: float = 1000.0
    """Mass density in kg/m^3 (used for gravity only)."""
    max_stretch: float | None = None
    """Largest principal stretch the material takes before it tears (an admissibility limit); None: none."""
    constants: tuple = ()
    """A strain-energy law's constants, (name, value) pairs in Pa: those of :data:`HYPERELASTIC_CONSTANTS`
    and ``bulk_modulus``. Empty for the laws given by E and nu; a strain-energy law given E and nu only
    takes its neo-Hookean member (C10 = mu/2, the others 0; Ogden: one term, alpha = 2)."""
    formulation: str = "displacement"
    """How a strain-energy law's volumetric term is integrated: ``displacement`` (at every quadrature point)
    , ``mixed`` (a constant pressure per element, condensed on the element: the mean dilatation, which does
    not lock on 10-node tetrahedra as nu -> 0.5) or ``taylor_hood`` (a pressure continuous across elements,
    linear on each 10-node tetrahedron, one unknown per corner node: :class:`casadi_ws.fem.terms.pressure.
    ContinuousPressure`). The laws given by E and nu take ``displacement``."""

    def __post_init__(self):
        if self.model in HYPERELASTIC_CONSTANTS and not self.constants:
            # a strain-energy law given by E and nu only: its neo-Hookean member (c10 = mu/2, or one Ogden
            # term mu, alpha = 2) with the same small-strain E and nu
            mu, lam = self.lame
            c = {"ogden": (("mu", (mu,)), ("alpha", (2.0,)))}.get(
                self.model, tuple((k, mu / 2 if k == "c10" else 0.0) for k in HYPERELASTIC_CONSTANTS[self.model]))
            object.__setattr__(self, "constants", c + (("bulk_modulus", lam + 2 * mu / 3),))

    @property
    def lame(self) -> tuple[float, float]:
        return lame(self.young_modulus, self.poisson_ratio)

    @property
    def parameters(self) -> np.ndarray:
        """The element kernel's material parameters: [mu, lambda], or a strain-energy law's constants then
        its bulk modulus."""
        if self.model in HYPERELASTIC_CONSTANTS:
            c = dict(self.constants)
            values = [np.atleast_1d(c[k]) for k in HYPERELASTIC_CONSTANTS[self.model]]
            return np.concatenate(values + [[c["bulk_modulus"]]]).astype(float)
        return np.array(self.lame, dtype=float)

    @property
    def kernel(self) -> str:
        """The name of its element kernels: the law, with Ogden's number of terms (``ogden3``)."""
        name = f"ogden{len(dict(self.constants)['mu'])}" if self.model == "ogden" else self.model
        if self.model not in HYPERELASTIC_CONSTANTS or self.formulation == "displacement":
            return name
        return name + ("_mixed" if self.formulation == "mixed" else "_iso")


def initial_shear_modulus(model: str, constants: dict) -> float:
    """mu0 of a strain-energy law's constants (Abaqus' convention)."""
    if model == "mooney_rivlin":
        return 2.0 * (constants["c10"] + constants["c01"])
    if model == "yeoh":
        return 2.0 * constants["c10"]
    if model == "ogden":
        return float(np.sum(constants["mu"]))
    raise ValueError(f"{model!r} is not a strain-energy law; expected one of {', '.join(HYPERELASTIC_CONSTANTS)}")


def hyperelastic(model: str, bulk_modulus: float | None = None, poisson_ratio: float | None = None,
                 density: float = 1000.0, max_stretch: float | None = None, formulation: str = "displacement",
                 **constants: float) -> Material:
    """A :class:`Material` of a strain-energy law from its constants (Pa; missing ones are 0) and its
    compressibility: ``bulk_modulus`` K (Pa), or the small-strain ``poisson_ratio`` (K = 2 mu0 (1 + nu) /
    (3 (1 - 2 nu))); neither: nu = 0.45, what the elements here take without locking."""
    names = HYPERELASTIC_CONSTANTS.get(model)
    if names is None:
        raise ValueError(f"{model!r} is not a strain-energy law; expected one of {', '.join(HYPERELASTIC_CONSTANTS)}")
    unknown = set(constants) - set(names)
    if unknown:
        raise ValueError(f"{model} takes the constants {', '.join(names)}, not {', '.join(sorted(unknown))}")
    if model == "ogden":
        mu, alpha = (tuple(float(x) for x in np.atleast_1d(constants.get(k, ()))) for k in names)
        if not 1 <= len(mu) <= MAX_OGDEN_TERMS or len(alpha) != len(mu):
            raise ValueError(f"ogden: give mu and alpha as lists of the same length, 1 to {MAX_OGDEN_TERMS} terms "
                             f"(got {len(mu)} and {len(alpha)})")
        if any(a == 0 for a in alpha):
            raise ValueError("ogden: every alpha must be nonzero")
        c = {"mu": mu, "alpha": alpha}
    else:
        c = {k: float(constants.get(k, 0.0)) for k in names}
    mu0 = initial_shear_modulus(model, c)
    if not mu0 > 0:
        raise ValueError(f"{model}: the initial shear modulus mu0 = {mu0:g} Pa must be positive")
    if bulk_modulus is not None and poisson_ratio is not None:
        raise ValueError("give bulk_modulus or poisson_ratio, not both")
    if bulk_modulus is None:
        nu = 0.45 if poisson_ratio is None else float(poisson_ratio)
        bulk_modulus = 2.0 * mu0 * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu))
    K = float(bulk_modulus)
    E = 9.0 * K * mu0 / (3.0 * K + mu0)
    nu = (3.0 * K - 2.0 * mu0) / (2.0 * (3.0 * K + mu0))
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation: expected one of {', '.join(FORMULATIONS)}, got {formulation!r}")
    return Material(model, E, nu, density, max_stretch, tuple(c.items()) + (("bulk_modulus", K),), formulation)


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


def _skew(v):
    """[v]x: the matrix of v x (.)."""
    return ca.vertcat(ca.horzcat(0, -v[2], v[1]), ca.horzcat(v[2], 0, -v[0]), ca.horzcat(-v[1], v[0], 0))


def _frame_corotational_stiffness(u, X, G, V0, mu, lam):
    """df/du (12 x 12, node-major) of the 4-node corotational force, in closed form.

    Why: differentiating the force whole cost 5702 instructions per element; the 4-node trunk's tangent is
    a quarter of its forward-backward's kernels. With Q the rotation rest -> current and h_a = Q g_a,
    f_a = sum_b K_ab (x_b - Q X_b) with K_ab = V0 (lam h_a h_b^T + mu ((g_a.g_b) I + h_b h_a^T)), Q Ke Q^T
    blockwise. A variation turns the frame by w (dQ = [w]x Q), so df_a = sum_b K_ab (dx_b + [x_b]x w)
    - [f_a]x w. The frame's axes follow the edges e1 = x_1 - x_0, e2 = x_2 - x_0 by Gram-Schmidt:
    w.ez = ey.de1 / |e1|, w.ey = -ez.de1 / |e1|, w.ex = (|e1| ez.de2 - (e2.ex) ez.de1) / (|e1| e2.ey).
    Equal to the Jacobian of the force to round-off (tests/test_model.py)."""
    x = X + u  # rows: positions relative to node 0 at rest
    Rc = _frame(x)
    Q = ca.mtimes(Rc.T, _frame(X))
    Hg = ca.mtimes(G, Q.T)  # rows h_a
    ex, ey, ez = Rc[0, :].T, Rc[1, :].T, Rc[2, :].T
    e1, e2 = (x[1, :] - x[0, :]).T, (x[2, :] - x[0, :]).T
    l1, c, s = ca.norm_2(e1), ca.dot(e2, ex), ca.dot(e2, ey)
    W1 = ca.mtimes(ez, ey.T) / l1 - ca.mtimes(ey, ez.T) / l1 - c / (l1 * s) * ca.mtimes(ex, ez.T)
    W2 = ca.mtimes(ex, ez.T) / s
    W = [-(W1 + W2), W1, W2]  # dw/dx_b of nodes 0, 1, 2 (node 3 does not turn the frame)
    blocks = [[None] * 4 for _ in range(4)]
    for a in range(4):
        for b in range(a, 4):  # K_ba = K_ab^T
            blocks[a][b] = V0 * (lam * ca.mtimes(Hg[a, :].T, Hg[b, :]) + mu * ca.mtimes(Hg[b, :].T, Hg[a, :])
                                 + mu * ca.dot(G[a, :], G[b, :]) * ca.SX.eye(3))
            blocks[b][a] = blocks[a][b].T
    xr = x - ca.mtimes(X, Q.T)  # rows x_b - Q X_b
    K = []
    for a in range(4):
        f_a = sum(ca.mtimes(blocks[a][b], xr[b, :].T) for b in range(4))
        M = sum(ca.mtimes(blocks[a][b], _skew(x[b, :])) for b in range(4)) - _skew(f_a)
        K.append(ca.horzcat(*[blocks[a][b] + (ca.mtimes(M, W[b]) if b < 3 else 0) for b in range(4)]))
    return ca.vertcat(*K)


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


def _polar_corotational_tangent(F, mu, lam):
    """dvec P / dvec F (9 x 9) of :func:`_polar_corotational_stress`, in closed form.

    Why: differentiating the five polar iterations cost 7422 instructions per point, this 2305, and the
    10-node corotational stiffness is most of an assembled tangent. With F = R U, R^T dR = W is skew and
    W U + U W = 2 skew(R^T dF) gives its axial vector w = (tr U I - U)^-1 axial(R^T dF - dF^T R); then
    dP = dR sigma + R sigma(sym(R^T dF - W R^T F)). Equal to the derivative of the iteration to round-off
    wherever the iteration has converged (tests/test_model.py: 1e-12 against the whole element's Jacobian)."""
    R = _polar_rotation(F)
    RtF = ca.mtimes(R.T, F)
    grad = RtF - ca.SX.eye(3)
    eps = 0.5 * (grad + grad.T)
    sigma = lam * ca.trace(eps) * ca.SX.eye(3) + 2 * mu * eps
    U = 0.5 * (RtF + RtF.T)
    dFv = ca.SX.sym("dF", 9)
    A = ca.mtimes(R.T, ca.reshape(dFv, 3, 3))
    skew = A - A.T
    w = ca.mtimes(ca.inv(ca.trace(U) * ca.SX.eye(3) - U), ca.vertcat(skew[2, 1], skew[0, 2], skew[1, 0]))
    W = ca.vertcat(ca.horzcat(0, -w[2], w[1]), ca.horzcat(w[2], 0, -w[0]), ca.horzcat(-w[1], w[0], 0))
    dgrad = A - ca.mtimes(W, RtF)
    deps = 0.5 * (dgrad + dgrad.T)
    dP = ca.mtimes(ca.mtimes(R, W), sigma) + ca.mtimes(R, lam * ca.trace(deps) * ca.SX.eye(3) + 2 * mu * deps)
    return ca.jacobian(ca.vec(dP), dFv)  # dP is linear in dF: the Jacobian is its coefficients


def _neohookean_stress(F, mu, lam):
    """First Piola-Kirchhoff stress of the compressible neo-Hookean law."""
    Finv_T = ca.inv(F).T
    return mu * (F - Finv_T) + lam * ca.log(ca.det(F)) * Finv_T


def _isochoric_invariants(F):
    """(I1b, I2b) of the deformation gradient F."""
    J = ca.det(F)
    C = ca.mtimes(F.T, F)
    I1 = ca.trace(C)
    I2 = 0.5 * (I1**2 - ca.trace(ca.mtimes(C, C)))
    return J ** (-2.0 / 3.0) * I1, J ** (-4.0 / 3.0) * I2


def _mooney_rivlin_energy(F, p):
    I1b, I2b = _isochoric_invariants(F)
    return p[0] * (I1b - 3) + p[1] * (I2b - 3)


def _yeoh_energy(F, p):
    I1b, _ = _isochoric_invariants(F)
    return p[0] * (I1b - 3) + p[1] * (I1b - 3) ** 2 + p[2] * (I1b - 3) ** 3


_EIG_A, _EIG_D = 1e-12, 1e-8


def _isochoric_eigenvalues(F):
    """The eigenvalues of Cb = J^(-2/3) F^T F (and J), smooth where they coincide.

    c_k = (I1 + 2 sqrt(a) cos((phi + 2 pi k) / 3)) / 3, phi = atan2(sqrt(4 a^3 - b^2), b), with a = 3/2
    tr(D^2) and b = 27 det(D) of the deviator D = Cb - I1/3 (computed from D, not from the invariants, which
    cancel catastrophically at small strains). Two regularisations keep every derivative finite: a + 1e-12
    (at rest a = 0, and sqrt' is infinite) and 4 a^3 - b^2 + 1e-8 (a + 1e-12)^3 (zero where two eigenvalues
    coincide, as in uniaxial tension, and relative so that it is scale-free). Their derivatives vanish at
    those states, so the stress there is right; they move the energy by ~1e-8 relative (measured: the energy
    within 6e-8 and the stress within 5e-7 of numpy's eigenvalues at stretches up to 3, the Hessian equal
    to finite differences of the stress to 5e-9)."""
    J = ca.det(F)
    Cb = J ** (-2.0 / 3.0) * ca.mtimes(F.T, F)
    I1 = ca.trace(Cb)
    D = Cb - I1 / 3 * ca.SX.eye(3)
    a = 1.5 * ca.trace(ca.mtimes(D, D))
    b = 27 * ca.det(D)
    ar = a + _EIG_A
    phi = ca.atan2(ca.sqrt(4 * a**3 - b**2 + _EIG_D * ar**3), b)
    return [(I1 + 2 * ca.sqrt(ar) * ca.cos((phi + 2 * np.pi * k) / 3)) / 3 for k in range(3)], J


def _ogden_energy(F, p):
    n = (p.numel() - 1) // 2
    c, _ = _isochoric_eigenvalues(F)
    W = 0
    for i in range(n):
        mu, alpha = p[i], p[n + i]
        W += 2 * mu / alpha**2 * (sum(ck ** (alpha / 2) for ck in c) - 3)
    return W


_ENERGIES = {"mooney_rivlin": _mooney_rivlin_energy, "yeoh": _yeoh_energy, "ogden": _ogden_energy}


def _law(kernel: str) -> tuple[str, int, str]:
    """(law, number of material parameters, volumetric part) of a kernel name (``ogden3``: Ogden with 3
    terms; ``yeoh_mixed``: Yeoh with a constant pressure per element, volumetric part "mixed"; ``yeoh_iso``:
    its isochoric part only, "iso", the pressure being a term of the model's; else "")."""
    mixed = next((v for v in ("mixed", "iso") if kernel.endswith("_" + v)), "")
    kernel = kernel.removesuffix("_" + mixed) if mixed else kernel
    if kernel.startswith("ogden") and kernel[5:].isdigit():
        return "ogden", 2 * int(kernel[5:]) + 1, mixed
    if kernel in HYPERELASTIC_CONSTANTS:
        return kernel, len(HYPERELASTIC_CONSTANTS[kernel]) + 1, mixed
    return kernel, 2, mixed


def n_parameters(kernel: str) -> int:
    """Length of the material part of a kernel's parameter vector."""
    return _law(kernel)[1]


def _energy_stress(kernel: str, volumetric: bool = True):
    """P(F, p) = dW/dF of a strain-energy law, as a function of SX arguments (inlined when called): the
    isochoric part, plus the volumetric one K (J - 1) J F^-T at the point if ``volumetric``."""
    law, npar, _ = _law(kernel)
    Fv, p = ca.SX.sym("F", 3, 3), ca.SX.sym("p", npar)
    W = _ENERGIES[law](Fv, p)
    if volumetric:
        W += 0.5 * p[npar - 1] * (ca.det(Fv) - 1) ** 2
    P = ca.Function(f"{kernel}_stress{'' if volumetric else '_iso'}", [Fv, p],
                    [ca.reshape(ca.gradient(W, ca.vec(Fv)), 3, 3)])
    return lambda F, *params: P(F, ca.vertcat(*params))


def _mean_dilatation_force(u, Gs, ws, K):
    """The volumetric forces of K/2 (Jbar - 1)^2 V_e, Jbar = sum_k w_k J_k / V_e the element's mean
    dilatation: the mixed displacement-pressure element with a constant pressure per element, the pressure
    p = K (Jbar - 1) condensed on the element. f = sum_k w_k p J_k G_k F_k^-1."""
    Fs = [ca.SX.eye(3) + ca.mtimes(u.T, G) for G in Gs]
    Js = [ca.det(F) for F in Fs]
    V = sum(ws)
    p = K * (sum(w * J for w, J in zip(ws, Js)) / V - 1)
    return sum(w * p * J * ca.mtimes(G, ca.inv(F)) for G, w, F, J in zip(Gs, ws, Fs, Js))


def _point_stress(model: str, n_qp: int):
    """The stress P(F, *params) whose quadrature-point sum is the element's force (the isochoric part of a
    mixed law), or None where the force is not such a sum in F: the linear law, and the 4-node corotational
    element, which turns with its edges, not with F (its stiffness is written out whole:
    :func:`_frame_corotational_stiffness`). A 4-node neo-Hookean element is also taken whole: one point,
    nothing to gain, and its compiled kernels stay as they were."""
    law, _, mixed = _law(model)
    if law in _ENERGIES:
        return _energy_stress(model, volumetric=not mixed)
    if n_qp == 1:
        return None
    return {"corotational": _polar_corotational_stress, "neohookean": _neohookean_stress}.get(model)


def _stiffness_by_quadrature_point(stress, u, Gs, ws, *params, tangent=None):
    """K_e = sum_k w_k B_k^T (dvec P/dvec F)(F_k) B_k for f_e = sum_k w_k B_k^T vec P(F_k), B_k = dvec(F_k)/du_e.

    The same matrix as the Jacobian of the element's forces, to round-off, at a fraction of the work: the
    9 x 9 tangent of the stress is differentiated once per point (or given in closed form: ``tangent``),
    and B_k is sparse. Differentiating the 30 forces through the polar iteration instead cost 33 us per
    corotational 10-node element, this 13 us (tests/test_model.py compares the two). Every law built
    here has an energy, so K_e is symmetric: its upper triangle is computed and mirrored (a fifth fewer
    instructions; the lower one differed by round-off)."""
    Fv = ca.SX.sym("F", 9)
    ps = [ca.SX.sym(f"p{i}") for i in range(len(params))]
    F = ca.reshape(Fv, 3, 3)
    dP = ca.Function("dP", [Fv, *ps], [tangent(F, *ps) if tangent else ca.jacobian(ca.vec(stress(F, *ps)), Fv)])
    K = 0
    for G, w in zip(Gs, ws):
        B = _dF_du(G)
        K = K + w * ca.mtimes(B.T, ca.mtimes(dP(ca.vec(ca.SX.eye(3) + ca.mtimes(u.T, G)), *params), B))
    return _symmetric(K)


def _symmetric(K):
    """K's upper triangle mirrored: the entries below the diagonal are those above (the same SX nodes, so
    the generated code computes each once)."""
    return ca.densify(ca.triu(K) + ca.triu(K, False).T)


def _hessian_vector_by_quadrature_point(stress, u, lam_e, Gs, ws, *params):
    """d(K_e^T lam_e)/du_e for a law P(F) summed over quadrature points, built in F-space.

    f_e = sum_k w_k G_k P(F_k)^T, so K_e^T lam_e = sum_k w_k G_k (dg_k/dF)^T with g_k = Lam_k : P(F) and
    Lam_k = lam_e^T G_k, and its derivative is sum_k w_k B_k^T (d2 g_k/dF2) B_k with B_k = dvec(F_k)/du_e.
    Differentiating the element's 30 outputs twice through the polar iteration instead made 166 MB of C for
    a corotational 10-node element, too large to compile; this is 2.8 MB and equal to round-off (and the
    neo-Hookean graph builds in a fraction of the time).
    """
    Fv, Lv = ca.SX.sym("F", 9), ca.SX.sym("Lam", 9)
    ps = [ca.SX.sym(f"p{i}") for i in range(len(params))]
    g = ca.dot(Lv, ca.vec(stress(ca.reshape(Fv, 3, 3), *ps)))
    d2g = ca.Function("d2g", [Fv, Lv, *ps], [ca.hessian(g, Fv)[0]])
    H = 0
    for G, w in zip(Gs, ws):
        F = ca.SX.eye(3) + ca.mtimes(u.T, G)
        B = _dF_du(G)
        N = d2g(ca.vec(F), ca.vec(ca.mtimes(lam_e.T, G)), *params)
        H = H + w * ca.mtimes(B.T, ca.mtimes(N, B))
    return H


def _dF_du(G):
    """B = dvec(F)/du_e of F = I + u^T G (constant in u): vec(F)[i + 3 J] = sum_b u[b, i] G[b, J] and
    u_e[3 b + i] = u[b, i]."""
    nn = G.shape[0]
    B = ca.SX.zeros(9, 3 * nn)
    for b in range(nn):
        for i in range(3):
            for J in range(3):
                B[i + 3 * J, 3 * b + i] = G[b, J]
    return B


def _mean_dilatation_hessian_vector(u, lam_e, Gs, ws, K):
    """d(K_vol^T lam_e)/du_e of the mean-dilatation term, in closed form.

    With a = sum_k w_k J_k, g = da/du, M = d2a/du2 (symmetric) and p = K (a/V - 1): f = p g,
    K_vol = K/V g g^T + p M, and d(K_vol^T lam)/du = K/V (M (g.lam) + g (M lam)^T + (M lam) g^T)
    + p d(M lam)/du, the last a sum over the points of B^T (d2(Lam : dJ/dF)/dF2) B (J is cubic in F, so this
    is constant in F). Differentiating the 30 forces twice instead made a 1.7M-node graph (too large to
    compile); this one is small."""
    V = sum(ws)
    Fv, Lv = ca.SX.sym("F", 9), ca.SX.sym("Lam", 9)
    J = ca.det(ca.reshape(Fv, 3, 3))
    dJ = ca.gradient(J, Fv)
    fun = ca.Function("dJ", [Fv, Lv], [dJ, ca.hessian(J, Fv)[0], ca.hessian(ca.dot(Lv, dJ), Fv)[0]])
    a, g, M, T = 0, 0, 0, 0
    for G, w in zip(Gs, ws):
        F = ca.SX.eye(3) + ca.mtimes(u.T, G)
        B = _dF_du(G)
        dJk, HJk, Tk = fun(ca.vec(F), ca.vec(ca.mtimes(lam_e.T, G)))
        a += w * ca.det(F)
        g += w * ca.mtimes(B.T, dJk)
        M += w * ca.mtimes(B.T, ca.mtimes(HJk, B))
        T += w * ca.mtimes(B.T, ca.mtimes(Tk, B))
    lam = ca.vec(lam_e.T)  # node-major, as u_e
    Ml = ca.mtimes(M, lam)
    return K / V * (M * ca.dot(g, lam) + ca.mtimes(g, Ml.T) + ca.mtimes(Ml, g.T)) + K * (a / V - 1) * T


def _element_force(model: str, u, X, Gs, ws, *params):
    """Nodal forces (n_nodes x 3) summed over the quadrature points (gradients ``Gs``, weights ``ws``)."""
    law, _, mixed = _law(model)
    if law in _ENERGIES:
        stress = _energy_stress(model, volumetric=not mixed)
        f = sum(w * ca.mtimes(G, stress(ca.SX.eye(3) + ca.mtimes(u.T, G), *params).T) for G, w in zip(Gs, ws))
        return f + _mean_dilatation_force(u, Gs, ws, params[-1]) if mixed == "mixed" else f
    mu, lam = params
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
    """SX functions of one element of type ``element`` for the material ``model`` (a law, or the name of a
    law's kernel, :attr:`Material.kernel`: ``ogden3``).

    Returns ``force`` (f_e, n_dof), ``stiffness`` (vec of df_e/dx_e, n_dof^2, column-major) and
    ``hessian_vector`` (vec of d(K_e^T lam_e)/du_e, n_dof^2: the element's share of the Hessian of
    lam^T f_int, needed by the full-space NLP; only with ``hessian``). Inputs: u_e (n_dof), X_e (n_dof, relative to node 0),
    G_e (n_qp * n_dof), p_e = [w_1 .. w_nqp, material parameters] (:attr:`Material.parameters`). Node-major layout: entry 3*a + i is coordinate
    i of node a.
    """
    nd, nn, nq = element.n_dof, element.n_nodes, element.n_qp
    xv = ca.SX.sym("u", nd)
    Xv = ca.SX.sym("X", nd)
    Gv = ca.SX.sym("G", nq * nd)
    npar = n_parameters(model)
    p = ca.SX.sym("p", nq + npar)
    lam_e = ca.SX.sym("lam", nd)
    x = ca.reshape(xv, 3, nn).T
    X = ca.reshape(Xv, 3, nn).T
    Gs = [ca.reshape(Gv[k * nd:(k + 1) * nd], 3, nn).T for k in range(nq)]
    ws = [p[k] for k in range(nq)]
    params = [p[nq + i] for i in range(npar)]
    f = ca.densify(ca.reshape(_element_force(model, x, X, Gs, ws, *params).T, nd, 1))
    stress = _point_stress(model, nq)
    if model == "corotational" and nq == 1:
        K = _frame_corotational_stiffness(x, X, Gs[0], ws[0], *params)
    elif stress is None:
        K = ca.jacobian(f, xv)
    else:
        tangent = _polar_corotational_tangent if model == "corotational" else None
        K = _stiffness_by_quadrature_point(stress, x, Gs, ws, *params, tangent=tangent)
        if _law(model)[2] == "mixed":  # the volumetric part couples the points
            f_vol = ca.reshape(_mean_dilatation_force(x, Gs, ws, params[-1]).T, nd, 1)
            K = _symmetric(K + ca.jacobian(f_vol, xv))
    ins = [xv, Xv, Gv, p]
    names = ["u", "X", "G", "p"]
    tag = f"{element.name}_{model}" if element is not TET4 else model  # tet4 keeps its compiled kernels' names
    out = {
        "force": ca.Function(f"{tag}_force", ins, [f], names, ["f"]),
        "stiffness": ca.Function(f"{tag}_stiffness", ins, [ca.densify(ca.reshape(K, nd * nd, 1))], names, ["K"]),
    }
    if hessian:
        if stress is not None:
            Hv = _hessian_vector_by_quadrature_point(stress, x, ca.reshape(lam_e, 3, nn).T, Gs, ws, *params)
            if _law(model)[2] == "mixed":  # the volumetric part couples the points
                Hv += _mean_dilatation_hessian_vector(x, ca.reshape(lam_e, 3, nn).T, Gs, ws, params[-1])
        else:
            Hv = ca.jacobian(ca.mtimes(K.T, lam_e), xv)
        out["hessian_vector"] = ca.Function(f"{tag}_hessian_vector", ins + [lam_e],
                                            [ca.densify(ca.reshape(Hv, nd * nd, 1))], names + ["lam"], ["H"])
    return out


def rest_geometry(X: np.ndarray, element: ElementType = TET4) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature weights in m^3 (m, n_qp) and shape-function gradients (m, n_qp, n_nodes, 3) of the
    elements ``X`` (m, n_nodes, 3); for the linear tetrahedron the weight is the volume."""
    return element.rest_geometry(X)
