"""Bad input gives one clear line and exit code 2; long runs survive being killed."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import REPO, coarse_problem_file
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from casadi_ws import ProblemError, load_problem, problem_from_dict
from casadi_ws.cli import main
from casadi_ws.workspace.result import load_result

BAD = Path(__file__).parent / "bad_inputs"
CASES = sorted(BAD.glob("*.yaml"))


def _expected(path: Path) -> str:
    first = path.read_text().splitlines()[0]
    assert first.startswith("# expect: ")
    return first[len("# expect: "):]


def test_the_corpus_is_large_enough():
    assert len(CASES) >= 20


@pytest.mark.parametrize("path", CASES, ids=lambda p: p.stem)
def test_bad_problem_file(path, capsys):
    fragment = _expected(path)
    with pytest.raises(ProblemError) as exc:
        load_problem(path)
    assert fragment in str(exc.value) and str(exc.value).count(str(path)) == 1  # named once, not re-wrapped
    assert "\n" not in str(exc.value)
    assert main(["equilibrium", str(path), "--u", "1"]) == 2
    err = capsys.readouterr().err
    assert fragment in err and err.count("\n") == 1 and "Traceback" not in err


def test_bad_file_through_the_real_command_line():
    path = BAD / "10_poisson_half.yaml"
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "solve", str(path), "--out", "/nonexistent/x"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr
    assert r.stderr.strip().endswith("must be < 0.5, got 0.5")


VALID = yaml.safe_load((BAD / "09_young_modulus_zero.yaml").read_text().replace("young_modulus: 0",
                                                                                 "young_modulus: 1.0e+6"))
LEAVES = st.one_of(st.none(), st.booleans(), st.integers(-10, 10), st.floats(allow_nan=True, allow_infinity=True),
                   st.text(max_size=5), st.lists(st.floats(-1, 1), max_size=4), st.dictionaries(st.text(max_size=3),
                                                                                               st.integers(), max_size=2))


def _paths(d, prefix=()):
    if isinstance(d, dict):
        for k, v in d.items():
            yield prefix + (k,)
            yield from _paths(v, prefix + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield prefix + (i,)
            yield from _paths(v, prefix + (i,))


ALL_PATHS = list(_paths(VALID))


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(ALL_PATHS), LEAVES, st.sampled_from(["replace", "delete", "add"]))
def test_perturbed_problem_loads_or_fails_with_the_validation_error(path, value, action):
    d = yaml.safe_load(yaml.safe_dump(VALID))
    parent = d
    for k in path[:-1]:
        parent = parent[k]
    key = path[-1]
    if action == "replace":
        parent[key] = value
    elif action == "delete":
        del parent[key]
    elif isinstance(parent, dict):
        parent["extra_" + str(key)] = value
    else:
        parent.append(value)
    try:
        problem_from_dict(d, "<perturbed>")
    except ProblemError as exc:
        assert str(exc).startswith("<perturbed>")


def test_invalid_grid_step_or_budget_is_refused(tmp_path, capsys):
    path = REPO / "problems" / "trunk_2cables.yaml"
    for flag, value in (("--step", "0"), ("--step", "-0.004"), ("--step", "nan"), ("--max-cells", "0")):
        assert main(["solve", str(path), "--method", "fb", flag, value, "--out", str(tmp_path / "o")]) == 2
        assert flag in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------- resume

_coarse_problem = coarse_problem_file


def _cli(*args):
    return [sys.executable, "-m", "casadi_ws.cli", *map(str, args)]


def _kill_when_checkpointed(cmd, out: Path, sig=signal.SIGKILL, timeout=120):
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while not (out / "checkpoint.npz").exists():
        assert proc.poll() is None, f"finished before a checkpoint: {proc.communicate()}"
        assert time.time() - t0 < timeout
        time.sleep(0.05)
    time.sleep(0.3)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err


@pytest.mark.parametrize("method,args", [("forward", ["--nd", "24", "--checkpoint-every", "0.3"]),
                                         ("fb", ["--step", "0.006"])])
def test_killed_run_resumes_to_the_same_result(tmp_path, method, args):
    prob = _coarse_problem(tmp_path)
    base = ["solve", prob, "--method", method, *args, "--quiet"]
    ref = subprocess.run(_cli(*base, "--out", tmp_path / "ref"), capture_output=True, text=True)
    assert ref.returncode == 0, ref.stderr
    out = tmp_path / "killed"
    code, _ = _kill_when_checkpointed(_cli(*base, "--out", out), out)
    assert code == -signal.SIGKILL
    assert not (out / "summary.json").exists()
    r = subprocess.run(_cli(*base, "--out", out), capture_output=True, text=True)
    assert r.returncode == 2 and "--resume" in r.stderr  # never silently overwritten
    r = subprocess.run(_cli(*base, "--out", out, "--resume"), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    a, b = load_result(tmp_path / "ref"), load_result(out)
    assert a.n_points == b.n_points and a.n_failed == b.n_failed
    np.testing.assert_array_equal(a.u, b.u)
    assert np.abs(a.points - b.points).max() < 1e-8
    if method == "fb":
        for k in ("explored", "feasible", "iterations", "backward_solves"):
            assert a.counters[k] == b.counters[k], k
        # the surface's face nodes start from the same seeds (kept in the checkpoint)
        np.testing.assert_array_equal(a.boundary.vertices, b.boundary.vertices)
    assert not (out / "checkpoint.npz").exists()
    # --resume on a finished result: its summary, nothing recomputed
    r = subprocess.run(_cli(*base, "--out", out, "--resume"), capture_output=True, text=True)
    assert r.returncode == 0 and "complete" in r.stdout and f"{b.n_points} reachable points" in r.stdout


def test_resume_without_a_checkpoint_starts_the_run(tmp_path):
    prob = _coarse_problem(tmp_path)
    out = tmp_path / "never_checkpointed"
    r = subprocess.run(_cli("solve", prob, "--nd", "5", "--quiet", "--out", out, "--resume"),
                       capture_output=True, text=True)
    assert r.returncode == 0 and "starting the run" in r.stderr, r.stderr
    assert json.loads((out / "summary.json").read_text())["n_points"] == 25


def test_fb_budget_stops_cleanly_and_resumes_with_a_larger_one(tmp_path):
    prob = _coarse_problem(tmp_path)
    base = ["solve", prob, "--method", "fb", "--step", "0.006", "--quiet"]
    ref = subprocess.run(_cli(*base, "--out", tmp_path / "ref"), capture_output=True, text=True)
    assert ref.returncode == 0, ref.stderr
    out = tmp_path / "budget"
    r = subprocess.run(_cli(*base, "--max-cells", "50", "--out", out), capture_output=True, text=True)
    assert r.returncode == 0 and "Traceback" not in r.stderr
    warnings = [ln for ln in r.stderr.splitlines() if "--max-cells" in ln]
    assert len(warnings) == 1 and "budget of 50" in warnings[0]
    s = json.loads((out / "summary.json").read_text())
    assert s["counters"]["stopped_at_max_cells"] and any("--max-cells" in w for w in s["warnings"])
    assert 0 < s["n_points"] < load_result(tmp_path / "ref").n_points
    assert (out / "checkpoint.npz").is_file()  # resumable
    partial = load_result(out)
    r = subprocess.run(_cli(*base, "--max-cells", "100000", "--out", out, "--resume"), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    a, b = load_result(tmp_path / "ref"), load_result(out)
    assert a.n_points == b.n_points and not b.counters["stopped_at_max_cells"]
    np.testing.assert_array_equal(a.u, b.u)
    assert {tuple(p) for p in partial.u} <= {tuple(p) for p in b.u}  # what was verified stays


def test_ctrl_c_stops_cleanly_with_a_resumable_checkpoint(tmp_path):
    prob = _coarse_problem(tmp_path)
    out = tmp_path / "run"
    cmd = _cli("solve", prob, "--nd", "24", "--checkpoint-every", "0.3", "--quiet", "--out", out)
    code, err = _kill_when_checkpointed(cmd, out, sig=signal.SIGINT)
    assert code == 130 and "--resume" in err and "Traceback" not in err, err[-3000:]
    r = subprocess.run(_cli("solve", prob, "--nd", "24", "--quiet", "--out", out, "--resume"),
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert json.loads((out / "summary.json").read_text())["n_points"] == 24 * 24


def _size_limited(limit: int):
    """A child process whose files may not grow past ``limit`` bytes (what a full disk does to a write: the
    kernel refuses it, EFBIG here, ENOSPC there; Python ignores SIGXFSZ, so it raises OSError)."""
    import resource

    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


def test_a_disk_that_fills_while_the_results_are_written_is_one_line_and_no_complete_looking_result(tmp_path):
    """Issue 66's fault: the disk fills while ``solve`` writes (a 200 kB file-size limit: report.html is MBs).
    Exit 2, one line naming the folder and the reason, and no summary.json -- the mark of a complete result,
    written last -- so nothing reads the half-written folder as a result; a complete result that --overwrite was
    replacing loses its summary.json first, so the mixed folder does not pass for either."""
    prob = _coarse_problem(tmp_path)
    out = tmp_path / "out"
    base = _cli("solve", prob, "--nd", "3", "--quiet", "--shapes", "0", "--out", out)
    assert subprocess.run(base, capture_output=True, text=True).returncode == 0 and (out / "summary.json").exists()
    r = subprocess.run(base + ["--overwrite"], capture_output=True, text=True, preexec_fn=_size_limited(200_000))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr[-3000:]
    assert lines[0].startswith("casadi-ws: cannot write the results into") and "File too large" in lines[0]
    assert not (out / "summary.json").exists()
    r = subprocess.run(_cli("report", out, "--out", tmp_path / "r.html"), capture_output=True, text=True)
    assert r.returncode == 2 and "not a result directory" in r.stderr


def test_an_out_folder_that_cannot_take_files_is_refused_before_the_run(tmp_path):
    """--out where a file already is (a folder cannot be made there; a read-only folder fails the same probe
    write): one line, exit 2, before any model is built."""
    prob = _coarse_problem(tmp_path)
    (tmp_path / "taken").write_text("a file\n")
    r = subprocess.run(_cli("solve", prob, "--nd", "3", "--out", tmp_path / "taken" / "out"), capture_output=True,
                       text=True)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0
    assert r.stderr.startswith("casadi-ws: error: --out: cannot write into") and "Not a directory" in r.stderr


def test_a_disk_that_fills_during_a_run_keeps_the_last_checkpoint_and_resumes(tmp_path):
    """The disk fills while a run writes its checkpoint (a 5 kB file-size limit): exit 2, one line saying
    --resume continues; no partial checkpoint is left, and --resume without the limit finishes the run with
    every point (that a resumed run's points are an uninterrupted one's: test_killed_run_resumes_to_the_same_result)."""
    prob = _coarse_problem(tmp_path)
    base = ["solve", prob, "--nd", "12", "--checkpoint-every", "0.2", "--quiet", "--shapes", "0"]
    out = tmp_path / "out"
    r = subprocess.run(_cli(*base, "--out", out), capture_output=True, text=True, preexec_fn=_size_limited(5000))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr[-3000:]
    assert lines[0] == (f"casadi-ws: cannot write the checkpoint into {out}: File too large; free the space or give "
                        f"another --out, then run the same command with --resume")
    assert not list(out.glob(".*.tmp")) and not (out / "summary.json").exists()
    r = subprocess.run(_cli(*base, "--out", out, "--resume"), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-3000:]
    res = load_result(out)
    assert res.n_points + res.n_failed == 12**2 and res.n_failed == 0
