"""One vocabulary of outcomes for every solve in casadi-ws: equilibria, backward problems, workspace points,
inverse control. A code is an integer (as result files store it) with a name (as JSON prints it).

====  ====================  ========================================================================
code  name                  meaning
====  ====================  ========================================================================
0     converged             verified: relative residual below tolerance and u inside U (for a
                            backward or reach solve: the answer is such an equilibrium)
1     max_iterations        Newton did not reach the tolerance in the allowed iterations
2     diverged              NaN/inf (e.g. an inverted element), a singular tangent, or the step
                            control failed
3     continuation_failed   load stepping could not reach the full load
4     outside_bounds        converged, but u lies outside [u_min, u_max]: not a valid point
5     iteration_limit       an optimiser (reduced backward, IPOPT) stopped before convergence; its
                            last iterate was verified and is returned
6     solve_failed          a backward or reach solve found no verified equilibrium to return
7     gave_up               reduced backward: the linearised closest point lies outside the target's
                            cell, so it stopped early; the last verified equilibrium is returned
8     not_reached           forward-backward: the verified answer lies outside the target's cell
9     prefiltered           forward-backward: not solved, the linearised closest point lies outside
                            the target's cell (see ``FBSettings.prefilter``)
10    inadmissible          a converged equilibrium that fails an admissibility check (unstable,
                            inverted, self-penetrating, beyond a state limit:
                            :mod:`casadi_ws.solvers.admissible`): counted and kept apart
====  ====================  ========================================================================

Codes 0-4 are an equilibrium's; 5-7 a backward or reach solve's; 8-9 a forward-backward target's; 10 any
method's. A point is reported only with code 0 and when admissible (or, with ``keep_inadmissible``, marked).
"""

from __future__ import annotations

from enum import IntEnum

__all__ = ["Status"]


class Status(IntEnum):
    """Outcome of a solve; see the module's table."""

    CONVERGED = 0
    MAX_ITERATIONS = 1
    DIVERGED = 2
    CONTINUATION_FAILED = 3
    OUTSIDE_BOUNDS = 4
    ITERATION_LIMIT = 5
    SOLVE_FAILED = 6
    GAVE_UP = 7
    NOT_REACHED = 8
    PREFILTERED = 9
    INADMISSIBLE = 10

    @property
    def label(self) -> str:
        """The name as result files and JSON print it (``converged``, ``not_reached``, ...)."""
        return self.name.lower()
