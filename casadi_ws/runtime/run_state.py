"""Run state of long runs: what determines the answer (fingerprint), checkpoints, resume, elapsed time.

A checkpoint is one ``checkpoint.npz`` in the output directory (arrays, plus a JSON string of plain data)
written to a temporary file and renamed over the previous one, so a run killed at any instant (even by
SIGKILL) leaves either the previous checkpoint or the new one, never a torn file. Its ``fingerprint``
(method, problem, settings that change the answer) must match on resume; otherwise resuming is refused with
a clear message. Forward and forward-backward keep their state through one :class:`RunState`.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

__all__ = ["CHECKPOINT", "CheckpointError", "RunState", "fingerprint", "load_checkpoint", "problem_fingerprint",
           "save_checkpoint"]

CHECKPOINT = "checkpoint.npz"


class CheckpointError(ValueError):
    """A checkpoint that cannot be resumed (missing, or made by a different run)."""


def fingerprint(method: str, model, settings: dict) -> str:
    """Hash of what determines the answer: the method, the model's geometry and loads, the settings."""
    h = hashlib.sha256(method.encode())
    # Pe: quadrature weights and material parameters per element, per law (material regions)
    for a in (model.X, model.mesh.tets, model.free, model.F, model.u_min, model.u_max, model.p0,
              *(g.Pe for g in model.element_groups), model.prescribed):
        h.update(np.ascontiguousarray(a).tobytes())
    pb = model.spec
    h.update(json.dumps([asdict(pb.material), [asdict(m) for _, m in pb.regions], asdict(pb.solver),
                         [a.describe() for a in model.actuators], asdict(pb.admissibility),
                         [o.describe() for o in pb.obstacles]],
                        default=float).encode())
    # the terms a specification adds (springs, pressure loads, a user's) and the self-contact pairs, as pickled
    h.update(pickle.dumps([pb.terms, pb.self_contact], protocol=4))
    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    return h.hexdigest()[:20]


def problem_fingerprint(problem) -> str:
    """Hash of a problem object as it travels to worker processes (pickled): workers key their models by it."""
    return hashlib.sha256(pickle.dumps(problem, protocol=4)).hexdigest()[:20]


def save_checkpoint(directory: str | Path, meta: dict, arrays: dict) -> Path:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    final = d / CHECKPOINT
    tmp = d / f".{CHECKPOINT}.{os.getpid()}.tmp"
    try:
        with open(tmp, "wb") as f:
            np.savez(f, __meta__=np.array(json.dumps(meta, default=_plain)), **arrays)
            f.flush()
            os.fsync(f.fileno())
    except OSError:  # a full disk: the last whole checkpoint stays, the partial one goes
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, final)
    return final


def load_checkpoint(directory: str | Path, expected_fingerprint: str) -> tuple[dict, dict]:
    path = Path(directory) / CHECKPOINT
    if not path.is_file():
        raise CheckpointError(f"{path}: no checkpoint to resume from")
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["__meta__"]))
        arrays = {k: z[k] for k in z.files if k != "__meta__"}
    if meta.get("fingerprint") != expected_fingerprint:
        raise CheckpointError(f"{path}: made by a different problem or settings; rerun without --resume "
                              f"(and with --overwrite) to start afresh")
    return meta, arrays


class RunState:
    """Checkpointing of one run of a method.

    ``RunState(directory, method, fingerprint, resume)``: with ``resume`` the checkpoint in ``directory`` is
    read (``saved`` holds its (meta, arrays), ``previous`` the seconds already spent); without a directory
    nothing is written. ``t0`` is when the run started (``time.perf_counter()``; default: now). :meth:`save` writes a checkpoint, :meth:`finish` removes it once the result files
    replace it.
    """

    def __init__(self, directory, method: str, fingerprint: str, resume: bool = False, t0: float | None = None):
        self.directory = None if directory is None else Path(directory)
        self.method = method
        self.fingerprint = fingerprint
        self.t0 = time.perf_counter() if t0 is None else t0
        self.saved: tuple[dict, dict] | None = None
        self.previous = 0.0
        if resume:
            if self.directory is None:
                raise ValueError("resume needs the checkpoint directory")
            self.saved = load_checkpoint(self.directory, fingerprint)
            self.previous = float(self.saved[0].get("elapsed", 0.0))

    def elapsed(self) -> float:
        """Seconds of this run, those before a resume included."""
        return self.previous + time.perf_counter() - self.t0

    def save(self, meta: dict, arrays: dict) -> None:
        if self.directory is not None:
            save_checkpoint(self.directory, {"fingerprint": self.fingerprint, "method": self.method,
                                             "elapsed": self.elapsed(), **meta}, arrays)

    def finish(self) -> None:
        if self.directory is not None:
            (self.directory / CHECKPOINT).unlink(missing_ok=True)


def _plain(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.integer, np.floating, np.bool_)):
        return o.item()
    raise TypeError(type(o).__name__)
