"""The workspace's boundary surface and volume (issue: the workspace's true size), the point maps, the
result files read back by meshio, and the interactive report rendered by a real browser."""

import csv
import itertools
from types import SimpleNamespace

import meshio
import numpy as np
import pytest

from casadi_ws.fem.model import StaticModel
from casadi_ws.solvers.equilibrium import solve_equilibrium, tangent_factorization
from casadi_ws.solvers.sensitivity import curvature, sensitivity
from casadi_ws.workspace.boundary import BoundarySettings, Seeds, _closed, _solve_nodes, boundary, distance_outside
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward
from casadi_ws.workspace.maps import point_maps
from casadi_ws.workspace.measures import measures
from conftest import REPO, cantilever, chromium, click_points, small_trunk


def jacobian_integral(model, n=3):
    """V = int_U |det dp/du| du by n^3-point Gauss-Legendre, and the tips at the Gauss points (verified
    equilibria, so points of the workspace). Exact for a one-to-one map whose det keeps its sign."""
    x, w = np.polynomial.legendre.leggauss(n)
    lo, hi = model.u_min, model.u_max
    V, dets, tips, q, u0 = 0.0, [], [], None, None
    for a, b, c in itertools.product(range(n), repeat=3):
        u = lo + (np.array([x[a], x[b], x[c]]) + 1) / 2 * (hi - lo)
        eq = solve_equilibrium(model, u, q0=q, u0=u0)
        assert eq.converged
        q, u0 = eq.q, u
        A, _ = sensitivity(model, eq.q, tangent_factorization(model, eq.q, u))
        dets.append(np.linalg.det(A))
        tips.append(eq.tip)
        V += w[a] * w[b] * w[c] * abs(dets[-1]) * np.prod((hi - lo) / 2)
    return V, np.array(dets), np.array(tips)


@pytest.fixture(scope="module")
def trunk3():
    return StaticModel(small_trunk(n_cables=3))


def test_volume_against_the_jacobian_integral_and_refinement(trunk3):
    V_ref, dets, tips = jacobian_integral(trunk3, 4)
    assert np.all(dets < 0) or np.all(dets > 0)  # one sign: the integral is the volume
    b5 = boundary(trunk3, BoundarySettings(n=5))
    b9 = boundary(trunk3, BoundarySettings(n=9))
    for b in (b5, b9):
        assert b.method == "input-faces" and b.closed and _closed(b.triangles)
        assert b.volume > 0  # outward orientation
    assert abs(b5.volume - V_ref) < 0.03 * V_ref
    assert abs(b9.volume - V_ref) < abs(b5.volume - V_ref)  # converges under refinement
    assert abs(b9.volume - V_ref) < 0.01 * V_ref
    assert abs(b5.volume - V_ref) <= b5.volume_error  # the estimate covers the error
    # every verified equilibrium lies inside the surface or on it within its tolerance
    assert np.all(distance_outside(b5, tips) <= b5.tolerance)


def test_a_planted_fault_breaks_the_closed_check(trunk3):
    b = boundary(trunk3, BoundarySettings(n=3))
    T = b.triangles.copy()
    assert _closed(T)
    T[0] = T[0, ::-1]  # one triangle turned over
    assert not _closed(T)
    assert not _closed(b.triangles[1:])  # a hole


def test_four_inputs_close_on_the_faces_with_one_cable_of_each_pair_free():
    model = StaticModel(small_trunk(n_cables=4, resolution=0.5))
    b = boundary(model, BoundarySettings(n=3))
    assert b.method == "input-faces" and b.closed and b.volume > 0
    assert any("faces of U bound the workspace" in n for n in b.notes)


def test_two_inputs_give_the_surface_and_its_boundary_curve():
    model = StaticModel(small_trunk(n_cables=2))
    b = boundary(model, BoundarySettings(n=5))
    assert b.method == "input-patch" and b.volume == 0.0 and b.area > 0
    assert len(b.curve) == 4 * 4 and len(set(b.curve.tolist())) == 16


def test_tip_compliance_of_a_cantilever_against_beam_theory():
    pb = cantilever(n=2, slender=10, model="linear", E=1e6, nu=0.3, L=0.2, order=2)
    m = StaticModel(pb)
    q = np.zeros(m.n_dof)
    maps = point_maps(m, q, np.zeros(m.n_u), None, tangent_factorization(m, q, np.zeros(m.n_u)))
    h, L, E, nu = 0.02, 0.2, 1e6, 0.3
    bending = L**3 / (3 * E * h**4 / 12)
    shear = L / (5 / 6 * E / (2 * (1 + nu)) * h * h)  # Timoshenko
    assert maps["compliance"] == pytest.approx(bending + shear, rel=0.03)
    assert maps["tilt"] == pytest.approx(0.0, abs=1e-9) and maps["effort"] == 0.0


@pytest.mark.parametrize("order", [1, 2])
def test_the_compliance_from_a_single_precision_lu_is_that_of_k(order):
    """Newton's LU is single precision where a probe allows (SuperLU for 4-node tetrahedra, PARDISO for 10-node
    ones), and the soft directions that the compliance measures are those it solves worst (1-5 % off on the
    trunks): point_maps and the sensitivities' merged solve refine it. Reference: a double-precision sparse
    solve with K."""
    from scipy.sparse.linalg import spsolve

    from casadi_ws.fem.mesh import quadratic

    pb = small_trunk(n_cables=2)
    if order == 2:
        pb.mesh = quadratic(pb.mesh)
    m = StaticModel(pb)
    u = np.array([40.0, 20.0])
    eq = solve_equilibrium(m, u)
    fac = tangent_factorization(m, eq.q, u)
    assert fac.K is not None  # single precision
    G = m.C_free @ spsolve(m.residual_and_tangent(eq.q, u)[1].tocsc(), m.C_free.T.toarray())
    ref = np.linalg.eigvalsh(0.5 * (G + G.T)).max()
    assert point_maps(m, eq.q, u, None, fac)["compliance"] == pytest.approx(ref, rel=3e-3)
    G_merged = sensitivity(m, eq.q, fac, compliance=True)[2]
    assert np.abs(G_merged - G).max() < 3e-3 * np.abs(G).max()


def test_steerability_and_tilt_against_finite_differences():
    m = StaticModel(small_trunk(n_cables=2))
    u = np.array([40.0, 20.0])
    eq = solve_equilibrium(m, u)
    fac = tangent_factorization(m, eq.q, u)
    A, _ = sensitivity(m, eq.q, fac)
    maps = point_maps(m, eq.q, u, A, fac)
    d = 1e-3
    A_fd = np.column_stack([(solve_equilibrium(m, u + d * e, q0=eq.q, u0=u).tip
                             - solve_equilibrium(m, u - d * e, q0=eq.q, u0=u).tip) / (2 * d) for e in np.eye(2)])
    assert maps["steerability"] == pytest.approx(np.linalg.svd(A_fd, compute_uv=False).min(), rel=1e-4)
    assert 1.0 < maps["tilt"] < 90.0  # bent by the cables
    # the tip element's axis turns the way the tip's neighbourhood does: along the deformed axis near the tip
    assert maps["direction"][2] > 0.5


def _steerability_fd(m, u, eq):
    """Smallest singular value of dp/du by central differences of independent equilibria (one-sided at a
    bound), each polished to 1e-13."""
    span = m.u_max - m.u_min
    cols = []
    for k in range(m.n_u):
        h = 1e-3 * span[k]
        up, um = u.copy(), u.copy()
        up[k], um[k] = min(u[k] + h, m.u_max[k]), max(u[k] - h, m.u_min[k])
        tips = [solve_equilibrium(m, v, q0=eq.q, u0=u, target=1e-13).tip for v in (up, um)]
        cols.append((tips[0] - tips[1]) / (up[k] - um[k]))
    return np.linalg.svd(np.column_stack(cols), compute_uv=False).min()


def _compliance_fd(pb, u, eq_q):
    """Largest eigenvalue of the tip's compliance by a small tip load in each direction, each equilibrium
    solved independently (a model per load)."""
    from dataclasses import replace

    f, G = 1e-3, []
    for e in np.eye(3):
        tips = []
        for sign in (1, -1):
            m = StaticModel(replace(pb, point_loads=list(pb.point_loads) + [(np.asarray(pb.end_effector, float),
                                                                             sign * f * e)]))
            tips.append(solve_equilibrium(m, u, q0=eq_q, u0=u, target=1e-13).tip)
        G.append((tips[0] - tips[1]) / (2 * f))
    G = np.array(G).T
    return float(np.linalg.eigvalsh(0.5 * (G + G.T)).max())


@pytest.mark.slow
@pytest.mark.parametrize("n_cables", [2, 3])
def test_forward_maps_at_every_point_are_the_robots(n_cables):
    """Steerability and compliance at forward points against finite differences of independent equilibria
    within 1 % (measured: 6e-6), and the same from 2 workers. On the shipped 2-cable trunk at n_d = 11 the
    maps were up to 8 % off (at u = (30, 80) and (0, 40) N among others: the LU a Newton solve ended with was
    a chord LU of an earlier iterate or point) and 15 % apart between a serial and a 2-worker run."""
    from casadi_ws import load_problem
    from casadi_ws.workspace.forward import ForwardSettings, forward

    pb = load_problem(REPO / "problems" / "trunk_2cables.yaml") if n_cables == 2 else small_trunk(n_cables=3)
    m = StaticModel(pb)
    nd = 11 if n_cables == 2 else 5
    res = forward(pb, settings=ForwardSettings(n_d=nd, progress=False), model=m)
    maps = res.maps()
    rng = np.random.default_rng(n_cables)
    picked = list(rng.choice(res.n_points, 3, replace=False))
    if n_cables == 2:
        picked += [int(np.flatnonzero(np.all(np.isclose(res.u, u), axis=1))[0]) for u in ([30.0, 80.0], [0.0, 40.0])]
    for k in picked:
        eq = solve_equilibrium(m, res.u[k], target=1e-13)
        assert maps["steerability"][k] == pytest.approx(_steerability_fd(m, res.u[k], eq), rel=1e-2), res.u[k]
    k = picked[-1]
    eq = solve_equilibrium(m, res.u[k], target=1e-13)
    assert maps["compliance"][k] == pytest.approx(_compliance_fd(pb, res.u[k], eq.q), rel=1e-2)
    two = forward(pb, settings=ForwardSettings(n_d=nd, progress=False, workers=2))
    np.testing.assert_array_equal(two.u, res.u)
    # measured 6e-11 and 5e-11 apart (were 3e-6 and 8e-5 from single-precision LUs at states that agree within
    # the tolerance, 2.4e-8 refined but not polished)
    for name in ("steerability", "compliance"):
        np.testing.assert_allclose(two.maps()[name], maps[name], rtol=1e-9)


@pytest.fixture(scope="module")
def fb_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fb3")
    r = forward_backward(small_trunk(n_cables=3), FBSettings(step=0.008, workers=1, progress=False))
    r.measures = measures(r)
    r.save(d)
    return r, d


def test_face_nodes_start_from_the_nearest_reached_configurations(trunk3):
    # seeded by forward-backward's configurations, the same surface (to the equilibria's tolerance) for fewer LUs
    pb = small_trunk(n_cables=3)
    r = forward_backward(pb, FBSettings(step=0.006, progress=False), model=trunk3)
    b = r.boundary
    assert b.counters["seeded_nodes"] == b.counters["solved_nodes"] == 98
    cold = boundary(trunk3, BoundarySettings())
    assert cold.counters["seeded_nodes"] == 0
    assert b.counters["factorizations"] < 0.8 * cold.counters["factorizations"]
    assert np.abs(b.vertices - cold.vertices).max() < 1e-6
    assert abs(b.volume - cold.volume) < 1e-6 * abs(cold.volume)


def test_a_seed_with_its_curvature_predicts_a_face_node_to_second_order(trunk3):
    # the exploration's d2q/du2 at the seed: the same equilibrium from a start nearer to it, for fewer LUs
    u0 = np.array([20.0, 10.0, 0.0])
    eq = solve_equilibrium(trunk3, u0)
    fac = tangent_factorization(trunk3, eq.q, eq.u)
    _, S = sensitivity(trunk3, eq.q, fac)
    Q = curvature(trunk3, eq.q, eq.u, S, fac, 0.004)
    us = np.array([[35.0, 25.0, 0.0]])
    first = _solve_nodes(trunk3, us, [(u0, eq.q, S.astype(np.float32), None)])
    second = _solve_nodes(trunk3, us, [(u0, eq.q, S.astype(np.float32), Q)])
    assert first[1][0] == second[1][0] == 0
    assert np.abs(first[0] - second[0]).max() < 1e-7
    assert second[3] < first[3]
    # and it is kept in a checkpoint's arrays, so a resumed run predicts the same
    model = SimpleNamespace(u_min=np.zeros(3), u_max=np.full(3, 100.0), n_u=3)
    s = Seeds(model, BoundarySettings())
    s.offer(u0, eq.q, S, Q)
    back = Seeds(model, BoundarySettings())
    back.restore(s.arrays())
    key = next(iter(s.of()))
    for a, b in zip(s.of()[key], back.of()[key]):
        np.testing.assert_array_equal(a, b)
    # a seed without Q (the IPOPT backward computes none) stays without after a resume, next to one with
    s.offer(np.array([100.0, 0.0, 0.0]), eq.q, S)
    back.restore(s.arrays())
    assert sorted(c[3] is None for c in back.configs.values()) == [False, True]


def test_seeds_cover_the_faces_of_up_to_four_inputs_and_ignore_an_input_without_range():
    # 4 inputs: every node of the 24 two-faces at n = 5, those with two or more inputs at a bound (5^4 - 3^4 -
    # 4 * 2 * 3^3); an offer seeds the nodes it is nearest to
    model = SimpleNamespace(u_min=np.zeros(4), u_max=np.ones(4), n_u=4)
    s = Seeds(model, BoundarySettings())
    assert len(s.nodes) == 5**4 - 3**4 - 4 * 2 * 3**3 == 328
    s.offer(np.array([0.0, 0.0, 0.3, 0.6]), np.zeros(3), np.zeros((3, 4)))
    assert len(s.of()) == 328 and len(s.configs) == 1
    # 5 inputs: no nodes, offers are no-ops
    model = SimpleNamespace(u_min=np.zeros(5), u_max=np.ones(5), n_u=5)
    s = Seeds(model, BoundarySettings())
    s.offer(np.ones(5), np.zeros(3), np.zeros((3, 5)))
    assert len(s.nodes) == 0 and s.of() == {} and len(s.arrays()["seed_u"]) == 0
    # a fixed input (u_min == u_max) is no dimension of U: the one face of the two others, offers without 0/0
    model = SimpleNamespace(u_min=np.zeros(3), u_max=np.array([1.0, 0.0, 1.0]), n_u=3)
    s = Seeds(model, BoundarySettings())
    with np.errstate(all="raise"):
        s.offer(np.array([1.0, 0.0, 1.0]), np.zeros(3), np.zeros((3, 3)))
    assert len(s.nodes) == 25 and len(s.of()) == 25


def test_an_input_held_at_one_value_is_no_dimension_of_the_box(trunk3):
    # the 3-cable trunk with its third cable held at zero: its workspace is the face u3 = 0 of the full one
    full = boundary(trunk3, BoundarySettings(n=5))
    pb = small_trunk(n_cables=3)
    pb.actuators[2].u_max = pb.actuators[2].u_min
    b = boundary(StaticModel(pb), BoundarySettings(n=5))
    assert b.method == "input-patch" and b.area > 0 and len(b.vertices) == 25 and len(b.curve) == 16
    assert np.all(b.u[:, 2] == pb.actuators[2].u_min)
    for u, p in zip(b.u, b.vertices):
        (k,) = np.flatnonzero(np.all(np.isclose(full.u, u), axis=1))
        assert np.allclose(full.vertices[k], p, atol=1e-9)


def test_forward_backward_reports_the_boundary_volume_and_maps(fb_dir):
    r, d = fb_dir
    m = r.measures
    assert m["volume_method"] == "boundary" and m["volume"] < 0.5 * m["cell_volume"]
    assert r.boundary.checks["points_outside"] == 0
    with open(d / "points.csv") as f:
        rows = list(csv.DictReader(f))
    for key in ("effort", "steerability", "compliance", "tilt", "state1", "state3"):
        assert all(np.isfinite(float(row[key])) for row in rows)
    with open(d / "failures.csv") as f:
        fails = list(csv.DictReader(f))
    assert list(fails[0]) == ["target_x", "target_y", "target_z", "status", "reason", "closest_x", "closest_y",
                              "closest_z"]
    assert {row["reason"] for row in fails} <= {"not_reached", "prefiltered", "gave_up", "inadmissible",
                                                 "solve_failed", "iteration_limit"}
    missed = [row for row in fails if row["reason"] == "not_reached"]
    assert all(row["closest_x"] != "" for row in missed)


def test_meshio_reads_every_mesh_file_back(fb_dir):
    r, d = fb_dir
    pts = meshio.read(d / "points.vtu")
    assert len(pts.points) == r.n_points and "compliance" in pts.point_data
    cells = meshio.read(d / "cells.vtu")
    assert cells.cells[0].type == "hexahedron" and len(cells.cells[0].data) == r.n_points
    for name in ("boundary.vtu", "boundary.stl"):
        b = meshio.read(d / name)
        assert len(b.cells_dict["triangle"]) == len(r.boundary.triangles)
    # hexahedra with positive volume (VTK's corner order)
    P = cells.points[cells.cells[0].data[0]]
    assert np.linalg.det(np.array([P[1] - P[0], P[3] - P[0], P[4] - P[0]])) > 0


def test_report_renders_in_headless_chromium(fb_dir, tmp_path):
    from casadi_ws.io.report import write_report

    r, d = fb_dir
    page_file = write_report(r, tmp_path / "report.html", small_trunk(n_cables=3).mesh)
    exe = chromium()
    from playwright.sync_api import sync_playwright
    from PIL import Image

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=["--use-angle=swiftshader",
                                                               "--enable-unsafe-swiftshader", "--no-sandbox"])
        for width, height in ((1280, 720), (1920, 1080)):
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(page_file.as_uri())
            page.wait_for_selector("#workspace .gl-container canvas", timeout=60000)
            page.wait_for_timeout(1000)
            assert page.locator("#summary tr").count() >= 5
            assert "volume" in page.locator("#summary").inner_text()
            # the summary is in view and nothing of the plot lies over it (plotly once laid itself out at the
            # window's full width, over the summary, until the window was resized)
            table = page.locator("#summary").bounding_box()
            assert table["x"] + table["width"] <= width and table["y"] + table["height"] <= height
            for svg in page.locator("#workspace .main-svg").all():
                box = svg.bounding_box()
                assert box["x"] + box["width"] <= table["x"] or box["y"] >= table["y"] + table["height"]
            # the colour bar and the menu name their quantity's unit; inputs go by the actuator's name
            title = page.locator("#workspace .cbtitle").all_text_contents()
            assert title and "(" in title[0] and title[0].endswith(")")
            menu = " ".join(page.locator("#workspace .updatemenu-item-text").all_text_contents())
            assert "mm/N" in menu or "compliance" not in menu
            if width == 1280:
                shot = tmp_path / "shot.png"
                page.locator("#workspace").screenshot(path=str(shot))
            page.close()
        browser.close()
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    # the WebGL scene drew the robot, the surface and the points: many colours, much non-white
    assert (img.sum(axis=2) < 740).mean() > 0.05
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 200


def test_the_default_grid_step_scales_with_the_robot():
    from casadi_ws.workspace.interval import default_step

    assert default_step(StaticModel(small_trunk(n_cables=2))) == 0.004  # the trunk keeps its 4 mm
    assert default_step(StaticModel(cantilever(L=0.01))) == pytest.approx(2e-4)  # a 1 cm finger
    assert default_step(StaticModel(cantilever(L=1.0))) == pytest.approx(0.02)  # a 1 m arm


def test_boundary_and_report_commands_refuse_bad_input_in_one_line(tmp_path):
    from conftest import run_cli

    for args, msg in ((["boundary", tmp_path], "not a result directory"),
                      (["report", tmp_path], "not a result directory")):
        r = run_cli(*args)
        assert r.returncode == 2 and msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_forward_grid_gives_the_surface_without_a_solve(trunk3):
    from casadi_ws.workspace.boundary import boundary_of
    from casadi_ws.workspace.forward import ForwardSettings, forward

    pb = trunk3.problem
    res = forward(pb, settings=ForwardSettings(n_d=5, progress=False), model=trunk3)
    b = boundary_of(res, pb, model=trunk3)
    assert b.counters == {"solved_nodes": 0, "known_nodes": 98, "seeded_nodes": 0, "factorizations": 0}
    assert b.closed and b.checks["points_outside"] == 0
    assert b.volume == pytest.approx(boundary(trunk3, BoundarySettings(n=5)).volume, rel=1e-9)


def test_only_the_face_nodes_another_starts_from_get_their_sensitivities():
    """_solve_nodes starts each node from the nearest of the seeds and the nodes before it (the first of
    equals); _starts_of_others names the nodes so chosen, which alone need S."""
    from casadi_ws.workspace.boundary import _starts_of_others

    rng = np.random.default_rng(3)
    span = np.array([100.0, 100.0, 150.0, 150.0])
    for trial in range(20):
        us = rng.integers(0, 5, size=(30, 4)) * span / 4
        seeds = [(rng.integers(0, 9, size=4) * span / 8, None, None, None) for _ in range(rng.integers(0, 12))]
        chosen, done = set(), list(seeds)
        for k, u in enumerate(us):
            if done:
                near = min(done, key=lambda d: np.abs((d[0] - u) / span).max())
                chosen |= {j for j in range(k) if near is done[len(seeds) + j]}
            done.append((u, None, None, None))
        assert _starts_of_others(us, seeds, span) == chosen


def test_clicking_a_point_shows_its_inputs_and_the_robot_deformed_there(tmp_path):
    """Three pages of one grid: the run's own states; states solved again after a run that kept none (a subset:
    a point outside it draws the nearest one's, naming it); no states at all."""
    from casadi_ws.io.output import write_outputs
    from casadi_ws.io.report import write_report
    from casadi_ws.workspace.forward import ForwardSettings, forward

    pb = small_trunk(n_cables=2)
    kept = forward(pb, settings=ForwardSettings(n_d=4, progress=False, store_states=True))
    bare = forward(pb, settings=ForwardSettings(n_d=4, progress=False))
    write_outputs(bare, pb, tmp_path / "solved", shapes=6)
    assert bare.counters["shapes"] == 6  # every picked point re-solved to its reported tip
    pages = [write_report(kept, tmp_path / "kept.html", pb.mesh), tmp_path / "solved" / "report.html",
             tmp_path / "solved" / "report.html", write_report(bare, tmp_path / "none.html", pb.mesh)]
    # the six points the solved page holds are 0, 3, 6, 9, 12, 15 (spread over 16): 10 is not one of them
    seen = click_points(list(zip(pages, [10, 9, 10, 10])), "robot at the clicked point")

    def drawn_at(robot, point):
        """The drawn robot's tip is ``point`` (the end effector is its tip node)."""
        V = np.array(robot[1:], float).T
        return robot[0] is True and np.linalg.norm(V - point * 1e3, axis=1).min() < 1e-3

    (text, robot), (text_s, robot_s), (text_n, robot_n), (bare_text, bare_robot) = seen
    assert "Point 10" in text and "long0 (N)" in text and "admissible" in text and "drawn (orange)" in text
    assert drawn_at(robot, kept.points[10]) and np.linalg.norm(kept.points[10] - kept.rest_tip) > 5e-3
    assert "Point 9" in text_s and "drawn (orange)" in text_s and "at point" not in text_s
    assert drawn_at(robot_s, bare.points[9])
    # point 10's nearest held point is 9 or 6 or 12 or 15 or 3 or 0: the page names it and draws it
    near = min((0, 3, 6, 9, 12, 15), key=lambda j: np.linalg.norm(bare.points[j] - bare.points[10]))
    assert f"at point {near}," in text_n and "the page holds the shapes of 6 of 16 points" in text_n
    assert drawn_at(robot_n, bare.points[near])
    # without states the page says where to get the robot, and draws none
    assert bare_robot is None and "write_outputs" in bare_text and "long90 (N)" in bare_text
