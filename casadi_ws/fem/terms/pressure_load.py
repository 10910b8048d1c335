"""A uniform pressure on part of the boundary, following the surface as it deforms (:class:`PressureLoad`, phase
``applied``): SOFA's ``SurfacePressureForceField``; an object or a fluid pushing on a membrane.

A pressure p on the deformed face pushes each of its nodes by

    f_a = -p  integral  N_a n da = -p  integral  N_a (x_xi x x_eta) dxi deta

(n out of the body: p > 0 pushes in). Its tangent -p d/dx of that is not symmetric on an open surface (the
load follows the surface but has no potential; on a closed one the non-symmetric parts cancel and it is a
cavity's p d2V/dq2), so the model's tangent is factorised as unsymmetric and its stability judged as the
corotational law's (docs/methods.md "Stability"). The integral is Radon's 7-point rule, exact for the 6-node
faces of 10-node tetrahedra (degree 4) and for flat ones. The load scales with a continuation's load factor.

A worked example of a term (docs/methods.md "How to add a term"): the problem-file key ``pressure_loads``
(:func:`casadi_ws.io.problem.problem_from_dict`), one :class:`PressureLoad` per entry in ``ModelSpec.terms``;
the SOFA importer maps ``SurfacePressureForceField`` to it.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ...actuation.cavity import _QP, _QW, _triangle6_basis
from ..kernels import ElementBatch
from .base import Term, tangent_data

__all__ = ["PressureLoad", "face_force_function"]


def _basis(n: int, xi: float, eta: float):
    if n == 6:
        return _triangle6_basis(xi, eta)
    return (np.array([1 - xi - eta, xi, eta]), np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]))


def face_force_function(n: int) -> ca.Function:
    """g(x) = integral N_a (x_xi x x_eta) dxi deta of a face of n = 3 or 6 nodes (x: 3n positions, node-major;
    g: 3n), with dg/dx (3n x 3n, column-major) and, given lam (3n), d(dg/dx^T lam)/dx: the face's nodal forces
    per unit pressure (times -1), their tangent and its Hessian share."""
    x = ca.SX.sym("x", 3 * n)
    lam = ca.SX.sym("lam", 3 * n)
    X = ca.reshape(x, 3, n)
    g = ca.SX.zeros(3 * n)
    for (xi, eta), w in zip(_QP, _QW):
        N, dN = _basis(n, xi, eta)
        t1 = X @ ca.DM(dN[:, 0])
        t2 = X @ ca.DM(dN[:, 1])
        a = ca.cross(t1, t2)
        g += w * ca.vec(a @ ca.DM(N).T)
    J = ca.jacobian(g, x)
    H = ca.jacobian(ca.mtimes(J.T, lam), x)
    return (ca.Function(f"face_force{n}", [x], [g, ca.densify(ca.vec(J))]),
            ca.Function(f"face_force_hessian{n}", [x, lam], [ca.densify(ca.vec(H))]))


@dataclass(eq=False)
class PressureLoad(Term):
    """A pressure ``pressure`` (Pa) on the boundary ``faces`` ((k, 3) or (k, 6) node indices, oriented out of
    the body)."""

    faces: np.ndarray
    pressure: float
    """Pa; positive pushes into the body."""
    name: str = "pressure_load"

    phase = "applied"
    negatives = 0  # no unknowns; its unsymmetric part is judged as the corotational tangent's

    def setup(self, model, pos):
        faces = np.asarray(self.faces, dtype=np.int64)
        n = faces.shape[1]
        self._dofs = (3 * faces[:, :, None] + np.arange(3)).reshape(len(faces), 3 * n)
        fun, hess = face_force_function(n)
        backend = "casadi" if model.backend == "casadi" else "auto"
        self._force = ElementBatch(fun, backend)
        self._hess = ElementBatch(hess, backend)
        p = pos[self._dofs]  # (k, 3n) free positions, -1 held
        rows = np.repeat(p[:, None, :], 3 * n, axis=1)  # (face, column j, row i): row dof i
        cols = np.repeat(p[:, :, None], 3 * n, axis=2)
        self._keep = ((rows >= 0) & (cols >= 0)).reshape(-1)
        self._keys = (cols.reshape(-1) * model.n_free + rows.reshape(-1))[self._keep]

    def _faces(self, model, q):
        return (model.X + q)[self._dofs]

    def forces(self, model, s):
        g, J = self._force(self._faces(model, s.q))
        if s.tangent:
            s.memo[self] = J
        f = np.zeros(model.n_dof)
        np.add.at(f, self._dofs.ravel(), g.ravel())
        return (s.load * self.pressure) * f

    def pattern(self, model, pos):
        return self._keys

    def add_tangent(self, model, s, cache, data):
        J = s.memo.get(self)
        if J is None:
            J = self._force(self._faces(model, s.q))[1]
        data = tangent_data(model, data)
        data[: model.nnz] += np.bincount(model.slots(self._keys), weights=(s.load * self.pressure) *
                                         J.reshape(-1)[self._keep], minlength=model.nnz)
        return data

    def hessian(self, model, q, u, lam):
        lam_full = np.zeros(model.n_dof)
        lam_full[model.free] = lam
        H = self._hess(self._faces(model, q), lam_full[self._dofs])[0]
        data = self.pressure * H.reshape(-1)[self._keep]
        n = model.n_free
        return sp.csc_matrix((data, (self._keys % n, self._keys // n)), shape=(n, n))

    @property
    def tangent_from_residual(self):
        return False
