"""Equilibrium solvers: Newton with continuation, casadi.rootfinder, sensitivities, bounded least squares."""

from .equilibrium import (Branch, Equilibrium, Factorization, factorize, quasi_static, solve_equilibrium,
                          tangent_factorization, verify)
from .rootfinder import equilibrium_function, release_rootfinders
from .sensitivity import bounded_step, sensitivity

__all__ = ["Branch", "Equilibrium", "Factorization", "bounded_step", "equilibrium_function", "factorize",
           "quasi_static", "release_rootfinders", "sensitivity", "solve_equilibrium", "tangent_factorization",
           "verify"]
