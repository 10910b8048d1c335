"""The workspace's boundary surface as data: :class:`Boundary` (what :mod:`.boundary` builds and a result
file holds) and the signed distance of points to it. Apart from :mod:`.boundary` so that the result files can
read a boundary back without importing the methods that build one."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..fem.surface import signed_distance, winding_numbers

__all__ = ["Boundary", "distance_outside"]


@dataclass
class Boundary:
    """A triangulated boundary of the workspace (or, for 2 inputs, the workspace surface itself)."""

    vertices: np.ndarray
    """(k, 3) tip positions, m."""
    triangles: np.ndarray
    """(t, 3) vertex indices, counter-clockwise seen from outside (closed surfaces)."""
    u: np.ndarray
    """(k, n_u) the inputs of the vertices."""
    method: str
    """``input-faces`` (a closed surface: the faces' images), ``input-cells`` (a closed surface: the union of
    the images of U's grid cells, built where the map folds, :mod:`.images`), ``input-patch`` (2 inputs: the
    surface W) or ``none``."""
    closed: bool = False
    """Every edge is shared by exactly two triangles, traversed once each way."""
    volume: float | None = None
    """Enclosed volume, m^3 (closed surfaces)."""
    volume_error: float | None = None
    """|volume - the volume through every other node|, m^3."""
    area: float = 0.0
    """Surface area, m^2."""
    tolerance: float = 0.0
    """Estimated largest distance between the triangles and the true boundary, m."""
    curve: np.ndarray | None = None
    """2 inputs: the boundary curve p(dU) as a closed polyline of vertex indices."""
    violations: np.ndarray | None = None
    """Admissibility bit mask of each vertex (:mod:`casadi_ws.solvers.admissible`)."""
    failed: int = 0
    """Face nodes whose equilibrium could not be verified (then there is no surface)."""
    notes: list = field(default_factory=list)
    """Plain-language caveats (non-closed surface, inadmissible vertices, sign changes of det A)."""
    counters: dict = field(default_factory=dict)
    """Face nodes solved here (``solved_nodes``; ``seeded_nodes`` of them started from a configuration the
    method reached, :class:`Seeds`) and taken from the method's own points (``known_nodes``), and LU
    factorisations."""
    checks: dict = field(default_factory=dict)
    """Results of checking the surface against the method's points (``points_outside``, ``max_outside``)."""
    fold: dict = field(default_factory=dict)
    """Where det dp/du changes sign (3 inputs): ``positive`` / ``negative`` samples of it (face nodes, the
    method's configurations) or turned-over tetrahedra of a forward grid, ``inputs`` (up to 8 inputs next to a
    sign change), ``jacobian_integral`` (m^3, an upper bound of the volume), ``turned_over`` / ``tetrahedra``
    of the grid the surface was built on. Empty: no fold seen."""

    @property
    def encloses(self) -> bool:
        """A closed surface with a volume (``input-faces`` or ``input-cells``)."""
        return self.method in ("input-faces", "input-cells") and self.closed

    def check_points(self, points) -> dict:
        """How many of ``points`` lie outside the closed surface by more than its tolerance (every verified
        point lies in W, so any is a defect of the surface); stored in :attr:`checks`."""
        if not self.encloses or not len(points):
            return {}
        d = distance_outside(self, points)
        self.checks = {"points_checked": int(len(points)),
                       "points_outside": int(np.count_nonzero(d > self.tolerance)),
                       "max_outside": float(max(d.max(), 0.0))}
        if self.checks["points_outside"]:
            self.notes.append(f"{self.checks['points_outside']} of {len(points)} verified points lie outside the "
                              f"surface by more than its tolerance {self.tolerance * 1e3:.3g} mm (at most "
                              f"{self.checks['max_outside'] * 1e3:.3g} mm)")
        return self.checks

    def summary(self) -> dict:
        return {**self.checks, **self.counters, "method": self.method, "closed": self.closed, "volume": self.volume,
                "volume_error": self.volume_error, "area": self.area, "tolerance": self.tolerance,
                "vertices": int(len(self.vertices)), "triangles": int(len(self.triangles)),
                "inadmissible_vertices": int(np.count_nonzero(self.violations)) if self.violations is not None
                else 0, "failed_nodes": self.failed, "notes": list(self.notes),
                **({"fold": self.fold} if self.fold else {})}


def distance_outside(b: Boundary, points) -> np.ndarray:
    """Signed distance of each point to a closed, outward-oriented surface (> 0 outside), m. VTK's sign comes
    from the nearest triangle's normal, which is wrong next to a sharp crease (the union of a folded map's
    images has many: 460 of 2000 points inside read as outside on tests/test_folds.py's map); the points it
    puts outside are settled by their winding number."""
    d = signed_distance(b.vertices, b.triangles, points)
    out = np.flatnonzero(d > 0)
    if len(out):
        inside = np.abs(winding_numbers(b.vertices, b.triangles, np.asarray(points, float)[out])) > 0.5
        d[out[inside]] *= -1.0
    return d
