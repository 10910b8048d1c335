"""The static model against finite differences, exact fields and invariances."""

import numpy as np
import pytest
import scipy.sparse.linalg as sla
from conftest import small_trunk

from casadi_ws import Material, Problem, StaticModel, box_mesh
from casadi_ws.fem.kernels import ElementBatch, have_compiler
from casadi_ws.fem.materials import MATERIAL_MODELS, element_functions, rest_geometry
from casadi_ws.fem.mesh import quadratic
from casadi_ws.io.problem import nodes_in_box

MODELS = list(MATERIAL_MODELS)


def _quadratic_trunk(model):
    """The coarse trunk with 10-node tetrahedra (resolution 0.25: 2 elements across)."""
    pb = small_trunk(model, resolution=0.25)
    pb.mesh = quadratic(pb.mesh)
    pb.fixed_nodes = nodes_in_box(pb.mesh, [-1, -1, -1], [1, 1, 0.02])
    return pb


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("model", MODELS)
def test_tangent_matches_central_differences(model, order, rng):
    m = StaticModel(small_trunk(model) if order == 1 else _quadratic_trunk(model))
    q = m.full(rng.normal(size=m.n_free) * 2e-4)
    u = np.array([30.0, 55.0])
    R, K, dRdu = m.residual_and_tangent(q, u)
    # K alone (without the internal forces' kernel pass) is the same matrix, to the bit
    K_alone = m.tangent(q, u)
    assert np.array_equal(K_alone.indptr, K.indptr) and np.array_equal(K_alone.indices, K.indices)
    assert np.array_equal(K_alone.data, K.data)
    for _ in range(2):
        v = rng.normal(size=m.n_free)
        h = 1e-7
        qp, qm = q.copy(), q.copy()
        qp[m.free] += h * v
        qm[m.free] -= h * v
        fd = (m.residual(qp, u) - m.residual(qm, u)) / (2 * h)
        assert np.linalg.norm(fd - K @ v) <= 1e-5 * np.linalg.norm(fd)
    # dR/du: R is affine in u
    du = np.array([1.0, -2.0])
    fd_u = m.residual(q, u + du) - m.residual(q, u)
    assert np.linalg.norm(fd_u - dRdu @ du) <= 1e-9 * np.linalg.norm(fd_u)
    # H = -dL/dq against differences of the cable lengths
    H = m.actuation_matrix(q)
    v = rng.normal(size=m.n_free)
    qp, qm = q.copy(), q.copy()
    qp[m.free] += 1e-7 * v
    qm[m.free] -= 1e-7 * v
    fdL = (m.actuator_states(qp) - m.actuator_states(qm)) / 2e-7
    np.testing.assert_allclose(-H @ v, fdL, rtol=1e-6)


@pytest.mark.skipif(not have_compiler(), reason="no C compiler")
@pytest.mark.parametrize("model", MODELS)
def test_compiled_and_interpreted_kernels_agree(model, rng):
    f = element_functions(model)["stiffness"]
    X = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 0.01)[None] \
        + rng.normal(size=(7, 4, 3)) * 1e-3
    V0, G = rest_geometry(X)  # (7, 1) volumes: one quadrature point
    X = (X - X[:, :1]).reshape(7, 12)
    params = Material(model, 5e5, 0.3).parameters  # the law's parameter vector, of its own length
    args = [rng.normal(size=X.shape) * 1e-4, X, G.reshape(7, 12), np.column_stack([V0, np.tile(params, (7, 1))])]
    a, = ElementBatch(f, "c")(*args)
    b, = ElementBatch(f, "casadi")(*args)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


@pytest.mark.skipif(not have_compiler(), reason="no C compiler")
@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("model", ["corotational", "neohookean", "ogden"])
def test_kernels_evaluated_lanes_at_a_time_give_the_scalar_numbers_to_the_bit(model, order, rng):
    """The compiled kernels evaluate several elements at once, one per lane of a vector; each lane does the
    scalar code's operations with its rounding, so forces, stiffnesses and the stiffness summed into the
    pattern are the one-element-at-a-time driver's to the bit, for an element count that is no multiple
    of the lanes and with an input shared by every element."""
    m = StaticModel(small_trunk(model) if order == 1 else _quadratic_trunk(model))
    q = m.full(rng.normal(size=m.n_free) * 2e-4)
    g = m.element_groups[0]
    n = 8 * 3 + 5
    args = (q[g.edofs][:n], g.Xe[:n], g.Ge[:n], g.Pe[0])
    for kernel in (g.force, g.stiff):
        assert kernel.lanes > 1, kernel.fun.name()
        scalar = ElementBatch(kernel.fun, "c", vector=False)
        assert scalar.lanes == 1
        for a, b in zip(kernel(*args), scalar(*args)):
            assert np.array_equal(a, b)
    slot = np.ascontiguousarray(m.elements.k_slot.reshape(m.mesh.n_tets, -1)[:n], dtype=np.int32)
    scalar = ElementBatch(g.stiff.fun, "c", vector=False)
    summed = g.stiff.scatter(slot, m.nnz + 1, *args)
    assert np.array_equal(summed, scalar.scatter(slot, m.nnz + 1, *args))
    # the nodal values read by the kernels where they are (``gather``), in both drivers: the same sums
    edofs = np.ascontiguousarray(g.edofs[:n], dtype=np.int32)
    for kernel in (g.stiff, scalar):
        assert np.array_equal(kernel.scatter(slot, m.nnz + 1, q, *args[1:], gather=edofs), summed)


@pytest.mark.parametrize("kernel, params", [
    ("corotational", [2e5, 1.8e6]), ("neohookean", [2e5, 1.8e6]), ("yeoh", [1e5, 2e4, -3e2, 2e6]),
    ("ogden2", [1.6e5, 3e3, 1.3, 5.0, 2e6]), ("yeoh_mixed", [1e5, 2e4, -3e2, 2e6]),
    ("mooney_rivlin_iso", [1.2e5, 3e4, 2e6])])
def test_the_stiffness_built_per_quadrature_point_is_the_jacobian_of_the_forces(kernel, params, rng):
    """The 10-node kernels assemble K_e from the stress's 9 x 9 tangent at each point: the same matrix as
    differentiating the element's forces whole, which is what they did before (2.6x the work), and
    symmetric (its upper triangle mirrored). The corotational tangent is the closed form of the converged
    polar decomposition, which five polar iterations reach for stretches within ~[0.5, 2]: it is compared
    at stretches 0.64-1.44 (displacements 4e-4); at 1e-3 this element has stretches down to 0.31, where
    the iteration and so the forces err by ~1e-8."""
    import casadi as ca

    from casadi_ws.fem.elements import TET10

    fs = element_functions(kernel, TET10, hessian=False)
    X = TET10.ref_nodes[None] * 0.01 + rng.normal(size=(3, 10, 3)) * 5e-4
    w, G = TET10.rest_geometry(X)
    size = 4e-4 if kernel == "corotational" else 1e-3
    args = [rng.normal(size=30) * size, (X[0] - X[0, 0]).reshape(-1), G[0].reshape(-1), np.concatenate([w[0], params])]
    sym = [ca.SX.sym(n, fs["force"].numel_in(i)) for i, n in enumerate("uXGp")]
    whole = ca.Function("whole", sym, [ca.jacobian(fs["force"](*sym), sym[0])])
    K_ref = np.asarray(whole(*args)).reshape(30, 30)
    K = np.asarray(fs["stiffness"](*args)).reshape(30, 30, order="F")
    assert np.abs(K - K_ref).max() < 1e-12 * np.abs(K_ref).max()
    assert np.array_equal(K, K.T)


@pytest.mark.parametrize("size", [1e-4, 3e-3])
def test_the_four_node_corotational_stiffness_in_closed_form_is_the_jacobian_of_the_forces(size, rng):
    """The 4-node corotational K_e is written out (the rotated Ke plus the frame's turn, which the first
    three nodes drive): the same matrix as differentiating the forces whole, which it replaced at half the
    work, at small strains and at ~30 % ones with large rotations; the NLPs' Hessian-vector kernel, built
    on it, against the second derivative of the forces taken whole."""
    import casadi as ca

    fs = element_functions("corotational", hessian=True)
    X = np.eye(4, 3, -1) * 0.01 + rng.normal(size=(4, 3)) * 5e-4
    V0, G = rest_geometry(X[None])
    args = [rng.normal(size=12) * size, (X - X[0]).reshape(-1), G.reshape(-1),
            np.concatenate([V0.ravel(), Material("corotational", 5e5, 0.3).parameters]), rng.normal(size=12)]
    sym = [ca.SX.sym(n, fs["hessian_vector"].numel_in(i)) for i, n in enumerate("uXGpl")]
    J = ca.jacobian(fs["force"](*sym[:4]), sym[0])
    whole = ca.Function("whole", sym, [J, ca.jacobian(ca.mtimes(J.T, sym[4]), sym[0])])
    K_ref, H_ref = (np.asarray(v) for v in whole(*args))
    K = np.asarray(fs["stiffness"](*args[:4])).reshape(12, 12, order="F")
    H = np.asarray(fs["hessian_vector"](*args)).reshape(12, 12, order="F")
    assert np.abs(K - K_ref).max() < 1e-13 * np.abs(K_ref).max()
    assert np.abs(H - H_ref).max() < 1e-12 * np.abs(H_ref).max()


@pytest.mark.skipif(not have_compiler(), reason="no C compiler")
@pytest.mark.parametrize("regions", [False, True])
def test_the_stiffness_and_forces_summed_as_computed_are_the_assembled_ones_to_the_bit(regions, rng):
    """The compiled stiffness kernels add each element's K_e into the pattern as they compute it; the sums
    are those of assembling the whole batch (a kernel on threads), bit for bit, with one law and with two
    (each law's elements summed apart); without a compiler, to round-off."""
    pb = small_trunk("corotational")
    if regions:
        lower = np.flatnonzero(pb.mesh.nodes[pb.mesh.tets].mean(axis=1)[:, 2] < 0.1)
        pb.regions = [(lower, Material("neohookean", 3e7, 0.45, 1100.0))]
    m = StaticModel(pb)
    assert len(m.element_groups) == (2 if regions else 1)
    q = np.zeros(m.n_dof)
    q[m.free] = rng.normal(size=m.n_free) * 1e-4
    whole = None
    for g in m.element_groups:
        ke, = g.stiff(q[g.edofs], g.Xe, g.Ge, g.Pe)
        slot = m.elements.k_slot.reshape(m.mesh.n_tets, -1)
        part = np.bincount((slot if g.index is None else slot[g.index]).ravel(), weights=ke.ravel(),
                           minlength=m.nnz + 1)
        whole = part if whole is None else whole + part
    assert np.array_equal(m.elements.stiffness_data(q, m.nnz), whole)
    K = m.element_stiffness(q)
    assert np.array_equal(K.data, whole[: m.nnz])
    # without a compiler the batch is computed whole by CasADi's virtual machine and summed by bincount
    K_vm = StaticModel(pb, backend="casadi").element_stiffness(q)
    assert np.abs(K_vm - K).max() < 1e-12 * np.abs(K.data).max()
    # the forces too (one law: summed as computed, with their norm; two: the batch, then a bincount)
    fe, = m.elements.values(q, "force")
    f, norm = m.internal_force(q, norm=True)
    assert np.array_equal(f, np.bincount(m.elements.edofs.ravel(), weights=fe.ravel(), minlength=m.n_dof))
    assert abs(norm - np.linalg.norm(fe)) < 1e-14 * norm


def _patch_problem(model, order=1):
    mesh = box_mesh((1.0, 1.0, 1.0), (3, 3, 3) if order == 1 else (2, 2, 2))
    if order == 2:
        mesh = quadratic(mesh)
    x = mesh.nodes
    boundary = np.flatnonzero(np.any((x < 1e-9) | (x > 1 - 1e-9), axis=1))
    return Problem(mesh, Material(model, 1e3, 0.3), boundary, [], np.array([0.5, 0.5, 0.5]))


@pytest.mark.parametrize("order", [1, 2])
@pytest.mark.parametrize("model,size", [("linear", 1e-3), ("corotational", 1e-3), ("neohookean", 0.15)])
def test_patch_homogeneous_deformation_is_exact(model, size, order, rng):
    """Boundary nodes moved by x -> F X + c; Newton on the interior must give the same affine field."""
    m = StaticModel(_patch_problem(model, order))
    F = np.eye(3) + size * rng.normal(size=(3, 3))
    X = m.mesh.nodes
    q_exact = (X @ F.T + np.array([0.01, -0.02, 0.03]) - X).ravel()
    q = np.zeros_like(q_exact)
    fixed = np.setdiff1d(np.arange(q.size), m.free)
    for s in (0.25, 0.5, 0.75, 1.0):  # move the boundary in steps, Newton on the interior each time
        q[fixed] = s * q_exact[fixed]
        for _ in range(20):
            R = m.internal_force(q)[m.free]
            if np.linalg.norm(R) < 1e-10 * m.problem.material.young_modulus:
                break
            q[m.free] -= sla.spsolve(m.element_stiffness(q).tocsc(), R)
    # every law and order reproduces a uniform F to round-off (10-node corotational elements take the polar
    # rotation of F at each quadrature point, so neighbours agree exactly; measured 3e-14)
    np.testing.assert_allclose(q[m.free], q_exact[m.free], atol=1e-12)


@pytest.mark.parametrize("model", ["corotational", "neohookean"])
def test_rigid_rotation_gives_no_internal_force(model, rng):
    m = StaticModel(small_trunk(model))
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    ang = np.deg2rad(70)
    Kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    Rot = np.eye(3) + np.sin(ang) * Kx + (1 - np.cos(ang)) * Kx @ Kx
    X = m.mesh.nodes
    q = (X @ Rot.T + np.array([0.1, -0.2, 0.05]) - X).ravel()
    f = m.internal_force(q)
    # force scale of a 1 % strain, for reference
    q_strain = (0.01 * X * np.array([1.0, 0, 0])).ravel()
    ref = np.linalg.norm(m.internal_force(q_strain))
    assert np.linalg.norm(f) < 1e-9 * ref
    if model == "corotational":  # the same motion is far from force-free for the small-strain law
        lin = StaticModel(small_trunk("linear"))
        assert np.linalg.norm(lin.internal_force(q)) > 10 * ref


def test_a_model_and_what_other_layers_built_for_it_go_when_it_is_dropped():
    """One cache per model (issue: one assembler): the CasADi Functions, the rootfinder, the IPOPT solver of the
    backward step, the admissibility samples and the maps' operator are the model's, not module globals keyed
    by id(model) that kept every model of a long study alive."""
    import gc
    import weakref

    from casadi_ws import FBSettings, forward_backward
    from casadi_ws.fem.functions import residual_function
    from casadi_ws.solvers.admissible import admissibility
    from casadi_ws.solvers.rootfinder import rootfinder_newton
    from casadi_ws.workspace.backward import BackwardSettings, backward_ipopt
    from conftest import small_trunk

    pb = small_trunk("corotational", n_cables=2)
    model = StaticModel(pb)
    residual_function(model)
    q, rel, _ = rootfinder_newton(model, np.array([5.0, 5.0]), np.zeros(model.n_dof), 1.0, 1e-8, 30)
    assert rel < 1e-8
    backward_ipopt(model, model.p0 + np.array([0.002, 0.0, 0.0]), q, np.array([5.0, 5.0]), BackwardSettings())
    admissibility(model, q, np.array([5.0, 5.0]))
    fb = forward_backward(pb, FBSettings(step=0.02, progress=False), model=model)  # maps: the tip's axis
    assert fb.n_points > 0 and len(model.cache._items) >= 4
    ref = weakref.ref(model)
    del model, fb
    gc.collect()
    assert ref() is None


def test_a_cable_segment_whose_ends_meet_keeps_a_continuous_length_and_force():
    """Two passage points on facing walls of a groove (the SOFA Trunk's disks) meet as it closes: the
    segment's length is blended below 1 % of its rest length (casadi_ws.actuation.cable.SHORT), so the length
    and its gradient stay continuous where the straight distance's gradient would flip; beyond the blend the
    length is the distance itself."""
    import casadi as ca

    from casadi_ws import Cable
    from casadi_ws.actuation.cable import SHORT

    c = Cable(points=np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.006]]))
    P = ca.SX.sym("P", 6)
    L = ca.Function("L", [P], [c.quantity(P), ca.gradient(c.quantity(P), P)])
    delta = SHORT * 0.006
    for z in (0.006, 0.003, 1.5 * delta):  # straight: the distance and the unit vector
        v, g = (np.asarray(a).ravel() for a in L([0, 0, 0, 0, 0, z]))
        assert v == pytest.approx(z, rel=1e-15) and g[5] == pytest.approx(1.0, rel=1e-15)
    z = np.linspace(-2 * delta, 2 * delta, 81)  # the second point passes through the first
    vals = np.array([float(L([0, 0, 0, 0, 0, zz])[0]) for zz in z])
    grads = np.array([float(L([0, 0, 0, 0, 0, zz])[1][5]) for zz in z])
    assert np.all(np.abs(np.diff(vals)) <= 1.01 * (z[1] - z[0]))  # continuous, at most unit slope
    assert np.all(np.abs(np.diff(grads)) <= 2 * (z[1] - z[0]) / delta)  # the gradient: no jump
    assert vals.min() == pytest.approx(delta / 2)
