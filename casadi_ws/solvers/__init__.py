"""Equilibrium solvers: Newton with continuation, casadi.rootfinder, sensitivities, bounded least squares."""

from .equilibrium import Equilibrium, Factorization, factorize, solve_equilibrium, tangent_factorization, verify
from .rootfinder import equilibrium_function, release_rootfinders
from .sensitivity import bounded_step, sensitivity

__all__ = ["Equilibrium", "Factorization", "bounded_step", "equilibrium_function", "factorize",
           "release_rootfinders", "sensitivity", "solve_equilibrium", "tangent_factorization", "verify"]
