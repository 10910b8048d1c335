"""The static FEM model of a soft robot: the sum of its terms, with its residual, tangent and their derivatives.

    R(q, u) = f_int(q) - H(q)^T u - F = 0,        H_a = sign_a dQ_a/dq,    p_E = C q + p_E(0)

q is the state: the nodal displacements (3n, node-major; fixed dofs stay 0), then the unknowns the terms bring
(:class:`casadi_ws.fem.dofs.DofMap`); u the actuator inputs. Every force is a term
(:mod:`casadi_ws.fem.terms`): the elements, the actuators, the prescribed quantities, the loads, contact with
obstacles and with the body itself, the continuous pressure, and what a problem file or a user adds (springs,
pressure on a face, a user's own). :class:`StaticModel` builds them, lays out their unknowns, gathers their
tangent entries into one sparsity pattern fixed for the model (factorisations reuse one ordering, the CasADi
Functions rely on it), and sums them: the residual in three phases (internal forces, applied loads, then the
terms that change rows), the tangent, dR/du, the Hessian of lam . R, the stability matrix, the Newton step
limit, the reports. It holds no physics of its own.
"""

from __future__ import annotations

import copy

import casadi as ca
import numpy as np
import scipy.sparse as sp

from .cache import ModelCache
from .dofs import DofMap
from .kernels import ElementBatch
from .mesh import embed
from .spec import ModelError, ModelSpec
from .terms import Evaluation, builtin_terms
from .terms.elements import ROUNDOFF

__all__ = ["ModelError", "ROUNDOFF", "StaticModel"]


class StaticModel:
    """Numeric static model of a :class:`casadi_ws.fem.spec.ModelSpec` (a problem file's
    :class:`casadi_ws.io.problem.Problem` is one): the sum of its terms."""

    def __init__(self, spec: ModelSpec, backend: str = "auto"):
        self.spec = spec
        """What the model was built from; the layers below ``io`` read nothing else of it."""
        self.cache = ModelCache()
        """What other layers build once for this model (:class:`casadi_ws.fem.cache.ModelCache`)."""
        self.mesh = mesh = spec.mesh
        self.element = mesh.element
        self.n_nodes = mesh.n_nodes
        self.actuators = list(spec.actuators)
        self.n_u = len(self.actuators)
        self.u_min = np.array([a.u_min for a in self.actuators], dtype=float)
        self.u_max = np.array([a.u_max for a in self.actuators], dtype=float)
        self.sign = np.array([a.sign for a in self.actuators], dtype=float)
        self.n_mech = 3 * mesh.n_nodes
        """Nodal displacements in the state; the terms' unknowns follow them."""
        self.fixed = spec.fixed_dofs()
        """(n_nodes, 3) the displacement components held at zero."""
        self.fixed_nodes = np.flatnonzero(self.fixed.all(axis=1))
        self.free_mech = np.flatnonzero(~self.fixed.ravel())
        self.n_free_mech = self.free_mech.size
        self.backend_request = backend

        # the terms: built in, then the specification's own (springs, pressure loads, a user's), a copy each
        self.terms = builtin_terms(self) + [copy.deepcopy(t) for t in spec.terms]
        """Every term, in the order they are summed within a phase (:mod:`casadi_ws.fem.terms`)."""
        names = [t.name for t in self.terms]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ModelError(f"{spec.source}: terms: two terms named {twice[0]!r} (a term's name is its block's "
                             f"and what model.term() finds: give each its own)")
        for t in self.terms:
            t.prepare(self)
        self.dofs = DofMap.build(self.n_mech, self.free_mech, [(t.name, t.n_rows) for t in self.terms if t.n_rows])
        """Where each block of the state lies (:class:`casadi_ws.fem.dofs.DofMap`)."""
        d = self.dofs
        self.n_dof, self.n_free, self.free = d.n_dof, d.n_free, d.free
        self.n_extra = d.n_extra
        for t in self.terms:
            if t.name in d.blocks:
                t.rows, t.state = d.rows(t.name), d.state(t.name)
        self.X = np.concatenate([mesh.nodes.reshape(-1), np.zeros(self.n_extra)])
        """Rest positions on all dofs (zeros for the unknowns)."""
        pos = d.positions()
        for t in self.terms:
            t.setup(self, pos)
        self._build_pattern(pos)
        for t in self.terms:
            t.ready(self)

        self._internal = [t for t in self.terms if t.phase == "internal"]
        self._applied = [t for t in self.terms if t.phase == "applied"]
        self._with_rows = [t for t in self.terms if t.phase == "rows"]
        self.has_contact = any(t.n_rows or t.grows for t in self.contact_terms())
        """Whether the model has contact points (the Newton steps' contact safeguards apply)."""
        self.pivot_threshold = 0.0 if any(t.negatives for t in self.terms) else 0.01
        """SuperLU's diag_pivot_thresh for this model's tangents (:func:`casadi_ws.solvers.linear.factorize`): 0
        where a term makes the tangent a symmetric saddle point (the pressure's), which is quasi-definite where
        stable and so factorises with diagonal pivots, whose signs the stability test reads; 0.01 otherwise."""

        # --- end-effector: p_E = C q + p_E(0)
        ee = np.atleast_2d(np.asarray(spec.end_effector, dtype=float))
        self.C = self.embedding(ee)
        self.p0 = self.C @ self.X
        self.C_free = self.C[:, self.free].tocsc()

    # ------------------------------------------------------------------ the terms the other layers ask for
    def term(self, name: str):
        """The term named ``name`` (``elements``, ``actuators``, ``intensities``, ``loads``, ``obstacles``...)."""
        for t in self.terms:
            if t.name == name:
                return t
        raise KeyError(f"the model has no term {name!r}")

    @property
    def elements(self):
        """The elements' term (:class:`casadi_ws.fem.terms.elements.Elements`)."""
        return self.terms[0]

    @property
    def actuators_term(self):
        """(:class:`casadi_ws.fem.terms.actuators.Actuators`)"""
        return self.terms[1]

    @property
    def prescribed_term(self):
        """(:class:`casadi_ws.fem.terms.prescribed.Prescribed`)"""
        return self.terms[2]

    def contact_terms(self) -> list:
        """The terms whose rows are contact points (obstacles, self-contact)."""
        return [t for t in self.terms if t.contact]

    @property
    def problem(self) -> ModelSpec:
        """The specification it was built from (for the layers above ``fem``: :attr:`spec`)."""
        return self.spec

    # the terms' quantities under the names the other layers use
    element_groups = property(lambda self: self.elements.groups)
    element_functions = property(lambda self: self.elements.groups[0].functions)
    backend = property(lambda self: self.elements.backend)
    max_stretch = property(lambda self: self.elements.max_stretch)
    element_force_scale = property(lambda self: self.elements.force_scale)
    force_floor = property(lambda self: self.elements.force_floor)

    @property
    def F(self) -> np.ndarray:
        """The constant loads on all dofs (n_dof,), N (gravity and point loads: :class:`casadi_ws.fem.terms.
        loads.Loads`); set it to load the body otherwise (an imperfection, :func:`casadi_ws.solvers.admissible.
        stable_branch`)."""
        return self.term("loads").F

    @F.setter
    def F(self, value: np.ndarray) -> None:
        self.term("loads").F = value

    actuator_data = property(lambda self: self.actuators_term.data)
    rest_quantities = property(lambda self: self.actuators_term.rest_quantities)
    quantity_limits = property(lambda self: self.actuators_term.quantity_limits)
    prescribed = property(lambda self: self.prescribed_term.index)
    n_lam = property(lambda self: self.prescribed_term.n_rows)
    kappa = property(lambda self: self.prescribed_term.kappa)
    eps = property(lambda self: self.prescribed_term.eps)
    contact = property(lambda self: next((t.contact_set for t in self.contact_terms() if hasattr(t, "contact_set")),
                                         None))
    n_con = property(lambda self: sum(t.n_rows for t in self.contact_terms()))
    """Contact points (the rows of the contact terms)."""

    # ------------------------------------------------------------------ the pattern
    def _build_pattern(self, pos):
        """One sparsity pattern of K on the free dofs, from every term's keys; each term is told its slots."""
        self._pos = pos
        self._keys = [t.pattern(self, pos) for t in self.terms]
        self._attach()

    def _attach(self):
        keys = self._keys
        ukey, slot = np.unique(np.concatenate(keys + [np.zeros(0, dtype=np.int64)]), return_inverse=True)
        self._ukey = ukey
        self.nnz = ukey.size
        """Entries of the pattern."""
        self._k_rows = (ukey % self.n_free).astype(np.int32)
        ccount = np.bincount(ukey // self.n_free, minlength=self.n_free)
        self._k_indptr = np.concatenate([[0], np.cumsum(ccount)]).astype(np.int32)
        self._term_slots = {}
        at = 0
        for t, k in zip(self.terms, keys):
            t.attach(self, slot[at:at + k.size])
            at += k.size

    pattern_version = 0
    """How many times the pattern grew (:meth:`grow_pattern`): what was built on an older one is stale."""

    def grow_pattern(self) -> None:
        """Re-read the keys of the terms whose pattern grows with the state (``Term.grows``: self-contact
        found as the body moves) and lay the pattern out again; called by such a term from its residual,
        before any tangent of the state is assembled. Factorisations see a new pattern and analyse it anew."""
        for i, t in enumerate(self.terms):
            if t.grows:
                self._keys[i] = t.pattern(self, self._pos)
        self._attach()
        self.pattern_version += 1

    def slots(self, keys: np.ndarray) -> np.ndarray:
        """The positions in the pattern's data of entries given by keys (column * n_free + row); a term that
        keeps its keys is looked up once (contact terms build new keys every time)."""
        cached = self._term_slots.get(id(keys))
        if cached is not None and cached[0] is keys:
            return cached[1]
        s = np.searchsorted(self._ukey, keys)
        if s.size and (s.max() >= self._ukey.size or np.any(self._ukey[s] != keys)):
            raise AssertionError("a term's tangent entry is outside the pattern it declared")
        if len(self._term_slots) > 4 * len(self.terms):
            self._term_slots.clear()
        self._term_slots[id(keys)] = (keys, s)
        return s

    def matrix(self, data: np.ndarray) -> sp.csc_matrix:
        """The free-dof matrix on the pattern whose values are data[:nnz] (explicit zeros kept)."""
        return sp.csc_matrix((data[: self.nnz], self._k_rows, self._k_indptr), shape=(self.n_free, self.n_free))

    def pattern_keys(self) -> np.ndarray:
        """The pattern's keys (column * n_free + row), sorted."""
        return self._ukey

    # ------------------------------------------------------------------ the sums
    def _residual(self, s: Evaluation):
        """(R on the free dofs, the applied loads there (with ``s.with_scale``), the rows terms' caches) at s."""
        f = None
        for t in self._internal:
            part = t.forces(self, s)
            f = part if f is None else f + part
        ext = None
        for t in self._applied:
            part = t.forces(self, s)
            if part is not None:
                ext = part if ext is None else ext + part
        ext = (np.zeros(self.n_dof) if ext is None else ext)[self.free]
        R = f[self.free] + ext
        caches = {}
        for t in self._with_rows:
            R0 = R.copy() if s.with_scale and t.applied else None
            caches[t] = t.residual(self, s.q, s.u, R)
            if R0 is not None:
                ext = ext + (R0 - R)  # the contact forces join the applied ones in the scale
        if s.with_scale:
            for t in self._with_rows:
                ext[t.rows] = 0.0
        return R, ext, caches

    def residual(self, q: np.ndarray, u: np.ndarray, load: float = 1.0, with_scale: bool = False):
        """R(q, u) = f_int - sum_a t_a sign_a dQ_a/dq - load * F + the terms' forces, on the free dofs (t the
        intensities: u, or the state's where the quantity is prescribed), and the terms' own rows.

        With ``with_scale`` also returns ||H^T t + load F|| (free dofs; contact forces included), the reference
        of the relative residual (plus a round-off allowance, see below), floored so that a zero load is judged
        absolutely."""
        s = Evaluation(q, np.asarray(u, dtype=float), load, with_scale=with_scale)
        R, ext, _ = self._residual(s)
        if with_scale:
            # 1e-6 of the unassembled element forces: the assembly's round-off (~1e-16 of them) then stays
            # far below any tolerance, even when the applied load is tiny
            return R, max(float(np.linalg.norm(ext)) + 1e-6 * s.force_norm, self.force_floor)
        return R

    def residual_and_tangent(self, q: np.ndarray, u: np.ndarray, load: float = 1.0):
        """(R, K, dR/du) on the free dofs; K = dR/dq, every term's entries summed on the pattern."""
        s = Evaluation(q, np.asarray(u, dtype=float), load, tangent=True)
        R, _, caches = self._residual(s)
        return R, self._tangent(s, caches), self._input_jacobian(s)

    def tangent(self, q: np.ndarray, u: np.ndarray, load: float = 1.0) -> sp.csc_matrix:
        """K of :meth:`residual_and_tangent`, the same to the bit, for callers that have R or do not need it
        (Newton's fresh factorisation, the sensitivities' refinement, the stability test). Where no term changes
        rows (their tangents are built with R), the internal forces are not computed: a kernel pass of its own,
        0.21 of the 1.73 ms of K and R together on the 4-cable trunk."""
        if any(t.tangent_from_residual for t in self._with_rows):
            return self.residual_and_tangent(q, u, load)[1]
        s = Evaluation(q, np.asarray(u, dtype=float), load)
        return self._tangent(s, {})

    def _tangent(self, s: Evaluation, caches: dict) -> sp.csc_matrix:
        data = None  # the values on the pattern, and last what falls on fixed dofs
        for t in self.terms:
            data = t.add_tangent(self, s, caches.get(t), data)
        return self.matrix(np.zeros(self.nnz + 1) if data is None else data)

    def _input_jacobian(self, s: Evaluation) -> np.ndarray:
        dRdu = np.zeros((self.n_free, self.n_u))
        for t in self.terms:
            t.input_jacobian(self, s, dRdu)
        return dRdu

    def stability_matrix(self, q: np.ndarray, u: np.ndarray) -> sp.csc_matrix:
        """The stiffness on the nodal dofs with what the terms hold held (the prescribed quantities, the contact
        points that press, the continuous pressure following the displacements: :meth:`Term.held`). Positive
        definite iff K is on the motions that keep the held quantities (the saddle-point K of Newton has
        negative pivots whatever the stability)."""
        n = self.n_free_mech
        K = self.tangent(q, u)[:n, :n]
        for t in self.terms:
            held = t.held(self, q, np.asarray(u, dtype=float))
            if held is not None:
                K = K + held
        return K.tocsc()

    def residual_hessian(self, q: np.ndarray, u: np.ndarray, lam: np.ndarray):
        """Second derivatives of lam . R (lam on the free dofs): (d(K^T lam)/dq on the free dofs, sparse;
        d(K^T lam)/du = d(dR/du^T lam)/dq, dense (n_free, n_u)). K^T lam, not K lam: the corotational
        tangent is not exactly symmetric, and this is what reverse-mode AD differentiates."""
        s = Evaluation(q, np.asarray(u, dtype=float))
        Hqq, Hqu = None, np.zeros((self.n_free, self.n_u))
        for t in self.terms:
            Hqq, Hqu = t.add_hessian(self, s, lam, Hqq, Hqu)
        return Hqq.tocsc(), Hqu

    def contact_step_limit(self, q: np.ndarray, dq: np.ndarray) -> tuple[float, bool]:
        """The share of the Newton step dq (free dofs) the terms allow (:meth:`Term.step_limit`), and whether
        the step so cut is taken as it is (the binding term's :attr:`Term.cut_judged` is False)."""
        limits = [(t.step_limit(self, q, dq), not t.cut_judged) for t in self.terms]
        return min(limits + [(1.0, False)], key=lambda a: a[0])

    def contacts(self, q: np.ndarray) -> list[dict]:
        """What the terms report at q: per obstacle (and per self-contact pair) its name, the total force
        [fx, fy, fz] (N) it exerts on the body, the number of contact points pressing, and the largest
        penetration (m, 0 if none); and what the other terms report."""
        return [c for t in self.terms for c in t.report(self, q)]

    # ------------------------------------------------------------------ kinematics of the mesh
    def embedding(self, points: np.ndarray) -> sp.csr_matrix:
        """W (3k x n_dof): positions of embedded points = W @ (X + q) (zero columns for the unknowns)."""
        W = sp.csr_matrix(embed(self.mesh, np.atleast_2d(points)).matrix(self.mesh))
        if self.n_extra:
            W = sp.hstack([W, sp.csr_matrix((W.shape[0], self.n_extra))]).tocsr()
        return W

    def positions(self, q: np.ndarray) -> np.ndarray:
        """Current node positions (n, 3)."""
        return (self.X + q)[: self.n_mech].reshape(-1, 3)

    @property
    def quadrature_points(self) -> int:
        """Quadrature points per element (the rows of :meth:`deformation_gradients` per element)."""
        return self.elements.G_qp.shape[1]

    def deformation_operator(self) -> sp.csr_matrix:
        """The sparse map of q to the entries of F - I at every quadrature point ((element, point, i, j) rows,
        row-major), built once."""
        if "_F_op" not in self.__dict__:
            G = self.elements.G_qp
            # F_ij at (element e, point k) = delta_ij + sum_a q[3 node_a + i] G[e, k, a, j]: a sparse map of q
            m, nq, nn, _ = G.shape
            e, k, a, i, j = np.meshgrid(np.arange(m), np.arange(nq), np.arange(nn), np.arange(3), np.arange(3),
                                        indexing="ij")
            rows = (((e * nq + k) * 3 + i) * 3 + j).ravel()
            cols = (3 * self.mesh.tets[e, a] + i).ravel()
            self._F_op = sp.csr_matrix((G[e, k, a, j].ravel(), (rows, cols)), shape=(m * nq * 9, self.n_dof))
        return self._F_op

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """F = I + du/dX at every quadrature point, (m, n_qp, 3, 3)."""
        m, nq = self.elements.G_qp.shape[:2]
        return np.eye(3) + (self.deformation_operator() @ q).reshape(m, nq, 3, 3)

    def node_sizes(self) -> np.ndarray:
        """Per node, the mean edge of the smallest element it belongs to (m): the scale of a safe nodal move
        (Newton's trust region, :data:`casadi_ws.solvers.equilibrium.TRUST_REGION`)."""
        if "_node_sizes" not in self.__dict__:
            h = self.mesh.element_sizes()
            size = np.full(self.n_nodes, np.inf)
            np.minimum.at(size, self.mesh.tets.ravel(), np.repeat(h, self.mesh.tets.shape[1]))
            size[~np.isfinite(size)] = h.max()  # nodes of no element
            self._node_sizes = size
        return self._node_sizes

    def jacobians(self, q: np.ndarray) -> np.ndarray:
        """det F at every quadrature point, (m, n_qp), from the element's nodal displacements.

        Why not from :meth:`deformation_gradients`: every verified point of a sweep asks for it (the inversion
        check), and F through a sparse map of q, then its determinant, took ~0.25 ms per point on the linear
        trunk, half its residual's time; one compiled pass over the elements reads only their displacements
        and shape gradients."""
        G = self.elements.G_qp
        if "_det_kernel" not in self.__dict__:
            _, nq, nn, _ = G.shape
            self._det_kernel = ElementBatch(_det_f_function(nq, nn), "c" if self.backend == "c" else "casadi")
        return self._det_kernel(q[self.elements.edofs], G.reshape(G.shape[0], -1))[0]

    # ------------------------------------------------------------------ the elements'
    def internal_force(self, q: np.ndarray, norm: bool = False):
        """f_int(q) on all dofs (n_dof,); with ``norm``, also the norm of the unassembled element forces."""
        return self.elements.internal_force(q, self.n_dof, norm)

    def element_stiffness(self, q: np.ndarray) -> sp.csc_matrix:
        """df_int/dq on the free dofs."""
        return self.matrix(self.elements.stiffness_data(q, self.nnz))

    def hessian_vector_function(self, group: int = 0):
        """The element function of d(K_e^T lam_e)/du_e of the elements of a law (the NLPs' Hessians)."""
        return self.elements.hessian_vector_function(group)

    # ------------------------------------------------------------------ the actuators'
    def actuator_terms(self, q: np.ndarray, hessians: bool = False):
        """Q (n_u,), dQ/dq (n_u, n_dof) and, if asked, the nonzeros of every d2Q/dP2, stacked."""
        return self.actuators_term.terms(q, hessians)

    def actuator_states(self, q: np.ndarray) -> np.ndarray:
        """Each actuator's quantity at q (a cable's length in m), (n_u,)."""
        return self.actuators_term.terms(q)[0]

    def actuator_hessians(self, q: np.ndarray) -> list[sp.csc_matrix]:
        """d2Q_a/dq2 on the free dofs, one sparse matrix per actuator."""
        return self.actuators_term.hessians(q)

    def actuation_rows(self, q: np.ndarray) -> np.ndarray:
        """H(q) = sign dQ/dq on the free dofs, (n_u, n_free) (a cable's row: -dL/dq): where each actuator's
        intensity pushes the body."""
        return self.actuators_term.rows(q)

    def intensities(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Each actuator's intensity (tension N, pressure Pa): u, or the state's unknown where the input is
        the quantity."""
        t = np.array(u, dtype=float, copy=True).reshape(-1)
        t[self.prescribed] = self.prescribed_term.intensities(q)
        return t

    def actuation_matrix(self, q: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """-dR/du^T (n_u, n_free), so that dq/du = K^-1 H^T: H = sign dQ/dq for an actuator whose input is
        its intensity; for a prescribed quantity, kappa dphi/db in its own row (at an equilibrium without
        ``u``, from the row's a b = eps^2/2: ~kappa for a taut cable, ~0 for a slack one)."""
        H = self.actuation_rows(q)
        pre = self.prescribed_term
        if pre.n_rows:
            Q = self.actuator_states(q) if u is not None else None
            pb = pre.rows_at(self, q, u, Q)[2]
            H[pre.index] = 0.0
            H[pre.index, pre.rows.start + np.arange(pre.n_rows)] = pb * pre.kappa
        return H

    def slack(self, q: np.ndarray) -> np.ndarray:
        """(n_u,) bool: the prescribed unilateral actuators that are slack at the equilibrium q (a cable with
        no tension, shortened more than its motor pulled)."""
        out = np.zeros(self.n_u, dtype=bool)
        out[self.prescribed] = self.prescribed_term.slack(q)
        return out

    def taut_rows(self, q: np.ndarray):
        """For each slack actuator a (:meth:`slack`): (a, its row j of the tangent, the change w of that row
        that makes the cable taut: (1 - phi_b) kappa H on its dofs and -phi_a at j). The sensitivities of a
        slack cable once taut follow from the tangent by a rank-one update."""
        out = []
        slack = self.slack(q)
        if not slack.any():
            return out
        pre = self.prescribed_term
        _, pa, pb, *_ = pre.rows_at(self, q, None, None)
        H = self.actuation_rows(q)
        for k, a in enumerate(pre.index):
            if slack[a]:
                j = pre.rows.start + k
                w = np.zeros(self.n_free)
                r = pre.border_dofs[k]
                w[r] = (1 - pb[k]) * pre.kappa[k] * H[a, r]
                w[j] = -pre.kappa[k] * pa[k]
                out.append((a, j, w))
        return out

    # ------------------------------------------------------------------ the contact terms'
    def contact_forces(self, q: np.ndarray) -> np.ndarray:
        """The forces (n_dof,) the obstacles (and the body on itself) exert on the nodes at q."""
        out = np.zeros(self.n_dof)
        for t in self.contact_terms():
            out[self.free] += t.contact_forces(self, q)
        return out

    def in_contact(self, q: np.ndarray) -> np.ndarray:
        """(n_con,) bool: the contact points that press at the equilibrium q (lambda > kappa g)."""
        return np.concatenate([t.in_contact(self, q) for t in self.contact_terms() if t.n_rows]
                              + [np.zeros(0, dtype=bool)])

    def min_gap(self, q: np.ndarray) -> float:
        """The smallest gap of any contact point at q (m; inf without contact)."""
        return min([float(t.geometry(self, q).g.min()) for t in self.contact_terms() if t.n_rows] + [np.inf])

    # ------------------------------------------------------------------ small things
    @property
    def u_lower(self) -> np.ndarray:
        """Lower bounds of u (the box U), (n_u,)."""
        return self.u_min

    @property
    def u_upper(self) -> np.ndarray:
        """Upper bounds of u, (n_u,)."""
        return self.u_max

    @property
    def q_rest(self) -> np.ndarray:
        """The free degrees of freedom at rest (zeros, (n_free,)): a start for an NLP over q."""
        return np.zeros(self.n_free)

    def tip(self, q: np.ndarray) -> np.ndarray:
        """End-effector position p_E = C q + p_E(0)."""
        return self.C @ q + self.p0

    @property
    def tip_frame(self):
        """The tip's frame (:class:`casadi_ws.fem.frame.TipFrame`): from the problem's three ``frame`` points, else
        the tip elements' rotation."""
        from .frame import TipFrame

        return self.cache.get("tip_frame", lambda: TipFrame(self, getattr(self.spec, "tip_frame", None)))

    def full(self, q_free: np.ndarray) -> np.ndarray:
        q = np.zeros(self.n_dof)
        q[self.free] = q_free
        return q


def _det_f_function(n_qp: int, n_nodes: int) -> ca.Function:
    """det F at each quadrature point of an element, from its displacements (3 per node, node-major) and its
    shape-function gradients at the quadrature points ((point, node, 3) flattened), as
    :meth:`StaticModel.deformation_gradients` builds F: F_ij = delta_ij + sum_a u_ai dN_a/dX_j."""
    u = ca.SX.sym("u", 3 * n_nodes)
    G = ca.SX.sym("G", 3 * n_nodes * n_qp)
    dets = []
    for k in range(n_qp):
        F = [[(1.0 if i == j else 0.0) + sum(u[3 * a + i] * G[(k * n_nodes + a) * 3 + j] for a in range(n_nodes))
              for j in range(3)] for i in range(3)]
        dets.append(F[0][0] * (F[1][1] * F[2][2] - F[1][2] * F[2][1])
                    - F[0][1] * (F[1][0] * F[2][2] - F[1][2] * F[2][0])
                    + F[0][2] * (F[1][0] * F[2][1] - F[1][1] * F[2][0]))
    return ca.Function("det_F", [u, G], [ca.vertcat(*dets)])
