"""Dask as the execution engine (issue: design studies): a LocalCluster gives the serial run's points, a
worker killed mid-sweep costs nothing but time, even with the only copy of the problem, and an unreachable
scheduler fails fast."""

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from conftest import REPO, small_trunk

import casadi_ws as cw


@pytest.fixture(scope="module")
def trunk():
    pb = small_trunk("corotational", 2)
    return pb, cw.StaticModel(pb)


@pytest.mark.slow
def test_local_cluster_forward_and_fb_equal_the_serial_runs(trunk):
    pb, m = trunk
    s = cw.ForwardSettings(n_d=8, progress=False)
    fs = cw.FBSettings(step=0.005, progress=False)
    a, c = cw.forward(pb, settings=s, model=m), cw.forward_backward(pb, fs, model=m)
    with cw.DaskExecutor(workers=2, problem=pb) as ex:
        assert ex.workers == 2 and ex.dashboard.startswith("http")
        b = cw.forward(pb, settings=s, model=m, executor=ex)
        d = cw.forward_backward(pb, fs, model=m, executor=ex)
    np.testing.assert_array_equal(a.u, b.u)
    # slices of the grid start from their own first point: equal to the equilibria's tolerance (the process
    # pool's test allows the same)
    assert np.abs(a.points - b.points).max() < 1e-9
    assert len(c.points) == len(d.points)
    np.testing.assert_array_equal(np.asarray(c.arrays["cells"]), np.asarray(d.arrays["cells"]))


def _sweep(trunk, ex, n_d=14):
    pb, m = trunk
    return cw.forward(pb, settings=cw.ForwardSettings(n_d=n_d, progress=False), model=m, executor=ex)


@pytest.mark.slow
def test_a_worker_killed_mid_sweep_changes_nothing(trunk):
    with cw.DaskExecutor(workers=2, problem=trunk[0]) as ex:
        # 900 points take ~1 s on 2 workers of an idle machine (14 x 14 took 0.5 s: a kill after 1 s came
        # after the sweep); the kill comes at 0.3 s
        calm = _sweep(trunk, ex, n_d=30)
        pids = list(ex.client.run(os.getpid).values())
        killer = threading.Timer(0.3, os.kill, (pids[0], signal.SIGKILL))
        killer.start()
        t = time.perf_counter()
        dask = _sweep(trunk, ex, n_d=30)
        killer.join()
        assert time.perf_counter() - t > 0.3  # the kill happened during the sweep
    for _ in range(50):  # the worker process is gone (its nanny reaps it and starts another)
        try:
            os.kill(pids[0], 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        raise AssertionError(f"worker process {pids[0]} still exists")
    # the lost slice ran again elsewhere, from the same start: the same points, bit for bit
    np.testing.assert_array_equal(calm.u, dask.u)
    np.testing.assert_array_equal(calm.points, dask.points)


@pytest.mark.slow
def test_the_problem_lost_with_the_worker_that_held_its_only_copy_is_sent_again(trunk):
    # once no task waits for the scattered problem, the scheduler keeps one copy of it (its active memory
    # manager); a worker killed with it used to cancel every later task ("lost dependencies")
    with cw.DaskExecutor(workers=2, problem=trunk[0]) as ex:
        calm = _sweep(trunk, ex)
        blob, = ex._blobs.values()
        for _ in range(100):
            holders = ex.client.who_has(blob)[blob.key]
            if len(holders) == 1:
                break
            time.sleep(0.1)
        else:
            pytest.fail(f"the problem stayed on {len(holders)} workers")
        pid = ex.client.run(os.getpid, workers=list(holders))[holders[0]]
        os.kill(pid, signal.SIGKILL)
        again = _sweep(trunk, ex)
    np.testing.assert_array_equal(calm.points, again.points)


def test_unreachable_scheduler_fails_fast_with_the_address():
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "solve", str(REPO / "problems" / "trunk_2cables.yaml"),
                        "--method", "fb", "--scheduler", "tcp://127.0.0.1:9", "--out", "/tmp/casadi-ws-no-scheduler",
                        "--overwrite"], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "--scheduler: cannot reach the Dask scheduler at tcp://127.0.0.1:9" in r.stderr
    assert time.perf_counter() - t < 20
