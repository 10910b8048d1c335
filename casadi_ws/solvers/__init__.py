"""Equilibrium solvers: Newton with continuation, sensitivities, bounded linear least squares."""

from .equilibrium import Equilibrium, Factorization, factorize, solve_equilibrium, tangent_factorization, verify
from .sensitivity import bounded_step, sensitivity

__all__ = ["Equilibrium", "Factorization", "bounded_step", "factorize", "sensitivity", "solve_equilibrium",
           "tangent_factorization", "verify"]
