"""The NLP library: optimisation problems over the static equilibria, solved by IPOPT with exact derivatives."""

from .formulations import IPOPT_OPTIONS, EquilibriumNLP, NLPSolution, tracking

__all__ = ["EquilibriumNLP", "IPOPT_OPTIONS", "NLPSolution", "tracking"]
