"""The tip's orientation (issue 72): a frame's rotation against closed forms, the range of orientations in each
cell against forward clouds, its ends re-solved, no range without redundancy, the dexterous workspace."""

import numpy as np
import pytest
from conftest import REPO, cantilever, click_points, run_cli, small_trunk
from scipy.spatial.transform import Rotation

from casadi_ws import StaticModel
from casadi_ws.runtime.executor import model_for
from casadi_ws.solvers.equilibrium import quasi_static, solve_equilibrium
from casadi_ws.workspace.forward import ForwardSettings, forward
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward
from casadi_ws.workspace.orientation import OrientationSettings, attach, orientation_ranges, parse_orientation


@pytest.mark.parametrize("kind", ["points", "deformation"])
def test_a_rigid_rotation_of_the_body_is_the_frames_rotation_tilt_and_roll(kind):
    """q = (R - I) X turns the whole body by R: the frame's rotation is R, the tilt the angle between the rest
    axis and R a0, the roll the twist of R about a0 (a closed form: R = swing(a0 -> R a0) twist(a0, roll))."""
    pb = cantilever(n=2, slender=5, model="corotational")
    if kind == "points":
        h = 0.2 / 5
        pb.tip_frame = np.array([[0, 0, 0.2], [h / 2, 0, 0.2], [0, h / 2, 0.2]])
    m = StaticModel(pb)
    a0 = m.tip_frame.axis0
    assert np.allclose(a0, [0, 0, 1])
    for roll_deg, tilt_deg, about in [(0, 30, [0, 1, 0]), (25, 0, [0, 0, 1]), (-40, 55, [1, 1, 0])]:
        twist = Rotation.from_rotvec(np.radians(roll_deg) * a0)
        swing = Rotation.from_rotvec(np.radians(tilt_deg) * np.asarray(about, float) / np.linalg.norm(about))
        R = (swing * twist).as_matrix()
        X = m.mesh.nodes
        q = np.zeros(m.n_dof)
        q[: m.n_mech] = (X @ R.T - X).ravel()
        o = m.tip_frame.orientation(q)
        assert np.abs(o["rotation"] - R).max() < 1e-9
        assert o["tilt"] == pytest.approx(tilt_deg, abs=1e-7) and o["roll"] == pytest.approx(roll_deg, abs=1e-7)


def test_the_tip_frame_of_a_beam_bent_by_an_offset_cable_turns_by_the_closed_form():
    """A straight cable at offset d bends the beam by the uniform moment T d: the section at z turns by
    T d z / (E I) (corotational, nu = 0: exact for plane sections, docs/methods.md "Orientation"). 10-node
    tetrahedra, four across, the frame one body width inside the end the cable pulls (on the end face itself
    the cable's point load warps the face: +7 % there)."""
    E, L, slender = 1e6, 0.2, 10
    h = L / slender
    d, I = 0.3 * h, h**4 / 12
    T = 0.5 / L * E * I / d
    pb = cantilever(n=4, slender=slender, model="corotational", nu=0.0, E=E, L=L, cable_offset=d, order=2)
    z = L - h
    pb.tip_frame = np.array([[0, 0, z], [h / 2, 0, z], [0, h / 2, z]])
    m = StaticModel(pb)
    eq = solve_equilibrium(m, [T])
    assert eq.converged
    o = m.tip_frame.orientation(eq.q)
    exact = np.degrees(T * d * z / (E * I))
    assert o["tilt"] == pytest.approx(exact, rel=0.01)  # measured +0.28 %
    assert abs(o["roll"]) < 0.01  # a bend in the cable's plane does not twist the tip
    assert abs(o["direction"][1]) < 1e-3 and o["direction"][0] > 0  # in the cable's plane, towards it (1e-4 measured)


def test_the_frames_gradient_is_its_finite_difference():
    m = StaticModel(small_trunk(n_cables=2))
    eq = solve_equilibrium(m, np.array([40.0, 20.0]))
    ref = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    f = lambda R: float((R @ m.tip_frame.axis0) @ ref)  # noqa: E731
    g = m.tip_frame.gradient(eq.q, f)
    rng = np.random.default_rng(3)
    for _ in range(3):
        v = np.zeros(m.n_dof)
        v[m.free] = rng.standard_normal(m.n_free)
        v *= 1e-7 / np.abs(v).max()
        fd = (f(m.tip_frame.rotation(eq.q + v)) - f(m.tip_frame.rotation(eq.q - v))) / 2
        assert g @ v == pytest.approx(fd, rel=1e-5)


@pytest.fixture(scope="module")
def four_cables():
    """The coarse 4-cable trunk (two long, two short cables: one input more than the tip's coordinates), its
    forward-backward cells at 20 mm and their orientation ranges."""
    pb = small_trunk(n_cables=4)
    r = forward_backward(pb, FBSettings(step=0.02, progress=False))
    m = model_for(pb)
    return pb, m, r, orientation_ranges(m, r)


def _cell_of(o, points):
    index = {tuple(c): i for i, c in enumerate(o.cell.tolist())}
    return [index.get(tuple(c)) for c in np.round((points - o.origin) / o.step).astype(int).tolist()]


@pytest.mark.slow
def test_each_cells_range_holds_the_tilt_of_every_forward_point_in_it(four_cables):
    """A forward cloud (n_d = 8, 4096 points: the ranges' own seeds are a 5^4 grid, which shares only U's
    corners with it): every point's tilt within its cell's range, up to one cell's worth of tilt variation
    (the ranges keep the tip 2 % of a cell inside the faces, and are local optima). Measured: 0.5 % of the
    points outside their range, by up to 0.8 deg, against a median cell variation of 18 deg."""
    pb, m, _, o = four_cables
    f = forward(pb, settings=ForwardSettings(n_d=8, progress=False, maps="none"))
    tilt = f.maps()["tilt"]
    cells = _cell_of(o, f.points)
    assert all(i is not None for i in cells)  # forward-backward found every cell the cloud lands in
    i = np.array(cells)
    assert np.all(tilt >= o.tilt_min[i] - o.variation[i]) and np.all(tilt <= o.tilt_max[i] + o.variation[i])
    # most points lie strictly inside their ranges: the ranges are not the variation's slack
    inside = (tilt >= o.tilt_min[i] - 0.01) & (tilt <= o.tilt_max[i] + 0.01)
    assert inside.mean() > 0.98


@pytest.mark.slow
def test_the_ranges_ends_are_verified_equilibria_in_their_cells(four_cables):
    """Each end, solved again at its inputs from rest along the quasi-static path (the definition of a reported
    point): converged, its tip in the cell, its tilt the range's end."""
    _, m, _, o = four_cables
    rng = np.random.default_rng(0)
    for i in rng.choice(len(o.point), size=6, replace=False):
        lo, hi = o.origin + o.cell[i] * o.step - o.step / 2, o.origin + o.cell[i] * o.step + o.step / 2
        for u, tilt in ((o.u_at_min[i], o.tilt_min[i]), (o.u_at_max[i], o.tilt_max[i])):
            eq = quasi_static(m, u)
            assert eq.converged
            assert np.all(eq.tip >= lo - 1e-9) and np.all(eq.tip <= hi + 1e-9)
            assert m.tip_frame.orientation(eq.q)["tilt"] == pytest.approx(tilt, abs=1e-4)  # solver tolerance
    assert o.tilt_max.max() - o.tilt_min.min() > 20  # the robot does turn its tip
    assert np.nanmax(o.tilt_max - o.tilt_min) > 5  # and holds a cell with a range of tilts


@pytest.mark.slow
def test_without_redundancy_a_cell_holds_one_orientation():
    """Three inputs for three coordinates: the range in each cell is only the cell's own variation. Three long
    cables 120 deg apart (bending either way, shortening when all pull), not the trunk's two long and one short:
    those reach one cell bent into an S as well as into a C (its map folds), so a cell there holds two tilts."""
    from casadi_ws import trunk_cable

    pb = small_trunk(n_cables=0)
    pb.actuators = [trunk_cable(a, "long") for a in (0, 120, 240)]
    r = forward_backward(pb, FBSettings(step=0.01, progress=False))
    cone = 12.0
    o = orientation_ranges(model_for(pb), r, OrientationSettings(cone=cone))
    ok = np.isfinite(o.tilt_min) & np.isfinite(o.tilt_max)
    assert ok.mean() > 0.9
    # the variation is estimated from the neighbours' points, one cell apart; the range's ends lie up to a cell's
    # diagonal apart (measured: width / variation up to 1.02)
    assert np.all(o.tilt_max[ok] - o.tilt_min[ok] <= 1.25 * o.variation[ok])
    # so the dexterous cells are those of the forward points within the cone, and none of those outside it
    f = forward(pb, settings=ForwardSettings(n_d=8, progress=False, maps="none"))
    cells = _cell_of(o, f.points)
    known = np.array([c is not None for c in cells])
    assert known.mean() > 0.98  # (forward-backward's strict recall)
    tilt, i = f.maps()["tilt"][known], np.array([c for c in cells if c is not None])
    assert np.all(o.dexterous[i[tilt < cone - o.variation[i]]])
    assert not np.any(o.dexterous[i[tilt > cone + o.variation[i]]])
    assert (tilt < cone - o.variation[i]).any() and (tilt > cone + o.variation[i]).any()  # both kinds tested


@pytest.mark.slow
def test_the_dexterous_workspace_is_where_the_tip_can_point_within_the_cone(four_cables, tmp_path):
    pb, m, r, o = four_cables
    wide = orientation_ranges(m, r, OrientationSettings(cone=180.0, seed_n_d=0, max_iterations=0))
    assert wide.dexterous.all()  # a 180 deg cone is the position workspace
    cone = 15.0
    narrow = orientation_ranges(m, r, OrientationSettings(cone=cone))
    f = forward(pb, settings=ForwardSettings(n_d=6, progress=False, maps="none"))
    tilt = f.maps()["tilt"]
    i = np.array(_cell_of(narrow, f.points))
    dex = narrow.dexterous[i]
    # every point that points within the cone (by more than its cell's variation) is in a dexterous cell
    assert np.all(dex[tilt < cone - narrow.variation[i]])
    assert 0 < narrow.dexterous.sum() < len(narrow.point)
    attach(r, narrow)
    d = r.measures["dexterous"]
    assert d["cells"] == narrow.dexterous.sum() and d["cell_volume"] == pytest.approx(d["cells"] * 0.02**3)
    r.save(tmp_path)
    import meshio

    assert len(meshio.read(tmp_path / "dexterous.vtu").cells[0].data) == d["cells"]
    head = (tmp_path / "points.csv").read_text().splitlines()[0].split(",")
    assert head[-3:] == ["tilt_min", "tilt_max", "dexterous"]


def test_orientation_specs_and_bad_ones():
    axis, cone = parse_orientation("axis=[0,0,2],cone=15")
    assert np.allclose(axis, [0, 0, 1]) and cone == 15
    assert parse_orientation("") == (None, None) and parse_orientation("cone=30")[1] == 30
    for bad, words in [("axis=[0,0]", "axis: expected three numbers"), ("cone=200", "cone: expected a half-angle"),
                       ("pointing up", "expected 'axis=[x,y,z],cone=degrees'")]:
        with pytest.raises(ValueError, match=words.replace("[", r"\[")):
            parse_orientation(bad)
    r = run_cli("solve", REPO / "problems" / "trunk_2cables.yaml", "--orientation", "cone=-3", "--out", "/tmp/x")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--orientation: cone: expected" in r.stderr


@pytest.mark.slow
def test_the_report_colours_by_tilt_range_and_draws_the_axis_range_at_a_clicked_point(four_cables, tmp_path):
    from casadi_ws.io.report import write_report

    pb, _, r, o = four_cables
    attach(r, o)
    page_file = write_report(r, tmp_path / "report.html", pb.mesh)
    text = page_file.read_text()
    assert "tilt range in the cell (deg)" in text
    k = int(np.nanargmax(r.maps()["tilt_max"] - r.maps()["tilt_min"]))
    ((shown, lines),) = click_points([(page_file, k)], "tip axis range at the clicked point")
    lo, hi = r.maps()["tilt_min"][k], r.maps()["tilt_max"][k]
    assert f"{lo:.2f} to {hi:.2f} deg" in shown
    # two segments from the clicked tip along the axis at each end of the range
    assert lines[0] is True
    x = np.array([lines[1], lines[2], lines[3]], dtype=float).T
    ends = x[[1, 4]] - x[[0, 3]]
    tilts = np.degrees(np.arccos(ends @ o.reference / np.linalg.norm(ends, axis=1)))
    assert np.allclose(x[[0, 3]], r.points[k] * 1e3, atol=1e-3)  # (the page keeps 0.1 um)
    assert np.allclose(sorted(tilts), [lo, hi], atol=1e-3)
