"""casadi-ws: where can the tip of a soft robot go? Static FEM in CasADi, forward and forward-backward
workspace estimation, reusable inverse-control NLPs.

The package is layered; each sub-package imports only those listed before it:
``status`` < ``actuation`` < ``fem`` < ``solvers`` < ``nlp`` < ``runtime`` < ``workspace`` < ``control``
< ``io`` < ``study`` < ``cli``. The names below are the public API.
"""

from .actuation import Actuator, Cable, Cavity, trunk_cable
from .control import FollowResult, ReachResult, ReachSettings, follow, reach
from .fem import (TET4, ElementType, Material, Mesh, MeshError, StaticModel, box_mesh, load_mesh, point_function,
                  residual_function, trunk_mesh)
from .fem.terms import Term
from .io import Problem, ProblemError, SolverSettings, default_problem, load_problem, problem_from_dict
from .io.output import write_outputs
from .runtime import DaskExecutor, Executor, ProcessExecutor, SerialExecutor
from .nlp import EquilibriumNLP, NLPSolution, tracking
from .solvers import Equilibrium, equilibrium_function, quasi_static, solve_equilibrium
from .status import Status
from .study import Study, StudyResult, load_study, run_study
from .workspace import (BackwardSettings, FBSettings, ForwardSettings, Task, WorkspaceResult, compare, forward,
                        forward_backward, load_result, measures)

__all__ = [
    "Actuator",
    "BackwardSettings",
    "Cable",
    "Cavity",
    "ElementType",
    "DaskExecutor",
    "Equilibrium",
    "EquilibriumNLP",
    "Executor",
    "FBSettings",
    "FollowResult",
    "ForwardSettings",
    "Material",
    "Mesh",
    "MeshError",
    "NLPSolution",
    "Problem",
    "ProblemError",
    "ProcessExecutor",
    "ReachResult",
    "ReachSettings",
    "SerialExecutor",
    "SolverSettings",
    "StaticModel",
    "Status",
    "Term",
    "Study",
    "StudyResult",
    "TET4",
    "Task",
    "WorkspaceResult",
    "box_mesh",
    "compare",
    "default_problem",
    "equilibrium_function",
    "follow",
    "forward",
    "forward_backward",
    "load_mesh",
    "load_problem",
    "load_result",
    "load_study",
    "measures",
    "point_function",
    "problem_from_dict",
    "quasi_static",
    "reach",
    "residual_function",
    "run_study",
    "solve_equilibrium",
    "tracking",
    "trunk_cable",
    "trunk_mesh",
    "write_outputs",
]
__version__ = "0.1.0"
