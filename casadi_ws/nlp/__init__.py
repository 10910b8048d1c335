"""The NLP library: optimisation problems over the static equilibria, solved by IPOPT with exact derivatives."""

from .formulations import FullSpaceNLP, TrackingNLP

__all__ = ["FullSpaceNLP", "TrackingNLP"]
