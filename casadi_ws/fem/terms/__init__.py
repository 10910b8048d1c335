"""The terms of the model's residual: each force (and each set of unknowns with its rows) is one term, and the
model sums them (:class:`casadi_ws.fem.model.StaticModel`)."""

from .base import Term, fischer_burmeister
from .contact import ContactGeometry, ContactTerm, ObstacleContact
from .pressure import ContinuousPressure, pressure_functions
from .self_contact import MLS_SLOTS, SelfContact

__all__ = ["ContactGeometry", "ContactTerm", "ContinuousPressure", "MLS_SLOTS", "ObstacleContact", "SelfContact",
           "Term", "fischer_burmeister", "pressure_functions"]
