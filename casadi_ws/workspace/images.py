"""The workspace of a map that folds: the union of the images of U's grid cells.

Where det dp/du changes sign inside U (the map folds over itself), the images of U's faces are no longer the
boundary of W = p(U): a fold's image (the critical set det A = 0, a surface inside U for 3 inputs) bounds W
too, and parts of the faces' images lie inside W as sheets. The construction here needs neither the
critical set nor one sign:

* U (3 inputs) is sampled on an n x n x n grid of verified equilibria; each grid cell is split into six
  tetrahedra along its main diagonal (Kuhn's split: neighbouring cells share their faces' diagonals, so the
  tetrahedra tile U), and p is taken linear on each. Its image is W_h = the union of the images of the
  tetrahedra, each a tetrahedron again (turned over where det A < 0).
* The union is computed exactly (a mesh boolean, manifold3d): its volume counts overlapping sheets once; its
  triangles bound W_h whatever the map does (a fold inside a cell included).
* The error of W_h is the interpolation's, O(h^2): the same union through every other node gives a second
  volume whose difference is reported as the error (conservative: on a map with a known fold it is 1.5-4x the
  actual error, see tests/test_folds.py).

Also reported, as references a sceptic can check: the sum of the tetrahedra's |volume| (the integral of
|det A| over U for the piecewise-linear map, each point counted once per preimage: an upper bound of the
volume, equal to it where the map does not fold) and how many tetrahedra are turned over.

Why a mesh boolean and not voxels: the exact union has no voxel error and gives the surface; with the
tetrahedra first joined into blocks of one sign (:class:`_Blocks`) it takes 0.3 s for a 17^3 grid's 24,534 on
tests/test_folds.py's map and 7.4 s on the folded SOFA trunk's (one by one: 27 s on the former). A
voxelisation fine enough for 1 % would cost seconds as well and give no surface. Why manifold3d: it is a
maintained library whose booleans are guaranteed to return a closed manifold (the surface's points are then
checked against it like the faces' surface).
"""

from __future__ import annotations

import itertools

import numpy as np

from ..fem.surface import _FACES as TET_FACES, components, unshared

__all__ = ["folded_share", "kuhn_tetrahedra", "orientations", "tetrahedron_volumes", "union_of_images"]

RELATIVE_DEGENERATE = 1e-12
"""A tetrahedron whose image's |volume| is below this share of the largest is left out of the union: it adds
no volume and a mesh boolean cannot take a flat solid."""


def kuhn_tetrahedra(n: int) -> np.ndarray:
    """(6 (n - 1)^3, 4) the tetrahedra of an n x n x n grid (node index (i n + j) n + k), each cell split along
    its main diagonal; positively oriented in the grid's own coordinates."""
    idx = np.arange(n**3).reshape(n, n, n)
    corner = {(a, b, c): idx[a:n - 1 + a, b:n - 1 + b, c:n - 1 + c].ravel()
              for a in (0, 1) for b in (0, 1) for c in (0, 1)}
    tets = []
    for perm in itertools.permutations(range(3)):
        cur, path = [0, 0, 0], [(0, 0, 0)]
        for axis in perm:
            cur[axis] = 1
            path.append(tuple(cur))
        t = np.column_stack([corner[p] for p in path])
        even = perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1))
        tets.append(t if even else t[:, [0, 2, 1, 3]])
    return np.vstack(tets)


def tetrahedron_volumes(P, T) -> np.ndarray:
    """Signed volumes of the tetrahedra T of the points P."""
    a, b, c, d = (P[T[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)) / 6.0


def orientations(P, n: int) -> np.ndarray:
    """The sign (+1, -1, or 0 where flat: below :data:`RELATIVE_DEGENERATE` of the largest) of each of the grid's
    tetrahedra's images (:func:`kuhn_tetrahedra` order)."""
    v = tetrahedron_volumes(P, kuhn_tetrahedra(n))
    return np.where(np.abs(v) > RELATIVE_DEGENERATE * np.abs(v).max(initial=0.0), np.sign(v), 0).astype(int)


def _turned(sign) -> int:
    return int(min(np.count_nonzero(sign > 0), np.count_nonzero(sign < 0)))


def folded_share(P, n: int) -> tuple[int, int]:
    """(turned over, all) tetrahedra of the grid's image whose orientation is the minority's: 0 where the map
    keeps one sign of det A at this sampling."""
    sign = orientations(P, n)
    return _turned(sign), int(np.count_nonzero(sign))


def union_of_images(P, n: int) -> dict:
    """The union of the images of the grid's tetrahedra (P: (n^3, 3) tips, node order (i n + j) n + k).

    Returns ``vertices``, ``triangles`` (outward, counter-clockwise seen from outside), ``volume``,
    ``jacobian_integral`` (sum of |tetrahedron volume|), ``turned_over``, ``tetrahedra`` and ``pieces`` (the
    solids the boolean joined)."""
    import manifold3d

    P = np.asarray(P, dtype=float)
    T = kuhn_tetrahedra(n)
    v = tetrahedron_volumes(P, T)
    sign = orientations(P, n)
    T = np.where((v < 0)[:, None], T[:, [0, 2, 1, 3]], T)
    # the boolean works in its own tolerance: centred, unit-sized coordinates
    centre, scale = P.mean(axis=0), max(float(np.ptp(P, axis=0).max()), 1e-300)
    solids = _Blocks((P - centre) / scale, T, sign, n - 1).solids()
    union = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add)
    mesh = union.to_mesh64()
    V = np.asarray(mesh.vert_properties, dtype=float)[:, :3] * scale + centre
    V, F = _without_flat_shells(V, np.asarray(mesh.tri_verts, dtype=np.int64))
    return {"vertices": V, "triangles": F,
            "volume": float(union.volume()) * scale**3, "jacobian_integral": float(np.abs(v[sign != 0]).sum()),
            "turned_over": _turned(sign), "tetrahedra": int(np.count_nonzero(sign)), "pieces": len(solids)}


def _without_flat_shells(V, F):
    """The surface without its shells (connected pieces) that enclose no volume: the boolean leaves sheets of
    zero thickness where tetrahedra nearly coincide (on the folded SOFA trunk, 359 shells of 310 cm^2 beside
    the workspace's one of 1,328 cm^2); they add area and no volume, and would be drawn."""
    if not len(F):
        return V, F
    shells = components(F)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    each = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    vol = np.array([each[s].sum() for s in shells])
    F = F[np.concatenate([s for s, v in zip(shells, vol) if abs(v) > 1e-9 * np.abs(vol).sum()])]
    used = np.unique(F)
    return V[used], np.searchsorted(used, F)


_FACES = np.array(TET_FACES)
"""A tetrahedron's faces, outward where its volume is positive."""


class _Blocks:
    """The tetrahedra (positively oriented) as few solids for the boolean, by an octree over the grid's cells:
    a block of cells whose tetrahedra all have one sign becomes one solid (the faces its tetrahedra do not
    share) if that surface is a manifold without self-intersections (ipctk): its winding number is then 0 or 1
    everywhere, so the solid is the union of its tetrahedra, overlaps excluded. Other blocks are split in
    eight; a cell that is not one solid gives its tetrahedra one by one. Why: the boolean of a 17^3 grid's
    24,534 tetrahedra one by one took 27 s (tests/test_folds.py's map)."""

    def __init__(self, X, T, sign, cells):
        self.X, self.T, self.sign, self.c = X, T, sign, cells

    def solids(self) -> list:
        return self._block((0, 0, 0), (self.c,) * 3)

    def _tets(self, lo, hi):
        idx = np.arange(self.c**3).reshape((self.c,) * 3)[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].ravel()
        t = (idx[None] + self.c**3 * np.arange(6)[:, None]).ravel()
        return t[self.sign[t] != 0]

    def _block(self, lo, hi) -> list:
        tets = self._tets(lo, hi)
        if not len(tets):
            return []
        if len(np.unique(self.sign[tets])) == 1:
            m = self._solid(tets)
            if m is not None:
                return [m]
        size = [b - a for a, b in zip(lo, hi)]
        if max(size) == 1:
            return [self._mesh(self.X[self.T[t]], _FACES) for t in tets]
        out = []
        halves = [((a, a + (b - a + 1) // 2), (a + (b - a + 1) // 2, b)) if b - a > 1 else ((a, b),)
                  for a, b in zip(lo, hi)]
        for parts in itertools.product(*halves):
            out += self._block(tuple(p[0] for p in parts), tuple(p[1] for p in parts))
        return out

    def _solid(self, tets):
        import ipctk
        import manifold3d

        if len(tets) == 1:
            return self._mesh(self.X[self.T[tets[0]]], _FACES)
        surface = unshared(self.T[tets][:, _FACES].reshape(-1, 3))
        used = np.unique(surface)
        local = np.searchsorted(used, surface).astype(np.int32)
        X = np.asfortranarray(self.X[used])
        m = self._mesh(X, local)
        if m.status() != manifold3d.Error.NoError:
            return None
        mesh = ipctk.CollisionMesh(X, np.asfortranarray(ipctk.edges(local)), np.asfortranarray(local))
        return None if ipctk.has_intersections(mesh, X) else m

    @staticmethod
    def _mesh(V, tris):
        import manifold3d

        return manifold3d.Manifold(manifold3d.Mesh64(vert_properties=np.ascontiguousarray(V),
                                                     tri_verts=np.asarray(tris, dtype=np.uint32)))
