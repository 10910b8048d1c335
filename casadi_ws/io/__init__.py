"""Input and output: problem files, pictures (result files are written by ``WorkspaceResult.save``)."""

from .problem import Problem, ProblemError, SolverSettings, default_problem, load_problem, problem_from_dict

__all__ = ["Problem", "ProblemError", "SolverSettings", "default_problem", "load_problem", "problem_from_dict"]
