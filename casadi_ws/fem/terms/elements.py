"""The body's elements: their internal forces, stiffness and second derivatives, one compiled kernel per law
(:class:`Elements`, phase ``internal``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..kernels import ElementBatch
from ..materials import element_functions
from ..spec import ModelError
from .base import Evaluation, Term

__all__ = ["ElementGroup", "Elements", "ROUNDOFF"]

ROUNDOFF = 20 * np.finfo(float).eps
"""Relative round-off allowed in the assembled internal forces: at rest (zero load) a residual below
ROUNDOFF x the elements' force scale counts as zero (measured at rest: ~3 eps for every law and order)."""


@dataclass
class ElementGroup:
    """The elements of one law: their dofs and rest inputs, and the law's kernels over them."""

    model: str
    index: np.ndarray | None
    """The elements' indices in the mesh; None: all of them."""
    edofs: np.ndarray
    Xe: np.ndarray
    Ge: np.ndarray
    Pe: np.ndarray
    """Quadrature weights, then the material parameters, per element."""
    functions: dict
    force: ElementBatch
    stiff: ElementBatch
    hv: ElementBatch | None = None


class Elements(Term):
    """Every element of the mesh, grouped by law (a region may have a law of its own): f_int, its tangent,
    and d(K^T lam)/dq for the NLPs' Hessians."""

    name = "elements"
    phase = "internal"
    negatives = 0

    def __init__(self, spec, backend: str = "auto"):
        mesh, element = spec.mesh, spec.mesh.element
        self.mesh, self.element, self.spec = mesh, element, spec
        self.materials, self.law = self._materials(spec)
        Xe = mesh.nodes[mesh.tets]
        self.w, self.G_qp = element.rest_geometry(Xe)
        """Quadrature weights (m, n_qp) and shape-function gradients (m, n_qp, n_nodes, 3) at rest."""
        self.rho = np.array([m.density for m in self.materials])[self.law]
        """Density per element (kg/m^3)."""
        self.Xe = Xe
        nd = element.n_dof
        self.edofs = (3 * mesh.tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, nd)
        Xl = (Xe - Xe[:, :1]).reshape(-1, nd)  # element-local: see materials' note on round-off
        Gl = self.G_qp.reshape(self.G_qp.shape[0], -1)
        kernels = list(dict.fromkeys(m.kernel for m in self.materials))
        self.groups: list[ElementGroup] = []
        """The elements of each law, with their inputs and compiled kernels (one group if the body has one
        law, as usual)."""
        for kernel in kernels:
            ks = [k for k, m in enumerate(self.materials) if m.kernel == kernel]
            idx = np.flatnonzero(np.isin(self.law, ks))
            params = np.array([self.materials[k].parameters for k in ks])[np.searchsorted(ks, self.law[idx])]
            funs = element_functions(kernel, element, hessian=False)
            self.groups.append(ElementGroup(
                kernel, None if len(kernels) == 1 else idx, self.edofs[idx], Xl[idx], Gl[idx],
                np.column_stack([self.w[idx], params]), funs, ElementBatch(funs["force"], backend),
                ElementBatch(funs["stiffness"], backend)))
        self.backend = self.groups[0].force.backend
        stretch = np.full(mesh.n_tets, np.inf if spec.material.max_stretch is None else spec.material.max_stretch)
        for tets, region in spec.regions:
            stretch[tets] = np.inf if region.max_stretch is None else region.max_stretch
        self.max_stretch = stretch
        """Largest principal stretch allowed per element (inf: none)."""
        self._force_scale()

    @staticmethod
    def _materials(spec):
        """(materials, index of each element's): the body's, then the regions' with a law or constants of
        their own."""
        law = np.zeros(spec.mesh.n_tets, dtype=np.int64)
        materials = [spec.material]
        for tets, region in spec.regions:
            law[tets] = len(materials)
            materials.append(region)
        return materials, law

    def taylor_hood(self) -> np.ndarray:
        """The elements whose law takes the continuous pressure (:mod:`casadi_ws.fem.terms.pressure`)."""
        th = [k for k, m in enumerate(self.materials) if m.kernel.endswith("_iso")]
        if th and self.element.name != "tet10":
            raise ModelError("formulation taylor_hood needs 10-node tetrahedra (order: 2): a linear pressure "
                                  "on 4-node ones locks")
        return np.flatnonzero(np.isin(self.law, th))

    def _force_scale(self):
        """The force scale under which a residual counts as zero. Loads of exactly 0 give q = 0, but the
        internal forces there are round-off, ~eps of the force each element exerts at unit strain
        (E V_e^(2/3), the polar decomposition's included); that round-off must pass the tolerance whatever
        the law. Nearly incompressible, the volumetric stress K (J - 1) carries K eps of round-off (J - 1 is
        computed from det F ~ 1): the modulus is then 0.3 K, which equals E at nu = 0.45, so up to there the
        scale is E as it always was (at nu = 0.499 Newton stalled at 10x the old floor)."""
        spec, mesh, mat = self.spec, self.mesh, self.spec.material

        def modulus(m):
            E, nu = m.young_modulus, m.poisson_ratio
            return E if nu <= 0.45 else max(E, 0.1 * E / (1 - 2 * nu))  # 0.3 K = 0.1 E / (1 - 2 nu)

        E_e = np.full(mesh.n_tets, modulus(mat))
        for tets, region in spec.regions:
            E_e[tets] = modulus(region)
        self.force_scale = float(np.linalg.norm(E_e * np.abs(self.w.sum(axis=1)) ** (2.0 / 3.0)))
        """The norm over elements of the force each exerts at unit strain, E_e V_e^(2/3) (N)."""
        self.force_floor = max(1e-12 * modulus(mat) * mesh.characteristic_length() ** 2,
                               ROUNDOFF * self.force_scale / spec.solver.tolerance)
        """The residual's scale is never below this (N)."""

    # ---------------------------------------------------------------- the pattern
    def pattern(self, model, pos):
        ed = pos[self.edofs]  # (m, n_dof_e), -1 for fixed
        nd = self.element.n_dof
        # element matrix is vec'ed column-major: entry (a, b) at index b * nd + a
        j = np.arange(nd * nd)
        rows, cols = ed[:, j % nd].ravel(), ed[:, j // nd].ravel()
        self._keep = (rows >= 0) & (cols >= 0)
        return cols[self._keep] * model.n_free + rows[self._keep]

    def attach(self, model, slots):
        # every element entry has a slot; those of fixed dofs go to one past the end, cut off after the
        # bincount (cheaper than gathering the kept ones on every assembly)
        self.k_slot = np.full(self._keep.size, model.nnz, dtype=np.int64)
        self.k_slot[self._keep] = slots
        m = self.mesh.n_tets
        self._k_slot32 = [np.ascontiguousarray(
            (self.k_slot.reshape(m, -1) if g.index is None else self.k_slot.reshape(m, -1)[g.index]).ravel(),
            dtype=np.int32) for g in self.groups]
        self._edofs32 = [np.ascontiguousarray(g.edofs, dtype=np.int32) for g in self.groups]
        self._f_slot32 = np.ascontiguousarray(self.edofs.ravel(), dtype=np.int32)

    # ---------------------------------------------------------------- evaluation
    def values(self, q: np.ndarray, kernels: str, *extra) -> list[np.ndarray]:
        """The outputs of the element kernels ``kernels`` (``force``, ``stiff``, ``hv``) of every law, in the
        mesh's element order."""
        if len(self.groups) == 1:
            g = self.groups[0]
            return [getattr(g, k)(q[g.edofs], g.Xe, g.Ge, g.Pe, *(e[g.edofs] for e in extra))[0]
                    for k in kernels.split()]
        outs = []
        for k in kernels.split():
            out = None
            for g in self.groups:
                v, = getattr(g, k)(q[g.edofs], g.Xe, g.Ge, g.Pe, *(e[g.edofs] for e in extra))
                if out is None:
                    out = np.empty((self.mesh.n_tets, v.shape[1]))
                out[g.index] = v
            outs.append(out)
        return outs

    def internal_force(self, q: np.ndarray, n_dof: int, norm: bool = False):
        """f_int(q) on all dofs (n_dof,); with ``norm``, also the norm of the unassembled element forces.

        One law: summed by the kernel as it computes them (:meth:`ElementBatch.scatter`), in the order a
        bincount of the batch sums them, without writing the batch (~60 us of a ~300 us residual on the
        linear trunk); several: the batch in the mesh's order, then a bincount."""
        if len(self.groups) == 1:
            g = self.groups[0]
            # (the slots of the element forces are their dofs: the same array says where to read q)
            out = g.force.scatter(self._f_slot32, n_dof, q, g.Xe, g.Ge, g.Pe, sumsq=norm,
                                  gather=self._f_slot32.reshape(g.edofs.shape))
            return (out[0], float(np.sqrt(out[1]))) if norm else out
        fe, = self.values(q, "force")
        f = np.bincount(self.edofs.ravel(), weights=fe.ravel(), minlength=n_dof)
        return (f, float(np.linalg.norm(fe))) if norm else f

    def forces(self, model, s: Evaluation):
        out = self.internal_force(s.q, model.n_dof, norm=s.with_scale)
        if s.with_scale:
            out, s.force_norm = out
        return out

    def stiffness_data(self, q: np.ndarray, nnz: int) -> np.ndarray:
        """The element stiffnesses at q summed into the pattern's slots (nnz + 1: the fixed dofs' entries
        last), by each group's kernel as it computes them (:meth:`ElementBatch.scatter`); group by group, so
        the sums do not depend on how a kernel runs."""
        data = None
        for g, slot, edofs in zip(self.groups, self._k_slot32, self._edofs32):
            part = g.stiff.scatter(slot, nnz + 1, q, g.Xe, g.Ge, g.Pe, gather=edofs)
            data = part if data is None else data + part
        return data

    def add_tangent(self, model, s, cache, data):
        part = self.stiffness_data(s.q, model.nnz)
        return part if data is None else data + part

    def hessian_vector_function(self, group: int = 0):
        """The element function of d(K_e^T lam_e)/du_e (for the NLPs' Hessians) of the elements of a law,
        built on first use."""
        g = self.groups[group]
        if "hessian_vector" not in g.functions:
            g.functions.update(element_functions(g.model, self.element))
        return g.functions["hessian_vector"]

    def add_hessian(self, model, s, lam, Hqq, Hqu):
        for k, g in enumerate(self.groups):
            if g.hv is None:
                # "auto", not "c": a kernel too large to compile (kernels.MAX_COMPILED_CODE) runs in CasADi's
                # VM even when the others are compiled
                g.hv = ElementBatch(self.hessian_vector_function(k), "casadi" if self.backend == "casadi" else "auto")
        lam_full = np.zeros(model.n_dof)
        lam_full[model.free] = lam
        he, = self.values(s.q, "hv", lam_full)
        H = self.assemble(model, he)
        return (H if Hqq is None else (Hqq + H).tocsc()), Hqu

    def assemble(self, model, ke: np.ndarray) -> sp.csc_matrix:
        """The free-dof matrix of element matrices ke (m, n_dof_e^2) on the model's pattern."""
        data = np.bincount(self.k_slot, weights=ke.ravel(), minlength=model.nnz + 1)
        return model.matrix(data)
