"""The static FEM model of a soft robot: residual, tangent stiffness, and their derivatives.

    R(q, u) = f_int(q) - H(q)^T u - F = 0,        H_a = sign_a dQ_a/dq,    p_E = C q + p_E(0)

q is the vector of nodal displacements (3n, node-major; fixed dofs stay 0), u the actuator inputs, Q_a the
quantity of actuator a (a cable's length: sign -1, so H = -dL/dq).

Prescribed quantities (a displacement-controlled cable, a cavity controlled by its volume growth): the input
u_a is then g_a's target, g_a(q) = sign_a (Q_a(q) - Q_a(rest)) (a cable's shortening, a chamber's growth),
and the actuator's intensity t_a (tension, pressure) is an unknown appended to the state: q = [nodal
displacements, t / kappa of the prescribed actuators] (the intensity in units of the quantity, so that the
state's entries are all lengths for cables and Newton's norms weigh them alike). Each adds one equation,

    bilateral (a chamber):     kappa_a (g_a(q) - u_a) = 0
    unilateral (a cable):      phi(t_a, kappa_a (g_a(q) - u_a)) = 0,   phi(a, b) = a + b - sqrt(a^2 + b^2 + eps^2)

phi is the Fischer-Burmeister function, zero iff a >= 0, b >= 0 and a b = eps^2 / 2: the cable is taut
(shortening = the motor's, tension >= 0) or slack (tension ~0, shortened more than the motor pulled), as
SOFA's CableConstraint with minForce 0. eps (1e-8 of kappa_a Q_a(rest)) keeps phi smooth, so Newton, the
sensitivities and the NLPs' Hessians see one smooth residual; what it changes is ~eps^2, far below any
tolerance. kappa_a = 1 / (H_a K0^-1 H_a^T), the actuator's own stiffness at rest, gives the row the units
and the scale of a force (or pressure). Every method then works unchanged on the augmented state: the
tangent is bordered by the prescribed actuators' rows, dR/du_a is nonzero in its own row only, and the
end-effector, the mesh operators and the loads carry zero columns for the intensities. The element laws come from
:mod:`casadi_ws.fem.materials` (CasADi SX, one graph per element type) and are evaluated over the mesh by
:class:`casadi_ws.fem.kernels.ElementBatch`; the actuators' quantities and their derivatives are one CasADi
function of the actuators' embedded points (:mod:`casadi_ws.actuation`). Terms that bring unknowns and rows of
their own (contact with obstacles, self-contact) are registered objects (:mod:`casadi_ws.fem.terms`) every
method iterates over. Assembly uses index maps fixed once per mesh. All matrices returned here are restricted to the free dofs.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp

from ..actuation.base import quantity_functions, third_function
from .cache import ModelCache
from .contact import contact_set, split_faces
from .terms import ContinuousPressure, ObstacleContact, SelfContact, fischer_burmeister
from .kernels import ElementBatch
from .materials import element_functions
from .mesh import embed
from .spec import ModelSpec

__all__ = ["ModelError", "ROUNDOFF", "StaticModel", "fischer_burmeister"]


class ModelError(ValueError):
    """A problem that reads well but cannot make a model; ``str()`` is one line naming the file and key."""

ROUNDOFF = 20 * np.finfo(float).eps
"""Relative round-off allowed in the assembled internal forces: at rest (zero load) a residual below
ROUNDOFF x the elements' force scale counts as zero (measured at rest: ~3 eps for every law and order)."""


@dataclass
class _ElementGroup:
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


@dataclass
class _ActuatorData:
    actuator: object
    W: sp.csr_matrix
    """(3k x 3n) positions of the actuator's points = W @ x."""
    hessian_sparsity: ca.Sparsity
    """Pattern of d2Q/dP2 (3k x 3k) as CasADi derives it."""
    _third: ca.Function | None = None

    @property
    def third(self) -> ca.Function:
        """(P, mu) -> d2(mu . dQ/dP)/dP2, for Lagrangian Hessians; built on first use (costly for a cavity)."""
        if self._third is None:
            self._third = third_function(self.actuator)
        return self._third


class StaticModel:
    """Numeric static model of a :class:`casadi_ws.fem.spec.ModelSpec` (a problem file's
    :class:`casadi_ws.io.problem.Problem` is one)."""

    def __init__(self, spec: ModelSpec, backend: str = "auto"):
        problem = spec
        self.spec = spec
        """What the model was built from; the layers below ``io`` read nothing else of it."""
        self.cache = ModelCache()
        """What other layers build once for this model (:class:`casadi_ws.fem.cache.ModelCache`)."""
        mesh = problem.mesh
        self.mesh = mesh
        self.element = element = mesh.element
        self.n_nodes = mesh.n_nodes
        self.actuators = list(problem.actuators)
        self.prescribed = np.flatnonzero([getattr(a, "prescribed", False) for a in self.actuators])
        """Indices of the actuators whose input is their quantity (their intensity is then a state)."""
        self.n_lam = self.prescribed.size
        self.n_mech = 3 * mesh.n_nodes
        """Nodal displacements in the state; the intensities of prescribed actuators follow them."""
        fixed = problem.fixed_dofs()  # (n_nodes, 3)
        self.fixed_nodes = np.flatnonzero(fixed.all(axis=1))
        self.free_mech = np.flatnonzero(~fixed.ravel())
        self.n_free_mech = self.free_mech.size
        self.contact = contact_set(mesh, problem.obstacles, ~fixed.all(axis=1),
                                   problem.material.young_modulus)
        """The contact points with the obstacles (:class:`casadi_ws.fem.contact.ContactSet`), or None."""
        self._backend = backend
        self.terms = self._register_terms(fixed)
        """The registered terms (:mod:`casadi_ws.fem.terms`): contact with obstacles, self-contact, the
        continuous pressure (:mod:`casadi_ws.fem.terms.pressure`). Their unknowns (contact forces over kappa,
        pressures over kappa) follow the intensities in the state."""
        self.pivot_threshold = 0.0 if any(t.negatives for t in self.terms) else 0.01
        """SuperLU's diag_pivot_thresh for this model's tangents (:func:`casadi_ws.solvers.equilibrium.
        factorize`): 0 where a term makes the tangent a symmetric saddle point (the pressure's), which is
        quasi-definite where stable and so factorises with diagonal pivots, whose signs the stability test
        reads; 0.01 otherwise."""
        self.has_contact = any(t.n_rows for t in self._contact_terms())
        """Whether the model has contact points (the Newton steps' contact safeguards apply)."""
        self.n_con = sum(t.n_rows for t in self.terms)
        self.n_extra = self.n_lam + self.n_con
        self.n_dof = self.n_mech + self.n_extra
        self.free = np.concatenate([self.free_mech, self.n_mech + np.arange(self.n_extra)])
        self.n_free = self.free.size
        self.con_rows = slice(self.n_free_mech + self.n_lam, self.n_free)
        """The terms' rows (and unknowns) among the free dofs."""
        self.X = np.concatenate([mesh.nodes.reshape(-1), np.zeros(self.n_extra)])

        mat = problem.material
        Xe, w, rho = self._build_elements(backend)

        # --- loads: consistent gravity loads and point loads on embedded points
        F = np.zeros(self.n_dof)
        g = np.asarray(problem.gravity, dtype=float)
        if np.any(g):
            weights = rho[:, None] * element.body_load_weights(Xe)  # kg per node and element
            for a in range(element.n_nodes):
                np.add.at(F[: self.n_mech].reshape(-1, 3), mesh.tets[:, a], weights[:, a, None] * g[None, :])
        for point, force in problem.point_loads:
            W = self.embedding(np.asarray(point)[None])
            F += W.T @ np.asarray(force, dtype=float)
        self.F = F

        # --- actuators
        self.n_u = len(self.actuators)
        self.u_min = np.array([a.u_min for a in self.actuators], dtype=float)
        self.u_max = np.array([a.u_max for a in self.actuators], dtype=float)
        self.sign = np.array([a.sign for a in self.actuators], dtype=float)
        self._build_actuators()
        self._build_pattern()
        rest_Q = self.actuator_states(np.zeros(self.n_dof))
        self.rest_quantities = rest_Q
        """Each actuator's quantity at rest (a cable's length, a chamber's volume)."""
        self._build_prescribed()
        limits = [a.quantity_limits(Q0) for a, Q0 in zip(self.actuators, rest_Q)]
        self.quantity_limits = (np.array([l[0] for l in limits]), np.array([l[1] for l in limits]),
                                [l[2] if np.isfinite(l[0]) or np.isfinite(l[1]) else "" for l in limits])
        """(lower, upper, violation name) of each actuator's quantity Q (a cable's stroke, a chamber's
        volume); the name is empty where it is unlimited."""
        if not any(self.quantity_limits[2]):
            self.quantity_limits = (self.quantity_limits[0], self.quantity_limits[1], [])
        stretch = np.full(mesh.n_tets, np.inf if mat.max_stretch is None else mat.max_stretch)
        for tets, region in problem.regions:
            stretch[tets] = np.inf if region.max_stretch is None else region.max_stretch
        self.max_stretch = stretch
        """Largest principal stretch allowed per element (inf: none)."""

        # --- end-effector: p_E = C q + p_E(0)
        ee = np.atleast_2d(np.asarray(problem.end_effector, dtype=float))
        self.C = self.embedding(ee)
        self.p0 = self.C @ self.X
        self.C_free = self.C[:, self.free].tocsc()

        self._force_scale(w)

    @property
    def problem(self) -> ModelSpec:
        """The specification it was built from (for the layers above ``fem``: :attr:`spec`)."""
        return self.spec

    def _register_terms(self, fixed) -> list:
        """The terms after the elements and actuators, each given its rows at the end of the state."""
        pos = -np.ones(self.n_mech, dtype=np.int64)
        pos[self.free_mech] = np.arange(self.n_free_mech)
        terms = []
        if self.contact is not None:
            terms.append(ObstacleContact(self.contact, pos))
        moving = ~fixed.all(axis=1)
        for pair in self.spec.self_contact:
            terms.append(SelfContact(pair.name, pair.points[moving[pair.points]], split_faces(pair.faces),
                                     self.mesh.nodes, pos, self.spec.material.young_modulus, pair.reach))
        th = self._taylor_hood_elements()
        if th.size:
            tets = self.mesh.tets[th]
            w, G = self.element.rest_geometry(self.mesh.nodes[tets])
            edofs = (3 * tets[:, :, None] + np.arange(3)).reshape(th.size, -1)
            bulk = np.array([m.parameters[-1] for m in self._materials()[0]])[self._materials()[1][th]]
            terms.append(ContinuousPressure(tets, edofs, w, G, bulk, self.n_free_mech, self._backend))
        start = self.n_free_mech + self.n_lam
        for t in terms:
            t.rows = slice(start, start + t.n_rows)
            t.state = slice(self.n_mech + start - self.n_free_mech, self.n_mech + start - self.n_free_mech + t.n_rows)
            start += t.n_rows
        return terms

    def _materials(self):
        """(materials, index of each element's): the body's, then the regions' with a law or constants of
        their own."""
        law = np.zeros(self.mesh.n_tets, dtype=np.int64)
        materials = [self.spec.material]
        for tets, region in self.spec.regions:
            law[tets] = len(materials)
            materials.append(region)
        return materials, law

    def _taylor_hood_elements(self) -> np.ndarray:
        """The elements whose law takes the continuous pressure (:mod:`casadi_ws.fem.terms.pressure`)."""
        materials, law = self._materials()
        th = [k for k, m in enumerate(materials) if m.kernel.endswith("_iso")]
        if th and self.element.name != "tet10":
            raise ModelError("formulation taylor_hood needs 10-node tetrahedra (order: 2): a linear pressure on "
                             "4-node ones locks")
        return np.flatnonzero(np.isin(law, th))

    def _build_elements(self, backend: str):
        """The element groups: the elements of each kernel (a region may have a law of its own), their rest
        inputs and compiled kernels. Returns the elements' rest nodes, quadrature weights and densities."""
        problem, mesh, element = self.spec, self.mesh, self.element
        Xe = mesh.nodes[mesh.tets]
        w, G = element.rest_geometry(Xe)
        materials, law = self._materials()
        rho = np.array([m.density for m in materials])[law]
        nd = element.n_dof
        self._edofs = (3 * mesh.tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, nd)
        Xl = (Xe - Xe[:, :1]).reshape(-1, nd)  # element-local: see materials' note on round-off
        Gl = G.reshape(G.shape[0], -1)
        self._G_qp = G  # (m, n_qp, n_nodes, 3): deformation gradients for the admissibility checks
        models = list(dict.fromkeys(m.kernel for m in materials))
        self.element_groups: list[_ElementGroup] = []
        """The elements of each law, with their inputs and compiled kernels (one group if the body has one
        law, as usual)."""
        for model in models:
            ks = [k for k, m in enumerate(materials) if m.kernel == model]
            idx = np.flatnonzero(np.isin(law, ks))
            params = np.array([materials[k].parameters for k in ks])[np.searchsorted(ks, law[idx])]
            funs = element_functions(model, element, hessian=False)
            self.element_groups.append(_ElementGroup(
                model, None if len(models) == 1 else idx, self._edofs[idx], Xl[idx], Gl[idx],
                np.column_stack([w[idx], params]), funs, ElementBatch(funs["force"], backend),
                ElementBatch(funs["stiffness"], backend)))
        self.element_functions = self.element_groups[0].functions
        self.backend = self.element_groups[0].force.backend
        return Xe, w, rho

    def _force_scale(self, w):
        """The force scale under which a residual counts as zero. Loads of exactly 0 give q = 0, but the
        internal forces there are round-off, ~eps of the force each element exerts at unit strain
        (E V_e^(2/3), the polar decomposition's included); that round-off must pass the tolerance whatever
        the law. Nearly incompressible, the volumetric stress K (J - 1) carries K eps of round-off (J - 1 is
        computed from det F ~ 1): the modulus is then 0.3 K, which equals E at nu = 0.45, so up to there the
        scale is E as it always was (at nu = 0.499 Newton stalled at 10x the old floor)."""
        problem, mesh, mat = self.spec, self.mesh, self.spec.material

        def modulus(m):
            E, nu = m.young_modulus, m.poisson_ratio
            return E if nu <= 0.45 else max(E, 0.1 * E / (1 - 2 * nu))  # 0.3 K = 0.1 E / (1 - 2 nu)

        E_e = np.full(mesh.n_tets, modulus(mat))
        for tets, region in problem.regions:
            E_e[tets] = modulus(region)
        self.element_force_scale = float(np.linalg.norm(E_e * np.abs(w.sum(axis=1)) ** (2.0 / 3.0)))
        """The norm over elements of the force each exerts at unit strain, E_e V_e^(2/3) (N)."""
        self.force_floor = max(1e-12 * modulus(mat) * mesh.characteristic_length() ** 2,
                               ROUNDOFF * self.element_force_scale / problem.solver.tolerance)

    # ------------------------------------------------------------------ assembly
    def embedding(self, points: np.ndarray) -> sp.csr_matrix:
        """W (3k x n_dof): positions of embedded points = W @ (X + q) (zero columns for intensities)."""
        return self._pad(embed(self.mesh, np.atleast_2d(points)).matrix(self.mesh))

    def _pad(self, W) -> sp.csr_matrix:
        W = sp.csr_matrix(W)
        if self.n_extra:
            W = sp.hstack([W, sp.csr_matrix((W.shape[0], self.n_extra))]).tocsr()
        return W

    def _build_actuators(self):
        """All actuators in one CasADi call (a call costs ~0.1 ms of overhead, a residual ~1 ms in all)."""
        self._act: list[_ActuatorData] = []
        Ps, Qs, gs, hs = [], [], [], []
        for a in self.actuators:
            pieces = quantity_functions(a)
            W = self._points_matrix(a)
            self._act.append(_ActuatorData(a, W, pieces["hessian_sparsity"]))
            Ps.append(pieces["P"])
            Qs.append(pieces["Q"])
            gs.append(pieces["dQ"])
            hs.append(pieces["d2Q"])
        sizes = [d.W.shape[0] for d in self._act]
        self._W_all = sp.vstack([d.W for d in self._act]).tocsr() if self._act else None
        self._W_all_T = self._W_all.T.tocsr() if self._act else None
        self._g_rows = np.arange(sum(sizes))
        self._g_cols = np.repeat(np.arange(self.n_u), sizes)
        self._h_offsets = np.cumsum([0] + [d.hessian_sparsity.nnz() for d in self._act])[:-1]
        P = ca.vertcat(*Ps) if Ps else ca.SX(0, 1)
        Q, g = ca.vertcat(*Qs), ca.vertcat(*gs)
        h = ca.vertcat(*hs)
        self._actuators_qg = ca.Function("actuators", [P], [Q, g])
        self._actuators_qgh = ca.Function("actuators_h", [P], [Q, g, h])
        # compiled like the element kernels: a CasADi call and its DM conversions cost ~50-90 us, 5-9 % of a
        # forward or forward-backward run on the linear trunk, whose element forces take ~130 us. Not a
        # cavity's: its volume's Hessian over the whole wall is megabytes of C, minutes of compiling
        small = max(self._actuators_qg.n_instructions(), self._actuators_qgh.n_instructions()) < 50_000
        self._actuator_kernels = (ElementBatch(self._actuators_qg, "c"), ElementBatch(self._actuators_qgh, "c")) \
            if self._act and self.backend == "c" and small else None

    def _points_matrix(self, actuator) -> sp.csr_matrix:
        """W (3k x 3n): the actuator's points from the nodal positions; points that are mesh nodes
        (``actuator.nodes``) follow them exactly, others are embedded in their host elements."""
        nodes = getattr(actuator, "nodes", None)
        if nodes is None:
            return self.embedding(np.asarray(actuator.rest_points(), dtype=float))
        cols = (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()
        return sp.csr_matrix((np.ones(cols.size), (np.arange(cols.size), cols)), shape=(cols.size, self.n_dof))

    def actuator_terms(self, q: np.ndarray, hessians: bool = False):
        """Q (n_u,), dQ/dq (n_u, 3n) and, if asked, the nonzeros of every d2Q/dP2, stacked."""
        if not self._act:
            return np.zeros(0), np.zeros((0, self.n_dof)), np.zeros(0)
        # a verified point asks for them two or three times at the same q (its residual, its state limits, its
        # maps): ~0.1 ms each, 5-7 % of an interpolated point of the forward sweep. The last answer is kept,
        # read-only, and returned while q is the same
        memo = self.__dict__.get("_actuator_memo")
        if not hessians and memo is not None and memo[0].shape == np.shape(q) and np.array_equal(memo[0], q):
            return memo[1]
        P = self._W_all @ (self.X + q)
        if self._actuator_kernels is not None:
            out = [v[0] for v in self._actuator_kernels[hessians](P[None])]
        else:
            out = [np.asarray(v).ravel() for v in (self._actuators_qgh if hessians else self._actuators_qg)(P)]
        G = np.zeros((self._g_rows.size, self.n_u))
        G[self._g_rows, self._g_cols] = out[1]
        dQ = (self._W_all_T @ G).T
        values = out[0]
        if hessians:
            return values, dQ, out[2]
        values.flags.writeable = dQ.flags.writeable = False
        self._actuator_memo = (np.array(q, dtype=float, copy=True), (values, dQ, None))
        return values, dQ, None

    def _build_pattern(self):
        """Index maps from element stiffness entries and actuator Hessian entries to the CSC data of K on
        the free dofs (one pattern for both, so assembling K is a single bincount)."""
        pos = -np.ones(self.n_dof, dtype=np.int64)
        pos[self.free] = np.arange(self.n_free)
        ed = pos[self._edofs]  # (m, n_dof_e), -1 for fixed
        nd = self.element.n_dof
        # element matrix is vec'ed column-major: entry (a, b) at index b * nd + a
        j = np.arange(nd * nd)
        rows, cols = ed[:, j % nd].ravel(), ed[:, j // nd].ravel()
        keep = (rows >= 0) & (cols >= 0)
        keys = [cols[keep] * self.n_free + rows[keep]]
        # actuator i adds -sign_i u_i W^T h_i W (h_i: Hessian of its quantity in its points, 3k x 3k, whose
        # nonzeros are stored after the previous actuators' in the stacked vector of actuator_terms): every
        # pair of nonzeros of W whose rows meet in h_i's pattern adds h_i[r1, r2] w1 w2 to K[i1, i2]
        h_index, h_weight, h_act = [], [], []
        for i, d in enumerate(self._act):
            Wc = d.W[:, self.free].tocsr()
            Wc.sort_indices()
            hr, hc = (np.asarray(x, dtype=np.int64) for x in d.hessian_sparsity.get_triplet())
            # nonzero s = (r1, r2) of h_i pairs every entry of W's row r1 with every entry of its row r2
            count = np.diff(Wc.indptr)
            n1, n2 = count[hr], count[hc]
            tot = n1 * n2
            slot = np.repeat(np.arange(hr.size), tot)
            k = np.arange(tot.sum()) - np.repeat(np.cumsum(tot) - tot, tot)
            e1 = np.repeat(Wc.indptr[hr], tot) + k // np.repeat(n2, tot)
            e2 = np.repeat(Wc.indptr[hc], tot) + k % np.repeat(n2, tot)
            h_index.append(self._h_offsets[i] + slot)
            h_weight.append(Wc.data[e1] * Wc.data[e2])
            h_act.append(np.full(e1.size, i))
            keys.append(Wc.indices[e2].astype(np.int64) * self.n_free + Wc.indices[e1])
        n_act_keys = sum(k.size for k in keys[1:])
        # prescribed actuator k borders K: column and row n_free_mech + k over the dofs its points move, and
        # the diagonal (the Fischer-Burmeister row's dependence on the intensity)
        self._border_dofs = []
        for k, a in enumerate(self.prescribed):
            r = np.unique(self._act[a].W[:, self.free].tocoo().col).astype(np.int64)
            self._border_dofs.append(r)
            j = self.n_free_mech + k
            keys += [np.full(r.size, j) * self.n_free + r, r * self.n_free + j, np.array([j * self.n_free + j])]
        n_border_keys = sum(k.size for k in keys[1 + len(self._act):])
        keys += [t.pattern(self, pos) for t in self.terms]
        ukey, slot = np.unique(np.concatenate(keys), return_inverse=True)
        # every element entry has a slot; those of fixed dofs go to one past the end, cut off after the
        # bincount (cheaper than gathering the kept ones on every assembly)
        n_el = keys[0].size
        self._k_slot = np.full(keep.size, ukey.size, dtype=np.int64)
        self._k_slot[keep] = slot[:n_el]
        self.__dict__.pop("_k_slot32", None)  # the kernels' int32 copies (:meth:`_stiffness_data`), rebuilt on use
        self._act_slots = slot[n_el:n_el + n_act_keys]
        border = slot[n_el + n_act_keys:n_el + n_act_keys + n_border_keys]
        self._ukey = ukey
        self._border_slots = []  # per prescribed actuator: (column slots, row slots, diagonal slot)
        for r in self._border_dofs:
            self._border_slots.append((border[: r.size], border[r.size: 2 * r.size], border[2 * r.size]))
            border = border[2 * r.size + 1:]
        self._act_h_index = np.concatenate(h_index + [np.zeros(0, dtype=np.int64)])
        self._act_h_weight = np.concatenate(h_weight + [np.zeros(0)])
        self._act_of_entry = np.concatenate(h_act + [np.zeros(0, dtype=np.int64)])
        self._k_rows = (ukey % self.n_free).astype(np.int32)
        ccount = np.bincount(ukey // self.n_free, minlength=self.n_free)
        self._k_indptr = np.concatenate([[0], np.cumsum(ccount)]).astype(np.int32)
        self._k_nnz = ukey.size
        self._term_slots = {}

    def hessian_vector_function(self, group: int = 0):
        """The element function of d(K_e^T lam_e)/du_e (for the NLPs' Hessians) of the elements of a law,
        built on first use."""
        g = self.element_groups[group]
        if "hessian_vector" not in g.functions:
            g.functions.update(element_functions(g.model, self.element))
        return g.functions["hessian_vector"]

    def _element_values(self, q: np.ndarray, kernels: str, *extra) -> list[np.ndarray]:
        """The outputs of the element kernels ``kernels`` (``force``, ``stiff``, ``hv``) of every law, in
        the mesh's element order."""
        groups = self.element_groups
        if len(groups) == 1:
            g = groups[0]
            return [getattr(g, k)(q[g.edofs], g.Xe, g.Ge, g.Pe, *(e[g.edofs] for e in extra))[0]
                    for k in kernels.split()]
        outs = []
        for k in kernels.split():
            out = None
            for g in groups:
                v, = getattr(g, k)(q[g.edofs], g.Xe, g.Ge, g.Pe, *(e[g.edofs] for e in extra))
                if out is None:
                    out = np.empty((self.mesh.n_tets, v.shape[1]))
                out[g.index] = v
            outs.append(out)
        return outs

    def positions(self, q: np.ndarray) -> np.ndarray:
        """Current node positions (n, 3)."""
        return (self.X + q)[: self.n_mech].reshape(-1, 3)

    @property
    def quadrature_points(self) -> int:
        """Quadrature points per element (the rows of :meth:`deformation_gradients` per element)."""
        return self._G_qp.shape[1]

    def deformation_operator(self) -> sp.csr_matrix:
        """The sparse map of q to the entries of F - I at every quadrature point ((element, point, i, j) rows,
        row-major), built once."""
        if "_F_op" not in self.__dict__:
            # F_ij at (element e, point k) = delta_ij + sum_a q[3 node_a + i] G[e, k, a, j]: a sparse map of q
            m, nq, nn, _ = self._G_qp.shape
            e, k, a, i, j = np.meshgrid(np.arange(m), np.arange(nq), np.arange(nn), np.arange(3), np.arange(3),
                                        indexing="ij")
            rows = (((e * nq + k) * 3 + i) * 3 + j).ravel()
            cols = (3 * self.mesh.tets[e, a] + i).ravel()
            self._F_op = sp.csr_matrix((self._G_qp[e, k, a, j].ravel(), (rows, cols)), shape=(m * nq * 9, self.n_dof))
        return self._F_op

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """F = I + du/dX at every quadrature point, (m, n_qp, 3, 3)."""
        m, nq = self._G_qp.shape[:2]
        return np.eye(3) + (self.deformation_operator() @ q).reshape(m, nq, 3, 3)

    def node_sizes(self) -> np.ndarray:
        """Per node, the mean edge of the smallest element it belongs to (m): the scale of a safe nodal move
        (Newton's trust region, :data:`casadi_ws.solvers.equilibrium.TRUST_REGION`)."""
        if "_node_sizes" not in self.__dict__:
            corners = self.mesh.nodes[self.mesh.tets[:, :4]]
            pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
            h = np.mean([np.linalg.norm(corners[:, a] - corners[:, b], axis=1) for a, b in pairs], axis=0)
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
        if "_det_kernel" not in self.__dict__:
            _, nq, nn, _ = self._G_qp.shape
            self._det_kernel = ElementBatch(_det_f_function(nq, nn), "c" if self.backend == "c" else "casadi")
        m = self._G_qp.shape[0]
        return self._det_kernel(q[self._edofs], self._G_qp.reshape(m, -1))[0]

    def internal_force(self, q: np.ndarray, norm: bool = False):
        """f_int(q) on all dofs (3n,); with ``norm``, also the norm of the unassembled element forces.

        One law: summed by the kernel as it computes them (:meth:`ElementBatch.scatter`), in the order a
        bincount of the batch sums them, without writing the batch (~60 us of a ~300 us residual on the
        linear trunk); several: the batch in the mesh's order, then a bincount."""
        if len(self.element_groups) == 1:
            g = self.element_groups[0]
            if "_f_slot32" not in self.__dict__:
                self._f_slot32 = np.ascontiguousarray(self._edofs.ravel(), dtype=np.int32)
            # (the slots of the element forces are their dofs: the same array says where to read q)
            out = g.force.scatter(self._f_slot32, self.n_dof, q, g.Xe, g.Ge, g.Pe, sumsq=norm,
                                  gather=self._f_slot32.reshape(g.edofs.shape))
            return (out[0], float(np.sqrt(out[1]))) if norm else out
        fe, = self._element_values(q, "force")
        f = np.bincount(self._edofs.ravel(), weights=fe.ravel(), minlength=self.n_dof)
        return (f, float(np.linalg.norm(fe))) if norm else f

    def element_stiffness(self, q: np.ndarray) -> sp.csc_matrix:
        """df_int/dq on the free dofs."""
        return self.assemble(data=self._stiffness_data(q))

    def _stiffness_data(self, q: np.ndarray) -> np.ndarray:
        """The element stiffnesses at q summed into the pattern's slots (k_nnz + 1: the fixed dofs' entries
        last), by each group's kernel as it computes them (:meth:`ElementBatch.scatter`); group by group, so
        the sums do not depend on how a kernel runs."""
        if "_k_slot32" not in self.__dict__:
            m = self.mesh.n_tets
            self._k_slot32 = [np.ascontiguousarray(
                (self._k_slot.reshape(m, -1) if g.index is None else self._k_slot.reshape(m, -1)[g.index]).ravel(),
                dtype=np.int32) for g in self.element_groups]
            self._edofs32 = [np.ascontiguousarray(g.edofs, dtype=np.int32) for g in self.element_groups]
        data = None
        for g, slot, edofs in zip(self.element_groups, self._k_slot32, self._edofs32):
            part = g.stiff.scatter(slot, self._k_nnz + 1, q, g.Xe, g.Ge, g.Pe, gather=edofs)
            data = part if data is None else data + part
        return data

    def assemble(self, ke: np.ndarray | None = None, actuator_weights: np.ndarray | None = None, border=None,
                 terms=(), data: np.ndarray | None = None) -> sp.csc_matrix:
        """The free-dof matrix from element matrices ke (m, n_dof_e^2), or their sums ``data`` already taken
        into the pattern's slots (:meth:`_stiffness_data`), plus actuator Hessian entries and
        the prescribed actuators' border values ((column, row, diagonal) per actuator) and the terms'
        (keys, values) (:meth:`casadi_ws.fem.terms.Term.tangent`) if given. The pattern is fixed (explicit
        zeros kept): factorisations reuse one ordering, and the CasADi Functions rely on it."""
        if data is None:
            data = np.bincount(self._k_slot, weights=ke.ravel(), minlength=self._k_nnz + 1)
        data = data[: self._k_nnz]
        if actuator_weights is not None and actuator_weights.size:
            data += np.bincount(self._act_slots, weights=actuator_weights, minlength=self._k_nnz)
        for (cs, rs, ds), values in zip(self._border_slots, border or ()):
            data[cs], data[rs], data[ds] = values
        for keys, values in terms:
            cached = self._term_slots.get(id(keys))
            if cached is None or cached[0] is not keys:  # a term that keeps its keys is looked up once
                if len(self._term_slots) > 4 * len(self.terms):  # contact terms build new keys every time
                    self._term_slots.clear()
                cached = self._term_slots[id(keys)] = (keys, self.slots(keys))
            data += np.bincount(cached[1], weights=values, minlength=self._k_nnz)
        return sp.csc_matrix((data, self._k_rows, self._k_indptr), shape=(self.n_free, self.n_free))

    def slots(self, keys: np.ndarray) -> np.ndarray:
        """The positions in the pattern's data of entries given by keys (column * n_free + row)."""
        s = np.searchsorted(self._ukey, keys)
        if s.size and (s.max() >= self._ukey.size or np.any(self._ukey[s] != keys)):
            raise AssertionError("a term's tangent entry is outside the pattern it declared")
        return s

    # ------------------------------------------------------------------ prescribed quantities
    def _build_prescribed(self):
        """kappa (the actuator's own stiffness at rest, 1 / H K0^-1 H^T) and eps of each prescribed actuator
        (see the module's docstring)."""
        self.kappa = np.zeros(self.n_lam)
        self.eps = np.zeros(self.n_lam)
        if not self.n_lam:
            return
        from scipy.sparse.linalg import splu

        q0 = np.zeros(self.n_dof)
        ke, = self._element_values(q0, "stiff")
        n = self.n_free_mech
        K0 = self.assemble(ke)[:n, :n].tocsc()
        H = self.actuation_rows(q0)[:, :n]
        lu = splu(K0)
        for k, a in enumerate(self.prescribed):
            c = float(H[a] @ lu.solve(H[a]))
            if not c > 0:
                act = self.actuators[a]
                j = [x for x in self.actuators if x.kind == act.kind].index(act)
                raise ModelError(f"{self.spec.source}: {act.kind}s[{j}].control: {act.name!r} does not move the "
                                 f"body at rest (its points are held: compliance {c:g}), so its {act.quantity_name} "
                                 f"cannot be prescribed")
            self.kappa[k] = 1.0 / c
            self.eps[k] = 1e-8 * self.kappa[k] * abs(self.rest_quantities[a])

    def intensities(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Each actuator's intensity (tension N, pressure Pa): u, or the state's unknown where the input is
        the quantity."""
        t = np.array(u, dtype=float, copy=True).reshape(-1)
        t[self.prescribed] = self.kappa * q[self.n_mech:self.n_mech + self.n_lam]
        return t

    def _prescribed_rows(self, q, u, Q):
        """(phi, dphi/da, dphi/db, d2phi/da2, d2phi/dadb, d2phi/db2) of each prescribed actuator's equation,
        a = its intensity, b = kappa (g(q) - u); with u None, b from the equilibrium's a b = eps^2/2. (The
        state holds a / kappa: its derivatives carry a factor kappa per a.)"""
        a = self.kappa * q[self.n_mech:self.n_mech + self.n_lam]
        pre = self.prescribed
        if u is None:
            b = self.eps**2 / (2 * np.maximum(a, self.eps))
        else:
            g = self.sign[pre] * (Q[pre] - self.rest_quantities[pre])
            b = self.kappa * (g - np.asarray(u, dtype=float)[pre])
        uni = np.array([self.actuators[i].unilateral for i in pre], dtype=bool)
        one, zero = np.ones_like(a), np.zeros_like(a)
        fb = fischer_burmeister(a, b, self.eps)
        return tuple(np.where(uni, f, bil) for f, bil in zip(fb, (b, zero, one, zero, zero, zero)))

    # ------------------------------------------------------------------ contact
    def _contact_terms(self):
        return [t for t in self.terms if hasattr(t, "geometry")]

    def contact_forces(self, q: np.ndarray) -> np.ndarray:
        """The forces (n_dof,) the obstacles (and the body on itself) exert on the nodes at q."""
        out = np.zeros(self.n_dof)
        for t in self._contact_terms():
            out[self.free] += t.contact_forces(self, q)
        return out

    def in_contact(self, q: np.ndarray) -> np.ndarray:
        """(n_con,) bool: the contact points that press at the equilibrium q (lambda > kappa g)."""
        return np.concatenate([t.in_contact(self, q) for t in self._contact_terms()] + [np.zeros(0, dtype=bool)])

    def contacts(self, q: np.ndarray) -> list[dict]:
        """Per obstacle (and per self-contact pair): its name, the total force [fx, fy, fz] (N) it exerts on
        the body (on the pair's points), the number of contact points pressing, and the largest penetration
        (m, 0 if none)."""
        return [c for t in self._contact_terms() for c in t.report(self, q)]

    def min_gap(self, q: np.ndarray) -> float:
        """The smallest gap of any contact point at q (m; inf without contact)."""
        return min([float(t.geometry(self, q).g.min()) for t in self._contact_terms() if t.n_rows] + [np.inf])

    def contact_step_limit(self, q: np.ndarray, dq: np.ndarray) -> float:
        """The share of the Newton step dq (free dofs) the terms allow (:meth:`ContactTerm.step_limit`)."""
        return min([t.step_limit(self, q, dq) for t in self.terms] + [1.0])

    def actuator_states(self, q: np.ndarray) -> np.ndarray:
        """Each actuator's quantity at q (a cable's length in m), (n_u,)."""
        return self.actuator_terms(q)[0]

    def _point_hessian(self, i: int, h: np.ndarray) -> sp.csr_matrix:
        """d2Q_i/dP2 (3k x 3k) of actuator i from the stacked nonzeros ``h`` of actuator_terms."""
        sp_h = self._act[i].hessian_sparsity
        r, c = sp_h.get_triplet()
        return sp.csr_matrix((h[self._h_offsets[i]: self._h_offsets[i] + sp_h.nnz()], (r, c)),
                             shape=(sp_h.size1(), sp_h.size2()))

    def actuator_hessians(self, q: np.ndarray) -> list[sp.csc_matrix]:
        """d2Q_a/dq2 on the free dofs, one sparse matrix per actuator."""
        _, _, h = self.actuator_terms(q, hessians=True)
        return [(d.W[:, self.free].T @ self._point_hessian(i, h) @ d.W[:, self.free]).tocsc()
                for i, d in enumerate(self._act)]

    def actuator_third(self, q: np.ndarray, lam_full: np.ndarray, u: np.ndarray):
        """The actuators' share of the Hessian of lam . R over (q, u) on the free dofs: the (q, q) block
        -sum_a sign_a u_a d2(lam . dQ_a/dq)/dq2 and the (q, u) columns -sign_a d2Q_a/dq2 lam."""
        x = self.X + q
        Hqq = sp.csc_matrix((self.n_free, self.n_free))
        cols = []
        _, _, h = self.actuator_terms(q, hessians=True)
        for i, (d, ua, sa) in enumerate(zip(self._act, u, self.sign)):
            P = d.W @ x
            mu = d.W @ lam_full
            Wf = d.W[:, self.free]
            T = d.third(P, mu).sparse()
            Hqq = Hqq + (-sa * ua) * (Wf.T @ T @ Wf)
            cols.append(-sa * (Wf.T @ (self._point_hessian(i, h) @ mu)))
        return Hqq, cols

    # ------------------------------------------------------------------ the static model
    def residual(self, q: np.ndarray, u: np.ndarray, load: float = 1.0, with_scale: bool = False):
        """R(q, u) = f_int - sum_a t_a sign_a dQ_a/dq - load * F on the free dofs (t the intensities: u, or
        the state's where the quantity is prescribed), then one equation per prescribed actuator.

        With ``with_scale`` also returns ||H^T t + load F|| (free dofs), the reference of the relative
        residual (plus a round-off allowance, see below), floored so that a zero load is judged absolutely.
        """
        Q, dQ, _ = self.actuator_terms(q)
        ext = (dQ.T @ (-self.sign * self.intensities(q, u)) - load * self.F)[self.free]
        out = self.internal_force(q, norm=with_scale)
        f_int, fe_norm = out if with_scale else (out, None)
        R = f_int[self.free] + ext
        if self.n_lam:
            R[self.n_free_mech:self.n_free_mech + self.n_lam] = self._prescribed_rows(q, u, Q)[0]
        if self.terms:
            for t in self.terms:
                R0 = R.copy() if t.applied else None
                t.residual(self, q, u, R)
                if t.applied:
                    ext = ext + (R0 - R)  # the contact forces join the applied ones in the scale
            ext[self.con_rows] = 0.0
        if with_scale:
            # 1e-6 of the unassembled element forces: the assembly's round-off (~1e-16 of them) then stays
            # far below any tolerance, even when the applied load is tiny
            return R, max(float(np.linalg.norm(ext)) + 1e-6 * fe_norm, self.force_floor)
        return R

    def residual_and_tangent(self, q: np.ndarray, u: np.ndarray, load: float = 1.0):
        """(R, K, dR/du) on the free dofs; K = dR/dq includes the actuators' geometric stiffness (and the
        prescribed actuators' border rows and columns)."""
        u = np.asarray(u, dtype=float)
        Q, dQ, h = self.actuator_terms(q, hessians=True)
        coef, weights = self._actuator_weights(q, u, h)
        R = (self.internal_force(q) + dQ.T @ coef - load * self.F)[self.free]
        dRdu = (dQ * -self.sign[:, None])[:, self.free].T
        border = None
        if self.n_lam:
            phi, pa, pb, *_ = self._prescribed_rows(q, u, Q)
            R[self.n_free_mech:self.n_free_mech + self.n_lam] = phi
            H = (dQ * self.sign[:, None])[:, self.free]
            border = []
            for k, (a, r) in enumerate(zip(self.prescribed, self._border_dofs)):
                kap = self.kappa[k]
                border.append((-kap * H[a, r], pb[k] * kap * H[a, r], kap * pa[k]))
                dRdu[:, a] = 0.0
                dRdu[self.n_free_mech + k, a] = -pb[k] * self.kappa[k]
        caches = [t.residual(self, q, u, R) for t in self.terms]
        terms = [t.tangent(self, c) for t, c in zip(self.terms, caches)]
        return R, self.assemble(actuator_weights=weights, border=border, terms=terms,
                                data=self._stiffness_data(q)), dRdu

    def tangent(self, q: np.ndarray, u: np.ndarray, load: float = 1.0) -> sp.csc_matrix:
        """K of :meth:`residual_and_tangent`, the same to the bit, for callers that have R or do not need it
        (Newton's fresh factorisation, the sensitivities' refinement, the stability test). Without terms or
        prescribed quantities, whose rows and tangents are built with R, the internal forces are not computed:
        a kernel pass of its own, 0.21 of the 1.73 ms of K and R together on the 4-cable trunk."""
        if self.n_lam or self.terms:
            return self.residual_and_tangent(q, u, load)[1]
        _, _, h = self.actuator_terms(q, hessians=True)
        _, weights = self._actuator_weights(q, np.asarray(u, dtype=float), h)
        return self.assemble(actuator_weights=weights, data=self._stiffness_data(q))

    def _actuator_weights(self, q, u, h) -> tuple:
        """(coef, weights): -sign_a t_a per actuator, the coefficient of dQ_a/dq in R, and the values of the
        actuators' Hessian entries in K, coef_a d2Q_a/dq2."""
        coef = -self.sign * self.intensities(q, u)  # R holds -sign_a t_a dQ_a/dq
        weights = (coef[self._act_of_entry] * self._act_h_weight * h[self._act_h_index]
                   if self._act else np.zeros(0))
        return coef, weights

    def actuation_rows(self, q: np.ndarray) -> np.ndarray:
        """H(q) = sign dQ/dq on the free dofs, (n_u, n_free) (a cable's row: -dL/dq): where each actuator's
        intensity pushes the body."""
        _, dQ, _ = self.actuator_terms(q)
        return (dQ * self.sign[:, None])[:, self.free]

    def actuation_matrix(self, q: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """-dR/du^T (n_u, n_free), so that dq/du = K^-1 H^T: H = sign dQ/dq for an actuator whose input is
        its intensity; for a prescribed quantity, kappa dphi/db in its own row (at an equilibrium without
        ``u``, from the row's a b = eps^2/2: ~kappa for a taut cable, ~0 for a slack one)."""
        H = self.actuation_rows(q)
        if self.n_lam:
            Q = self.actuator_states(q) if u is not None else None
            pb = self._prescribed_rows(q, u, Q)[2]
            H[self.prescribed] = 0.0
            H[self.prescribed, self.n_free_mech + np.arange(self.n_lam)] = pb * self.kappa
        return H

    def slack(self, q: np.ndarray) -> np.ndarray:
        """(n_u,) bool: the prescribed unilateral actuators that are slack at the equilibrium q (a cable with
        no tension, shortened more than its motor pulled: tension below eps / sqrt 2, where the Fischer-
        Burmeister row depends more on the tension than on the shortening)."""
        out = np.zeros(self.n_u, dtype=bool)
        if self.n_lam:
            uni = np.array([self.actuators[a].unilateral for a in self.prescribed], dtype=bool)
            out[self.prescribed] = uni & (self.kappa * q[self.n_mech:self.n_mech + self.n_lam] < self.eps / np.sqrt(2))
        return out

    def taut_rows(self, q: np.ndarray):
        """For each slack actuator a (:meth:`slack`): (a, its row j of the tangent, the change w of that row
        that makes the cable taut: (1 - phi_b) kappa H on its dofs and -phi_a at j). The sensitivities of a
        slack cable once taut follow from the tangent by a rank-one update."""
        out = []
        slack = self.slack(q)
        if not slack.any():
            return out
        _, pa, pb, *_ = self._prescribed_rows(q, None, None)
        H = self.actuation_rows(q)
        for k, a in enumerate(self.prescribed):
            if slack[a]:
                j = self.n_free_mech + k
                w = np.zeros(self.n_free)
                r = self._border_dofs[k]
                w[r] = (1 - pb[k]) * self.kappa[k] * H[a, r]
                w[j] = -self.kappa[k] * pa[k]
                out.append((a, j, w))
        return out

    def stability_matrix(self, q: np.ndarray, u: np.ndarray) -> sp.csc_matrix:
        """The stiffness on the nodal dofs with the prescribed quantities held: K + sum_k w_k rho_k H_k H_k^T,
        rho_k = 1e3 kappa_k (held 1000x stiffer than the body holds them at rest), w_k = dphi/db (1 for a
        taut cable or a chamber, 0 for a slack cable); so are the contact points that press (gap rows, w = 1
        in contact, 0 apart). Positive definite iff K is on the motions that keep the held quantities (the
        saddle-point K of Newton has negative pivots whatever the stability)."""
        K = self.tangent(q, u)
        n = self.n_free_mech
        K = K[:n, :n]
        for t in self.terms:
            held = t.held(self, q)
            if held is not None:
                K = K + held
        if not self.n_lam:
            return K.tocsc()
        Q = self.actuator_states(q)
        pb = self._prescribed_rows(q, u, Q)[2]
        H = self.actuation_rows(q)[:, :n]
        for k, a in enumerate(self.prescribed):
            r = self._border_dofs[k]
            rr, cc = np.meshgrid(r, r, indexing="ij")
            K = K + sp.csc_matrix(((1e3 * self.kappa[k] * pb[k] * np.outer(H[a, r], H[a, r])).ravel(),
                                   (rr.ravel(), cc.ravel())), shape=(n, n))
        return K.tocsc()

    def residual_hessian(self, q: np.ndarray, u: np.ndarray, lam: np.ndarray):
        """Second derivatives of lam . R (lam on the free dofs): (d(K^T lam)/dq on the free dofs, sparse;
        d(K^T lam)/du = d(dR/du^T lam)/dq, dense (n_free, n_u)). K^T lam, not K lam: the corotational
        tangent is not exactly symmetric, and this is what reverse-mode AD differentiates."""
        for k, g in enumerate(self.element_groups):
            if g.hv is None:
                # "auto", not "c": a kernel too large to compile (kernels.MAX_COMPILED_CODE) runs in CasADi's
                # VM even when the others are compiled
                g.hv = ElementBatch(self.hessian_vector_function(k), "casadi" if self.backend == "casadi" else "auto")
        u = np.asarray(u, dtype=float)
        lam_full = np.zeros(self.n_dof)
        lam_full[self.free] = lam
        he, = self._element_values(q, "hv", lam_full)
        Hact, cols = self.actuator_third(q, lam_full, self.intensities(q, u))
        Hqu = np.column_stack(cols) if cols else np.zeros((self.n_free, 0))
        Hqq = self.assemble(he) + Hact
        if self.n_lam:
            Hqq, Hqu = self._prescribed_hessian(q, u, lam, Hqq, Hqu)
        for t in self.terms:
            Hqq = (Hqq + t.hessian(self, q, u, lam)).tocsc()
        return Hqq, Hqu

    def _prescribed_hessian(self, q, u, lam, Hqq, Hqu):
        """The prescribed actuators' share of d(K^T lam)/d(q, u) (see the module's docstring): the
        intensity's column of the geometric stiffness, and the second derivatives of phi(a, b)."""
        Q, dQ, h = self.actuator_terms(q, hessians=True)
        _, pa, pb, paa, pab, pbb = self._prescribed_rows(q, u, Q)
        H = (dQ * self.sign[:, None])[:, self.free]
        n, nm = self.n_free, self.n_free_mech
        extra = sp.lil_matrix((n, n))
        for k, a in enumerate(self.prescribed):
            j, lk, kap = nm + k, lam[nm + k], self.kappa[k]
            d = self._act[a]
            Wf = d.W[:, self.free]
            d2Q = (Wf.T @ self._point_hessian(a, h) @ Wf).tocsr()
            # lam_k phi(a, b(q)): kappa (phi_b sign d2Q + phi_bb kappa H H^T) in (q, q)
            Hqq = Hqq + (lk * kap * pb[k] * self.sign[a]) * d2Q
            r = self._border_dofs[k]
            rr, cc = np.meshgrid(r, r, indexing="ij")
            Hqq = Hqq + sp.csr_matrix(((lk * pbb[k] * kap * kap * np.outer(H[a, r], H[a, r])).ravel(),
                                       (rr.ravel(), cc.ravel())), shape=(n, n))
            # (q, t_k) and (t_k, q): d(K^T lam)_q / dt_k = -sign d2Q lam_m (the column actuator_third gave
            # for u_a), plus lam_k kappa phi_ab H; times kappa, the state holding t_k / kappa
            c = kap * (Hqu[:, a] + lk * kap * pab[k] * H[a])
            c[nm:] = 0.0
            extra[:, j] = c[:, None]
            extra[j, :] = c[None, :]
            extra[j, j] = lk * paa[k] * kap * kap
            # d(dR/du_a^T lam)/dq = d(-kappa phi_b lam_k)/dq
            col = np.zeros(n)
            col[:] = -kap * lk * pbb[k] * kap * H[a]
            col[j] = -kap * lk * pab[k] * kap
            Hqu[:, a] = col
        return (Hqq + extra.tocsr()).tocsc(), Hqu

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
