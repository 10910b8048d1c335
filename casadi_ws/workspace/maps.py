"""What each reported point is worth: maps over the workspace, from the LU and sensitivities a method holds.

``effort``         RMS of the inputs, each as a fraction of its largest magnitude max(|u_min|, |u_max|):
                   0 at rest, 1 with every actuator at its extreme.
``steerability``   the smallest singular value of A = dp/du (m per input unit): how far the tip moves for
                   the worst-steered unit change of the inputs there; 0 where a direction cannot be steered.
``compliance``     the largest eigenvalue of the symmetric part of the tip compliance C K^-1 C^T (m/N): how
                   far the tip moves per newton of external load in its softest direction (1 / the
                   stiffness a task feels there). The full 3 x 3 matrix is kept in result.npz.
``tilt``           the angle (degrees) between the tip's axis now and at rest (:mod:`casadi_ws.fem.frame`: the
                   normal of the problem's three ``frame`` points, or the direction from the supports'
                   centroid to the rest tip turned by the tip elements' rotation); ``axis_x/y/z``: that axis
                   now (unit vector); ``roll`` (degrees): the tip frame's twist about its rest axis.
``contact``        the magnitude of the total force (N) the obstacles exert on the body (summed over those it
                   presses on; 0 without obstacles or out of contact).
``state1..n``      each actuator's quantity (a cable's length, m; a cavity's volume, m^3).
"""

from __future__ import annotations

import numpy as np

from ..fem.spec import ranged_inputs
from ..solvers.sensitivity import tip_compliance

__all__ = ["MAPS", "effort", "point_maps"]

MAPS = ("effort", "steerability", "compliance", "tilt", "roll", "axis_x", "axis_y", "axis_z", "contact")
"""The scalar maps, in the column order of points.csv."""


def effort(model, u) -> np.ndarray:
    """(k,) the inputs' RMS fraction of their largest magnitude (see the module docstring)."""
    scale = np.maximum(np.abs(model.u_min), np.abs(model.u_max))
    scale = np.where(scale > 0, scale, 1.0)
    u = np.atleast_2d(u)
    if not u.shape[1]:
        return np.zeros(len(u))
    return np.sqrt(np.mean((u / scale) ** 2, axis=1))


def direction(model, q) -> np.ndarray:
    """The tip's axis now (unit vector, :meth:`casadi_ws.fem.frame.TipFrame.axis`)."""
    return model.tip_frame.axis(q)


def point_maps(model, q, u, A, fac, G=None) -> dict:
    """The maps at one verified equilibrium (q, u) with its sensitivity A and an LU of its tangent (or the
    tip's compliance G = C K^-1 C^T, 3 x 3, already solved with it: ``sensitivity(..., compliance=True)``)."""
    s = np.linalg.svd(A, compute_uv=False) if A is not None and A.size else np.zeros(1)
    if G is None:
        G = tip_compliance(model, fac)
    ranged = ranged_inputs(model.u_min, model.u_max)
    det = float(np.linalg.det(A[:, ranged])) if A is not None and ranged.size == 3 else np.nan
    return {**state_maps(model, q, u), "steerability": float(s.min()),
            "compliance": float(np.linalg.eigvalsh(0.5 * (G + G.T)).max()), "compliance_matrix": G, "det_A": det}


def state_maps(model, q, u) -> dict:
    """The maps that need no LU: effort, the tip's orientation (tilt, roll, axis, ``direction``), contact, and the
    actuators' states."""
    o = model.tip_frame.orientation(q)
    d = o["direction"]
    # the obstacles that points press on (the others' forces are the smoothing's ~eps^2 / (kappa g))
    contact = sum(np.linalg.norm(c["force"]) for c in model.contacts(q) if c["points"]) if getattr(model, "has_contact", False) else 0.0
    return {"effort": float(effort(model, u)[0]), "tilt": o["tilt"], "roll": o["roll"], "axis_x": float(d[0]),
            "axis_y": float(d[1]), "axis_z": float(d[2]), "contact": float(contact), "direction": d,
            "states": model.actuator_states(q), "intensities": model.intensities(q, u)}


def stack(maps: list[dict], n_u: int) -> dict:
    """Arrays from a list of :func:`point_maps` dicts (None: a point without maps, NaN there)."""
    k = len(maps)
    out = {name: np.full(k, np.nan) for name in MAPS}
    out["compliance_matrix"] = np.full((k, 3, 3), np.nan)
    out["direction"] = np.full((k, 3), np.nan)
    out["states"] = np.full((k, n_u), np.nan)
    out["intensities"] = np.full((k, n_u), np.nan)
    out["det_A"] = np.full(k, np.nan)  # det dp/du over the 3 inputs with a range: its sign shows a fold
    for i, m in enumerate(maps):
        if m is None:
            continue
        for key in out:
            out[key][i] = m.get(key, np.nan)
    return out
