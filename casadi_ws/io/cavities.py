"""Cavities of a problem file: from a closed triangle surface file, or the inner boundary enclosing a point.

Both return a :class:`casadi_ws.actuation.Cavity` whose vertices are mesh nodes and whose triangles are
oriented with normals out of the cavity; bad input raises ``ValueError`` with the one-line reason (the
problem reader adds the file and key).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..actuation.cavity import Cavity, surface_volume
from ..fem.mesh import embed
from ..fem.surface import boundary_faces, components, edge_report, reverse, winding_number

__all__ = ["cavity_enclosing", "cavity_from_surface", "inner_boundaries"]


def _compact(mesh, faces, name, u_min, u_max) -> Cavity:
    nodes, local = np.unique(faces, return_inverse=True)
    return Cavity(mesh.nodes[nodes], local.reshape(faces.shape), nodes, u_min, u_max, name)


def inner_boundaries(mesh) -> list[np.ndarray]:
    """The closed inner boundaries of the mesh (walls of chambers), each as faces oriented out of the
    cavity, i.e. into the solid. The outer boundary is the component enclosing the largest volume."""
    faces = boundary_faces(mesh)
    comps = [faces[c] for c in components(faces)]
    if len(comps) <= 1:
        return []
    # with solid-outward normals the outer boundary encloses a positive volume, inner ones negative
    vols = [float(surface_volume(mesh.nodes, f[:, :3])) for f in comps]
    outer = int(np.argmax(vols))
    return [reverse(f) for i, f in enumerate(comps) if i != outer]


def cavity_enclosing(mesh, point, name="cavity", u_min=0.0, u_max=1e4) -> Cavity:
    """The closed inner boundary of the mesh that encloses ``point``."""
    point = np.asarray(point, dtype=float)
    inner = inner_boundaries(mesh)
    for faces in inner:
        if winding_number(mesh.nodes, faces, point) > 0.5:
            return _compact(mesh, faces, name, u_min, u_max)
    if embed(mesh, point[None]).outside[0] == 0.0:
        raise ValueError(f"point {point.tolist()} lies inside the solid, not in a cavity")
    raise ValueError(f"point {point.tolist()} lies in none of the mesh's {len(inner)} closed inner "
                     f"boundaries (cavities)")


def cavity_from_surface(mesh, path: Path, name="cavity", u_min=0.0, u_max=1e4, scale: float = 1.0,
                        transform=None, embed_tolerance: float | None = None) -> Cavity:
    """A cavity from a closed triangle surface file (``scale`` converts its units to metres, ``transform``
    then places it). An inverted but consistently oriented surface is turned around.

    If every vertex is a mesh node the surface follows those nodes exactly and must lie on the mesh's
    boundary. Otherwise (SOFA maps a cavity's surface onto the body barycentrically) its vertices are
    embedded in their host tetrahedra, each within ``embed_tolerance`` metres of the mesh (default: 1 % of
    the mesh's size); its triangles must then be 3-node ones.
    """
    from ..fem.mesh import MeshError, read_meshio

    try:
        m = read_meshio(path)
    except MeshError as exc:
        raise ValueError(str(exc)) from None
    tris = [c.data for c in m.cells if c.type in ("triangle", "triangle6")]
    if not tris:
        raise ValueError(f"{path} holds no triangles (cell types: {sorted({c.type for c in m.cells})})")
    if len({t.shape[1] for t in tris}) > 1:
        raise ValueError(f"{path} mixes 3- and 6-node triangles")
    faces = np.concatenate(tris).astype(np.int64)
    X = np.asarray(m.points, dtype=float)[:, :3] * scale
    if transform is not None:
        X = transform(X)
    used = np.unique(faces)
    # vertices that coincide with mesh nodes (to a millionth of the mesh's size) follow them exactly
    from scipy.spatial import cKDTree

    dist, node = cKDTree(mesh.nodes).query(X[used])
    tol = 1e-6 * mesh.characteristic_length()
    if np.any(dist > tol):
        return _embedded(mesh, path, X, faces, name, u_min, u_max, embed_tolerance)
    to_node = np.full(len(X), -1, dtype=np.int64)
    to_node[used] = node
    faces = to_node[faces]
    if faces.shape[1] == 6 and mesh.tets.shape[1] != 10:
        raise ValueError("6-node triangles need a mesh of 10-node tetrahedra (mesh.order: 2)")
    if faces.shape[1] == 3 and mesh.tets.shape[1] == 10:
        raise ValueError("a mesh of 10-node tetrahedra needs a surface of 6-node triangles (triangle6)")
    faces = _closed_and_outward(mesh.nodes, faces)
    # a pressure acts on the body's boundary: every triangle must be a boundary face of the mesh
    boundary = {tuple(k) for k in np.sort(boundary_faces(mesh)[:, :3], axis=1)}
    inside = sum(tuple(k) not in boundary for k in np.sort(faces[:, :3], axis=1))
    if inside:
        raise ValueError(f"{inside} of its {len(faces)} triangles are not on the mesh's boundary (a cavity's "
                         f"wall is a boundary of the mesh)")
    return _compact(mesh, faces, name, u_min, u_max)


def _closed_and_outward(X, faces) -> np.ndarray:
    """The faces of a closed, consistently oriented surface, turned so that normals leave the cavity."""
    open_edges, same = edge_report(faces)
    if open_edges:
        raise ValueError(f"the surface is not closed: {open_edges} edge(s) not shared by exactly two triangles")
    if same:
        raise ValueError(f"the surface is not consistently oriented: {same} edge(s) run the same way in both "
                         f"of their triangles")
    # each closed piece encloses a chamber: turn around the pieces whose normals point into it, if all do
    pieces = [faces[c] for c in components(faces)]
    signs = [np.sign(surface_volume(X, f)) for f in pieces]
    if len(set(signs)) > 1:
        raise ValueError(f"its {len(pieces)} closed pieces are oriented differently ({signs.count(-1.0)} with "
                         f"normals into their chamber): orient them all the same way")
    return reverse(faces) if signs[0] < 0 else faces  # closed and consistent, but normals into the cavity


def _embedded(mesh, path, X, faces, name, u_min, u_max, tolerance) -> Cavity:
    """A cavity whose vertices are embedded in the mesh (SOFA's barycentric mapping of a cavity surface)."""
    if faces.shape[1] != 3:
        raise ValueError("a surface whose vertices are not mesh nodes must be made of 3-node triangles")
    used, local = np.unique(faces, return_inverse=True)
    faces, pts = local.reshape(faces.shape), X[used]
    tolerance = 0.01 * mesh.characteristic_length() if tolerance is None else tolerance
    out = embed(mesh, pts).outside
    if out.max() > tolerance:
        j = int(np.argmax(out))
        raise ValueError(f"vertex {np.round(pts[j], 6).tolist()} lies {out[j]:.3g} m from the mesh (allowed "
                         f"{tolerance:.3g} m: embed_tolerance); {int((out > tolerance).sum())} such vertices")
    faces = _closed_and_outward(pts, faces)
    return Cavity(pts, faces, None, u_min, u_max, name)
