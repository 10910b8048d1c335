"""Boundary surfaces of a tetrahedral mesh: its faces, their connected components, closedness, orientation,
and which closed inner boundary (a cavity) encloses a point.

A boundary face belongs to one tetrahedron only; it is listed with its normal pointing out of the solid
(3 corners, or for 10-node tetrahedra 6 nodes: corners, then the mid-edge nodes of edges 01, 12, 20). An
inner boundary (the wall of a closed chamber) therefore has its normals pointing into the chamber; the
cavity's own surface is the same faces reversed.
"""

from __future__ import annotations

import numpy as np

from .elements import TET10_EDGES

__all__ = ["boundary_faces", "components", "edge_report", "reverse", "signed_distance", "winding_number",
           "winding_numbers"]

# faces of a positively oriented tetrahedron, normals outwards
_FACES = ((0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2))
_MID = {frozenset(e): 4 + i for i, e in enumerate(TET10_EDGES)}


def boundary_faces(mesh) -> np.ndarray:
    """The boundary faces, (f, 3) node indices or (f, 6) for 10-node tetrahedra, oriented out of the solid."""
    quadratic = mesh.tets.shape[1] == 10
    local = []
    for a, b, c in _FACES:
        idx = [a, b, c] + ([_MID[frozenset((a, b))], _MID[frozenset((b, c))], _MID[frozenset((c, a))]]
                           if quadratic else [])
        local.append(idx)
    return unshared(np.concatenate([mesh.tets[:, idx] for idx in local]))


def unshared(faces: np.ndarray) -> np.ndarray:
    """The faces whose corners (the first three columns) no other face has: a set of solids' outer surface."""
    key = np.sort(faces[:, :3], axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1]


def reverse(faces: np.ndarray) -> np.ndarray:
    """The same faces with the opposite orientation."""
    faces = np.asarray(faces)
    if faces.shape[1] == 3:
        return faces[:, [0, 2, 1]]
    return faces[:, [0, 2, 1, 5, 4, 3]]


def _edges(faces: np.ndarray) -> np.ndarray:
    """Directed corner edges (3f, 2) of the faces, in face order."""
    c = faces[:, :3]
    return np.concatenate([c[:, [0, 1]], c[:, [1, 2]], c[:, [2, 0]]])


def components(faces: np.ndarray) -> list[np.ndarray]:
    """Face indices of each connected component (faces sharing an edge), largest first."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = len(faces)
    e = np.sort(_edges(faces), axis=1)
    owner = np.tile(np.arange(f), 3)
    _, edge_id = np.unique(e, axis=0, return_inverse=True)
    edge_id = edge_id.ravel()
    # faces and edges as one bipartite graph
    n_e = edge_id.max() + 1
    G = coo_matrix((np.ones(3 * f), (owner, f + edge_id)), shape=(f + n_e, f + n_e))
    _, label = connected_components(G, directed=False)
    label = label[:f]
    comps = [np.flatnonzero(label == k) for k in np.unique(label)]
    return sorted(comps, key=len, reverse=True)


def edge_report(faces: np.ndarray) -> tuple[int, int]:
    """(open edges, inconsistently oriented edges) of a triangle surface: an edge of a closed surface is
    shared by exactly two faces, and a consistently oriented one runs through them in opposite directions."""
    d = _edges(np.asarray(faces))
    key = np.sort(d, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    open_edges = int(np.sum(counts != 2))
    # for edges shared by two faces, the directed copies must differ
    _, dcounts = np.unique(d, axis=0, return_counts=True)
    same_direction = int(np.sum(dcounts > 1))
    return open_edges, same_direction


def winding_number(X: np.ndarray, faces: np.ndarray, p: np.ndarray) -> float:
    """Winding number of the closed surface (flat corner triangles) around p: 1 inside a surface whose
    normals point outwards, 0 outside (van Oosterom and Strackee's solid angle)."""
    return float(winding_numbers(X, faces, np.asarray(p, dtype=float)[None])[0])


def winding_numbers(X: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """:func:`winding_number` around each of ``points`` (k, 3), at once (in pieces of ~2e6 point-triangle
    pairs, 150 MB)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    piece = max(1, 2_000_000 // max(len(faces), 1))
    if len(points) > piece:
        return np.concatenate([winding_numbers(X, faces, points[i:i + piece]) for i in range(0, len(points), piece)])
    tri = X[np.asarray(faces)[:, :3]][None] - points[:, None, None]  # (k, faces, 3, 3)
    a, b, c = tri[:, :, 0], tri[:, :, 1], tri[:, :, 2]
    la, lb, lc = (np.linalg.norm(v, axis=-1) for v in (a, b, c))
    num = np.einsum("kij,kij->ki", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("kij,kij->ki", a, b) * lc + np.einsum("kij,kij->ki", b, c) * la \
        + np.einsum("kij,kij->ki", c, a) * lb
    return np.sum(2 * np.arctan2(num, den), axis=1) / (4 * np.pi)


def signed_distance(vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Signed distance of each point to the closed surface of ``triangles`` (vertex indices, counter-clockwise
    seen from outside) over ``vertices``: negative inside, positive outside.

    VTK's implicit distance, called through VTK's own modules rather than pyvista (which calls the same): their
    import takes ~0.1 s against pyvista's ~0.25 s, paid at the end of every forward-backward run (the points'
    check against the boundary surface), with the workers idle."""
    from vtkmodules.util.numpy_support import VTK_ID_TYPE, get_numpy_array_type, numpy_to_vtk, vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkDoubleArray, vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkFiltersCore import vtkImplicitPolyDataDistance

    def ids(a):
        return numpy_to_vtk(np.ascontiguousarray(a, dtype=get_numpy_array_type(VTK_ID_TYPE)), True, VTK_ID_TYPE)

    corners = vtkPoints()
    corners.SetData(numpy_to_vtk(np.ascontiguousarray(vertices, dtype=float), deep=True))
    cells = vtkCellArray()
    cells.SetData(ids(np.arange(0, 3 * len(triangles) + 1, 3)), ids(np.ravel(triangles)))
    surface = vtkPolyData()
    surface.SetPoints(corners)
    surface.SetPolys(cells)
    distance = vtkImplicitPolyDataDistance()
    distance.SetInput(surface)
    out = vtkDoubleArray()
    distance.FunctionValue(numpy_to_vtk(np.ascontiguousarray(points, dtype=float), deep=True), out)
    return np.array(vtk_to_numpy(out), dtype=float)
