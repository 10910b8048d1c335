"""Element types: nodes, quadrature, shape functions, consistent body loads, embedding weights.

An :class:`ElementType` is everything the layers above need to know about an element, so that no number
such as "4 nodes", "12 dofs" or "V/4 of the weight" is written anywhere else: the materials build their
element functions from its quadrature, the model sizes its index maps and body loads from it, and points
are embedded with its shape functions.

Conventions: reference coordinates xi in the unit tetrahedron {xi >= 0, sum xi <= 1}; the first four nodes
are the corners, in the order of the mesh file; quadrature weights are fractions of the element's volume
(they sum to 1), so an integral is V_e sum_k w_k f(xi_k) for straight-sided elements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ELEMENT_TYPES", "ElementType", "TET10", "TET4", "TET10_EDGES", "element_type"]


@dataclass(frozen=True)
class ElementType:
    """A Lagrange tetrahedron (see the module's conventions)."""

    name: str
    """Short name: ``tet4``."""
    cell_type: str
    """The meshio/VTK cell type name: ``tetra``."""
    order: int
    """Polynomial order of the shape functions."""
    ref_nodes: np.ndarray
    """Reference coordinates of the nodes, (n_nodes, 3); the first four are the corners."""
    quad_points: np.ndarray
    """Quadrature points in reference coordinates, (n_qp, 3)."""
    quad_weights: np.ndarray
    """Quadrature weights as fractions of the element's volume, (n_qp,), summing to 1."""
    tangent_cost: float = 10.0
    """What the residual and assembled tangent of a mesh of these elements cost, in residuals (measured on
    the trunk, one process: 8.1 against 0.78 ms for 4-node, 21.2 against 1.28 ms for 10-node tetrahedra;
    with the closed-form 10-node corotational tangent, on a faster day, 4.75 against 0.42 and 7.75 against
    0.51 ms: 11 and 15).
    Forward-backward refines the sensitivities with products by the tangent taken from residuals where they
    cost less (:class:`casadi_ws.workspace.backward.BackwardSettings` ``tangent_products``)."""

    @property
    def n_nodes(self) -> int:
        return int(self.ref_nodes.shape[0])

    @property
    def n_dof(self) -> int:
        """Degrees of freedom of one element: 3 per node."""
        return 3 * self.n_nodes

    @property
    def n_qp(self) -> int:
        return int(self.quad_points.shape[0])

    def shape(self, xi: np.ndarray) -> np.ndarray:
        """Shape function values N_a(xi), (k, n_nodes) for xi (k, 3)."""
        xi = np.atleast_2d(np.asarray(xi, dtype=float))
        if self.order == 1:
            # written out so a point's weights are exactly 1 - sum and its coordinates
            return np.column_stack([1.0 - xi.sum(axis=1), xi])
        L = np.column_stack([1.0 - xi.sum(axis=1), xi])  # barycentric coordinates of the corners
        corners = L * (2.0 * L - 1.0)
        edges = np.column_stack([4.0 * L[:, i] * L[:, j] for i, j in TET10_EDGES])
        return np.hstack([corners, edges])

    def shape_gradients(self, xi: np.ndarray) -> np.ndarray:
        """dN_a/dxi, (k, n_nodes, 3)."""
        xi = np.atleast_2d(np.asarray(xi, dtype=float))
        dL = np.vstack([-np.ones(3), np.eye(3)])  # dL_i/dxi (4, 3)
        if self.order == 1:
            return np.broadcast_to(dL, (xi.shape[0], 4, 3)).copy()
        L = np.column_stack([1.0 - xi.sum(axis=1), xi])
        corners = (4.0 * L - 1.0)[:, :, None] * dL[None]
        edges = np.stack([4.0 * (L[:, i, None] * dL[j] + L[:, j, None] * dL[i]) for i, j in TET10_EDGES], axis=1)
        return np.concatenate([corners, edges], axis=1)

    def rest_geometry(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Quadrature weights in m^3 (m, n_qp) and shape-function gradients dN_a/dX at the quadrature
        points (m, n_qp, n_nodes, 3) of elements whose rest node positions are ``X`` (m, n_nodes, 3)."""
        if self.order == 1:
            # constant gradients: the closed form, rows of the inverse edge matrix
            Dm = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2)
            V0 = np.linalg.det(Dm) / 6.0
            Dinv = np.linalg.inv(Dm)
            G = np.empty((X.shape[0], 1, 4, 3))
            G[:, 0, 1:] = Dinv
            G[:, 0, 0] = -Dinv.sum(axis=1)
            return V0[:, None] * self.quad_weights[None, :], G
        dN = self.shape_gradients(self.quad_points)  # (n_qp, n_nodes, 3)
        J = np.einsum("mai,kaj->mkij", X, dN)  # dx_i/dxi_j
        detJ = np.linalg.det(J)
        Jinv = np.linalg.inv(J)
        G = np.einsum("kaj,mkji->mkai", dN, Jinv)
        return detJ / 6.0 * self.quad_weights[None, :], G

    def body_load_weights(self, X: np.ndarray) -> np.ndarray:
        """Integrals of the shape functions over each element, (m, n_nodes) in m^3: a uniform body force
        density b gives the consistent nodal forces b * these weights."""
        w, _ = self.rest_geometry(X)
        if self.order == 1:
            return np.repeat(w / 4.0, 4, axis=1)  # each corner carries a quarter, exactly
        return w @ self.shape(self.quad_points)

    def local_coordinates(self, X: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Reference coordinates of point ``p`` (3,) in each element ``X`` (m, n_nodes, 3), (m, 3), from the
        affine map of the corners (exact for straight-sided elements)."""
        T = np.stack([X[:, 1] - X[:, 0], X[:, 2] - X[:, 0], X[:, 3] - X[:, 0]], axis=2)
        return np.einsum("mij,mj->mi", np.linalg.inv(T), p - X[:, 0])


TET4 = ElementType("tet4", "tetra", 1, np.vstack([np.zeros(3), np.eye(3)]), np.full((1, 3), 0.25), np.ones(1))
"""The linear (4-node) tetrahedron with its one-point rule (exact for constant strain)."""

TET10_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))
"""Corner pairs of the mid-edge nodes 4..9 of a 10-node tetrahedron, in VTK's (and meshio's) order."""

_CORNERS = np.vstack([np.zeros(3), np.eye(3)])
_A, _B = 0.5854101966249685, 0.1381966011250105  # the 4-point rule, exact for quadratic integrands
TET10 = ElementType("tet10", "tetra10", 2,
                    np.vstack([_CORNERS] + [(_CORNERS[i] + _CORNERS[j]) / 2 for i, j in TET10_EDGES]),
                    np.array([[_B, _B, _B], [_A, _B, _B], [_B, _A, _B], [_B, _B, _A]]), np.full(4, 0.25),
                    tangent_cost=16.0)
"""The quadratic (10-node) tetrahedron with the 4-point rule: its linear-elastic stiffness (a quadratic
integrand on straight-sided elements) is exact; the nonlinear laws are integrated to second order."""

ELEMENT_TYPES = {TET4.name: TET4, TET10.name: TET10}


def element_type(name: str) -> ElementType:
    """The element type called ``name`` (``tet4``)."""
    try:
        return ELEMENT_TYPES[name]
    except KeyError:
        raise ValueError(f"unknown element type {name!r}; expected one of {', '.join(ELEMENT_TYPES)}") from None
