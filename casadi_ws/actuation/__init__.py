"""Actuation: the :class:`Actuator` interface and the actuator kinds (cables, pressure cavities)."""

from .base import Actuator, quantity_functions, third_function
from .cable import Cable, trunk_cable
from .cavity import Cavity, surface_volume

__all__ = ["Actuator", "Cable", "Cavity", "quantity_functions", "surface_volume", "third_function",
           "trunk_cable"]
