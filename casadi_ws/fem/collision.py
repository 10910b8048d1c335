"""The body's boundary as a collision surface: what self-contact and the self-penetration audit query.

The geometry queries are the IPC Toolkit's (``ipctk``): a bounding-volume hierarchy over the current
triangles, exact edge-triangle intersection tests, point-triangle and edge-edge distances with their
derivatives, continuous collision detection. The surface is the boundary's straight triangles: a 4-node
mesh's boundary faces, a 10-node mesh's faces each split into four through their mid-edge nodes (the curved
face's piecewise-linear interpolant through its six nodes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CollisionSurface", "collision_surface", "collision_surface_of_mesh", "mean_edge", "rest_clearance",
           "surface_crosses"]


@dataclass
class CollisionSurface:
    """The boundary triangles of a mesh on the boundary's own numbering of nodes."""

    nodes: np.ndarray
    """(s,) the mesh nodes on the boundary: surface vertex i is mesh node ``nodes[i]``."""
    triangles: np.ndarray
    """(t, 3) surface vertex indices, oriented out of the body."""
    edges: np.ndarray
    """(e, 2) surface vertex indices, each edge once."""
    mesh: object
    """The ``ipctk.CollisionMesh`` at rest (adjacency: vertices, edges and faces that share a vertex are never
    candidates)."""

    def vertices(self, x: np.ndarray) -> np.ndarray:
        """(s, 3) the surface's vertices for node positions x (n, 3), in the layout ipctk reads."""
        return np.asfortranarray(x[self.nodes])


def collision_surface(model) -> CollisionSurface:
    """The model's collision surface, built once (:attr:`casadi_ws.fem.model.StaticModel.cache`)."""
    return model.cache.get("collision_surface", lambda: collision_surface_of_mesh(model.mesh))


def mean_edge(surface: CollisionSurface, x: np.ndarray) -> float:
    """The mean length of the surface's edges for node positions x (n, 3)."""
    e = x[surface.nodes[surface.edges[:, 0]]] - x[surface.nodes[surface.edges[:, 1]]]
    return float(np.mean(np.linalg.norm(e, axis=1)))


def rest_clearance(surface: CollisionSurface, x: np.ndarray) -> tuple[float, float]:
    """(the smallest distance between two parts of the surface that share no vertex, 0 where it passes
    through itself, capped at the mean edge; the mean edge) for node positions x."""
    import ipctk

    h = mean_edge(surface, x)
    V = surface.vertices(x)
    if ipctk.has_intersections(surface.mesh, V):
        return 0.0, h
    col = ipctk.NormalCollisions()
    col.build(surface.mesh, V, h)
    E, F = surface.edges, surface.triangles
    d = [float(np.sqrt(col[i].compute_distance(col[i].dof(V, E, F)))) for i in range(len(col))]
    return min(d + [h]), h


def collision_surface_of_mesh(mesh) -> CollisionSurface:
    """The collision surface of a mesh's boundary."""
    import ipctk

    from .contact import split_faces
    from .surface import boundary_faces

    ipctk.set_num_threads(1)  # Dask workers are one-thread processes; a result must not depend on threads
    tris = split_faces(boundary_faces(mesh))
    nodes = np.unique(tris)
    local = np.full(mesh.n_nodes, -1, dtype=np.int64)
    local[nodes] = np.arange(nodes.size)
    F = np.ascontiguousarray(local[tris], dtype=np.int32)
    E = ipctk.edges(F)
    return CollisionSurface(nodes, F, np.asarray(E, dtype=np.int64),
                            ipctk.CollisionMesh(np.asfortranarray(mesh.nodes[nodes]), E, F))


def surface_crosses(model, x: np.ndarray) -> bool:
    """Whether the deformed boundary (node positions x, (n, 3)) passes through itself: some edge crosses a
    triangle it shares no vertex with (a bounding-volume hierarchy, then exact tests; ~1 ms for a thousand
    triangles, 5 ms for 6,500)."""
    import ipctk

    s = collision_surface(model)
    return bool(ipctk.has_intersections(s.mesh, s.vertices(x)))
