"""Tetrahedral meshes: loading, generating, checking, and embedding points in them.

A :class:`Mesh` holds rest node positions (n, 3) in metres and tetrahedra (m, n_nodes of its element type),
positively oriented.
Files are read with meshio (legacy VTK, VTU, Gmsh, ...); only ``tetra`` cells are kept, the triangles, lines
and vertices such files often carry are ignored, and nodes used by no tetrahedron are dropped.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from .elements import TET4, TET10, TET10_EDGES, ElementType

__all__ = [
    "Mesh",
    "quadratic",
    "MeshError",
    "box_mesh",
    "embed",
    "Embedding",
    "load_mesh",
    "read_meshio",
    "sniff_format",
    "transform_points",
    "trunk_mesh",
]


class MeshError(ValueError):
    """A mesh that cannot be used; the message names the file and the element."""


@dataclass
class Mesh:
    nodes: np.ndarray
    """Rest positions of the nodes, (n, 3), metres."""
    tets: np.ndarray
    """Node indices of the tetrahedra, (m, element.n_nodes), corners first, positively oriented."""
    source: str = "<generated>"
    """Where the mesh came from, for messages."""
    file_tet_index: np.ndarray | None = field(default=None, repr=False)
    """Index of each tetrahedron among the file's tetra cells (for error messages)."""
    element: ElementType = TET4
    """The element type of the cells."""
    file_nodes: np.ndarray | None = field(default=None, repr=False)
    """Index in the file's point list of each node (a file's unused points are dropped, so a SOFA scene's
    ``indices`` are mapped through this); None for generated meshes, whose nodes are the file's."""

    def node_of_file_index(self, indices) -> np.ndarray:
        """Mesh nodes of the file's point indices; -1 where the file point is used by no tetrahedron."""
        indices = np.asarray(indices, dtype=np.int64)
        if self.file_nodes is None:
            return np.where((indices >= 0) & (indices < self.n_nodes), indices, -1)
        lookup = np.full(max(int(self.file_nodes.max()) + 1, int(indices.max(initial=0)) + 1), -1, dtype=np.int64)
        lookup[self.file_nodes] = np.arange(self.file_nodes.size)
        return np.where(indices >= 0, lookup[np.clip(indices, 0, lookup.size - 1)], -1)

    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[0]

    @property
    def n_tets(self) -> int:
        return self.tets.shape[0]

    @property
    def corners(self) -> np.ndarray:
        """Node indices of the tetrahedra's four corners (m, 4): every element type lists them first."""
        return self.tets[:, :4]

    def volumes(self) -> np.ndarray:
        """Volumes of the tetrahedra spanned by the corners (m,)."""
        X = self.nodes[self.corners]
        return np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0]) / 6

    def check(self) -> None:
        """Reject degenerate and inverted tetrahedra, naming the first offending element."""
        X = self.nodes[self.corners]
        V = self.volumes()
        edges = [X[:, i] - X[:, j] for i, j in ((1, 0), (2, 0), (3, 0), (2, 1), (3, 1), (3, 2))]
        h = np.mean([np.linalg.norm(e, axis=1) for e in edges], axis=0)
        rel = V / np.maximum(h, 1e-300) ** 3  # a regular tet has V/h^3 = 0.118
        idx = self.file_tet_index if self.file_tet_index is not None else np.arange(self.n_tets)
        bad = np.flatnonzero(np.abs(rel) < 1e-6)
        if bad.size:
            e = bad[0]
            raise MeshError(f"{self.source}: tetrahedron {idx[e]} (nodes {self.tets[e].tolist()}) is degenerate "
                            f"(volume {V[e]:.3g}, relative {rel[e]:.2g}); {bad.size} such element(s)")
        bad = np.flatnonzero(rel < 0)
        if bad.size:
            e = bad[0]
            raise MeshError(f"{self.source}: tetrahedron {idx[e]} (nodes {self.tets[e].tolist()}) is inverted "
                            f"(negative volume {V[e]:.3g}); {bad.size} such element(s)")
        if self.element.order > 1:
            # curved elements are fine, folded ones are not: the map must keep its orientation everywhere
            el = self.element
            xi = np.vstack([el.ref_nodes, el.quad_points])
            J = np.einsum("mai,kaj->mkij", self.nodes[self.tets], el.shape_gradients(xi))
            ratio = np.linalg.det(J).min(axis=1) / (6.0 * V)
            bad = np.flatnonzero(ratio <= 0.05)
            if bad.size:
                e = bad[0]
                raise MeshError(f"{self.source}: tetrahedron {idx[e]} (nodes {self.tets[e].tolist()}) is folded: "
                                f"its mid-edge nodes lie far from the edges' midpoints (Jacobian down to "
                                f"{ratio[e]:.2g} of the straight element's); {bad.size} such element(s)")

    def characteristic_length(self) -> float:
        return float(np.linalg.norm(self.nodes.max(0) - self.nodes.min(0)))

    def element_sizes(self) -> np.ndarray:
        """The mean corner-to-corner edge of each element (m)."""
        X = self.nodes[self.corners]
        return np.mean([np.linalg.norm(X[:, a] - X[:, b], axis=1)
                        for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))], axis=0)


# First bytes of the formats SOFA scenes ship, for files whose extension lies (a SoftRobots tutorial's
# ``diamond.vtk`` is an XML VTU file): (marker, meshio format name)
_SIGNATURES = ((b"<?xml", None), (b"<VTKFile", "vtu"), (b"# vtk DataFile", "vtk"), (b"$MeshFormat", "gmsh"),
               (b"solid", "stl"))


def sniff_format(path: str | Path) -> str | None:
    """The meshio format name a file's content says (``vtu``, ``vtk``, ``gmsh``, ``stl``), or None."""
    head = Path(path).read_bytes()[:512].lstrip()
    for marker, name in _SIGNATURES:
        if head.startswith(marker):
            if name is None:  # XML: which VTK XML file
                return "vtu" if b"UnstructuredGrid" in head else ("vtp" if b"PolyData" in head else None)
            return name
    return None


def read_meshio(path: str | Path):
    """meshio's reading of a file, by its extension and, if that fails or disagrees with the content, by
    its content; any failure is a one-line :class:`MeshError` naming the file."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: file not found")
    by_content = sniff_format(path)
    by_extension = {".vtk": "vtk", ".vtu": "vtu", ".vtp": "vtp", ".msh": "gmsh", ".stl": "stl"}.get(path.suffix.lower())
    chatter = io.StringIO()
    formats = [None] if by_content is None or by_content == by_extension else [by_content]
    if by_content is not None and by_content != by_extension and by_extension is not None:
        formats = [by_content]  # the content wins over a lying extension
    last = None
    for fmt in formats:
        try:
            # meshio prints its own complaints ("Illegal VTK header"): the user gets one line from us instead
            with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
                return meshio.read(path, file_format=fmt) if fmt else meshio.read(path)
        except (Exception, SystemExit) as exc:  # meshio raises many kinds, and exits on some unreadable files
            text = chatter.getvalue().strip() if isinstance(exc, SystemExit) else str(exc).strip()
            last = text.splitlines()[-1] if text else type(exc).__name__
    if path.suffix.lower() == ".obj":
        obj = _read_obj(path)
        if obj is not None:
            return obj
    raise MeshError(f"{path}: could not be read as a mesh ({last})")


def _read_obj(path: Path):
    """The vertices and faces (fanned into triangles) of a Wavefront OBJ that meshio refuses (texture
    coordinates counted unlike the vertices, as SoftRobots' bunny cavity has), or None."""
    import meshio

    v, tri = [], []
    try:
        for line in path.read_text(errors="replace").splitlines():
            s = line.split()
            if s and s[0] == "v":
                v.append([float(x) for x in s[1:4]])
            elif s and s[0] == "f":
                ids = [int(x.split("/")[0]) for x in s[1:]]
                ids = [i - 1 if i > 0 else len(v) + i for i in ids]  # OBJ counts from 1, negatives from the end
                tri += [[ids[0], ids[k], ids[k + 1]] for k in range(1, len(ids) - 1)]
    except ValueError:
        return None
    if not v or not tri or max(max(t) for t in tri) >= len(v):
        return None
    return meshio.Mesh(np.asarray(v, dtype=float), [("triangle", np.asarray(tri, dtype=np.int64))])


def load_mesh(path: str | Path, scale: float = 1.0, transform=None) -> Mesh:
    """Read the tetrahedra of any meshio-readable file; ``scale`` converts its unit to metres (mm: 0.001),
    ``transform`` (a function of (n, 3) points in metres) then places it (:func:`transform_points`)."""
    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: mesh file not found")
    m = read_meshio(path)
    linear = [c.data for c in m.cells if c.type == "tetra"]
    quad = [c.data for c in m.cells if c.type == "tetra10"]
    if not linear and not quad:
        kinds = sorted({c.type for c in m.cells})
        raise MeshError(f"{path}: contains no linear tetrahedra (cell types: {', '.join(kinds) or 'none'})")
    if linear and quad:
        raise MeshError(f"{path}: mixes {sum(map(len, linear))} linear (tetra) and {sum(map(len, quad))} quadratic "
                        f"(tetra10) tetrahedra; use one kind")
    element = TET10 if quad else TET4
    tets = np.concatenate(quad or linear).astype(np.int64)
    used, inverse = np.unique(tets, return_inverse=True)
    nodes = np.asarray(m.points, dtype=float)[used, :3] * float(scale)
    if transform is not None:
        nodes = transform(nodes)
    if not np.all(np.isfinite(nodes)):
        raise MeshError(f"{path}: node coordinates contain NaN or infinite values")
    tets = inverse.reshape(tets.shape)
    if element is TET4:
        # a file written with the other orientation convention (or mirrored by a negative scale) has every
        # tetrahedron negative: turn them all around. A mix of orientations stays an error (check()).
        X = nodes[tets]
        V = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0])
        if np.all(V < 0):
            tets = tets[:, [0, 2, 1, 3]]
    mesh = Mesh(nodes, tets, str(path), np.arange(tets.shape[0]), element, used)
    mesh.check()
    return mesh


def transform_points(points: np.ndarray, rotation=(0.0, 0.0, 0.0), translation=(0.0, 0.0, 0.0),
                     scale=1.0) -> np.ndarray:
    """SOFA's loader transform: x' = translation + R (scale * x), R from Euler angles in degrees applied
    about x, then y, then z (fixed axes; SOFA's ``createQuaterFromEuler``)."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_euler("xyz", np.asarray(rotation, dtype=float), degrees=True).as_matrix()
    return np.asarray(translation, dtype=float) + (np.asarray(points, dtype=float) * scale) @ R.T


def quadratic(mesh: Mesh) -> Mesh:
    """The same mesh with 10-node tetrahedra: a node added at the midpoint of every edge (straight edges).
    The corner nodes keep their indices; the mid-edge nodes follow them."""
    if mesh.element is TET10:
        return mesh
    corners = mesh.tets[:, :4]
    pairs = np.stack([np.sort(corners[:, [i, j]], axis=1) for i, j in TET10_EDGES], axis=1)  # (m, 6, 2)
    edges, inverse = np.unique(pairs.reshape(-1, 2), axis=0, return_inverse=True)
    mid = 0.5 * (mesh.nodes[edges[:, 0]] + mesh.nodes[edges[:, 1]])
    tets = np.hstack([corners, mesh.n_nodes + inverse.reshape(-1, 6)])
    out = Mesh(np.vstack([mesh.nodes, mid]), tets, mesh.source, mesh.file_tet_index, TET10)
    out.check()
    return out


def _hex_grid_to_tets(shape: tuple[int, int, int]) -> np.ndarray:
    """Conforming split of a structured (nx, ny, nz)-cell grid into 6 tets per cell.

    Kuhn's split along a main diagonal, with the cell mirrored in every direction where its index is odd:
    neighbouring cells then share face diagonals (conforming) and the mesh is mirror-symmetric, so a
    symmetric load gives a symmetric answer (the plain Kuhn split twists a bent beam sideways).
    Node (i, j, k) has index (k * (ny + 1) + j) * (nx + 1) + i.
    """
    nx, ny, nz = shape
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    ri, rj, rk = i % 2, j % 2, k % 2

    def nid(di, dj, dk):
        return ((k + (dk ^ rk)) * (ny + 1) + (j + (dj ^ rj))) * (nx + 1) + (i + (di ^ ri))

    e = [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
    tets = []
    for a, b in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)):
        p1 = e[a]
        p2 = tuple(x + y for x, y in zip(e[a], e[b]))
        tets.append(np.stack([nid(0, 0, 0), nid(*p1), nid(*p2), nid(1, 1, 1)], axis=1))
    return np.concatenate(tets)


def _orient(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    X = nodes[tets]
    V = np.einsum("ij,ij->i", np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), X[:, 3] - X[:, 0])
    tets = tets.copy()
    neg = V < 0
    tets[neg, 1], tets[neg, 2] = tets[neg, 2], tets[neg, 1].copy()
    return tets


def box_mesh(size=(1.0, 1.0, 1.0), divisions=(2, 2, 2), origin=(0.0, 0.0, 0.0)) -> Mesh:
    """A rectangular block [origin, origin + size] split into 6 tetrahedra per grid cell."""
    nx, ny, nz = divisions
    xs = [np.linspace(o, o + s, n + 1) for o, s, n in zip(origin, size, divisions)]
    Z, Y, X = np.meshgrid(xs[2], xs[1], xs[0], indexing="ij")
    nodes = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    tets = _orient(nodes, _hex_grid_to_tets((nx, ny, nz)))
    mesh = Mesh(nodes, tets, f"box {tuple(size)} / {tuple(divisions)}")
    mesh.check()
    return mesh


def trunk_mesh(length: float = 0.195, radius_base: float = 0.013, radius_tip: float = 0.005,
               resolution: float = 1.0) -> Mesh:
    """A tapered cylinder along +z from z = 0 (base) to z = ``length`` (tip), like SOFA's trunk.

    A square grid of the cross-section is mapped onto the disc (elliptical grid mapping) and extruded;
    ``resolution`` 1 gives 6 x 6 cells across and 20 along (1029 nodes, 4320 tetrahedra); the number of
    cells grows linearly with it in each direction. The tip centre (0, 0, length) is a node.
    """
    n_xy = max(2, 2 * int(round(3 * resolution)))
    n_z = max(2, int(round(20 * resolution)))
    s = np.linspace(-1.0, 1.0, n_xy + 1)
    z = np.linspace(0.0, length, n_z + 1)
    Z, Y, X = np.meshgrid(z, s, s, indexing="ij")
    u = X * np.sqrt(1.0 - Y**2 / 2.0)
    v = Y * np.sqrt(1.0 - X**2 / 2.0)
    r = radius_base + (radius_tip - radius_base) * Z / length
    nodes = np.stack([(u * r).ravel(), (v * r).ravel(), Z.ravel()], axis=1)
    tets = _orient(nodes, _hex_grid_to_tets((n_xy, n_xy, n_z)))
    mesh = Mesh(nodes, tets, f"trunk(length={length}, r={radius_base}->{radius_tip}, resolution={resolution})")
    mesh.check()
    return mesh


@dataclass
class Embedding:
    """Points attached to the mesh by the shape functions of their host elements."""

    tet: np.ndarray
    """Index of the host tetrahedron of each point, (k,)."""
    weights: np.ndarray
    """Shape function values at the point in its host, (k, n_nodes); for the linear tetrahedron the
    barycentric coordinates. Negative barycentric coordinates mean extrapolation."""
    outside: np.ndarray
    """Distance from each point to its host tetrahedron, (k,) metres (0 inside the mesh)."""

    def matrix(self, mesh: Mesh) -> sp.csr_matrix:
        """W (3k x 3n) with positions of the points = W @ nodal positions (node-major)."""
        k = self.tet.shape[0]
        rows, cols, vals = [], [], []
        for a in range(self.weights.shape[1]):
            nodes = mesh.tets[self.tet, a]
            for i in range(3):
                rows.append(3 * np.arange(k) + i)
                cols.append(3 * nodes + i)
                vals.append(self.weights[:, a])
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(3 * k, 3 * mesh.n_nodes))


def closest_point_in_tet(p: np.ndarray, X: np.ndarray) -> np.ndarray:
    """The point of the solid tetrahedron X (4, 3) nearest to p: min over convex combinations."""
    from scipy.optimize import nnls

    big = 1e3 * max(1.0, float(np.abs(X).max()))
    A = np.vstack([X.T, big * np.ones(4)])
    b = np.concatenate([p, [big]])
    lam, _ = nnls(A, b)
    return X.T @ lam


def _distance_to_tet(p: np.ndarray, X: np.ndarray) -> float:
    """Euclidean distance from p to the solid tetrahedron X (4, 3)."""
    return float(np.linalg.norm(closest_point_in_tet(p, X) - p))


def embed(mesh: Mesh, points: np.ndarray) -> Embedding:
    """Attach each point to the tetrahedron containing it or, if outside the mesh, to the nearest one.

    The host of an outside point is the tetrahedron closest to it; its barycentric coordinates are then
    extrapolated (as SOFA's BarycentricMapping does), and ``outside`` says how far it lies from the mesh.
    The weights are the host element type's shape functions at the point.
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    element = mesh.element
    X = mesh.nodes[mesh.corners]
    T = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2)
    Tinv = np.linalg.inv(T)
    centroids = X.mean(axis=1)
    tet = np.empty(len(points), dtype=np.int64)
    weights = np.empty((len(points), element.n_nodes))
    outside = np.zeros(len(points))
    for k, p in enumerate(points):
        lam = np.einsum("mij,mj->mi", Tinv, p - X[:, 0])
        bary = np.column_stack([1.0 - lam.sum(axis=1), lam])
        worst = bary.min(axis=1)
        e = int(np.argmax(worst))
        if worst[e] < -1e-9:
            # outside: pick the truly nearest of the candidates closest by centroid
            cand = np.argsort(np.linalg.norm(centroids - p, axis=1))[:32]
            dist = np.array([_distance_to_tet(p, X[c]) for c in cand])
            e = int(cand[np.argmin(dist)])
            outside[k] = float(dist.min())
        tet[k] = e
        weights[k] = element.shape((Tinv[e] @ (p - X[e, 0]))[None])[0]
    return Embedding(tet, weights, outside)
