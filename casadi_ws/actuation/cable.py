"""Cable actuators: a polyline of passage points embedded in the mesh, pulled with tension u.

The cable's quantity is its length L(x) = sum of the segment lengths of the polyline (pull point, if any,
then the passage points), each passage point moving with its host element (embedded). A tension does work
by shortening the cable, so its force on the nodes is H(q)^T u with H = -dL/dq (sign -1 in
:class:`casadi_ws.actuation.base.Actuator`). This is SOFA's CableConstraint in force mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .base import Actuator

__all__ = ["Cable", "SHORT", "trunk_cable"]

SHORT = 1e-2
"""A cable segment shorter than this share of its rest length has its length blended (:meth:`Cable.quantity`)."""


@dataclass
class Cable(Actuator):
    points: np.ndarray
    """Passage points at rest, (k, 3), metres, in order from the pulled end."""
    pull_point: np.ndarray | None = None
    """Fixed point in space the cable is pulled from (3,), or None."""
    u_min: float = 0.0
    """Lower bound of the tension, N."""
    u_max: float = 100.0
    """Upper bound of the tension, N."""
    name: str = "cable"
    stroke_max: float | None = None
    """Largest shortening of the cable from its rest length (the motor's stroke), m; None: unlimited."""
    nodes: np.ndarray | None = None
    """Mesh node of each passage point (k,), if the points were given as node indices (SOFA's
    ``indices``): they then move exactly with those nodes."""

    spread: float | None = None
    """Distance (m) over which each passage point's force is spread on the body's boundary nodes, weights
    falling linearly to zero at it (SOFA's CableConstraint ``centers``/``radii``, methods sphere and geodesic);
    None: the point is embedded in its host element."""

    control: str = "force"
    """``force``: u is the tension (N); ``displacement``: u is the shortening L0 - L (m) the motor imposes,
    the tension an unknown >= 0 (a slack cable carries none), like SOFA's CableConstraint."""

    kind = "cable"
    intensity_unit = "N"
    unilateral = True
    quantity_name = "length"
    quantity_unit = "m"
    sign = -1.0

    @property
    def input_unit(self) -> str:
        return "m" if self.control == "displacement" else "N"

    def rest_points(self) -> np.ndarray:
        return np.asarray(self.points, dtype=float)

    def polyline(self) -> np.ndarray:
        pts = self.rest_points()
        if self.pull_point is None:
            return pts
        return np.vstack([np.asarray(self.pull_point, dtype=float)[None], pts])

    def quantity(self, P: ca.SX) -> ca.SX:
        """The length; a segment shorter than :data:`SHORT` of its rest length counts as
        (delta^2 + l^2) / (2 delta) (delta that share): where two passage points on facing walls of a groove
        meet as the groove closes (the SOFA Trunk's points sit on its disks' faces), the segment's direction
        would flip and its force with it; the blend keeps the length and its gradient continuous (it differs
        from l by at most delta / 2 there, and not at all beyond)."""
        pts = [P[3 * i:3 * i + 3] for i in range(P.numel() // 3)]
        if self.pull_point is not None:
            pts = [ca.DM(np.asarray(self.pull_point, dtype=float))] + pts
        rest = np.linalg.norm(np.diff(self.polyline(), axis=0), axis=1) if len(pts) == len(self.polyline()) \
            else np.zeros(len(pts) - 1)  # rest lengths unknown: no blend
        L = 0
        for a, b, l0 in zip(pts[:-1], pts[1:], rest):
            length, delta = ca.norm_2(b - a), SHORT * float(l0)
            L += ca.if_else(length < delta, (delta**2 + length**2) / (2 * delta), length) if delta > 0 else length
        return L

    def quantity_limits(self, rest: float) -> tuple[float, float, str]:
        return (-np.inf if self.stroke_max is None else rest - self.stroke_max), np.inf, "stroke"

    def describe(self) -> dict:
        return {**super().describe(), "stroke_max": self.stroke_max, "spread": self.spread,
                "nodes": None if self.nodes is None else np.asarray(self.nodes).tolist(),
                "pull_point": None if self.pull_point is None else np.asarray(self.pull_point, float).tolist()}


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
