"""The model's state q and its free positions, in named blocks (:class:`DofMap`).

q holds the nodal displacements (3 per node, node-major), then each block of unknowns a term brings (the
prescribed actuators' intensities, the contact forces, the continuous pressure), in the order the terms are
registered. The free dofs are the displacements not held by a support, then every unknown; the model's vectors
and matrices live on them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["DofMap"]


@dataclass
class DofMap:
    """Where each block of the state lies in q and among the free dofs."""

    n_mech: int
    """Nodal displacements in q (3 n_nodes): q[:n_mech]."""
    free_mech: np.ndarray
    """The displacements not held by a support (indices into q)."""
    blocks: dict[str, tuple[int, int]] = field(default_factory=dict)
    """name -> (start in q, size) of each block of unknowns after the displacements."""

    @classmethod
    def build(cls, n_mech: int, free_mech: np.ndarray, sizes: list[tuple[str, int]]) -> "DofMap":
        """Blocks of the given (name, size), one after the other after the displacements."""
        blocks, at = {}, n_mech
        for name, size in sizes:
            if name in blocks:
                raise ValueError(f"two blocks of unknowns named {name!r}")
            blocks[name] = (at, size)
            at += size
        return cls(n_mech, np.asarray(free_mech, dtype=np.int64), blocks)

    @property
    def n_extra(self) -> int:
        return sum(size for _, size in self.blocks.values())

    @property
    def n_dof(self) -> int:
        return self.n_mech + self.n_extra

    @property
    def n_free_mech(self) -> int:
        return self.free_mech.size

    @property
    def free(self) -> np.ndarray:
        """The free dofs (indices into q): the free displacements, then every unknown."""
        return np.concatenate([self.free_mech, self.n_mech + np.arange(self.n_extra)])

    @property
    def n_free(self) -> int:
        return self.n_free_mech + self.n_extra

    def state(self, name: str) -> slice:
        """The block ``name`` in q."""
        start, size = self.blocks[name]
        return slice(start, start + size)

    def rows(self, name: str) -> slice:
        """The block ``name`` among the free dofs (its rows of R, of K)."""
        start, size = self.blocks[name]
        start += self.n_free_mech - self.n_mech
        return slice(start, start + size)

    def positions(self) -> np.ndarray:
        """(n_dof,) each dof's position among the free dofs, -1 where it is held."""
        pos = -np.ones(self.n_dof, dtype=np.int64)
        pos[self.free] = np.arange(self.n_free)
        return pos
