"""Executors: where the methods' independent pieces of work run (this process, or worker processes).

A method hands an executor a function, the problem and a list of jobs; the executor calls
``fn(model, *job)`` for each job with a model of the problem and yields the results. A design study, whose
pieces are whole workspace runs of different problems, uses the plain interface instead:
``submit(fn, *args)`` returns a future and ``wait(futures)`` splits futures into done and pending. Compiled CasADi
objects do not travel between processes, so only the problem, the jobs and the results (plain data and
numpy arrays) do: every worker process builds its model once per problem (:func:`model_for`, keyed by the
problem's fingerprint) and keeps it for the next job. IPOPT is not thread-safe under CasADi, so parallel
workers are processes with one thread each.

``SerialExecutor``   in this process, with the caller's model (no copy)
``ProcessExecutor``  a pool of N processes with one BLAS thread each: forked from this one where that is safe
                     (Linux, no other thread of Python's), else fresh ('spawn'); see :func:`start_method`
``DaskExecutor``     the workers of a Dask cluster: an existing one (its scheduler's address; workers on one
                     machine or many, started with ``dask worker ADDRESS --nthreads 1``) or a
                     ``distributed.LocalCluster`` of N single-threaded worker processes

OpenBLAS's threads slow this workload down: SuperLU and the small dense least-squares problems call BLAS on
blocks too small to share, and two processes each running two BLAS threads on two cores fight. Measured on
the trunk: a backward solve takes 0.29 s with one BLAS thread against 0.40 s with the default, a forward
point 33 ms against 36 ms. The methods therefore run with one BLAS thread (:func:`one_blas_thread`).

They also run with NumPy's large arrays in small pages (:func:`small_pages`).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import pickle
import signal
import sys
import tempfile
import threading
import weakref
from concurrent.futures import FIRST_COMPLETED, CancelledError, ProcessPoolExecutor, as_completed, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Callable, Iterator

from .run_state import problem_fingerprint

__all__ = ["DaskExecutor", "Executor", "ProcessExecutor", "SerialExecutor", "SchedulerError", "deferred_interrupt",
           "make_executor", "model_for", "one_blas_thread", "small_pages", "start_method", "StartMethodError"]


@contextlib.contextmanager
def one_blas_thread():
    """Run the enclosed code with a single BLAS thread, and MKL's PARDISO on one (restored afterwards)."""
    from threadpoolctl import threadpool_limits

    from ..solvers.linear import one_mkl_thread

    with threadpool_limits(limits=1, user_api="blas"), one_mkl_thread():
        yield


@contextlib.contextmanager
def small_pages():
    """Run the enclosed code with NumPy's arrays of 4 MB and more in ordinary pages (restored afterwards),
    unless ``NUMPY_MADVISE_HUGEPAGE`` says otherwise.

    Why: NumPy asks Linux for transparent huge pages for such arrays, and where the kernel then compacts memory
    to find one (``defrag`` = ``madvise``, the usual setting) while memory is fragmented, the first touch of an
    array stalls. Measured on the developers' virtual machines (Linux 6.18, 24 GiB, 6 GiB of page cache): a
    250 MB array took 2.7-4.0 s to fill or copy the first time against 0.1 s in small pages; the forward sweep
    of the 3-cable trunk at n_d = 30, whose cube keeps 0.3 GB of states, took 81 and 67 s in one process,
    42.7-45.7 and 38.4-39.7 s with 2 workers. The arrays that are large here are states and sensitivities,
    read a few times each: huge pages would save little in address translation."""
    before = _huge_pages(False)
    try:
        yield
    finally:
        if before is not None:
            _huge_pages(before)


def _huge_pages(enabled: bool) -> bool | None:
    """Whether NumPy asks for huge pages from now on; returns the setting before, or None (nothing changed)
    where NumPy has no such switch or ``NUMPY_MADVISE_HUGEPAGE`` is set."""
    import numpy as np

    core = getattr(np, "_core", None) or getattr(np, "core", None)
    toggle = getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)
    if toggle is None or "NUMPY_MADVISE_HUGEPAGE" in os.environ:
        return None
    return bool(toggle(bool(enabled)))


_MODELS: dict[str, object] = {}


def model_for(problem, key: str | None = None):
    """This process's model of ``problem``, built on first use and kept (one per problem fingerprint).

    ``problem`` may be given pickled (bytes), with its ``key``: it is then unpickled only if no model of
    that key exists yet.
    """
    from ..fem.model import StaticModel

    key = key or problem_fingerprint(problem)
    if key not in _MODELS:
        if isinstance(problem, bytes):
            problem = pickle.loads(problem)
        if len(_MODELS) >= 4:  # a design study sends many problems: keep the newest few
            _MODELS.pop(next(iter(_MODELS)))
        _MODELS[key] = StaticModel(problem)
    return _MODELS[key]


def _call(fn, key, blob, job):
    return fn(model_for(blob, key), *job)


def _plain_one_thread(fn, args):
    with one_blas_thread(), small_pages():
        return fn(*args)


def _call_one_thread(fn, key, blob, job):
    # a Dask worker process is not ours to configure at start: limit BLAS around each job
    with one_blas_thread(), small_pages():
        return fn(model_for(blob, key), *job)


class Executor:
    """Interface: run ``fn(model, *job)`` for every job. Use as a context manager or call :meth:`close`."""

    workers: int = 1

    def map_unordered(self, fn: Callable, problem, jobs: list) -> Iterator[tuple[int, object]]:
        """Yield ``(index, result)`` as jobs complete."""
        raise NotImplementedError

    def map(self, fn: Callable, problem, jobs: list) -> list:
        """The results in job order."""
        out = [None] * len(jobs)
        for i, r in self.map_unordered(fn, problem, jobs):
            out[i] = r
        return out

    def submit(self, fn: Callable, *args):
        """Start ``fn(*args)`` (a module-level function: it may run in another process); a future."""
        raise NotImplementedError

    def wait(self, futures) -> tuple[set, set]:
        """Block until at least one of ``futures`` is done: (done, pending)."""
        done, pending = wait(futures, return_when=FIRST_COMPLETED)
        return set(done), set(pending)

    def restart(self) -> None:
        """Start over after a worker was lost (a process pool breaks when one of its processes dies)."""

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SerialExecutor(Executor):
    """Jobs run here, one after the other, on ``model`` (or on this process's model of the problem)."""

    def __init__(self, model=None):
        self.model = model

    def map_unordered(self, fn, problem, jobs):
        model = self.model if self.model is not None else model_for(problem)
        for i, job in enumerate(jobs):
            yield i, fn(model, *job)

    def submit(self, fn, *args):
        return _Ready(fn, args)

    def wait(self, futures):
        return set(futures), set()


class _Ready:
    """A call already made (SerialExecutor.submit): the part of a Future's interface callers use."""

    def __init__(self, fn, args):
        try:
            self._value, self._error = fn(*args), None
        except Exception as exc:  # noqa: BLE001 - re-raised by result(), as a Future does
            self._value, self._error = None, exc

    def done(self) -> bool:
        return True

    def result(self):
        if self._error is not None:
            raise self._error
        return self._value


def _init_worker(key, blob_file):
    from threadpoolctl import threadpool_limits

    # Ctrl-C in a worker is Python's KeyboardInterrupt (or ignored, where it was when the parent started), as in a
    # fresh process: a forked one would otherwise keep a handler its parent set (a deferred one lets the job run on)
    handler = signal.getsignal(signal.SIGINT)
    if callable(handler) and handler is not signal.default_int_handler:
        signal.signal(signal.SIGINT, signal.default_int_handler)

    threadpool_limits(limits=1, user_api="blas")  # for the worker's lifetime
    _huge_pages(False)  # likewise (see small_pages)
    if blob_file is not None:
        with open(blob_file, "rb") as f:
            model_for(f.read(), key)  # built while the caller still prepares the first jobs


def _remove(path: str) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


class ProcessExecutor(Executor):
    """A pool of ``workers`` fresh processes, each with one BLAS thread and its own models.

    Given a ``problem``, every worker builds its model at start and jobs of that problem send no copy of it;
    jobs of other problems carry it (pickled once per call, unpickled by a worker only to build its model).
    The workers read the problem from a temporary file, not from what starts them: Python writes that to a
    new worker through a pipe (64 KiB) before the worker reads it, and where the worker dies first (a script
    without the ``__main__`` guard) the write never ended. Given the ``model`` of ``problem`` as well, forked
    workers (:func:`start_method`) start with it instead of building their own.
    """

    def __init__(self, workers: int, problem=None, model=None):
        if getattr(mp.current_process(), "_inheriting", False):
            # this is a worker importing the caller's script (Python's 'spawn' runs it again in every worker):
            # without the guard the script would start pools of its own, and the pool that started this worker
            # would wait for it forever
            raise RuntimeError("casadi-ws: a script that runs a method with more than one worker must do so under "
                               "'if __name__ == \"__main__\":' (every worker process imports the script again)")
        self.workers = int(workers)
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")  # inherited by the children before they import numpy
        self._key = None if problem is None else problem_fingerprint(problem)
        self._blob_file = None
        if problem is not None:
            fd, self._blob_file = tempfile.mkstemp(prefix="casadi-ws-problem-", suffix=".pickle")
            with os.fdopen(fd, "wb") as f:
                pickle.dump(problem, f, protocol=4)
            weakref.finalize(self, _remove, self._blob_file)
        self._starter = None
        self._pool = self._start(model)

    def _start(self, model=None):
        method = start_method()
        pool = ProcessPoolExecutor(self.workers, mp_context=mp.get_context(method), initializer=_init_worker,
                                   initargs=(self._key, self._blob_file))
        _large_pipes(pool)
        if method == "fork":
            # Python forks every worker at the pool's first submission, here, in this thread: they start at once
            # with this process's modules and model (the caller's, when given)
            lent = model is not None and self._key is not None and self._key not in _MODELS
            if lent:
                _MODELS[self._key] = model
            try:
                _start_workers(pool, self.workers)
            finally:
                if lent:
                    _MODELS.pop(self._key, None)
            return pool
        # a pool spawns its processes at its first submissions, each blocking the submitter until the child
        # has imported the main module (~0.4 s): asked for here, from a thread, the workers start and build
        # their models while this process builds its own and solves the first equilibrium
        self._starter = threading.Thread(target=_start_workers, args=(pool, self.workers), daemon=True)
        self._starter.start()
        return pool

    def restart(self) -> None:
        if self._starter is not None:
            self._starter.join()
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = self._start()

    def map_unordered(self, fn, problem, jobs):
        key = problem_fingerprint(problem)
        blob = None if key == self._key else pickle.dumps(problem, protocol=4)
        futures = {self._pool.submit(_call, fn, key, blob, job): i for i, job in enumerate(jobs)}
        pending = set(futures)
        try:
            for f in as_completed(futures):  # one waiter per future (wait() adds one to each pending per call)
                pending.discard(f)
                yield futures[f], f.result()
        except BrokenProcessPool:
            raise BrokenProcessPool("a worker process ended while running (killed, out of memory, or a script "
                                    "that starts workers outside 'if __name__ == \"__main__\":')") from None
        finally:
            for f in pending:
                f.cancel()

    def submit(self, fn, *args):
        return self._pool.submit(fn, *args)

    def close(self) -> None:
        if self._starter is not None:
            self._starter.join()
        if getattr(self._pool, "_broken", False):
            # a worker died: the pool signals the workers it knew of then, and waits for all of them; one it
            # spawned meanwhile (a submission racing with the break) would keep it waiting forever (seen once,
            # a benchmark hung at start with one idle worker left)
            for p in list((getattr(self._pool, "_processes", None) or {}).values()):
                p.kill()
        self._pool.shutdown(cancel_futures=True)
        if self._blob_file is not None:
            _remove(self._blob_file)


PIPE_BYTES = 1 << 20
"""The buffer of the pool's job and result pipes (Linux; its default limit for a process is 1 MiB)."""


def _large_pipes(pool) -> None:
    """Enlarge the pipes that carry the pool's jobs and results to :data:`PIPE_BYTES`, where the system allows.

    Why: a forward-backward job and its result carry a configuration's state, S and Q (~0.2 MB each on the
    4-cable trunk), and a pipe holds 64 KiB: a worker's write then waited for this process to be scheduled and
    read, with both cores busy. Measured on the 4-cable trunk (2 workers): the gaps between a worker's jobs
    1.7 -> 1.0 ms (median), 1.5 -> 0.85 s per worker over the run. The queues are the pool's own (private in
    ``concurrent.futures``): if a Python version names them otherwise, the pipes keep their size."""
    try:
        import fcntl

        for queue in (pool._call_queue, pool._result_queue):
            for end in (queue._reader, queue._writer):
                fcntl.fcntl(end.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)
    except (ImportError, AttributeError, OSError):
        pass


START_METHOD_VARIABLE = "CASADI_WS_START_METHOD"
"""The environment variable that chooses how worker processes start: ``fork``, ``spawn`` or ``auto`` (default)."""


class StartMethodError(ValueError):
    """:data:`START_METHOD_VARIABLE` names no start method."""


def start_method() -> str:
    """How :class:`ProcessExecutor` starts its workers: ``fork`` on Linux while this process runs no other
    Python thread (and, from Python 3.12 on, which warns about it, no other thread at all), else ``spawn``;
    :data:`START_METHOD_VARIABLE` overrides it.

    Why fork: a spawned worker imports the package again (~0.7 s) and builds its model (~0.2 s), competing for
    the cores with this process's first solves; on the 4-cable trunk with 2 workers the first jobs started
    1.1-1.4 s into the run, 0.5 s with forked workers, which take the caller's model as it is. Why not always:
    a fork copies only the thread that calls it, and a lock another thread held stays held in the child
    (macOS's system libraries are not fork-safe at all). The idle threads of OpenBLAS's pool are made safe by
    OpenBLAS itself, which stops them around a fork."""
    chosen = os.environ.get(START_METHOD_VARIABLE, "auto")
    if chosen in ("fork", "spawn"):
        return chosen
    if chosen != "auto":
        raise StartMethodError(f"{START_METHOD_VARIABLE}={chosen!r}: expected 'fork', 'spawn' or 'auto'")
    alone = threading.active_count() == 1 and (sys.version_info < (3, 12) or _os_threads() == 1)
    return "fork" if sys.platform.startswith("linux") and alone else "spawn"


def _os_threads() -> int:
    try:
        return len(os.listdir("/proc/self/task"))
    except OSError:
        return 0


def _ready() -> None:
    from ..solvers.linear import available

    available("pardiso")  # MKL loaded before the first job


def _start_workers(pool, workers: int) -> None:
    try:
        for _ in range(workers):
            pool.submit(_ready)
    except RuntimeError:  # shut down or broken meanwhile: the caller's own submissions say so
        pass


class SchedulerError(RuntimeError):
    """The Dask scheduler could not be reached."""


class DaskExecutor(Executor):
    """Jobs run as Dask tasks: on the cluster at ``address`` or on a LocalCluster of ``workers`` processes.

    The problem travels once to every worker (``Client.scatter(broadcast=True)``); each worker builds its
    model on its first job of that problem and keeps it. Tasks lost with a worker are run again elsewhere by
    the scheduler (and by this executor, with the problem scattered again, where the worker held its last
    copy), and the jobs are deterministic, so the results are the same. Workers must run one thread
    each: IPOPT under CasADi is not thread-safe.

    ``window`` tasks at most are in flight per ``map_unordered`` (default: two per worker), the next job
    submitted as one finishes: the caller orders its jobs longest first, and handing all of them to the
    scheduler at once loses that order (the whole FB of ``trunk_2cables_order2`` with 2 workers: 138-141 s
    with every task submitted at once, 120 s with a window of 2 and 123 s with 4; the process pool 99 s).
    """

    def __init__(self, address: str | None = None, workers: int | None = None, problem=None,
                 timeout: float = 10.0, window: int | None = None, security=None):
        from distributed import Client, LocalCluster

        self._cluster = None
        if address:
            try:
                # security: a distributed.Security for a tls:// scheduler (casadi_ws.runtime.tls.security)
                self.client = Client(address, timeout=timeout, **({"security": security} if security else {}))
            except (OSError, TimeoutError) as exc:
                raise SchedulerError(f"cannot reach the Dask scheduler at {address} within {timeout:g} s "
                                     f"({type(exc).__name__})") from None
        else:
            for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
                os.environ.setdefault(var, "1")
            self._cluster = LocalCluster(n_workers=int(workers or 1), threads_per_worker=1, processes=True,
                                         dashboard_address=":0", silence_logs=50)
            self.client = Client(self._cluster)
        self.workers = max(1, len(self.client.scheduler_info().get("workers", {})))
        self.dashboard = self.client.dashboard_link
        self._blobs: dict[str, object] = {}
        self.window = max(1, int(window)) if window else 2 * self.workers

    def _blob(self, problem):
        key = problem_fingerprint(problem)
        if key not in self._blobs:
            # (a new key each time: one scattered again after a loss must not be taken for the lost one)
            self._blobs[key] = self.client.scatter(pickle.dumps(problem, protocol=4), broadcast=True, hash=False)
        return key, self._blobs[key]

    def map_unordered(self, fn, problem, jobs):
        from distributed import as_completed

        key, blob = self._blob(problem)
        todo = iter(enumerate(jobs))
        index, live, job_of, resent = {}, set(), {}, {}
        done = as_completed()

        def submit(i, job):
            f = self.client.submit(_call_one_thread, fn, key, blob, job, pure=False)
            index[f.key], job_of[f.key] = i, (job, blob)
            live.add(f)
            done.add(f)

        def submit_next():
            for i, job in todo:
                submit(i, job)
                return

        for _ in range(self.window):
            submit_next()
        try:
            for f in done:
                live.discard(f)
                job, sent_with = job_of.pop(f.key)
                try:
                    out = f.result()
                except CancelledError:
                    # the scheduler keeps one copy of the scattered problem once no task waits for it (its
                    # active memory manager); a task that then needs it on a worker lost meanwhile is
                    # cancelled ("lost dependencies"), not run again: the problem is scattered anew and the
                    # job resubmitted, a few times at most
                    resent[index[f.key]] = resent.get(index[f.key], 0) + 1
                    if resent[index[f.key]] > 3:
                        raise
                    if sent_with is blob:  # (the tasks in flight with it share one new copy)
                        self._blobs.pop(key, None)
                        key, blob = self._blob(problem)
                    submit(index[f.key], job)
                    continue
                submit_next()
                yield index[f.key], out
        finally:
            self.client.cancel([f for f in live if not f.done()])

    def submit(self, fn, *args):
        return self.client.submit(_plain_one_thread, fn, args, pure=False)

    def wait(self, futures):
        from distributed import wait as dask_wait

        done, pending = dask_wait(list(futures), return_when="FIRST_COMPLETED")
        return set(done), set(pending)

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_executor(workers: int, model=None, problem=None) -> Executor:
    """``SerialExecutor(model)`` for one worker, else a ``ProcessExecutor`` (set up for ``problem``)."""
    return SerialExecutor(model) if int(workers) <= 1 else ProcessExecutor(workers, problem, model)


class _Deferred:
    requested = False

    def check(self) -> None:
        """Raise KeyboardInterrupt here, at a safe point, if Ctrl-C was pressed."""
        if self.requested:
            self.requested = False
            raise KeyboardInterrupt


@contextlib.contextmanager
def deferred_interrupt():
    """Turn Ctrl-C into a flag that the code checks at safe points (``.check()``).

    A KeyboardInterrupt raised inside CasADi's or SciPy's C code can surface as a SystemError, and it can
    leave a half-updated state; deferring it to points where the state is complete keeps the checkpoint
    consistent and the exit clean. A second Ctrl-C interrupts at once.
    """
    d = _Deferred()
    if threading.current_thread() is not threading.main_thread():
        yield d
        return
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum, frame):
        if d.requested:  # pressed twice: stop now
            signal.signal(signal.SIGINT, previous)
            raise KeyboardInterrupt
        d.requested = True

    signal.signal(signal.SIGINT, handler)
    try:
        yield d
    finally:
        signal.signal(signal.SIGINT, previous)
