"""Checkpoints of long runs: written atomically into the output directory, read back by ``--resume``.

A checkpoint is one ``checkpoint.npz`` (arrays, plus a JSON string of plain data) written to a temporary
file and renamed over the previous one, so a run killed at any instant (even by SIGKILL) leaves either
the previous checkpoint or the new one, never a torn file. Its ``fingerprint`` (method, problem, settings
that change the answer) must match on resume; otherwise resuming is refused with a clear message.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict
from pathlib import Path

import numpy as np

__all__ = ["CheckpointError", "fingerprint", "load_checkpoint", "save_checkpoint", "CHECKPOINT"]

CHECKPOINT = "checkpoint.npz"


class CheckpointError(ValueError):
    """A checkpoint that cannot be resumed (missing, or made by a different run)."""


def fingerprint(method: str, model, settings: dict) -> str:
    """Hash of what determines the answer: the method, the model's geometry and loads, the settings."""
    h = hashlib.sha256(method.encode())
    for a in (model.X, model.mesh.tets, model.free, model.F, model.u_min, model.u_max, model.p0):
        h.update(np.ascontiguousarray(a).tobytes())
    pb = model.problem
    h.update(json.dumps([asdict(pb.material), asdict(pb.solver),
                         [np.asarray(c.points).tolist() for c in pb.cables],
                         [None if c.pull_point is None else np.asarray(c.pull_point).tolist() for c in pb.cables]],
                        default=float).encode())
    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    return h.hexdigest()[:20]


def save_checkpoint(directory: str | Path, meta: dict, arrays: dict) -> Path:
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    final = d / CHECKPOINT
    tmp = d / f".{CHECKPOINT}.{os.getpid()}.tmp"
    with open(tmp, "wb") as f:
        np.savez(f, __meta__=np.array(json.dumps(meta, default=_plain)), **arrays)
        f.flush()
        os.fsync(f.fileno())
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


def _plain(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.integer, np.floating, np.bool_)):
        return o.item()
    raise TypeError(type(o).__name__)
