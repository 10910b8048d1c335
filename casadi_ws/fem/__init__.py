"""The finite-element model: meshes, element types, materials, compiled element kernels, assembly."""

from .elements import TET4, ElementType, element_type
from .functions import point_function, residual_function
from .materials import MATERIAL_MODELS, Material, element_functions
from .mesh import Embedding, Mesh, MeshError, box_mesh, embed, load_mesh, trunk_mesh
from .model import StaticModel

__all__ = ["MATERIAL_MODELS", "TET4", "ElementType", "Embedding", "Material", "Mesh", "MeshError", "StaticModel",
           "box_mesh", "element_functions", "element_type", "embed", "load_mesh", "point_function", "residual_function",
           "trunk_mesh"]
