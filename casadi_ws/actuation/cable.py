"""Cable actuators: a polyline of passage points embedded in the mesh, pulled with tension u.

The cable length is L(x) = sum of the segment lengths of the polyline (pull point, if any, then the passage
points), each passage point moving with its host tetrahedron (barycentric embedding). The actuation force
on the nodes is H(q)^T u with H = -dL/dq: a tension shortens the cable. This is SOFA's CableConstraint in
force mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

__all__ = ["Cable", "cable_length_function", "cable_third_derivative_function", "trunk_cable"]


@dataclass
class Cable:
    points: np.ndarray
    """Passage points at rest, (k, 3), metres, in order from the pulled end."""
    pull_point: np.ndarray | None = None
    """Fixed point in space the cable is pulled from (3,), or None."""
    u_min: float = 0.0
    """Lower bound of the tension, N."""
    u_max: float = 100.0
    """Upper bound of the tension, N."""
    name: str = "cable"

    def polyline(self) -> np.ndarray:
        pts = np.asarray(self.points, dtype=float)
        if self.pull_point is None:
            return pts
        return np.vstack([np.asarray(self.pull_point, dtype=float)[None], pts])


def cable_length_function(n_points: int, has_pull_point: bool) -> ca.Function:
    """SX function of the passage point positions P (3k, point-major) -> (L, dL/dP, d2L/dP2).

    The pull point, when present, is a fixed parameter ``pull`` (3).
    """
    P = ca.SX.sym("P", 3 * n_points)
    pull = ca.SX.sym("pull", 3)
    pts = [P[3 * i:3 * i + 3] for i in range(n_points)]
    if has_pull_point:
        pts = [pull] + pts
    L = 0
    for a, b in zip(pts[:-1], pts[1:]):
        L += ca.norm_2(b - a)
    g = ca.gradient(L, P)
    Hs = ca.hessian(L, P)[0]
    return ca.Function("cable_length", [P, pull], [L, g, ca.densify(Hs)], ["P", "pull"], ["L", "dL", "d2L"])


def cable_third_derivative_function(n_points: int, has_pull_point: bool) -> ca.Function:
    """SX function (P, pull, mu) -> d2(mu . dL/dP)/dP2: the cable's share of a Lagrangian Hessian."""
    f = cable_length_function(n_points, has_pull_point)
    P = ca.SX.sym("P", 3 * n_points)
    pull = ca.SX.sym("pull", 3)
    mu = ca.SX.sym("mu", 3 * n_points)
    g = f(P, pull)[1]
    T = ca.hessian(ca.dot(mu, g), P)[0]
    return ca.Function("cable_third", [P, pull, mu], [ca.densify(T)], ["P", "pull", "mu"], ["T"])


def trunk_cable(angle_deg: float, kind: str = "long", radius: float = 0.010, taper: float = 8.0 / 195.0,
                z_start: float = 0.021, z_end: float | None = None, spacing: float = 0.009,
                u_min: float = 0.0, u_max: float = 100.0, name: str | None = None) -> Cable:
    """A cable routed along a trunk's axis (+z) like the SOFA trunk scene.

    The cable runs at ``angle_deg`` around the axis (0 deg = +x, 90 deg = +y), at ``radius`` from the axis at
    ``z_start``, moving inwards by ``taper`` per unit length; passage points every ``spacing`` up to
    ``z_end`` (default 0.184 m for ``long`` cables, near the tip, and 0.091 m for ``short`` ones, mid-length).
    It is pulled from the base plane z = 0 at the same angle and radius.
    """
    if kind not in ("long", "short"):
        raise ValueError(f"cable kind must be 'long' or 'short', got {kind!r}")
    if z_end is None:
        z_end = 0.184 if kind == "long" else 0.091
    n = max(2, int(round((z_end - z_start) / spacing)) + 1)
    z = np.linspace(z_start, z_end, n)
    r = radius - taper * (z - z_start)
    th = np.deg2rad(angle_deg)
    pts = np.stack([r * np.cos(th), r * np.sin(th), z], axis=1)
    pull = np.array([radius * np.cos(th), radius * np.sin(th), 0.0])
    return Cable(pts, pull, u_min, u_max, name or f"{kind}{int(round(angle_deg))}")
