"""Execution: executors (this process, worker processes) and the run state of long runs (checkpoints)."""

from .executor import Executor, ProcessExecutor, SerialExecutor, make_executor
from .run_state import CheckpointError, RunState

__all__ = ["CheckpointError", "Executor", "ProcessExecutor", "RunState", "SerialExecutor", "make_executor"]
