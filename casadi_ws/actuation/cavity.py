"""Pressure cavities: a closed triangulated surface on the body's boundary, inflated by a pressure u.

The cavity's quantity is its volume, by the divergence theorem over its oriented surface (normals out of
the cavity, into the solid):

    V = (1/3) sum_triangles  integral  x . n dA
      = (1/6) sum (x_a x x_b) . x_c                        for 3-node (flat) triangles
      = (1/3) sum  sum_k w_k x(xi_k) . (x_xi x x_eta)(xi_k)   for 6-node (curved) triangles, a 7-point rule
                                                           exact for the integrand's degree 4

A pressure p does the virtual work p dV, so its force on the nodes is p dV/dq (sign +1 in
:class:`casadi_ws.actuation.base.Actuator`) and its tangent stiffness p d2V/dq2: CasADi derives both, exactly,
from V, face by face (:meth:`Cavity.quantity_terms`). This is SOFA's SurfacePressureConstraint in pressure
mode. The surface's vertices are mesh nodes (``nodes``), so they move exactly with the body; with 10-node
tetrahedra the faces are 6-node triangles (VTK ``triangle6``: corners, then the mid-edge nodes of edges 01,
12, 20) and follow the body's quadratic displacement.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .base import Actuator

__all__ = ["Cavity", "surface_volume"]

# Radon's 7-point rule on the reference triangle (weights sum to 1: multiply by the area 1/2), degree 5
_A, _B = (6 - np.sqrt(15)) / 21, (6 + np.sqrt(15)) / 21
_WA, _WB = (155 - np.sqrt(15)) / 1200, (155 + np.sqrt(15)) / 1200
_QP = np.array([[1 / 3, 1 / 3], [_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A],
                [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]])
_QW = 0.5 * np.array([9 / 40, _WA, _WA, _WA, _WB, _WB, _WB])


def _triangle6_basis(xi: float, eta: float):
    """Shape functions of the 6-node triangle and their derivatives in (xi, eta) at one point."""
    l1, l2, l3 = 1 - xi - eta, xi, eta
    N = np.array([l1 * (2 * l1 - 1), l2 * (2 * l2 - 1), l3 * (2 * l3 - 1), 4 * l1 * l2, 4 * l2 * l3, 4 * l3 * l1])
    dl = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])  # d(l1, l2, l3)/d(xi, eta)
    L = (l1, l2, l3)
    dN = np.array([(4 * L[0] - 1) * dl[0], (4 * L[1] - 1) * dl[1], (4 * L[2] - 1) * dl[2],
                   4 * (L[0] * dl[1] + L[1] * dl[0]), 4 * (L[1] * dl[2] + L[2] * dl[1]),
                   4 * (L[2] * dl[0] + L[0] * dl[2])])
    return N, dN


_BASIS = [_triangle6_basis(*p) for p in _QP]


def surface_volume(X, triangles):
    """Volume enclosed by an oriented closed surface: X (k, 3) positions (numpy or a CasADi 3 x k matrix
    transposed by the caller), triangles (m, 3) or (m, 6) indices. Works on numpy arrays and CasADi SX."""
    triangles = np.asarray(triangles, dtype=np.int64)
    symbolic = isinstance(X, (ca.SX, ca.MX))
    row = (lambda i: X[i, :].T) if symbolic else (lambda i: np.asarray(X[i], dtype=float))
    cross = ca.cross if symbolic else np.cross
    dot = ca.dot if symbolic else np.dot
    V = 0
    if triangles.shape[1] == 3:
        for a, b, c in triangles:
            V += dot(cross(row(a), row(b)), row(c))
        return V / 6
    for tri in triangles:
        xs = [row(i) for i in tri]
        for (N, dN), w in zip(_BASIS, _QW):
            x = sum(N[j] * xs[j] for j in range(6))
            t1 = sum(dN[j, 0] * xs[j] for j in range(6))
            t2 = sum(dN[j, 1] * xs[j] for j in range(6))
            V += w * dot(x, cross(t1, t2))
    return V / 3


@dataclass
class Cavity(Actuator):
    points: np.ndarray
    """Rest positions (k, 3) of the surface's vertices, metres."""
    triangles: np.ndarray
    """(m, 3) or (m, 6) indices into ``points``, oriented with normals out of the cavity."""
    nodes: np.ndarray | None = None
    """Mesh node of each point (k,), if known: the points then move exactly with those nodes."""
    u_min: float = 0.0
    """Lower bound of the pressure, Pa (negative: vacuum)."""
    u_max: float = 1e4
    """Upper bound of the pressure, Pa."""
    name: str = "cavity"
    volume_max: float | None = None
    """Largest volume of the chamber (m^3) before it bursts; None: unlimited."""

    control: str = "pressure"
    """``pressure``: u is the pressure (Pa); ``volume``: u is the volume growth V - V0 (m^3), the pressure
    an unknown (SOFA's volumeGrowth)."""

    kind = "cavity"
    intensity_unit = "Pa"
    quantity_name = "volume"
    quantity_unit = "m^3"
    sign = 1.0

    @property
    def input_unit(self) -> str:
        return "m^3" if self.control == "volume" else "Pa"

    def rest_points(self) -> np.ndarray:
        return np.asarray(self.points, dtype=float)

    def quantity(self, P: ca.SX) -> ca.SX:
        k = P.numel() // 3
        return surface_volume(ca.reshape(P, 3, k).T, self.triangles)

    def quantity_terms(self):
        """The volume as a sum over the faces, each its own triangle's term of :func:`surface_volume`."""
        n = np.asarray(self.triangles).shape[1]
        x = ca.SX.sym("x", 3 * n)
        face = ca.Function("face_volume", [x], [surface_volume(ca.reshape(x, 3, n).T, np.arange(n)[None, :])])
        tri = np.asarray(self.triangles, dtype=np.int64)
        return face, (3 * tri[:, :, None] + np.arange(3)).reshape(len(tri), 3 * n)

    def rest_volume(self) -> float:
        return float(surface_volume(self.rest_points(), self.triangles))

    def quantity_limits(self, rest: float) -> tuple[float, float, str]:
        return -np.inf, (np.inf if self.volume_max is None else self.volume_max), "volume"

    def describe(self) -> dict:
        return {**super().describe(), "volume_max": self.volume_max, "triangles": np.asarray(self.triangles).tolist()}
