"""Workspace methods: forward, forward-backward (Algorithm 1) with its backward problem and interval boxes,
the result they share, and comparison measures."""

from .backward import BackwardResult, BackwardSettings, backward
from .compare import compare
from .forward import ForwardSettings, forward
from .forward_backward import FBSettings, forward_backward
from .interval import Grid, interval_box, neighbourhood
from .measures import Task, measures, read_task
from .result import WorkspaceResult, load_result

__all__ = ["BackwardResult", "BackwardSettings", "FBSettings", "ForwardSettings", "Grid", "Task", "WorkspaceResult",
           "backward", "compare", "forward", "forward_backward", "interval_box", "load_result", "measures",
           "neighbourhood", "read_task"]
