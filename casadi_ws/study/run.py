"""Run a design study: trials on an executor, the study's state in an Optuna SQLite file.

The main process is the only one that talks to the study file: it asks Optuna for a design, sends the
design's problem data to a worker (:func:`~casadi_ws.study.trial.run_trial`), and tells Optuna the
measures when the trial comes back, so a trial is recorded once however the workers fare. A grid study
enqueues every combination when it starts; an Optuna study asks its sampler (TPE for one objective,
NSGA-II for several, with generations of a quarter of the trials, 4 to 50 designs). Trials that were running when a study was killed are marked ``interrupted`` on
``--resume`` and their designs run again; they are not counted and not listed in trials.csv.

Best design: one objective, the best feasible trial; several, the Pareto-optimal feasible trial closest to
the ideal point once every objective is scaled to [0, 1] over the front (the "knee").
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
import time
from concurrent.futures import BrokenExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .spec import MEASURES, Study, StudyError
from .trial import run_trial

__all__ = ["StudyResult", "TrialRecord", "run_study"]

DB = "study.db"


@dataclass
class TrialRecord:
    number: int
    params: dict
    status: str
    """complete or failed."""
    measures: dict = field(default_factory=dict)
    time_s: float = 0.0
    reason: str = ""
    feasible: bool = False
    pareto: bool = False


@dataclass
class StudyResult:
    study: Study
    trials: list[TrialRecord]
    best: TrialRecord | None
    out: Path
    time_s: float

    @property
    def n_complete(self) -> int:
        return sum(t.status == "complete" for t in self.trials)


def _constraints(study: Study, m: dict) -> list[float]:
    """Values <= 0 when satisfied (Optuna's convention)."""
    out = []
    for name, lo, hi in study.constraints:
        v = m.get(name)
        if v is None:
            out.append(math.inf)
            continue
        if lo is not None:
            out.append(lo - v)
        if hi is not None:
            out.append(v - hi)
    if any(o.measure.startswith("reach_") for o in study.objectives):  # a tension that misses the target is no answer
        out.append(m.get("reach_error", math.inf) - study.reach_tolerance)
    return out


def _set_constraints(trial, values: list[float]) -> None:
    trial.set_user_attr("constraints", values)
    if hasattr(trial, "set_constraint"):  # Optuna >= 5 reads them from the trial (constraints_func is deprecated)
        for i, v in enumerate(values):
            trial.set_constraint(f"c{i}", v)


def _sampler(study: Study, done: int = 0):
    """``done``: trials already in the study (a resumed sampler is re-seeded, or its seeded stream would
    propose the designs it proposed before the interruption once more)."""
    import optuna

    def from_attrs(frozen):
        return frozen.user_attrs.get("constraints", [0.0])

    constraints = None if hasattr(optuna.trial.Trial, "set_constraint") else from_attrs
    if study.method == "grid":
        return optuna.samplers.RandomSampler(seed=study.seed)  # never used: every grid trial is enqueued
    if len(study.objectives) == 1:
        return optuna.samplers.TPESampler(seed=study.seed + done, constraints_func=constraints)
    # generations of about a quarter of the trials (Optuna's default, 50, would make a study of a few dozen
    # trials one random generation)
    population = max(4, min(50, study.trials // 4))
    return optuna.samplers.NSGAIISampler(seed=study.seed + done, population_size=population,
                                         constraints_func=constraints)


def _open(study: Study, out: Path, resume: bool):
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    storage = optuna.storages.RDBStorage(f"sqlite:///{(out / DB).resolve()}")
    names = [s.study_name for s in optuna.get_all_study_summaries(storage)]
    existed = study.name in names
    if names and not existed:
        raise StudyError(str(out / DB), "", f"holds the study {names[0]!r}, not {study.name!r}: use another output "
                         f"directory")
    if existed and not resume:
        raise StudyError(str(out / DB), "", f"holds the study {study.name!r} already: resume it, or use another "
                         f"output directory")
    done = len(optuna.load_study(study_name=study.name, storage=storage).trials) if existed else 0
    st = optuna.create_study(storage=storage, study_name=study.name, sampler=_sampler(study, done),
                             directions=[o.direction for o in study.objectives], load_if_exists=existed)
    if existed and st.user_attrs.get("fingerprint") != study.fingerprint():
        raise StudyError(str(out / DB), "", f"the study {study.name!r} there was run from a different study file "
                         f"(base problem, variables, objectives, workspace, method or seed changed): resuming it "
                         f"would mix designs; use another output directory")
    if not existed:
        st.set_user_attr("fingerprint", study.fingerprint())
    rerun = 0
    for t in st.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        # its process is gone (this is the only process writing the study): run its design again
        st._storage.set_trial_user_attr(t._trial_id, "interrupted", True)
        st.tell(t.number, state=optuna.trial.TrialState.FAIL)
        if study.method != "grid":  # (a grid's missing designs are queued below)
            st.enqueue_trial(t.params)
        rerun += 1
    if study.method == "grid":
        # every design not finished or queued yet: all of them at the start; on resume, those an interruption
        # lost (killed while queueing, or running)
        S = optuna.trial.TrialState
        have = [t.params for t in st.get_trials(deepcopy=False, states=(S.COMPLETE,))]
        # a queued trial has no params yet: Optuna keeps the design it will get as "fixed_params"
        have += [t.system_attrs.get("fixed_params", {}) for t in st.get_trials(deepcopy=False, states=(S.WAITING,))]
        have += [t.params for t in st.get_trials(deepcopy=False, states=(S.FAIL,))
                 if not t.user_attrs.get("interrupted")]
        for design in study.designs():
            if design not in have:
                st.enqueue_trial(design)
    return st, rerun


def _records(st, study: Study) -> list[TrialRecord]:
    import optuna

    S = optuna.trial.TrialState
    recs = []
    for t in st.get_trials(deepcopy=False, states=(S.COMPLETE, S.FAIL)):
        if t.user_attrs.get("interrupted"):
            continue
        m = t.user_attrs.get("measures", {})
        rec = TrialRecord(t.number, dict(t.params), "complete" if t.state == S.COMPLETE else "failed", m,
                          t.user_attrs.get("time_s", 0.0), t.user_attrs.get("reason", ""))
        rec.feasible = rec.status == "complete" and all(c <= 0 for c in t.user_attrs.get("constraints", []))
        recs.append(rec)
    _mark_pareto(recs, study)
    return recs


def _signed(study: Study, rec: TrialRecord) -> np.ndarray:
    """Objective values, all to be minimised."""
    return np.array([(-1 if o.direction == "maximize" else 1) * rec.measures[o.measure] for o in study.objectives])


def _mark_pareto(recs: list[TrialRecord], study: Study) -> None:
    ok = [r for r in recs if r.feasible]
    for r in ok:
        f = _signed(study, r)
        r.pareto = not any(np.all(_signed(study, o) <= f) and np.any(_signed(study, o) < f) for o in ok)


def best_trial(recs: list[TrialRecord], study: Study) -> TrialRecord | None:
    front = [r for r in recs if r.pareto]
    if not front:
        return None
    F = np.array([_signed(study, r) for r in front])
    span = np.where(F.max(0) > F.min(0), F.max(0) - F.min(0), 1.0)
    return front[int(np.argmin(np.linalg.norm((F - F.min(0)) / span, axis=1)))]


def write_trials_csv(recs: list[TrialRecord], study: Study, path: Path) -> None:
    names = [m for m in MEASURES if any(m in r.measures and r.measures[m] is not None for r in recs)]
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["trial", "status"] + [v.path for v in study.variables] + names
                   + ["feasible", "pareto", "time_s", "reason"])
        for r in sorted(recs, key=lambda r: r.number):
            w.writerow([r.number, r.status] + [r.params.get(v.path) for v in study.variables]
                       + [("" if r.measures.get(m) is None else f"{r.measures[m]:.6g}") for m in names]
                       + [int(r.feasible), int(r.pareto), f"{r.time_s:.2f}", r.reason])
    os.replace(tmp, path)  # a reader (or a kill) never sees half a table


def _relative_paths(data: dict, base_dir: Path, to: Path) -> dict:
    """The problem's file names, rewritten relative to ``to`` so the written problem file opens from there."""
    import copy

    data = copy.deepcopy(data)

    def fix(d, key):
        if isinstance(d, dict) and isinstance(d.get(key), str):
            d[key] = os.path.relpath((base_dir / d[key]).resolve(), to.resolve())

    fix(data.get("mesh"), "file")
    fix(data.get("task"), "points")
    for c in data.get("cavities") or []:
        fix(c, "surface")
    return data


def _write_problem(data: dict, study: Study, directory: Path, name: str, trial: int) -> Path:
    import yaml

    data = {**data, "name": f"{study.name}_trial{trial}"}  # pictures and summaries say which design they show
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / name
    body = yaml.safe_dump(_relative_paths(data, study.base_dir, directory), sort_keys=False)
    path.write_text(f"# written by casadi-ws study {study.name}\n" + body)
    return path


def _describe_best(study: Study, best: TrialRecord | None) -> str:
    if best is None:
        return "none yet"
    return ", ".join(f"{o.measure} {best.measures[o.measure]:.4g}" for o in study.objectives)


def run_study(study: Study, out, executor=None, resume: bool = False, progress: bool = True) -> StudyResult:
    """Run (or continue) ``study``, writing trials/, trials.csv, study.png, best.yaml and best/ into ``out``."""
    import optuna

    from ..runtime.executor import SerialExecutor

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    st, rerun = _open(study, out, resume)
    if rerun and progress:
        print(f"casadi-ws: {rerun} trial(s) interrupted by the previous run will run again", file=sys.stderr)
    executor = executor or SerialExecutor()
    dists = {v.path: v.distribution(study.method) for v in study.variables}
    needed = study.measures_needed()
    S = optuna.trial.TrialState

    def finished() -> int:
        return len(_records(st, study))

    def more() -> bool:
        if study.method == "grid":
            return bool(st.get_trials(deepcopy=False, states=(S.WAITING,)))
        return finished() + len(inflight) < study.trials

    total = len(study.designs()) if study.method == "grid" else study.trials
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, initial=finished(), desc=f"study {study.name}", unit="trial", file=sys.stderr)
    inflight = {}
    try:
        while True:
            while len(inflight) < max(1, executor.workers) and more():
                trial = st.ask(dists)
                same = _same_design(st, trial)
                if same is not None:  # samplers repeat designs (NSGA-II's crossover of equal parents)
                    _copy(st, study, trial, same, out)
                    if bar is not None:
                        bar.update(1)
                    continue
                data = study.problem_data(trial.params)
                job = (run_trial, data, str(study.base_dir), f"{study.name} (trial {trial.number})",
                       study.workspace, needed, study.target, study.reach_tolerance)
                try:
                    fut = executor.submit(*job)
                except BrokenExecutor:  # a worker process died (a crash, out of memory): start new ones
                    executor.restart()
                    fut = executor.submit(*job)
                inflight[fut] = (trial, data)
            if not inflight:
                break
            done, _ = executor.wait(set(inflight))
            for fut in done:
                trial, data = inflight.pop(fut)
                try:
                    rec = fut.result()
                except Exception as exc:  # noqa: BLE001 - a worker lost or a crash: recorded, the study goes on
                    why = "a worker process died running it" if isinstance(exc, BrokenExecutor) else \
                        f"{type(exc).__name__}: {exc}"
                    rec = {"status": "failed", "reason": why, "measures": {}, "time_s": 0.0, "result": None}
                _record(st, study, trial, data, rec, out)
                if bar is not None:
                    recs = _records(st, study)
                    bar.set_postfix_str(f"best: {_describe_best(study, best_trial(recs, study))}")
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    recs = _records(st, study)
    best = best_trial(recs, study)
    result = StudyResult(study, recs, best, out, time.perf_counter() - t0)
    write_study_outputs(result)
    return result


def _same_design(st, trial):
    """A finished trial with exactly these parameters, or None."""
    import optuna

    S = optuna.trial.TrialState
    for t in st.get_trials(deepcopy=False, states=(S.COMPLETE, S.FAIL)):
        if t.number != trial.number and not t.user_attrs.get("interrupted") and t.params == trial.params:
            return t
    return None


def _copy(st, study: Study, trial, same, out: Path) -> None:
    """Record a repeated design with the measures of its first trial: workspace runs are deterministic."""
    import optuna

    if "measures" in same.user_attrs:
        trial.set_user_attr("measures", same.user_attrs["measures"])
    if "constraints" in same.user_attrs:
        _set_constraints(trial, same.user_attrs["constraints"])
    trial.set_user_attr("time_s", 0.0)
    why = same.user_attrs.get("reason", "")
    trial.set_user_attr("reason", f"same design as trial {same.number}: its measures, not recomputed"
                        + (f" ({why})" if why else ""))
    if same.state == optuna.trial.TrialState.COMPLETE:
        st.tell(trial, list(same.values))
    else:
        st.tell(trial, state=optuna.trial.TrialState.FAIL)
    write_trials_csv(_records(st, study), study, out / "trials.csv")


def _record(st, study: Study, trial, data: dict, rec: dict, out: Path) -> None:
    import optuna

    m = {k: v for k, v in rec["measures"].items() if v is not None}
    trial.set_user_attr("measures", m)
    trial.set_user_attr("time_s", float(rec["time_s"]))
    trial.set_user_attr("reason", rec["reason"])
    d = out / "trials" / f"{trial.number:04d}"
    _write_problem(data, study, d, "problem.yaml", trial.number)
    if rec["result"] is not None:
        rec["result"].save(d)
    if rec["status"] == "complete":
        _set_constraints(trial, _constraints(study, m))
        st.tell(trial, [m[o.measure] for o in study.objectives])
    else:
        st.tell(trial, state=optuna.trial.TrialState.FAIL)
    write_trials_csv(_records(st, study), study, out / "trials.csv")


def write_study_outputs(result: StudyResult) -> None:
    """trials.csv, study.json, study.png; best.yaml and best/ (the best design's workspace files)."""
    from .plots import study_plot

    study, out = result.study, result.out
    write_trials_csv(result.trials, study, out / "trials.csv")
    study_plot(result, out / "study.png")
    summary = {"name": study.name, "method": study.method, "objectives": [[o.direction, o.measure] for o in study.objectives],
               "trials": len(result.trials), "complete": result.n_complete,
               "failed": len(result.trials) - result.n_complete,
               "feasible": sum(t.feasible for t in result.trials),
               "pareto": [t.number for t in result.trials if t.pareto],
               "best": None if result.best is None else {"trial": result.best.number, "params": result.best.params,
                                                         "measures": result.best.measures},
               "time_s": result.time_s, "units": {m: u for m, (u, _, _) in MEASURES.items()}}
    (out / "study.json").write_text(json.dumps(summary, indent=2) + "\n")
    if result.best is not None:
        from ..io.output import write_outputs
        from ..io.problem import load_problem
        from ..workspace.result import load_result

        data = study.problem_data(result.best.params)
        path = _write_problem(data, study, out, "best.yaml", result.best.number)
        problem = load_problem(path)
        src = out / "trials" / f"{result.best.number:04d}"
        if (src / "summary.json").is_file():
            write_outputs(load_result(src), problem, out / "best", quiet=True)
