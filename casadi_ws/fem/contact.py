"""Rigid, fixed obstacles (a plane, a box, a sphere, a capped cylinder, a closed triangle surface) and the
frictionless contact of the body's boundary with them.

Each obstacle gives the signed distance of points to it (m; positive on the free side, negative inside),
its gradient (the unit normal) and its Hessian (the surface's curvature), by closed forms; a triangle
surface by libigl's AABB tree and winding number. :class:`ContactSet` holds the contact points the model checks: the
boundary nodes that can move and, where a face can pass through an obstacle between its nodes (any
obstacle but a plane, or curved 10-node faces), points inside the boundary faces, each paired with every
obstacle closer than the body's size at rest. Each pair adds an unknown (its normal force) and a
complementarity row to the model (:class:`casadi_ws.fem.model.StaticModel`, docs/methods.md "Contact").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .surface import signed_distance

__all__ = ["ContactSet", "Obstacle", "boundary_nodes", "contact_set", "split_faces"]


@dataclass
class Obstacle:
    """One obstacle: ``kind`` is ``plane``, ``box``, ``sphere``, ``cylinder`` or ``surface``."""

    kind: str
    name: str
    params: dict = field(default_factory=dict)
    """plane: point, normal (unit); box: lower, upper; sphere: center, radius; cylinder: a, b (axis end
    points), radius; surface: vertices, triangles (closed, outward normals)."""

    def __getstate__(self):
        # libigl's trees of a surface, built on first use (:meth:`_surface_gap`), are caches, not the obstacle:
        # they do not pickle, and a problem sent to worker processes (or fingerprinted) must not depend on them
        return {k: v for k, v in self.__dict__.items() if not k.startswith("_")}

    def distance(self, x: np.ndarray) -> np.ndarray:
        """Signed distance (k,) of the points x (k, 3): positive outside the obstacle."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        p = self.params
        if self.kind == "plane":
            return (x - p["point"]) @ p["normal"]
        if self.kind == "sphere":
            return np.linalg.norm(x - p["center"], axis=1) - p["radius"]
        if self.kind == "box":
            c, h = 0.5 * (p["lower"] + p["upper"]), 0.5 * (p["upper"] - p["lower"])
            d = np.abs(x - c) - h
            return np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0)
        if self.kind == "cylinder":
            a, b, r = p["a"], p["b"], p["radius"]
            axis = b - a
            length = np.linalg.norm(axis)
            t = (x - a) @ (axis / length)  # along the axis from a
            radial = np.linalg.norm((x - a) - np.outer(t, axis / length), axis=1) - r
            along = np.abs(t - 0.5 * length) - 0.5 * length
            d = np.column_stack([radial, along])
            return np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0)
        if self.kind == "surface":
            return signed_distance(p["vertices"], p["triangles"], x)
        raise ValueError(f"unknown obstacle kind {self.kind!r}")

    def gap(self, x: np.ndarray):
        """(d, n, H) at the points x (k, 3): the signed distance (k,), its gradient, the unit normal out of
        the obstacle (k, 3), and its Hessian (k, 3, 3), which is zero on flat parts. Where the distance has
        a kink (a box's or a cylinder's edge seen from inside), the side of the larger distance is taken."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        k = len(x)
        p = self.params
        eye = np.broadcast_to(np.eye(3), (k, 3, 3))
        if self.kind == "plane":
            return (x - p["point"]) @ p["normal"], np.broadcast_to(p["normal"], (k, 3)).copy(), np.zeros((k, 3, 3))
        if self.kind == "sphere":
            v = x - p["center"]
            r = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
            n = v / r[:, None]
            return r - p["radius"], n, (eye - n[:, :, None] * n[:, None, :]) / r[:, None, None]
        if self.kind == "box":
            return _box_gap(x, p["lower"], p["upper"])
        if self.kind == "cylinder":
            return _cylinder_gap(x, p["a"], p["b"], p["radius"])
        if self.kind == "surface":
            return self._surface_gap(x)
        raise ValueError(f"unknown obstacle kind {self.kind!r}")

    def _surface_gap(self, x):
        """libigl's distance (an AABB tree; the sign by the winding number): the closest point c on the
        triangles, the normal (x - c) / |x - c| outside (the face's at the surface and inside). Curvature
        where c lies on an edge or a vertex and x outside: (I - n n^T [- e e^T along the edge]) / d. The
        distance is to the triangles rounded by rho = 1e-4 of their mean edge (see the end)."""
        import igl

        V, F = self.params["vertices"], self.params["triangles"]
        if "_tree" not in self.__dict__:  # built once: an AABB tree of the triangles
            nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
            self._normals = nrm / np.linalg.norm(nrm, axis=1)[:, None]
            self._tree = igl.AABB()
            self._tree.init(V, F)
            self._winding = igl.FastWindingNumberBVH()
            self._winding.init(V, F)
            self._rho = 1e-4 * float(np.mean(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1)))
        lo, hi = V.min(axis=0), V.max(axis=0)
        scale = np.linalg.norm(hi - lo)
        # far from the surface's bounding box a point cannot touch it: the box's distance, a lower bound,
        # serves (its contact row is then ~eps^2 / (kappa g) from zero whichever distance is used)
        d, n, H = _box_gap(x, lo, hi)
        d -= self._rho
        near = np.flatnonzero(d < 0.1 * scale)
        if near.size:
            d[near], n[near], H[near] = self._near_gap(np.ascontiguousarray(x[near], dtype=float), scale)
        return d, n, H

    def _near_gap(self, x, scale):
        V, F = self.params["vertices"], self.params["triangles"]
        d2, face, c = self._tree.squared_distance(V, F, x)
        v = x - c
        r = np.linalg.norm(v, axis=1)
        # the sign: inside where the surface winds around the point (generalised winding number > 1/2)
        d = np.where(self._winding.winding_number(x) > 0.5, -r, r)
        along = r > 1e-9 * scale
        n = self._normals[face].copy()
        n[along] = (np.sign(d)[along, None] * v[along]) / r[along, None]
        # where on its triangle c lies: barycentric coordinates near 0 put it on an edge or a vertex
        tri = V[F[face]]
        lam = _barycentric(c, tri)
        on = lam < 1e-9
        k = len(x)
        H = np.zeros((k, 3, 3))
        curved = along & (d > 0) & on.any(axis=1)
        if curved.any():
            i = np.flatnonzero(curved)
            nn = n[i]
            P = np.eye(3)[None] - nn[:, :, None] * nn[:, None, :]
            edge = on[i].sum(axis=1) == 1  # on one edge: straight along it
            if edge.any():
                a = np.argmax(on[i][edge], axis=1)  # the edge opposite the zero coordinate
                t = tri[i[edge], (a + 2) % 3] - tri[i[edge], (a + 1) % 3]
                t /= np.linalg.norm(t, axis=1)[:, None]
                P[edge] -= t[:, :, None] * t[:, None, :]
            H[i] = P / d[i, None, None]
        # the contact surface is the triangles rounded by a radius rho (their points within rho): smooth,
        # so a point resting on an edge or a vertex has one normal; on the bare triangles the normal there
        # is any of a cone's, the contact row has no exact root and Newton stalls ~1e-7 above it
        return d - self._rho, n, H

    def describe(self) -> dict:
        return {"kind": self.kind, "name": self.name,
                **{k: np.asarray(v).tolist() if isinstance(v, np.ndarray) else v for k, v in self.params.items()}}


def boundary_nodes(mesh) -> np.ndarray:
    """The nodes on the body's boundary (mid-edge nodes of 10-node faces included): what an obstacle is
    checked against."""
    from .surface import boundary_faces

    return np.unique(boundary_faces(mesh))


def _box_gap(x, lower, upper):
    c, h = 0.5 * (lower + upper), 0.5 * (upper - lower)
    s = np.where(x >= c, 1.0, -1.0)
    d = np.abs(x - c) - h  # per axis: > 0 outside that pair of faces
    o = np.maximum(d, 0.0)
    r = np.linalg.norm(o, axis=1)
    out = r > 0
    k = len(x)
    dist = np.where(out, r, d.max(axis=1))
    n = np.zeros((k, 3))
    H = np.zeros((k, 3, 3))
    ro = np.maximum(r, 1e-300)[:, None]
    n[out] = (s * o / ro)[out]
    inner = np.flatnonzero(~out)
    ax = d[inner].argmax(axis=1)
    n[inner, ax] = s[inner, ax]
    # outside an edge or a corner the distance is to a line or a point: curvature across the outside axes
    P = (o > 0)[:, :, None] * np.eye(3)[None]
    H[out] = ((P - n[:, :, None] * n[:, None, :]) / ro[:, :, None])[out]
    return dist, n, H


def _cylinder_gap(x, a, b, radius):
    axis = b - a
    length = np.linalg.norm(axis)
    e = axis / length
    t = (x - a) @ e
    v = (x - a) - np.outer(t, e)
    rho = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
    er = v / rho[:, None]
    dr = rho - radius
    sz = np.where(t >= 0.5 * length, 1.0, -1.0)
    dz = np.abs(t - 0.5 * length) - 0.5 * length
    ez = sz[:, None] * e
    k = len(x)
    # the circle direction: curvature 1/rho of the radial distance around the axis
    tang = np.eye(3)[None] - e[None, :, None] * e[None, None, :] - er[:, :, None] * er[:, None, :]
    rim = (dr > 0) & (dz > 0)
    side = (dr > 0) & ~rim | (dr <= 0) & (dz <= 0) & (dr >= dz)
    dist = np.where(rim, np.hypot(dr, dz), np.where(side, dr, dz))
    n = np.where(side[:, None], er, ez)
    H = np.where(side[:, None, None], tang / rho[:, None, None], 0.0)
    if rim.any():
        w = np.hypot(dr, dz)[rim]
        nr = (dr[rim, None] * er[rim] + dz[rim, None] * ez[rim]) / w[:, None]
        m = (dz[rim, None] * er[rim] - dr[rim, None] * ez[rim]) / w[:, None]  # in-plane, across the normal
        n[rim] = nr
        H[rim] = (m[:, :, None] * m[:, None, :]) / w[:, None, None] \
            + (dr[rim] / (w * rho[rim]))[:, None, None] * tang[rim]
    return dist, n, H


# points inside a boundary face (area coordinates): a linear face's centroid; the centroids of a curved
# 10-node face's four sub-triangles (its middle bulges between the nodes)
_FACE_POINTS = {3: np.array([[1, 1, 1]]) / 3.0,
                6: np.array([[1, 1, 1], [4, 1, 1], [1, 4, 1], [1, 1, 4]]) / 6.0}


def _face_weights(L: np.ndarray, quadratic: bool) -> np.ndarray:
    """Shape functions of a face's nodes at area coordinates L (p, 3): (p, 3) linear, (p, 6) quadratic
    (corners, then the mid-edge nodes of edges 01, 12, 20)."""
    if not quadratic:
        return L
    l1, l2, l3 = L.T
    return np.column_stack([l1 * (2 * l1 - 1), l2 * (2 * l2 - 1), l3 * (2 * l3 - 1), 4 * l1 * l2, 4 * l2 * l3,
                            4 * l3 * l1])


@dataclass
class ContactSet:
    """The contact points of the body with the obstacles: point i is ``W[i] @ x`` (x the nodal positions,
    (n, 3)) and may touch obstacle ``obstacle[i]``. Its normal force lambda_i >= 0 is an unknown of the
    model (held as lambda_i / kappa, a length)."""

    obstacles: list
    W: "sp.csr_matrix"
    """(k, n_nodes) weights of the nodes on each contact point (a node: one 1; a face point: its shape
    functions)."""
    obstacle: np.ndarray
    """(k,) the obstacle of each point."""
    kappa: float
    """Stiffness scale (N/m) of the contact rows: E h, the stiffness a boundary node of size h has."""
    eps: float
    """Smoothing of the Fischer-Burmeister rows (N): 1e-8 kappa h."""
    h: float = 0.0
    """The mean edge of the boundary faces (m)."""

    @property
    def n(self) -> int:
        return self.W.shape[0]

    def points(self, x: np.ndarray) -> np.ndarray:
        return self.W @ x

    def gaps(self, x: np.ndarray):
        """(g, n, H) of every contact point at the nodal positions x: gap (k,), normal (k, 3), curvature
        (k, 3, 3) of its obstacle's distance."""
        P = self.points(x)
        k = len(P)
        g, nrm, H = np.empty(k), np.empty((k, 3)), np.empty((k, 3, 3))
        for j, ob in enumerate(self.obstacles):
            i = np.flatnonzero(self.obstacle == j)
            if i.size:
                g[i], nrm[i], H[i] = ob.gap(P[i])
        return g, nrm, H


def contact_set(mesh, obstacles, moving: np.ndarray, young_modulus: float) -> ContactSet | None:
    """The contact points of ``mesh`` with ``obstacles``: boundary nodes that move (``moving``, (n,) bool)
    and, where needed, points inside boundary faces, each with every obstacle that is nearer than the body's
    size at rest (farther ones cannot be reached). None without obstacles."""
    import scipy.sparse as sp

    from .surface import boundary_faces

    if not obstacles:
        return None
    faces = boundary_faces(mesh)
    quadratic = faces.shape[1] == 6
    nodes = np.unique(faces)
    nodes = nodes[moving[nodes]]
    faces = faces[moving[faces].any(axis=1)]
    L = _FACE_POINTS[faces.shape[1]]
    w = _face_weights(L, quadratic)  # (p, m)
    n_nodes = mesh.n_nodes
    node_rows = sp.csr_matrix((np.ones(nodes.size), (np.arange(nodes.size), nodes)), shape=(nodes.size, n_nodes))
    p, m = w.shape
    rows = np.repeat(np.arange(len(faces) * p), m)
    face_rows = sp.csr_matrix((np.tile(w.ravel(), len(faces)), (rows, np.repeat(faces, p, axis=0).ravel())),
                              shape=(len(faces) * p, n_nodes))
    edges = np.linalg.norm(mesh.nodes[faces[:, 0]] - mesh.nodes[faces[:, 1]], axis=1)
    h = float(np.mean(edges)) if edges.size else mesh.characteristic_length()
    reach = mesh.characteristic_length()
    blocks, owner = [], []
    for j, ob in enumerate(obstacles):
        Wj = node_rows if (ob.kind == "plane" and not quadratic) else sp.vstack([node_rows, face_rows]).tocsr()
        keep = np.flatnonzero(ob.distance(Wj @ mesh.nodes) < reach)
        blocks.append(Wj[keep])
        owner.append(np.full(keep.size, j))
    W = sp.vstack(blocks).tocsr()
    W.eliminate_zeros()
    kappa = float(young_modulus * h)
    return ContactSet(list(obstacles), W, np.concatenate(owner), kappa, 1e-8 * kappa * h, h)


def split_faces(faces: np.ndarray) -> np.ndarray:
    """Triangles (t, 3) on the nodes of boundary faces: a 3-node face itself, a 6-node face as the four
    triangles through its mid-edge nodes (same orientation)."""
    faces = np.asarray(faces, dtype=np.int64)
    if faces.shape[1] == 3:
        return faces
    return faces[:, [0, 3, 5, 3, 1, 4, 5, 4, 2, 3, 4, 5]].reshape(-1, 3)


def _barycentric(c, tri):
    """Barycentric coordinates (k, 3) of the points c (k, 3) in the triangles tri (k, 3, 3)."""
    a, b, cc = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, cc - a, c - a
    d00, d01, d11 = (np.einsum("ij,ij->i", p, q) for p, q in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    l1 = (d11 * d20 - d01 * d21) / den
    l2 = (d00 * d21 - d01 * d20) / den
    return np.column_stack([1.0 - l1 - l2, l1, l2])
