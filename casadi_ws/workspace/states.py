"""The robot's state at some reported points of a finished run, solved again where the run did not keep it.

A run keeps no nodal states by default (``store_states``: 8 B per dof and point, 90 MB for 10^4 points of the
2646-dof trunk). What the report needs is the deformed robot at the points a user clicks: a subset, solved again
after the run from the nearest state already known (rest first), and kept only where the solved state's tip is
the reported point -- so a drawn robot is one the run reported, not a neighbour on another branch.
"""

from __future__ import annotations

import numpy as np

from ..solvers.equilibrium import admissible_guess, quasi_static, settle, solve_equilibrium, tangent_factorization
from ..solvers.sensitivity import sensitivity

__all__ = ["SAME_TIP", "states_at"]

SAME_TIP = 1e-6
"""Largest distance (m) between a re-solved state's tip and the reported point for the state to be kept: two
verified equilibria at one input on one branch differ by the solver's tolerance (~1e-9 m on the trunk)."""


def states_at(model, result, indices) -> tuple[np.ndarray, np.ndarray]:
    """(the indices among ``indices`` whose state was found, their states (k, n_dof)).

    Each point is solved at its inputs from the nearest point solved before it (in inputs scaled by U's span;
    rest before any), points nearest rest first, so each solve is a short step; where the answer's tip is not
    the reported point (:data:`SAME_TIP`) the path from rest (:func:`quasi_static`, the definition of a reported
    point) is tried, and where that misses too the point gets no state."""
    indices = np.asarray(indices, dtype=int)
    U = np.asarray(result.u, float)[indices]
    P = np.asarray(result.points, float)[indices]
    span = np.where(model.u_max > model.u_min, model.u_max - model.u_min, 1.0)
    X = (U - model.u_min) / span
    done_x, done = [np.clip(-model.u_min / span, 0.0, 1.0)], [None]  # rest: u = 0, or U's point nearest it
    found, states = [], []
    for k in np.argsort(np.abs(X - done_x[0]).max(axis=1), kind="stable"):
        start = done[int(np.argmin(np.abs(np.array(done_x) - X[k]).max(axis=1)))]
        if start is None:
            eq = settle(model, solve_equilibrium(model, U[k]), None)
        else:
            q0, u0, S = start
            guess = q0.copy()  # first order, dq = S du: a Newton of ~2 LUs instead of ~4 (trunk_2cables)
            guess[model.free] += S @ (U[k] - u0)
            eq = solve_equilibrium(model, U[k], q0=q0, u0=u0, guess=guess if admissible_guess(model, guess) else None)
            eq = settle(model, eq, q0)
        if not (eq.converged and np.linalg.norm(eq.tip - P[k]) <= SAME_TIP):
            eq = quasi_static(model, U[k])
        if eq.converged and np.linalg.norm(eq.tip - P[k]) <= SAME_TIP:
            found.append(indices[k])
            states.append(eq.q)
            done_x.append(X[k])
            fac = eq.factorization or tangent_factorization(model, eq.q, eq.u)
            S = sensitivity(model, eq.q, fac, K=model.tangent(eq.q, eq.u))[1]
            done.append((eq.q, eq.u, S.astype(np.float32)))  # a predictor's: single precision halves the memory
    order = np.argsort(found)
    n_dof = model.n_dof
    return (np.asarray(found, dtype=int)[order],
            np.asarray(states, float).reshape(-1, n_dof)[order])
