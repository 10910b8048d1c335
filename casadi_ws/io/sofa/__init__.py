"""SOFA scenes: record a scene's graph with no SOFA installed (:mod:`.recorder`) and translate it into a
problem (:mod:`.translate`)."""

from .recorder import SceneError, record
from .translate import UNIT_SYSTEMS, Translation, import_scene, translate, write_problem

__all__ = ["SceneError", "Translation", "UNIT_SYSTEMS", "import_scene", "record", "translate", "write_problem"]
