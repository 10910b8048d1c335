"""Processes and threads for the hot loops.

OpenBLAS's threads slow this workload down: SuperLU and the small dense least-squares problems call BLAS on
blocks too small to share, and two processes each running two BLAS threads on two cores fight. Measured on
the trunk: a backward solve takes 0.29 s with one BLAS thread against 0.40 s with the default, a forward
point 33 ms against 36 ms. The methods therefore run with one BLAS thread and use processes (each with its
own model; IPOPT is not thread-safe under CasADi's ``map``) for parallel work.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import threading
from concurrent.futures import ProcessPoolExecutor

__all__ = ["deferred_interrupt", "one_blas_thread", "process_pool"]


@contextlib.contextmanager
def one_blas_thread():
    """Run the enclosed code with a single BLAS thread (restored afterwards)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _init(initializer, initargs):
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")  # for the worker's lifetime
    if initializer is not None:
        initializer(*initargs)


def process_pool(workers: int, initializer=None, initargs=()) -> ProcessPoolExecutor:
    """A pool of fresh ('spawn') processes with one BLAS thread each."""
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")  # inherited by the children before they import numpy
    return ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"), initializer=_init,
                               initargs=(initializer, initargs))


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
