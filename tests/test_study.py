"""Design studies (issue: design studies at scale): a study's trials are the designs solved one by one, a
killed study resumes without repeating a trial, bad designs are recorded and bad study files refused."""

import csv
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO

import casadi_ws as cw
from casadi_ws.study.spec import apply

STUDIES = Path(__file__).parent / "bad_inputs" / "studies"


def tiny_study(tmp_path, **extra) -> Path:
    """2 x 2 designs of the coarse 2-cable trunk (Young's modulus x tension limit), FB at 8 mm."""
    d = {"name": "tiny", "problem": str(REPO / "problems" / "trunk_2cables.yaml"),
         "set": {"mesh.resolution": 0.5},
         "variables": [{"path": "material.young_modulus", "values": [1.2e7, 1.8e7]},
                       {"path": "cables[*].u_max", "values": [60, 100]}],
         "workspace": {"method": "fb", "step": 0.008}, "objectives": [{"maximize": "area"}], "method": "grid"}
    d.update(extra)
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


def rows(out: Path) -> list[dict]:
    with open(out / "trials.csv") as f:
        return list(csv.DictReader(f))


def cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "casadi_ws.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=REPO, **kw)


@pytest.mark.slow
def test_a_grid_study_on_dask_reproduces_the_designs_solved_one_by_one(tmp_path):
    study = cw.load_study(tiny_study(tmp_path))
    with cw.DaskExecutor(workers=2) as ex:
        res = cw.run_study(study, tmp_path / "out", executor=ex, progress=False)
    assert len(res.trials) == 4 and res.n_complete == 4
    base = yaml.safe_load((REPO / "problems" / "trunk_2cables.yaml").read_text())
    volumes = {}
    for E in (1.2e7, 1.8e7):
        for umax in (60, 100):
            data = apply(base, {"mesh.resolution": 0.5, "material.young_modulus": E, "cables[*].u_max": umax})
            pb = cw.problem_from_dict(data, "design", REPO / "problems")
            r = cw.forward_backward(pb, cw.FBSettings(step=0.008, progress=False))
            volumes[(E, umax)] = cw.measures(r, step=0.008)["area"]  # two cables: a surface, its area
    got = {(t.params["material.young_modulus"], t.params["cables[*].u_max"]): t.measures["area"] for t in res.trials}
    assert got == volumes
    assert len(set(volumes.values())) > 1  # the designs differ: the study could have mixed them up
    best = max(volumes, key=volumes.get)
    assert (res.best.params["material.young_modulus"], res.best.params["cables[*].u_max"]) == best
    # best.yaml is a problem file of that design that loads from where it is
    pb = cw.load_problem(tmp_path / "out" / "best.yaml")
    assert pb.material.young_modulus == best[0] and pb.cables[0].u_max == best[1]
    for f in ("trials.csv", "study.png", "study.json", "best/cells.vtu", "best/three_views.png"):
        assert (tmp_path / "out" / f).is_file(), f
    assert [float(r["volume"]) for r in rows(tmp_path / "out")] == pytest.approx([t.measures["volume"] for t in
                                                                                 sorted(res.trials, key=lambda t: t.number)])


@pytest.mark.slow
def test_a_dask_worker_killed_mid_study_costs_time_only_and_no_trial_is_recorded_twice(tmp_path):
    import optuna

    study = cw.load_study(tiny_study(tmp_path, workspace={"method": "fb", "step": 0.006}))
    calm = cw.run_study(study, tmp_path / "serial", progress=False)
    with cw.DaskExecutor(workers=2) as ex:
        pids = list(ex.client.run(os.getpid).values())
        killer = threading.Timer(1.5, os.kill, (pids[0], signal.SIGKILL))
        killer.start()
        t = time.perf_counter()
        res = cw.run_study(study, tmp_path / "dask", executor=ex, progress=False)
        killer.join()
        assert time.perf_counter() - t > 1.5  # the kill happened during the study
    with pytest.raises(ProcessLookupError):
        for _ in range(50):
            os.kill(pids[0], 0)
            time.sleep(0.1)
    stored = optuna.load_study(study_name="tiny", storage=f"sqlite:///{tmp_path / 'dask' / 'study.db'}").trials
    assert len(stored) == 4 and all(t.state == optuna.trial.TrialState.COMPLETE for t in stored)
    key = lambda t: tuple(sorted(t.params.items()))  # noqa: E731
    assert {key(t): t.measures for t in res.trials} == {key(t): t.measures for t in calm.trials}


@pytest.mark.slow
def test_a_killed_study_resumes_and_finishes_with_no_trial_repeated(tmp_path):
    path, out = tiny_study(tmp_path), tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "casadi_ws.cli", "study", str(path), "--out", str(out), "--quiet"],
                         cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t = time.perf_counter()
    while time.perf_counter() - t < 120:
        if (out / "trials.csv").is_file() and len(rows(out)) >= 2:
            break
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.wait()
    done_before = len(rows(out))
    assert 2 <= done_before < 4, "the study was not killed in the middle"
    r = cli("study", path, "--out", out, "--resume")
    assert r.returncode == 0, r.stderr
    got = rows(out)
    designs = [(float(g["material.young_modulus"]), float(g["cables[*].u_max"])) for g in got]
    assert len(got) == 4 and sorted(designs) == [(1.2e7, 60), (1.2e7, 100), (1.8e7, 60), (1.8e7, 100)]
    assert all(g["status"] == "complete" for g in got)
    assert len({g["trial"] for g in got}) == 4
    # resuming a finished study runs nothing
    r = cli("study", path, "--out", out, "--resume", "--quiet")
    assert r.returncode == 0 and len(rows(out)) == 4


@pytest.mark.slow
def test_an_optuna_study_with_two_objectives_on_two_workers(tmp_path):
    # two cables reach a surface: a pick point counts as reached within 1 mm (the study's tolerance)
    target = [0.0, 0.02, 0.19]
    path = tiny_study(tmp_path, method="optuna", trials=4, seed=3, target=target, reach_tolerance=1e-3,
                      variables=[{"path": "material.young_modulus", "range": [1.0e7, 3.0e7], "scale": "log"}],
                      objectives=[{"maximize": "area"}, {"minimize": "reach_tension"}])
    r = cli("study", path, "--out", tmp_path / "out", "--workers", "2", "--quiet")
    assert r.returncode == 0, r.stderr
    got = rows(tmp_path / "out")
    assert len(got) == 4 and all(g["status"] == "complete" for g in got)
    E = [float(g["material.young_modulus"]) for g in got]
    assert all(1.0e7 <= e <= 3.0e7 for e in E) and len(set(E)) == 4
    vol = np.array([float(g["area"]) for g in got])
    ten = np.array([float(g["reach_tension"]) for g in got])
    feas = np.array([g["feasible"] == "1" for g in got])
    assert np.all(np.array([float(g["reach_error"]) for g in got])[feas] <= 1e-3) and feas.any()
    pareto = np.array([g["pareto"] == "1" for g in got])
    for i in np.flatnonzero(pareto):  # no feasible design beats a Pareto design in both objectives
        assert feas[i]
        assert not np.any(feas & (vol >= vol[i]) & (ten <= ten[i]) & ((vol > vol[i]) | (ten < ten[i])))
    for i in np.flatnonzero(feas & ~pareto):
        assert np.any(feas & (vol >= vol[i]) & (ten <= ten[i]))
    best = cw.load_problem(tmp_path / "out" / "best.yaml")
    assert any(pareto[k] and float(got[k]["material.young_modulus"]) == best.material.young_modulus
               for k in range(4))
    # the tension a design needs to hold the target: checked against reach on that design
    k = int(np.argmax(feas))
    rr = cw.reach(cw.load_problem(tmp_path / "out" / "trials" / f"{int(got[k]['trial']):04d}" / "problem.yaml"), target,
                  settings=cw.ReachSettings(tolerance=1e-3))
    assert np.max(rr.u) == pytest.approx(ten[k], rel=1e-6)


def test_an_invalid_design_is_recorded_as_failed_and_the_study_goes_on(tmp_path):
    path = tiny_study(tmp_path, variables=[{"path": "cables[*].trunk_routing.radius", "values": [0.008, 0.05]}],
                      workspace={"method": "forward", "n_d": 3})
    res = cw.run_study(cw.load_study(path), tmp_path / "out", progress=False)
    by = {t.params["cables[*].trunk_routing.radius"]: t for t in res.trials}
    assert by[0.008].status == "complete"
    assert by[0.05].status == "failed" and "outside the body" in by[0.05].reason
    assert "cables[0].points" in by[0.05].reason
    assert res.best.number == by[0.008].number


@pytest.mark.parametrize("path", sorted(STUDIES.glob("*.yaml")), ids=lambda p: p.stem)
def test_a_bad_study_file_is_refused_in_one_line_before_any_trial(path, tmp_path):
    r = cli("study", path, "--out", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("casadi-ws: error: "), r.stderr
    assert str(path) in r.stderr or "no_such_problem" in r.stderr
    assert not (tmp_path / "out").exists()


EXPECTED = {"01_key_path_missing": "cables has 2 element(s)", "02_key_unknown_to_the_format": "no such key",
            "03_range_wrong_type": "expected [low, high]", "04_range_reversed": "low < high",
            "05_unknown_objective": "did you mean 'volume'", "06_reach_without_target": "target",
            "07_log_range_negative": "log scale", "08_optuna_without_trials": "number of trials",
            "09_base_problem_missing": "file not found", "10_base_problem_invalid": "poisson_ratio",
            "11_path_through_a_number": "not a mapping", "12_unknown_study_key": "did you mean 'objectives'",
            "13_index_past_the_list": "no [2]", "14_objective_not_a_name": "unknown objective",
            "15_workspace_backward_unknown": "reduced, ipopt"}


def test_the_bad_study_corpus_says_what_is_wrong():
    assert sorted(EXPECTED) == sorted(p.stem for p in STUDIES.glob("*.yaml"))
    for stem, words in EXPECTED.items():
        with pytest.raises(cw.ProblemError, match=None) as e:
            cw.load_study(STUDIES / f"{stem}.yaml")
        assert words in str(e.value), (stem, str(e.value))


def test_an_unreachable_scheduler_fails_before_any_trial(tmp_path):
    t = time.perf_counter()
    r = cli("study", tiny_study(tmp_path), "--out", tmp_path / "out", "--scheduler", "tcp://127.0.0.1:9")
    assert r.returncode == 2 and "tcp://127.0.0.1:9" in r.stderr and r.stderr.count("\n") == 1
    assert time.perf_counter() - t < 20
    assert not (tmp_path / "out" / "study.db").exists()


def test_a_repeated_design_is_recorded_with_its_first_trials_measures_not_recomputed(tmp_path):
    path = tiny_study(tmp_path, method="optuna", trials=3, variables=[{"path": "cables[*].u_max", "values": [80]}],
                      workspace={"method": "forward", "n_d": 3})
    res = cw.run_study(cw.load_study(path), tmp_path / "out", progress=False)
    assert [t.number for t in res.trials] == [0, 1, 2]
    assert res.trials[1].measures == res.trials[0].measures and res.trials[1].time_s == 0.0
    assert "same design as trial 0" in res.trials[2].reason
    assert not (tmp_path / "out" / "trials" / "0001").exists()


def test_resuming_with_a_changed_study_file_is_refused(tmp_path):
    path = tiny_study(tmp_path, variables=[{"path": "cables[*].u_max", "values": [80]}],
                      workspace={"method": "forward", "n_d": 3})
    assert cli("study", path, "--out", tmp_path / "out", "--quiet").returncode == 0
    changed = tiny_study(tmp_path, variables=[{"path": "cables[*].u_max", "values": [90]}],
                         workspace={"method": "forward", "n_d": 3})
    r = cli("study", changed, "--out", tmp_path / "out", "--resume")
    assert r.returncode == 2 and "different study file" in r.stderr and r.stderr.count("\n") == 1
    renamed = tiny_study(tmp_path, name="other", variables=[{"path": "cables[*].u_max", "values": [80]}],
                         workspace={"method": "forward", "n_d": 3})
    r = cli("study", renamed, "--out", tmp_path / "out", "--resume")
    assert r.returncode == 2 and "holds the study 'tiny', not 'other'" in r.stderr
    assert [g["cables[*].u_max"] for g in rows(tmp_path / "out")] == ["80"]


def test_a_resumed_optuna_study_proposes_new_designs_not_the_ones_it_ran(tmp_path):
    kw = dict(method="optuna", seed=5, variables=[{"path": "cables[*].u_max", "range": [50.0, 100.0]}],
              workspace={"method": "forward", "n_d": 3})
    cw.run_study(cw.load_study(tiny_study(tmp_path, trials=2, **kw)), tmp_path / "out", progress=False)
    res = cw.run_study(cw.load_study(tiny_study(tmp_path, trials=4, **kw)), tmp_path / "out", resume=True,
                       progress=False)
    assert len(res.trials) == 4 and not any("same design" in t.reason for t in res.trials)
    assert len({t.params["cables[*].u_max"] for t in res.trials}) == 4


def _die():
    os._exit(3)


def test_a_process_pool_that_lost_a_worker_restarts():
    from concurrent.futures import BrokenExecutor

    with cw.ProcessExecutor(1) as ex:
        with pytest.raises(BrokenExecutor):
            ex.submit(_die).result()
        with pytest.raises(BrokenExecutor):
            ex.submit(abs, -1)
        ex.restart()
        assert ex.submit(abs, -1).result() == 1



def test_a_script_without_the_main_guard_fails_at_once_with_the_reason(tmp_path):
    """Python's 'spawn' imports the caller's script again in every worker: without the guard each worker
    would start a pool of its own. It used to hang for ever (the parent's write of what starts a worker
    waited on a worker that had died); now the workers refuse, the parent stops, and both say why. Forked
    workers (Linux's default here, :func:`casadi_ws.runtime.executor.start_method`) import nothing again,
    and the same script runs."""
    script = tmp_path / "no_guard.py"
    script.write_text("import casadi_ws as cw\n"
                      f"p = cw.load_problem({str(REPO / 'problems' / 'trunk_2cables.yaml')!r})\n"
                      "r = cw.forward_backward(p, settings=cw.FBSettings(workers=2, progress=False, max_cells=30))\n"
                      "print('cells', r.counters['feasible'])\n")
    env = {**os.environ, "CASADI_WS_START_METHOD": "spawn"}
    t = time.perf_counter()
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                       env=env)
    assert r.returncode != 0 and time.perf_counter() - t < 60
    assert "must do so under 'if __name__ == \"__main__\":'" in r.stderr
    assert "BrokenProcessPool: a worker process ended while running" in r.stderr
    if sys.platform.startswith("linux"):
        env["CASADI_WS_START_METHOD"] = "fork"
        r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                           env=env)
        assert r.returncode == 0, r.stderr[-2000:]
        assert r.stdout.startswith("cells ")


def test_the_documented_study_file_is_valid(tmp_path):
    import re

    text = (REPO / "docs" / "studies.md").read_text()
    block = re.search(r"```yaml\n(.*?)```", text, flags=re.S).group(1)
    d = yaml.safe_load(block)
    d["problem"] = str(REPO / "problems" / d["problem"])
    study = cw.study.study_from_dict(d, "docs/studies.md", tmp_path)
    assert [v.path for v in study.variables][-1] == "material.model"
    for design in (study.designs()[0], study.designs()[-1]):  # every listed value is one the format accepts
        cw.problem_from_dict(study.problem_data(design), "design", REPO / "problems")


def test_trials_flag_is_for_optuna_studies_and_positive(tmp_path):
    r = cli("study", tiny_study(tmp_path), "--out", tmp_path / "out", "--trials", "2")
    assert r.returncode == 2 and "--trials: a grid study runs every design" in r.stderr and r.stderr.count("\n") == 1
    r = cli("study", REPO / "problems" / "study_trunk3.yaml", "--out", tmp_path / "out", "--trials", "0")
    assert r.returncode == 2 and "--trials: expected an integer >= 1, got 0" in r.stderr
    assert not (tmp_path / "out").exists()


def test_workers_are_forked_only_where_that_is_safe(monkeypatch):
    from casadi_ws.runtime.executor import START_METHOD_VARIABLE, StartMethodError, start_method

    monkeypatch.setenv(START_METHOD_VARIABLE, "spawn")
    assert start_method() == "spawn"
    monkeypatch.setenv(START_METHOD_VARIABLE, "threads")
    with pytest.raises(StartMethodError, match="expected 'fork', 'spawn' or 'auto'"):
        start_method()
    monkeypatch.setenv(START_METHOD_VARIABLE, "auto")
    assert start_method() in (("fork", "spawn") if sys.platform.startswith("linux") else ("spawn",))
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:  # a lock another thread holds would stay held in a forked child
        assert start_method() == "spawn"
    finally:
        stop.set()
        other.join()


def _sigint_is_pythons_own():
    return signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_forked_worker_does_not_keep_its_parents_ctrl_c_handler(monkeypatch):
    """A worker forked while the caller defers Ctrl-C would run its job on after Ctrl-C; a spawned one never
    had the handler."""
    if not sys.platform.startswith("linux"):
        monkeypatch.setenv("CASADI_WS_START_METHOD", "spawn")
    else:
        monkeypatch.setenv("CASADI_WS_START_METHOD", "fork")
    previous = signal.signal(signal.SIGINT, lambda *_: None)
    try:
        with cw.ProcessExecutor(1) as ex:
            assert ex.submit(_sigint_is_pythons_own).result()
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.slow
def test_a_long_study_in_one_process_keeps_its_memory_flat(tmp_path):
    """Issue 66: 45 trials run one after another in one process (a coarse 2-cable trunk, forward n_d = 3, ~0.35 s
    each) keep the resident memory flat. Bound: after ten trials of warm-up, less than a tenth of what one kept
    model costs (2.6 MB for this design with its forward run, measured by keeping six) per trial -- what keeping
    every trial's model alive (the id(model)-keyed caches once did) would exceed ten times over; measured ~25 kB
    per trial, so a 200-trial study grows by ~5 MB."""
    def rss_mb():
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS")) / 1024

    d = {"name": "long", "problem": str(REPO / "problems" / "trunk_2cables.yaml"), "set": {"mesh.resolution": 0.4},
         "variables": [{"path": "material.young_modulus", "range": [1.2e7, 2.0e7]}],
         "workspace": {"method": "forward", "n_d": 3}, "objectives": [{"maximize": "area"}],
         "method": "optuna", "trials": 45, "seed": 1}
    (tmp_path / "study.yaml").write_text(yaml.safe_dump(d))
    out, samples, done = tmp_path / "out", [], threading.Event()

    def watch():
        while not done.is_set():
            try:
                with open(out / "trials.csv") as f:
                    n = sum(1 for _ in f) - 1
            except OSError:
                n = -1
            samples.append((n, rss_mb()))
            time.sleep(0.2)

    t = threading.Thread(target=watch, daemon=True)
    t.start()
    res = cw.run_study(cw.load_study(tmp_path / "study.yaml"), out, progress=False)
    done.set()
    t.join()
    assert len(res.trials) == 45
    warm = [(n, r) for n, r in samples if 10 <= n < 45]
    assert warm[-1][0] - warm[0][0] >= 25, samples
    per_trial = (warm[-1][1] - warm[0][1]) / (warm[-1][0] - warm[0][0])
    print(f"resident memory: {per_trial * 1024:.0f} kB per trial")
    assert per_trial < 0.26
