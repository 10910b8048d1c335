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


@pytest.mark.slow
def test_a_tls_cluster_gives_the_process_pools_cells_and_refuses_a_stranger(trunk, tmp_path):
    """Issue 66: a scheduler and workers speaking TLS with the credentials casadi-ws cluster-certs writes; a
    client holding them gets the process pool's forward-backward cells; a client holding another authority's
    credentials, or none, is refused (one line, exit 2, on the command line)."""
    from distributed import LocalCluster, Security

    from casadi_ws.runtime.executor import SchedulerError
    from casadi_ws.runtime.tls import FILES, security, write_certificates

    pb, m = trunk
    ours, theirs = tmp_path / "ours", tmp_path / "theirs"
    write_certificates(ours), write_certificates(theirs)
    assert (ours / FILES["key"]).stat().st_mode & 0o077 == 0  # the key: its owner's only
    server = Security(tls_ca_file=str(ours / FILES["ca"]), tls_scheduler_cert=str(ours / FILES["cert"]),
                      tls_scheduler_key=str(ours / FILES["key"]), tls_worker_cert=str(ours / FILES["cert"]),
                      tls_worker_key=str(ours / FILES["key"]), tls_client_cert=str(ours / FILES["cert"]),
                      tls_client_key=str(ours / FILES["key"]), require_encryption=True)
    fs = cw.FBSettings(step=0.006, progress=False)
    with cw.ProcessExecutor(2) as ex:
        ref = cw.forward_backward(pb, fs, model=m, executor=ex)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, protocol="tls", security=server,
                      host="127.0.0.1", dashboard_address=":0", silence_logs=50) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://")
        with cw.DaskExecutor(address, problem=pb, security=security(ours)) as ex:
            got = cw.forward_backward(pb, fs, model=m, executor=ex)
        with pytest.raises(SchedulerError, match="cannot reach"):
            cw.DaskExecutor(address, problem=pb, security=security(theirs), timeout=3.0)
        for extra in (["--tls", str(theirs)], []):
            r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "solve",
                                str(REPO / "problems" / "trunk_2cables.yaml"), "--method", "fb", "--scheduler",
                                address, *extra, "--out", str(tmp_path / "out"), "--overwrite"],
                               capture_output=True, text=True)
            assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr[-2000:]
            assert ("cannot reach the Dask scheduler" if extra else "a TLS scheduler needs --tls DIR") in r.stderr
    np.testing.assert_array_equal(np.asarray(ref.arrays["cells"]), np.asarray(got.arrays["cells"]))
    np.testing.assert_allclose(ref.points, got.points, atol=1e-9)


def test_a_plain_tcp_scheduler_is_still_accepted_where_the_user_asks_for_it():
    """The README keeps a tcp:// scheduler to one machine (--host 127.0.0.1): its address works as it did, and
    --tls with it is refused as a contradiction."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=":0",
                      silence_logs=50) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        with cw.DaskExecutor(cluster.scheduler_address) as ex:
            assert ex.workers == 1
        from casadi_ws.cli import main

        assert main(["solve", str(REPO / "problems" / "trunk_2cables.yaml"), "--scheduler", cluster.scheduler_address,
                     "--tls", "tls", "--out", "/tmp/casadi-ws-tcp-tls", "--overwrite"]) == 2
