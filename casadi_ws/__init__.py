"""casadi-ws: where can the tip of a soft robot go? Static FEM in CasADi, forward and forward-backward
workspace estimation, reusable inverse-control NLPs."""

from .actuation.cable import Cable, trunk_cable
from .solvers.equilibrium import Equilibrium, solve_equilibrium
from .fem.materials import Material
from .fem.mesh import Mesh, MeshError, box_mesh, load_mesh, trunk_mesh
from .fem.model import StaticModel
from .io.problem import Problem, ProblemError, SolverSettings, default_problem, load_problem, problem_from_dict

__all__ = [
    "Cable",
    "Equilibrium",
    "Material",
    "Mesh",
    "MeshError",
    "Problem",
    "ProblemError",
    "SolverSettings",
    "StaticModel",
    "box_mesh",
    "default_problem",
    "load_mesh",
    "load_problem",
    "problem_from_dict",
    "solve_equilibrium",
    "trunk_cable",
    "trunk_mesh",
]
__version__ = "0.1.0"
