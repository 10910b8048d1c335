"""What is computed once per model and kept with it: one cache, owned by the model, gone with it.

Other layers keep their per-model objects here (the CasADi Functions of :mod:`casadi_ws.fem.functions`, the
rootfinders and IPOPT solvers of the NLPs, the admissibility checks' samples, the maps' operators) instead of
in module-level dictionaries keyed by ``id(model)``, which kept every model alive (a study's trials
accumulated theirs) or, weakly keyed, could hand a new model an old one's objects.
"""

from __future__ import annotations

import contextlib
import os
import sys

__all__ = ["ModelCache", "quiet_stdout"]


@contextlib.contextmanager
def quiet_stdout():
    """Silence the C-level stdout (MUMPS prints 'Entering DMUMPS ... JOB=-2' when a solver is destroyed)."""
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


class ModelCache:
    """Objects built once per model: ``get(key, make)`` builds on first use and returns the same object after.
    Dropped with the model (quietly: a solver destroyed then would print MUMPS's farewell)."""

    def __init__(self):
        self._items: dict = {}

    def get(self, key, make):
        try:
            return self._items[key]
        except KeyError:
            value = self._items[key] = make()
            return value

    def __contains__(self, key) -> bool:
        return key in self._items

    def pop(self, key, default=None):
        with quiet_stdout():
            return self._items.pop(key, default)

    def clear(self) -> None:
        if self._items:
            with quiet_stdout():
                self._items.clear()

    def __del__(self):
        try:
            self.clear()
        except Exception:  # noqa: BLE001 - at interpreter shutdown os or sys may be gone already
            pass

    def __getstate__(self):  # a model is never sent whole; if it is, its cache is rebuilt where it lands
        return {"_items": {}}
