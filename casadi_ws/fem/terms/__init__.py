"""The terms of the model's residual: each force (and each set of unknowns with its rows) is one term, and the
model sums them (:class:`casadi_ws.fem.model.StaticModel`; the protocol: :class:`Term`).

The model's own terms come from its specification's fields (:func:`builtin_terms`); a problem file's
``springs`` and ``pressure_loads``, and a user's own terms, are in ``ModelSpec.terms``. A new force is a new
module here with a :class:`Term` and a reader of its problem-file key (docs/methods.md "How to add a term").
"""

import numpy as np

from .actuators import ActuatorData, Actuators
from .base import Evaluation, Term, complementarity, fischer_burmeister, held_block, point_pairs, tangent_data
from .contact import ContactGeometry, ContactTerm, ObstacleContact
from .elements import ElementGroup, Elements
from .loads import Loads
from .prescribed import Prescribed
from .pressure import ContinuousPressure, pressure_functions
from .pressure_load import PressureLoad
from .auto_contact import AutoSelfContact
from .self_contact import MLS_SLOTS, SelfContact
from .springs import Springs

__all__ = ["ActuatorData", "Actuators", "AutoSelfContact", "ContactGeometry", "ContactTerm", "ContinuousPressure", "ElementGroup",
           "Elements", "Evaluation", "Loads", "MLS_SLOTS", "ObstacleContact", "Prescribed", "PressureLoad",
           "SelfContact", "Springs", "Term",
           "builtin_terms", "complementarity", "fischer_burmeister", "held_block", "point_pairs",
           "pressure_functions"]


def builtin_terms(model) -> list[Term]:
    """The terms a model's specification makes, in the order they are summed within a phase: the elements,
    the actuators, the prescribed quantities (whose intensities lead the state's unknowns), the loads, contact
    with the obstacles, self-contact pairs, the continuous pressure of Taylor-Hood elements."""
    from ..contact import contact_set, split_faces

    spec = model.spec
    elements = Elements(spec, model.backend_request)
    terms = [elements, Actuators(spec), Prescribed(spec), Loads(spec)]
    pos = -np.ones(model.n_mech, dtype=np.int64)
    pos[model.free_mech] = np.arange(model.n_free_mech)
    moving = ~model.fixed.all(axis=1)
    contact = contact_set(spec.mesh, spec.obstacles, moving, spec.material.young_modulus)
    if contact is not None:
        terms.append(ObstacleContact(contact, pos))
    for pair in spec.self_contact:
        terms.append(SelfContact(pair.name, pair.points[moving[pair.points]], split_faces(pair.faces), spec.mesh.nodes,
                                 pos, spec.material.young_modulus, pair.reach))
    if spec.self_contact_auto is not None:
        a = spec.self_contact_auto
        terms.append(AutoSelfContact(spec.material.young_modulus, a.distance, a.stiffness))
    th = elements.taylor_hood()
    if th.size:
        tets = spec.mesh.tets[th]
        w, G = spec.mesh.element.rest_geometry(spec.mesh.nodes[tets])
        edofs = (3 * tets[:, :, None] + np.arange(3)).reshape(th.size, -1)
        bulk = np.array([m.parameters[-1] for m in elements.materials])[elements.law[th]]
        terms.append(ContinuousPressure(tets, edofs, w, G, bulk, model.n_free_mech, model.backend_request))
    return terms
