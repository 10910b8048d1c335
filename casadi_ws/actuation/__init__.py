"""Actuation: the :class:`Actuator` interface and the actuator kinds (cables)."""

from .base import Actuator, quantity_functions
from .cable import Cable, trunk_cable

__all__ = ["Actuator", "Cable", "quantity_functions", "trunk_cable"]
