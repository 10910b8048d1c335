"""Execution: executors (this process, worker processes, a Dask cluster) and the run state of long runs."""

from .executor import DaskExecutor, Executor, ProcessExecutor, SchedulerError, SerialExecutor, make_executor
from .run_state import CheckpointError, RunState

__all__ = ["CheckpointError", "DaskExecutor", "Executor", "ProcessExecutor", "RunState", "SchedulerError",
           "SerialExecutor", "make_executor"]
