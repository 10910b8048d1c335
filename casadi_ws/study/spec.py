"""A design study as read from its YAML file: base problem, design variables, objectives, method.

Format (docs/studies.md):

    name: study_trunk3
    problem: trunk_3cables.yaml          # the base problem, relative to this file
    set: {mesh.resolution: 0.7}          # fixed changes to the base problem (key path: value)
    variables:
      - path: cables[*].trunk_routing.radius     # [*]: every element of the list
        range: [0.008, 0.011]                    # or values: [...]; scale: linear (default) or log
        n: 3                                     # values of a range in a grid study
    workspace: {method: fb, step: 0.006}         # the workspace run of every trial
    target: [0.0, 0.05, 0.17]                    # for the reach_* measures
    objectives: [{maximize: volume}, {minimize: reach_tension}]
    constraints: [{measure: reach_error, max: 1.0e-4}]
    method: optuna                               # or grid (full factorial)
    trials: 24
    seed: 0

A key path names a key of the problem file: ``material.young_modulus``, ``cables[2].trunk_routing.z_end``.
Every list and mapping on the way must exist in the base problem; the last key may be absent if the problem
format accepts it there (it then takes the value the trial gives it).
"""

from __future__ import annotations

import copy
import difflib
import itertools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.problem import ProblemError, _as_number, problem_from_dict, read_yaml

__all__ = ["MEASURES", "Objective", "Study", "StudyError", "Variable", "apply", "load_study", "study_from_dict"]

# name: (unit, what it is, direction a designer usually wants)
MEASURES = {
    "volume": ("m^3", "enclosed by the boundary surface (cells x step^3 where there is none)", "maximize"),
    "area": ("m^2", "area of the tip surface (two actuators)", "maximize"),
    "cells": ("", "workspace cells", "maximize"),
    "task_share": ("", "share of the task region reached", "maximize"),
    "extent_x": ("m", "width of the workspace along x", "maximize"),
    "extent_y": ("m", "width of the workspace along y", "maximize"),
    "extent_z": ("m", "width of the workspace along z", "maximize"),
    "reach_tension": ("N", "largest input of the reach solution for the target", "minimize"),
    "reach_error": ("m", "distance from the target to the closest tip reach finds", "minimize"),
}

_STUDY_KEYS = {"name", "description", "problem", "set", "variables", "workspace", "target", "objectives",
               "constraints", "method", "trials", "seed", "reach_tolerance"}
_VARIABLE_KEYS = {"path", "range", "values", "scale", "n", "name"}
_WORKSPACE_KEYS = {"method", "step", "n_d", "backward", "strategy"}
_TOKEN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[(?:\d+|\*)\])*)$")


class StudyError(ProblemError):
    """Invalid study input: one line, ``FILE: KEY: what was wrong``."""


def parse_path(text: str) -> list:
    """``cables[2].trunk_routing.z_end`` -> ["cables", 2, "trunk_routing", "z_end"] ("*" for [*])."""
    out = []
    for part in str(text).split("."):
        m = _TOKEN.match(part)
        if not m:
            raise ValueError(f"not a key path: {text!r} (expected e.g. cables[2].trunk_routing.z_end)")
        out.append(m.group(1))
        out += ["*" if i == "*" else int(i) for i in re.findall(r"\[(\d+|\*)\]", m.group(2))]
    return out


def _show(keys) -> str:
    s = ""
    for k in keys:
        s += f"[{k}]" if isinstance(k, int) or k == "*" else (f".{k}" if s else k)
    return s


def _containers(data, keys: list, where: str):
    """The containers that hold the path's last key (several with [*]); ValueError if the path is absent."""
    level = [data]
    for i, k in enumerate(keys[:-1]):
        nxt = []
        for c in level:
            if k == "*" or isinstance(k, int):
                if not isinstance(c, list):
                    raise ValueError(f"{_show(keys[:i]) or 'the top level'} is not a list in {where}")
                if k != "*" and not -len(c) <= k < len(c):
                    raise ValueError(f"{_show(keys[:i])} has {len(c)} element(s) in {where}, no [{k}]")
                nxt += c if k == "*" else [c[k]]
            else:
                if not isinstance(c, dict) or k not in c:
                    raise ValueError(f"{_show(keys[:i + 1])} does not exist in {where}")
                nxt.append(c[k])
        level = nxt
    last = keys[-1]
    for c in level:
        if isinstance(last, str) and last != "*" and not isinstance(c, dict):
            raise ValueError(f"{_show(keys[:-1])} is not a mapping in {where}")
        if (last == "*" or isinstance(last, int)) and not isinstance(c, list):
            raise ValueError(f"{_show(keys[:-1])} is not a list in {where}")
        if isinstance(last, int) and not -len(c) <= last < len(c):
            raise ValueError(f"{_show(keys[:-1])} has {len(c)} element(s) in {where}, no [{last}]")
        if last == "*" and not c:
            raise ValueError(f"{_show(keys[:-1])} is empty in {where}: [*] would set nothing")
    if "*" in keys and not level:
        raise ValueError(f"{_show(keys)}: [*] over an empty list in {where} sets nothing")
    return level


def apply(data: dict, assignments: dict) -> dict:
    """A copy of the problem data with each key path set to its value."""
    out = copy.deepcopy(data)
    for path, value in assignments.items():
        keys = parse_path(path)
        for c in _containers(out, keys, "the problem"):
            if keys[-1] == "*":  # a copy each: a later path must not edit them all through one object
                c[:] = [copy.deepcopy(value) for _ in c]
            else:
                c[keys[-1]] = copy.deepcopy(value)
    return out


@dataclass
class Variable:
    """A design variable: a key path of the problem file and the values it may take."""

    path: str
    low: float | None = None
    high: float | None = None
    values: list | None = None
    """A list of values instead of a range (any YAML scalars the problem accepts there)."""
    log: bool = False
    n: int = 3
    """Values of a range in a grid study (equally spaced, geometrically for log)."""

    def grid(self) -> list:
        if self.values is not None:
            return list(self.values)
        v = np.geomspace(self.low, self.high, self.n) if self.log else np.linspace(self.low, self.high, self.n)
        return [float(x) for x in v]

    def distribution(self, method: str):
        import optuna.distributions as d

        if self.values is not None or method == "grid":
            return d.CategoricalDistribution(self.grid())
        return d.FloatDistribution(self.low, self.high, log=self.log)


@dataclass
class Objective:
    measure: str
    direction: str
    """"maximize" or "minimize"."""


@dataclass
class Study:
    name: str
    source: str
    base: dict
    """The base problem as plain data, with the study's ``set`` changes applied."""
    base_dir: Path
    """Directory the base problem's relative file names are read from."""
    variables: list[Variable]
    objectives: list[Objective]
    constraints: list[tuple[str, float | None, float | None]] = field(default_factory=list)
    """(measure, min, max) that a feasible design satisfies."""
    workspace: dict = field(default_factory=dict)
    method: str = "grid"
    trials: int | None = None
    """Trials to run (optuna); a grid study runs every combination."""
    seed: int = 0
    target: list | None = None
    reach_tolerance: float = 1e-4
    """A target counts as reached within this distance (m)."""
    description: str = ""

    def measures_needed(self) -> list[str]:
        return list(dict.fromkeys([o.measure for o in self.objectives] + [c[0] for c in self.constraints]))

    def designs(self) -> list[dict]:
        """Every combination of the grid (variable path -> value)."""
        return [dict(zip([v.path for v in self.variables], combo))
                for combo in itertools.product(*[v.grid() for v in self.variables])]

    def problem_data(self, params: dict) -> dict:
        return apply(self.base, params)

    def fingerprint(self) -> str:
        """Hash of what decides the trials' answers (not ``trials``: a study may be resumed for more)."""
        import hashlib
        import json
        from dataclasses import asdict

        what = [self.base, [asdict(v) for v in self.variables], [asdict(o) for o in self.objectives],
                self.constraints, self.workspace, self.method, self.seed, self.target, self.reach_tolerance]
        return hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:20]


def _number(r, d, key, where, *, positive=False) -> float:
    v = _as_number(d.get(key))
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        r(f"{where}.{key}", f"expected a {'positive ' if positive else ''}finite number, got {v!r}")
    return float(v)


def _variable(fail, v, i: int, base: dict, base_name: str) -> Variable:
    key = f"variables[{i}]"
    if not isinstance(v, dict):
        fail(key, f"expected a mapping with path and range or values, got {v!r}")
    for k in v:
        if k not in _VARIABLE_KEYS:
            fail(f"{key}.{k}", f"unknown key; expected one of: {', '.join(sorted(_VARIABLE_KEYS))}")
    if "path" not in v:
        fail(f"{key}.path", "missing: the key path of the problem file to vary, e.g. material.young_modulus")
    try:
        keys = parse_path(v["path"])
        _containers(base, keys, base_name)
    except ValueError as exc:
        fail(f"{key}.path", str(exc))
    if ("range" in v) == ("values" in v):
        fail(key, "give either 'range: [low, high]' or 'values: [...]'")
    scale = v.get("scale", "linear")
    if scale not in ("linear", "log"):
        fail(f"{key}.scale", f"expected linear or log, got {scale!r}")
    n = v.get("n", 3)
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        fail(f"{key}.n", f"expected an integer >= 1 (values of the range in a grid study), got {n!r}")
    if "values" in v:
        vals = v["values"]
        vals = [_as_number(x) for x in vals] if isinstance(vals, list) else vals
        if not isinstance(vals, list) or not vals:
            fail(f"{key}.values", f"expected a non-empty list of values, got {vals!r}")
        if "scale" in v or "n" in v:
            fail(key, "'scale' and 'n' apply to a range, not to a list of values")
        return Variable(str(v["path"]), values=vals)
    rg = v["range"]
    rg = [_as_number(x) for x in rg] if isinstance(rg, list) else rg
    if (not isinstance(rg, list) or len(rg) != 2
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in rg)):
        fail(f"{key}.range", f"expected [low, high], two finite numbers, got {rg!r}")
    lo, hi = float(rg[0]), float(rg[1])
    if not lo < hi:
        fail(f"{key}.range", f"expected low < high, got {rg!r}")
    if scale == "log" and lo <= 0:
        fail(f"{key}.range", f"a log scale needs low > 0, got {rg!r}")
    return Variable(str(v["path"]), lo, hi, log=scale == "log", n=n)


def _read_base(fail, d: dict, base_dir: Path) -> tuple[dict, Path]:
    """The base problem's data with the study's ``set`` changes, and its file; it must be valid."""
    if "problem" not in d:
        fail("problem", "missing: the base problem file, relative to the study file")
    problem_path = (base_dir / str(d["problem"])).resolve()
    if not problem_path.is_file():
        fail("problem", f"file not found: {problem_path}")
    try:
        base = read_yaml(problem_path)
    except ProblemError as exc:
        fail("problem", f"{problem_path}: {exc.message}")
    if not isinstance(base, dict):
        fail("problem", f"{problem_path}: not a problem file (expected a mapping)")
    sets = d.get("set") or {}
    if not isinstance(sets, dict):
        fail("set", f"expected a mapping of key path: value, got {sets!r}")
    for path in sets:
        try:
            _containers(base, parse_path(path), str(problem_path))
        except ValueError as exc:
            fail(f"set.{path}", str(exc))
    base = apply(base, sets)
    # the base problem itself must be valid: its errors are the user's, not a trial's
    try:
        problem_from_dict(base, str(problem_path), problem_path.parent)
    except ProblemError as exc:
        fail("set" if sets else "problem", f"the base problem{' with these changes' if sets else ''} is invalid: "
             f"{problem_path.name}: {exc.key}: {exc.message}")
    return base, problem_path


def _read_variables(fail, d: dict, base: dict, problem_path: Path) -> list[Variable]:
    variables = d.get("variables")
    if not isinstance(variables, list) or not variables:
        fail("variables", "expected a non-empty list of {path, range | values}")
    variables = [_variable(fail, v, i, base, str(problem_path)) for i, v in enumerate(variables)]
    paths = [v.path for v in variables]
    if len(set(paths)) != len(paths):
        fail("variables", "a key path is listed twice")
    for i, v in enumerate(variables):  # the last key must be one the problem format accepts there
        trial = apply(base, {v.path: v.grid()[0]})
        try:
            problem_from_dict(trial, str(problem_path), problem_path.parent)
        except ProblemError as exc:
            if "unknown key" in exc.message:
                fail(f"variables[{i}].path", f"{v.path}: the problem format has no such key ({exc.message})")
    return variables


def _read_objectives(fail, d: dict) -> tuple[list[Objective], list]:
    objectives = d.get("objectives")
    if not isinstance(objectives, list) or not objectives:
        fail("objectives", "expected a list such as [{maximize: volume}, {minimize: reach_tension}]")
    objs = []
    for i, o in enumerate(objectives):
        if not isinstance(o, dict) or len(o) != 1 or next(iter(o)) not in ("maximize", "minimize"):
            fail(f"objectives[{i}]", f"expected {{maximize: MEASURE}} or {{minimize: MEASURE}}, got {o!r}")
        direction, measure = next(iter(o.items()))
        if not isinstance(measure, str) or measure not in MEASURES:
            close = difflib.get_close_matches(str(measure), sorted(MEASURES), n=1)
            fail(f"objectives[{i}].{direction}", f"unknown objective {measure!r}"
                 + (f" (did you mean '{close[0]}'?)" if close else "") + f"; expected one of: {', '.join(MEASURES)}")
        objs.append(Objective(measure, direction))
    constraints = []
    lst = d.get("constraints") or []
    if not isinstance(lst, list):
        fail("constraints", "expected a list of {measure, min, max}")
    for i, c in enumerate(lst):
        key = f"constraints[{i}]"
        if not isinstance(c, dict) or "measure" not in c or not set(c) - {"measure"} or set(c) - {"measure", "min", "max"}:
            fail(key, f"expected {{measure: NAME, min: VALUE and/or max: VALUE}}, got {c!r}")
        if not isinstance(c["measure"], str) or c["measure"] not in MEASURES:
            fail(f"{key}.measure", f"unknown measure {c['measure']!r}; expected one of: {', '.join(MEASURES)}")
        constraints.append((c["measure"], _number(fail, c, "min", key) if "min" in c else None,
                            _number(fail, c, "max", key) if "max" in c else None))
    return objs, constraints


def _read_workspace(fail, d: dict, base: dict) -> dict:
    """The workspace run of every trial: the study's settings over the base problem's, numbers normalised."""
    w = d.get("workspace") or {}
    if not isinstance(w, dict) or set(w) - _WORKSPACE_KEYS:
        fail("workspace", f"expected a mapping with keys among {', '.join(sorted(_WORKSPACE_KEYS))}, got {w!r}")
    workspace = {"method": "fb", **(base.get("workspace") or {}), **w}
    workspace = {k: v for k, v in workspace.items() if k in _WORKSPACE_KEYS}
    if workspace["method"] not in ("forward", "fb"):
        fail("workspace.method", f"expected forward or fb, got {workspace['method']!r}")
    if "step" in workspace:  # stored as numbers: PyYAML reads 6e-3 as a string
        workspace["step"] = _number(fail, workspace, "step", "workspace", positive=True)
    if "n_d" in workspace:
        n_d = _as_number(workspace["n_d"])
        if isinstance(n_d, bool) or not isinstance(n_d, (int, float)) or n_d != int(n_d) or n_d < 1:
            fail("workspace.n_d", f"expected an integer >= 1, got {workspace['n_d']!r}")
        workspace["n_d"] = int(n_d)
    for key, allowed in (("strategy", ("uniform", "relative")), ("backward", ("reduced", "ipopt"))):
        if key in workspace and workspace[key] not in allowed:
            fail(f"workspace.{key}", f"expected one of {', '.join(allowed)}, got {workspace[key]!r}")
    return workspace


def study_from_dict(d, source: str = "<study>", base_dir: Path | None = None) -> Study:
    """Validate a study given as plain data; every error here is raised before any trial runs."""

    def fail(key, message):
        raise StudyError(source, key, message)

    base_dir = Path(base_dir or Path.cwd())
    if not isinstance(d, dict):
        fail("", f"expected a mapping at the top level, got {type(d).__name__}")
    for k in d:
        if k not in _STUDY_KEYS:
            close = difflib.get_close_matches(str(k), sorted(_STUDY_KEYS), n=1)
            fail(str(k), "unknown key" + (f" (did you mean '{close[0]}'?)" if close else "")
                 + f"; expected one of: {', '.join(sorted(_STUDY_KEYS))}")
    base, problem_path = _read_base(fail, d, base_dir)
    variables = _read_variables(fail, d, base, problem_path)
    objs, constraints = _read_objectives(fail, d)
    method = d.get("method", "grid")
    if method not in ("grid", "optuna"):
        fail("method", f"expected grid or optuna, got {method!r}")
    trials = d.get("trials")
    if method == "optuna":
        if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
            fail("trials", f"an optuna study needs the number of trials, an integer >= 1, got {trials!r}")
    elif trials is not None:
        fail("trials", "a grid study runs every combination; 'trials' is for method: optuna")
    seed = d.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        fail("seed", f"expected an integer, got {seed!r}")
    workspace = _read_workspace(fail, d, base)

    needed = [o.measure for o in objs] + [c[0] for c in constraints]
    target = d.get("target")
    target = [_as_number(x) for x in target] if isinstance(target, list) else target
    if any(m.startswith("reach_") for m in needed):
        if (not isinstance(target, list) or len(target) != 3
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in target)):
            fail("target", f"the reach_* measures need a target point [x, y, z] in metres, got {target!r}")
    if "task_share" in needed and base.get("task") is None:
        fail("objectives", "task_share needs a task region: add 'task' to the base problem or the study's 'set'")
    tol = _as_number(d.get("reach_tolerance", 1e-4))
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not tol > 0:
        fail("reach_tolerance", f"expected a positive distance in metres, got {tol!r}")
    return Study(str(d.get("name", Path(source).stem)), source, base, problem_path.parent, variables, objs,
                 constraints, workspace, method, trials, seed, target, float(tol), str(d.get("description", "")))


def load_study(path) -> Study:
    """Read and validate a study file."""
    path = Path(path)
    return study_from_dict(read_yaml(path, "study file", StudyError), str(path), path.parent)
