"""SOFA scenes: the recording stand-in, each translation rule on a small scene written for it, the two
SoftRobots tutorial scenes shipped in problems/sofa/ (numbers read from the scenes by hand), and the problem
format's SOFA conventions (indices, six-number boxes, spheres, transforms, total mass, content-sniffed
files, snapped effectors, tips along any axis)."""

import subprocess
import sys
import textwrap

import meshio
import numpy as np
import pytest
import yaml
from conftest import REPO

from casadi_ws import ProblemError, box_mesh, problem_from_dict
from casadi_ws.fem.mesh import load_mesh, transform_points
from casadi_ws.fem.model import StaticModel
from casadi_ws.io.sofa import SceneError, record, translate, write_problem
from casadi_ws.solvers.equilibrium import solve_equilibrium

SOFA = REPO / "problems" / "sofa"
FINGER, TRUNK = SOFA / "finger" / "Finger.py", SOFA / "trunk" / "trunk.py"


def _load(tr, base):
    return problem_from_dict(tr.problem, "<imported>", base)


# ----------------------------------------------------------------------------------------------- tutorials
def test_the_finger_tutorial_imports_as_its_scene_says():
    tr = translate(FINGER, out_dir=FINGER.parent)
    p = _load(tr, FINGER.parent)
    # mesh/finger.vtk: 158 points, 389 tetrahedra (meshio count); units mm-kg-s from gravity -9810
    assert (p.mesh.n_nodes, p.mesh.n_tets) == (158, 389) and tr.units == "mm-kg-s"
    # BoxROI [-15, 0, 0, 5, 10, 15] (mm) holds these 20 points, bounds inclusive, read from the file by hand
    assert sorted(p.fixed_nodes.tolist()) == [16, 17, 18, 19, 20, 21, 48, 51, 52, 54, 63, 101, 103, 104, 105, 106,
                                              107, 116, 128, 143]
    assert p.material.model == "corotational" and p.material.young_modulus == pytest.approx(600e3)
    assert p.material.poisson_ratio == 0.45
    assert p.material.density * p.mesh.volumes().sum() == pytest.approx(0.075)  # UniformMass totalMass 0.075 kg
    assert np.allclose(p.gravity, [0, -9.81, 0])
    (cable,) = p.cables
    assert np.allclose(cable.pull_point, [0.0, 0.0125, 0.0025]) and len(cable.points) == 14
    model = StaticModel(p)
    # pull point, then the 14 points in index order: 165.240963 mm
    assert model.actuator_states(np.zeros(model.n_dof))[0] * 1e3 == pytest.approx(165.240963, abs=1e-6)
    # no PositionEffector: the centre of the end away from the support, the -x end at x = -103.366 mm
    assert p.end_effector[0] == pytest.approx(-0.103366, abs=1e-6)
    lines = "\n".join(tr.untranslated)
    for kind in ("FingerController", "OglModel", "EulerImplicitSolver", "GenericConstraintSolver", "VisualStyle"):
        assert kind in lines
    # valueType unset: SOFA's default, displacement; no maxPositiveDisp: 10 % of the rest length, said so
    assert cable.control == "displacement" and cable.u_max == pytest.approx(0.01652)
    assert any("no maxPositiveDisp" in n for n in tr.notes)
    eq = solve_equilibrium(model, 0.5 * model.u_max)
    assert eq.converged and model.intensities(eq.q, eq.u)[0] > 0  # taut, lifting the finger


def test_the_trunk_tutorial_imports_as_its_scene_says():
    tr = translate(TRUNK, out_dir=TRUNK.parent)
    p = _load(tr, TRUNK.parent)
    assert (p.mesh.n_nodes, p.mesh.n_tets) == (709, 1972)
    assert len(p.fixed_nodes) == 86  # BoxROI [[-20, -20, 0], [20, 20, 20]] mm: every node with z <= 20 mm
    assert p.material.young_modulus == pytest.approx(450e3) and p.material.poisson_ratio == 0.45
    assert p.material.density * p.mesh.volumes().sum() == pytest.approx(0.042)
    assert [c.name for c in p.cables] == [f"cableL{i}" for i in range(4)] + [f"cableS{i}" for i in range(4)]
    assert all(c.pull_point is None for c in p.cables)  # hasPullPoint '0': the first point is on the body
    # the long cables use the 21 points (flattened pull point + 20), the short ones indices 0..9 of 11
    assert [len(c.points) for c in p.cables] == [21] * 4 + [10] * 4
    model = StaticModel(p)
    L0 = model.actuator_states(np.zeros(model.n_dof)) * 1e3
    assert L0[0] == pytest.approx(184.569043, abs=1e-5) and L0[4] == pytest.approx(91.030686, abs=1e-5)
    assert np.allclose(p.end_effector, [0, 0, 0.195])  # tip: the +z end, away from the base
    assert all(c.control == "displacement" for c in p.cables)
    assert [c.u_max for c in p.cables] == [0.07] * 4 + [0.04] * 4  # maxPositiveDisp 70 / 40 mm
    # no cable pulled (u = 0): the cables hold their rest length, so the upper ones carry the weight
    eq = solve_equilibrium(model, np.zeros(8))
    t = model.intensities(eq.q, eq.u)
    assert eq.converged and t[0] > 0.1 and t[4] > 0.1 and np.all(t[[1, 2, 3, 5, 6, 7]] < 1e-6)
    # force-free, it droops ~150 mm under its own weight (the SOFA run)
    free = problem_from_dict({**tr.problem, "cables": [{**c, "control": "force", "u_min": 0, "u_max": 1}
                                                      for c in tr.problem["cables"]]}, "<free>", TRUNK.parent)
    mf = StaticModel(free)
    ef = solve_equilibrium(mf, np.zeros(8))
    assert ef.converged and 0.14 < -mf.tip(ef.q)[1] < 0.16


def test_the_trunk_tutorial_curls_into_itself_within_its_stroke():
    """What the trunk's own input box asks for: one long cable pulled to 30 % of its 70 mm stroke curls the
    trunk without contact; at 40 % its disks pass through each other, which is reported as inadmissible: the
    imported problem has no self-contact (tests/test_auto_contact.py adds ``self_contact: auto``)."""
    from casadi_ws.solvers.admissible import admissibility

    p = problem_from_dict(translate(TRUNK, out_dir=TRUNK.parent).problem, "<trunk>", TRUNK.parent)
    model = StaticModel(p)
    e0 = solve_equilibrium(model, np.zeros(8))
    for share, violations in ((0.3, ()), (0.4, ("self_penetration",))):
        u = np.zeros(8)
        u[0] = share * model.u_max[0]
        eq = solve_equilibrium(model, u, q0=e0.q, u0=np.zeros(8))
        assert eq.converged and admissibility(model, eq.q, u, eq.factorization).violations == violations


@pytest.mark.parametrize("scene", [FINGER, TRUNK], ids=["finger", "trunk"])
def test_the_shipped_problem_files_are_what_the_importer_writes(scene, tmp_path):
    tr = translate(scene, out_dir=scene.parent)
    out = tmp_path / "p.yaml"
    write_problem(tr, out, scene.name)
    assert out.read_text() == scene.with_name(scene.stem.lower() + ".yaml").read_text()


# ----------------------------------------------------------------------------------------------- small scenes
def _box_file(tmp_path, name="block.vtk", fmt=None, size=(10.0, 10.0, 40.0), div=(2, 2, 8)):
    """A block in millimetres (x, y across, z along) written as a SOFA scene would ship it."""
    m = box_mesh(size, div, (-size[0] / 2, -size[1] / 2, 0.0))
    path = tmp_path / name
    meshio.write(path, meshio.Mesh(m.nodes, [("tetra", m.tets)]), file_format=fmt)
    return path, m


def _scene(tmp_path, body: str, extra: str = "", gravity="[0, -9810, 0]", name="scene.py"):
    text = textwrap.dedent(f"""\
        import Sofa.Core
        def createScene(root):
            root.gravity = {gravity}
            root.addObject('FreeMotionAnimationLoop')
            body = root.addChild('body')
            body.addObject('EulerImplicitSolver')
        """) + textwrap.indent(textwrap.dedent(body), "    ") + textwrap.indent(textwrap.dedent(extra), "    ")
    path = tmp_path / name
    path.write_text(text)
    return path


_BODY = """\
body.addObject('MeshVTKLoader', name='loader', filename='block.vtk'{transform})
body.addObject('MeshTopology', src='@loader')
body.addObject('MechanicalObject', name='dofs')
body.addObject('UniformMass', totalMass=0.01)
body.addObject('TetrahedronFEMForceField', youngModulus=500, poissonRatio=0.3, method='large')
body.addObject('BoxROI', name='roi', box=[-6, -6, -1, 6, 6, 0.1])
body.addObject('FixedConstraint', indices='@roi.indices')
cable = body.addChild('cable')
cable.addObject('MechanicalObject', position=[[4, 0, 5], [4, 0, 20], [4, 0, 35]])
cable.addObject('CableConstraint', name='c', indices=[0, 1, 2], pullPoint=[4, 0, 0], valueType='force', maxForce=1000)
cable.addObject('BarycentricMapping')
"""


def test_a_loader_transform_places_the_mesh_as_sofa_does(tmp_path):
    _, m = _box_file(tmp_path)
    body = _BODY.format(transform=", rotation=[0, 0, 90], translation=[10, 0, 0], scale=2")
    scene = _scene(tmp_path, body.replace("box=[-6, -6, -1, 6, 6, 0.1]", "box=[-1, -11, -1, 21, 11, 0.1]"))
    tr = translate(scene, out_dir=tmp_path)
    p = _load(tr, tmp_path)
    # by hand: (1, 0, 0) mm -> scaled (2, 0, 0) -> turned 90 deg about z (0, 2, 0) -> moved (10, 2, 0) mm
    assert np.allclose(transform_points(np.array([[1.0, 0, 0]]), [0, 0, 90], [10, 0, 0], 2.0), [[10, 2, 0]])
    assert np.allclose(p.mesh.nodes, (10 * np.array([1, 0, 0]) + 2 * m.nodes @ np.array([[0, 1, 0], [-1, 0, 0],
                                                                                       [0, 0, 1]])) * 1e-3)


def test_indices_boxes_and_masses_of_a_small_scene(tmp_path):
    _, m = _box_file(tmp_path)
    tr = translate(_scene(tmp_path, _BODY.format(transform="")), out_dir=tmp_path)
    p = _load(tr, tmp_path)
    base = np.flatnonzero(m.nodes[:, 2] <= 0.1)  # BoxROI [-6, -6, -1, 6, 6, 0.1] mm: the z = 0 face
    assert sorted(p.fixed_nodes.tolist()) == base.tolist()
    assert p.material.density * p.mesh.volumes().sum() == pytest.approx(0.01)
    (c,) = p.cables
    assert c.u_max == pytest.approx(1.0)  # maxForce 1000 (mN in mm-kg-s)
    assert np.allclose(c.points, [[0.004, 0, 0.005], [0.004, 0, 0.02], [0.004, 0, 0.035]])
    assert p.material.young_modulus == pytest.approx(500e3)  # kPa -> Pa


def test_cable_indices_on_the_body_sphere_roi_and_partial_fixing(tmp_path):
    _, m = _box_file(tmp_path)
    top = np.flatnonzero(np.isclose(m.nodes[:, 0], 5) & np.isclose(m.nodes[:, 1], 0))
    top = top[np.argsort(m.nodes[top, 2])][1:].tolist()
    body = f"""\
    body.addObject('MeshVTKLoader', name='loader', filename='block.vtk')
    body.addObject('MechanicalObject')
    body.addObject('TetrahedronFEMForceField', youngModulus=500, poissonRatio=0.3)
    body.addObject('SphereROI', name='s', centers=[0, 0, 0], radii=8)
    body.addObject('RestShapeSpringsForceField', points='@s.indices', stiffness=1e12)
    body.addObject('BoxROI', name='side', box=[[-6, -6, 30], [6, 6, 41]])
    body.addObject('PartialFixedConstraint', indices='@side.indices', fixedDirections=[1, 0, 0])
    body.addObject('CableConstraint', indices={top}, pullPoint=[5, 0, 0], minForce=0, maxForce=500, valueType='force')
    """
    tr = translate(_scene(tmp_path, body), out_dir=tmp_path)
    p = _load(tr, tmp_path)
    assert sorted(p.fixed_nodes.tolist()) == np.flatnonzero(np.linalg.norm(m.nodes, axis=1) <= 8).tolist()
    (nodes, comps), = p.partial_fixed
    assert comps == (0,) and sorted(nodes.tolist()) == np.flatnonzero(m.nodes[:, 2] >= 30).tolist()
    assert p.cables[0].nodes.tolist() == top  # points that are mesh nodes follow them exactly
    assert p.end_effector[2] == pytest.approx(0.04)


def test_a_file_whose_extension_lies_is_read_by_its_content(tmp_path):
    path, m = _box_file(tmp_path, "diamond.vtk", fmt="vtu")  # XML VTU named .vtk, like SoftRobots' diamond
    assert path.read_bytes().startswith(b"<")
    mesh = load_mesh(path, 1e-3)
    assert mesh.n_nodes == m.n_nodes and np.allclose(mesh.nodes, m.nodes * 1e-3)


def test_unsupported_components_each_get_their_line(tmp_path):
    _box_file(tmp_path)
    extra = """\
    body.addObject('TriangleCollisionModel')
    body.addObject('LineCollisionModel')
    body.addObject('MyOwnThing', name='mine')
    visu = body.addChild('visu')
    visu.addObject('OglModel')
    class Ctl(Sofa.Core.Controller):
        pass
    body.addObject(Ctl(name='ctl'))
    """
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), extra), out_dir=tmp_path)
    lines = tr.untranslated
    assert any(l.startswith("TriangleCollisionModel: collision") for l in lines)
    assert any(l.startswith("MyOwnThing: unknown to the importer at /body/mine") for l in lines)
    assert any(l.startswith("OglModel: visual only") for l in lines)
    assert any(l.startswith("controller Ctl") for l in lines)
    assert any(l.startswith("EulerImplicitSolver: dynamics") for l in lines)
    assert len(lines) == len(set(lines))


def test_a_cavity_surface_off_the_nodes_is_embedded(tmp_path):
    from casadi_ws.io.cavities import cavity_enclosing, cavity_from_surface

    mesh = load_mesh(REPO / "tests" / "meshes" / "hollow_sphere_4mm.vtu")
    exact = cavity_enclosing(mesh, [0, 0, 0])
    # the same wall with every vertex moved 0.2 % towards the centre: off the nodes, inside the void
    pts = exact.points * 0.998
    surf = tmp_path / "cavity.stl"
    meshio.write(surf, meshio.Mesh(pts, [("triangle", exact.triangles)]), binary=True)
    cav = cavity_from_surface(mesh, surf)
    assert cav.nodes is None and cav.rest_volume() == pytest.approx(exact.rest_volume() * 0.998 ** 3, rel=1e-9)
    with pytest.raises(ValueError, match="lies .* from the mesh"):
        cavity_from_surface(mesh, surf, embed_tolerance=1e-9)


def test_units_come_from_gravity_or_are_asked_for(tmp_path):
    _box_file(tmp_path)
    with pytest.raises(SceneError, match=r"cannot tell the units from gravity's magnitude 5 \(9.81: m, 9810: mm\); give --units"):
        translate(_scene(tmp_path, _BODY.format(transform=""), gravity="[0, 0, -5]"), out_dir=tmp_path)
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), gravity="[0, 0, -5]"), units="mm-kg-s",
                   out_dir=tmp_path)
    assert np.allclose(tr.problem["gravity"], [0, 0, -0.005])


def test_an_xml_scene_is_parsed_into_the_same_graph(tmp_path):
    _box_file(tmp_path)
    (tmp_path / "s.scn").write_text("""<Node name="root" gravity="0 -9810 0">
      <Node name="body">
        <MeshVTKLoader name="loader" filename="block.vtk"/>
        <MechanicalObject/>
        <TetrahedronFEMForceField youngModulus="500" poissonRatio="0.3" method="small"/>
        <FixedConstraint indices="0 1 2 3 4 5 6 7 8"/>
        <Node name="cable">
          <MechanicalObject position="4 0 5  4 0 20"/>
          <CableConstraint indices="0 1" pullPoint="4 0 0" valueType="force" maxForce="100"/>
        </Node>
      </Node>
    </Node>""")
    p = _load(translate(tmp_path / "s.scn", out_dir=tmp_path), tmp_path)
    assert p.material.model == "linear" and len(p.fixed_nodes) == 9 and p.cables[0].u_max == pytest.approx(0.1)


def test_bad_scenes_give_one_line_and_exit_2(tmp_path):
    _box_file(tmp_path)
    cases = {
        "no_create.py": ("x = 1\n", "defines no createScene"),
        # an unknown module runs as stubs: what is left to refuse is the scene itself
        "imports.py": ("import stlib3.animation\ndef createScene(root):\n    pass\n",
                       "no node holds a TetrahedronFEMForceField"),
        "syntax.py": ("def createScene(root)\n    pass\n", "createScene failed: SyntaxError"),
        "raises.py": ("def createScene(root):\n    root.nothing.addObject('A')\n", "createScene failed (line 2)"),
        "no_body.py": ("def createScene(root):\n    root.addObject('FreeMotionAnimationLoop')\n",
                       "no node holds a TetrahedronFEMForceField"),
    }
    for name, (text, message) in cases.items():
        (tmp_path / name).write_text(text)
        r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "import-sofa", str(tmp_path / name),
                            "--out", str(tmp_path / "o.yaml")], capture_output=True, text=True)
        assert r.returncode == 2 and message in r.stderr and len(r.stderr.strip().splitlines()) == 1, (name, r.stderr)


def test_the_command_writes_a_problem_that_solves(tmp_path):
    _box_file(tmp_path)
    scene = _scene(tmp_path, _BODY.format(transform=""))
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "import-sofa", str(scene)], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = scene.with_suffix(".yaml")
    assert "# Not translated:" in out.read_text() and "not translated: EulerImplicitSolver" in r.stdout
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "equilibrium", str(out), "--u", "0.5"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_the_recorder_leaves_no_stand_in_behind(tmp_path):
    _box_file(tmp_path)
    record(_scene(tmp_path, _BODY.format(transform="")))
    assert "Sofa" not in sys.modules or not hasattr(sys.modules["Sofa"], "Core") or \
        sys.modules["Sofa"].__dict__.get("__file__")


# ----------------------------------------------------------------------------------------------- the format
def _problem(tmp_path, **keys):
    _, m = _box_file(tmp_path)
    d = {"mesh": {"file": "block.vtk", "units": "mm"}, "material": {"young_modulus": 1e5, "poisson_ratio": 0.3},
         "fixed": {"box": [-0.006, -0.006, -0.001, 0.006, 0.006, 0.0001]},
         "cables": [{"points": [[0.004, 0, 0.005], [0.004, 0, 0.03]], "pull_point": [0.004, 0, 0]}]}
    d.update(keys)
    return problem_from_dict(d, "p.yaml", tmp_path), m


def test_format_six_number_boxes_spheres_indices_tips_and_snaps(tmp_path):
    p, m = _problem(tmp_path)
    assert sorted(p.fixed_nodes.tolist()) == np.flatnonzero(m.nodes[:, 2] <= 0.1).tolist()
    p, _ = _problem(tmp_path, fixed={"indices": list(range(9))}, end_effector={"tip": {"axis": "-z"}})
    assert sorted(p.fixed_nodes.tolist()) == list(range(9)) and p.end_effector[2] == 0.0
    p, _ = _problem(tmp_path, fixed={"sphere": {"center": [0, 0, 0], "radius": 0.008}},
                    end_effector={"point": [0.0, 0.0, 0.0405], "snap": 0.001})
    assert np.allclose(p.end_effector, [0, 0, 0.04])  # moved onto the top face
    p, _ = _problem(tmp_path, mesh={"file": "block.vtk", "units": "mm", "transform": {"rotation": [0, 0, 90]}},
                    material={"young_modulus": 1e5, "poisson_ratio": 0.3, "total_mass": 0.5})
    assert p.material.density * p.mesh.volumes().sum() == pytest.approx(0.5)


@pytest.mark.parametrize("keys, message", [
    ({"fixed": {"indices": [0, 5000]}}, "fixed.indices[1]: index 5000 is not a node of the mesh"),
    ({"fixed": {"box": [0, 0, 0, 1, 1]}}, "fixed.box: expected [[xmin, ymin, zmin], [xmax, ymax, zmax]] or"),
    ({"mesh": {"file": "block.vtk", "transform": {"scale": 0}}}, "mesh.transform.scale: must not be zero"),
    ({"material": {"young_modulus": 1, "poisson_ratio": 0.3, "density": 1, "total_mass": 1}},
     "material.total_mass: give density (kg/m^3) or total_mass (kg), not both"),
    ({"end_effector": {"point": [0, 0, 0.05], "snap": 0.001}}, "end_effector: point [0.0, 0.0, 0.05] lies 0.01 m"),
    ({"end_effector": {"tip": {"axis": "w"}}}, "end_effector.tip.axis: expected one of"),
    ({"cables": [{"indices": [1], "points": [[0, 0, 0]]}]}, "cables[0].points: give either 'points' or 'indices'"),
])
def test_format_bad_sofa_style_keys_are_one_line(tmp_path, keys, message):
    with pytest.raises(ProblemError) as exc:
        _problem(tmp_path, **keys)
    assert message in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("value_type", ["pressure", "volumeGrowth", "unbounded"])
def test_a_pressure_cavity_scene_with_an_effector(tmp_path, value_type):
    """SurfacePressureConstraint on a surface loader whose vertices are not mesh nodes (embedded, as SOFA
    maps it), in pressure or volume growth (without a bound: half the rest volume, in a note), and a
    PositionEffector a hair off the mesh (snapped)."""
    from casadi_ws.io.cavities import cavity_enclosing

    mesh = load_mesh(REPO / "tests" / "meshes" / "hollow_sphere_4mm.vtu")  # metres: written back in mm
    meshio.write(tmp_path / "ball.vtu", meshio.Mesh(mesh.nodes * 1e3, [("tetra", mesh.tets)]))
    wall = cavity_enclosing(mesh, [0, 0, 0])
    meshio.write(tmp_path / "cavity.stl", meshio.Mesh(wall.points * 1e3 * 0.998, [("triangle", wall.triangles)]),
                 binary=True)
    top = mesh.nodes[:, 2].max() * 1e3
    bounds = {"pressure": "maxPressure=2, minPressure=0", "volumeGrowth": "maxVolumeGrowth=300",
              "unbounded": "minVolumeGrowth=0"}[value_type]
    body = f"""\
    body.addObject('MeshVTKLoader', name='loader', filename='ball.vtu')
    body.addObject('MechanicalObject')
    body.addObject('TetrahedronFEMForceField', youngModulus=1000, poissonRatio=0.3)
    body.addObject('BoxROI', name='base', box=[-30, -30, -30, 30, 30, -17])
    body.addObject('FixedConstraint', indices='@base.indices')
    cav = body.addChild('cavity')
    cav.addObject('MeshSTLLoader', name='surf', filename='cavity.stl')
    cav.addObject('MeshTopology', src='@surf')
    cav.addObject('MechanicalObject')
    cav.addObject('SurfacePressureConstraint', valueType='{value_type.replace("unbounded", "volumeGrowth")}', {bounds})
    cav.addObject('BarycentricMapping')
    eff = body.addChild('effector')
    eff.addObject('MechanicalObject', position=[0, 0, {top + 0.05}])
    eff.addObject('PositionEffector', indices=[0], effectorGoal=[0, 0, 30])
    eff.addObject('BarycentricMapping')
    """
    tr = translate(_scene(tmp_path, body), out_dir=tmp_path)
    p = _load(tr, tmp_path)
    (cav,) = p.cavities
    assert cav.nodes is None and cav.rest_volume() == pytest.approx(wall.rest_volume() * 0.998**3, rel=1e-9)
    assert np.allclose(p.end_effector, [0, 0, top * 1e-3], atol=1e-9)  # moved onto the top of the ball
    if value_type == "pressure":
        assert cav.control == "pressure" and cav.u_max == pytest.approx(2000.0)  # 2 kPa in mm-kg-s
    elif value_type == "volumeGrowth":
        assert cav.control == "volume" and cav.u_max == pytest.approx(300e-9)  # 300 mm^3
    else:
        assert cav.control == "volume" and cav.u_max == pytest.approx(0.5 * cav.rest_volume(), rel=1e-3)
        assert any("no maxVolumeGrowth in the scene: u_max set to half its rest volume" in n for n in tr.notes)
    model = StaticModel(p)
    eq = solve_equilibrium(model, 0.5 * model.u_max)
    assert eq.converged and model.intensities(eq.q, eq.u)[0] > 0


def test_the_stlib_finger_tutorial_builds_the_same_robot():
    """FingerWithSTLIB.py builds the finger with stlib3's ElasticMaterialObject and VisualModel prefabs
    (recorded by their stand-ins): same mesh and supports as Finger.py, its own mass and cable order."""
    scene = FINGER.with_name("FingerWithSTLIB.py")
    tr = translate(scene, out_dir=scene.parent)
    p, ref = _load(tr, scene.parent), _load(translate(FINGER, out_dir=FINGER.parent), FINGER.parent)
    assert p.mesh.n_nodes == ref.mesh.n_nodes and sorted(p.fixed_nodes) == sorted(ref.fixed_nodes)
    assert p.material.density * p.mesh.volumes().sum() == pytest.approx(0.05)  # totalMass=0.05 in this one
    assert p.cables[0].points[5].tolist() == pytest.approx([-0.0835, 0.0125, 0.0045])  # its own point order
    assert any(l.startswith("LinearSolverConstraintCorrection: dynamics") for l in tr.untranslated)


def test_stlib_fixed_box_and_softrobots_pulling_cable_placed_by_their_transform(tmp_path):
    _, m = _box_file(tmp_path)
    text = textwrap.dedent("""\
        from stlib3.scene import MainHeader
        from stlib3.physics.deformable import ElasticMaterialObject
        from stlib3.physics.constraints import FixedBox
        from softrobots.actuators import PullingCable
        def createScene(root):
            MainHeader(root, gravity=[0, 0, -9810])
            body = ElasticMaterialObject(name='body', volumeMeshFileName='block.vtk', youngModulus=500,
                                         poissonRatio=0.3, totalMass=0.01, attachedTo=root)
            FixedBox(applyTo=body, atPositions=[-6, -6, -1, 6, 6, 0.1])
            PullingCable(body, 'c', cableGeometry=[[0, 0, 5], [0, 0, 35]], translation=[4, 0, 0],
                         pullPointLocation=[4, 0, 0], valueType='force')
        """)
    (tmp_path / "stlib.py").write_text(text)
    tr = translate(tmp_path / "stlib.py", out_dir=tmp_path)
    p = _load(tr, tmp_path)
    assert sorted(p.fixed_nodes.tolist()) == np.flatnonzero(m.nodes[:, 2] <= 0.1).tolist()
    assert np.allclose(p.cables[0].points, [[0.004, 0, 0.005], [0.004, 0, 0.035]])  # moved by 4 mm along x
    assert p.material.young_modulus == pytest.approx(500e3) and np.allclose(p.gravity, [0, 0, -9.81])


def test_a_stiff_layer_on_a_sub_topology_adds_its_stiffness(tmp_path):
    """A second TetrahedronFEMForceField on a BoxROI's tetrahedraInROI (a strain-limiting layer, as in
    SoftRobots' PneuNets gripper) becomes a material region whose Lame parameters are the sum."""
    _, m = _box_file(tmp_path)
    extra = """\
    layer = body.addChild('layer')
    body.addObject('BoxROI', name='bottom', box=[-6, -6, -1, 6, 0, 41])
    layer.addObject('TetrahedronSetTopologyContainer', tetrahedra='@../bottom.tetrahedraInROI')
    layer.addObject('TetrahedronFEMForceField', youngModulus=1500, poissonRatio=0.3)
    """
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), extra), out_dir=tmp_path)
    p = _load(tr, tmp_path)
    (tets, region), = p.regions
    assert region.young_modulus == pytest.approx(2000e3) and region.poisson_ratio == pytest.approx(0.3)  # 500 + 1500
    centroids = m.nodes[m.tets].mean(axis=1)
    assert sorted(tets.tolist()) == np.flatnonzero(centroids[:, 1] <= 0).tolist()
    assert not any("bodies" in n for n in tr.notes)  # a layer, not a second body


def test_sofa_soft_springs_constant_forces_and_surface_pressure(tmp_path):
    """The importer's rules: a soft RestShapeSpringsForceField becomes ``springs`` (a stiff one stays a support:
    tests/test_sofa.py), ConstantForceField ``loads``, SurfacePressureForceField on a surface of the body's
    points ``pressure_loads`` with casadi-ws's sign; the translated problem solves."""
    from casadi_ws import StaticModel, solve_equilibrium
    from casadi_ws.fem.surface import boundary_faces
    from casadi_ws.fem.terms import PressureLoad, Springs

    _, m = _box_file(tmp_path)
    f = boundary_faces(m)
    side = f[(m.nodes[f][:, :, 0] > 5 - 1e-9).all(axis=1)]  # the +x side, wound out of the body
    meshio.write(tmp_path / "side.stl", meshio.Mesh(m.nodes, [("triangle", side)]))
    top = np.flatnonzero(m.nodes[:, 2] > 40 - 1e-9)
    body = _BODY.format(transform="").replace(
        "body.addObject('FixedConstraint', indices='@roi.indices')",
        "body.addObject('RestShapeSpringsForceField', points='@roi.indices', stiffness=50)")
    extra = f"""\
    body.addObject('ConstantForceField', indices={top.tolist()}, totalForce=[0, 10, 0])
    skin = body.addChild('skin')
    skin.addObject('MeshSTLLoader', name='side', filename='side.stl')
    skin.addObject('MechanicalObject')
    skin.addObject('SurfacePressureForceField', pressure=0.5)
    skin.addObject('BarycentricMapping')
    """
    tr = translate(_scene(tmp_path, body, extra), out_dir=tmp_path)
    assert "fixed" not in tr.problem
    (s,) = tr.problem["springs"]
    assert s["stiffness"] == pytest.approx(50.0)  # N/m in mm-kg-s: 50 kg/s^2 either way
    assert len(tr.problem["loads"]) == top.size
    assert np.allclose(np.sum([ld["force"] for ld in tr.problem["loads"]], axis=0), [0, 0.01, 0])  # 10 mN
    (pl,) = tr.problem["pressure_loads"]
    assert pl["pressure"] == pytest.approx(-500.0)  # 0.5 kPa along the outward winding: pulls the side out
    p = _load(tr, tmp_path)
    springs, load = p.terms
    assert isinstance(springs, Springs) and isinstance(load, PressureLoad) and len(load.faces) == len(side)
    eq = solve_equilibrium(StaticModel(p), p.u_min)
    assert eq.converged and (eq.tip - p.end_effector)[0] > 1e-4  # the side pulled out along +x


# ----------------------------------------------------------------------------------------------- any scene
def test_node_data_read_before_set_key_modules_and_unknown_modules_run_as_stubs(tmp_path):
    """A scene reads root.dt.value before setting it, writes gravity through .value, imports Key as a module,
    splib3.loaders, a decorator and a module the stand-in does not know: it runs, the robot is translated, and
    the stubbed names are listed."""
    _box_file(tmp_path)
    body = _BODY.format(transform="")
    head = """\
    import Sofa.constants.Key as Key
    from splib3.loaders import getLoadingLocation
    from splib3.objectmodel import SofaPrefab
    import some_plugin_nobody_has
    some_plugin_nobody_has.configure(root, level=3)
    root.dt.value = root.dt.value / 2
    root.gravity.value = [0, -9810, 0]
    assert Key.uparrow and getLoadingLocation("block.vtk", __file__).endswith("block.vtk")

    @SofaPrefab
    class Decor:
        pass
    Decor()
    """
    tr = translate(_scene(tmp_path, textwrap.dedent(head) + body, gravity="None"), out_dir=tmp_path)
    assert tr.units == "mm-kg-s" and "cables" in tr.problem
    (note,) = [n for n in tr.notes if n.startswith("run as stubs")]
    assert "some_plugin_nobody_has" in note and "splib3.objectmodel" in note


def test_the_mechanical_object_places_the_body_and_boxes_select_on_the_placed_points(tmp_path):
    """DiamondRobot's MechanicalObject turns its mesh (rx=90, dz=35): the BoxROIs select on the placed points,
    and an empty selection is one line, not a traceback."""
    _, m = _box_file(tmp_path)
    body = _BODY.format(transform="").replace(
        "body.addObject('MechanicalObject', name='dofs')", "body.addObject('MechanicalObject', name='dofs', rx=90, dz=35)")
    # turned 90 deg about x, the block's z = 0 face lies at y = 0, then moved to z = 35 +- 5
    body = body.replace("box=[-6, -6, -1, 6, 6, 0.1]", "box=[6, 0.1, 29, -6, -1, 41]")  # corners swapped: SOFA sorts
    body = body.replace("[4, 0, 5], [4, 0, 20], [4, 0, 35]", "[4, -5, 35], [4, -20, 35], [4, -35, 35]")
    body = body.replace("pullPoint=[4, 0, 0]", "pullPoint=[4, 0, 35]")
    tr = translate(_scene(tmp_path, body), out_dir=tmp_path)
    p = _load(tr, tmp_path)
    assert tr.problem["mesh"]["transform"] == {"rotation": [90.0, 0.0, 0.0], "translation": [0.0, 0.0, 0.035]}
    assert sorted(p.fixed_nodes.tolist()) == np.flatnonzero(m.nodes[:, 2] <= 0.1).tolist()
    assert np.allclose(p.mesh.nodes[:, 1].max(), 0.0) and np.allclose(p.mesh.nodes[:, 2].mean(), 0.035)
    far = body.replace("box=[6, 0.1, 29, -6, -1, 41]", "box=[-6, -6, -1, 6, 6, 0.1]")
    with pytest.raises(SceneError, match=r"FixedConstraint .* holds no point of the body \(the body spans"):
        translate(_scene(tmp_path, far), out_dir=tmp_path)


def test_gravity_with_a_typo_picks_its_units_with_a_note(tmp_path):
    _box_file(tmp_path)
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), gravity="[0, -9180, 0]"), out_dir=tmp_path)
    assert tr.units == "mm-kg-s" and any("6% off 9810: a typo?" in n for n in tr.notes)
    with pytest.raises(SceneError, match="cannot tell the units"):
        translate(_scene(tmp_path, _BODY.format(transform=""), gravity="[0, -5000, 0]"), out_dir=tmp_path)


def test_stlib_scene_header_children_and_a_second_robot(tmp_path):
    """stlib3's Scene creates Settings, Modelling and Simulation; a scene of two fingers translates the first
    with its own cable and lists the other's."""
    _box_file(tmp_path)
    body = _BODY.format(transform="")
    two = body + body.replace("body.", "body2.").replace("cable = body2", "cable = body2").replace(
        "cable.", "cable2.").replace("cable2 = ", "").replace("cable = body2.addChild('cable')",
                                                               "cable2 = body2.addChild('cable')")
    head = """\
    from stlib3.scene import Scene
    scene = Scene(root, gravity=[0, -9810, 0])
    scene.addMainHeader()
    scene.Simulation.addObject('GenericConstraintSolver')
    body2 = root.addChild('body2')
    """
    tr = translate(_scene(tmp_path, textwrap.dedent(head) + two), out_dir=tmp_path)
    assert len(tr.problem["cables"]) == 1
    assert any("at /body2/cable acts on another body: not translated" in n for n in tr.notes)


# ------------------------------------------------------------------ any SOFA robot: rules of issue "SOFA corpus"
def test_softrobots_parts_run_from_the_vendored_copy_and_leave_nothing_behind(tmp_path):
    """``softrobots.parts.finger.Finger`` is SoftRobots' own code (casadi_ws/io/sofa/vendor), run against the
    stand-ins: four fingers, the first translated with its cable, the others one line each."""
    scene = tmp_path / "parts.py"
    scene.write_text(textwrap.dedent("""\
        from softrobots.parts.finger import Finger
        def createScene(root):
            root.gravity = [0, -981, 0]
            for i, name in enumerate(("A", "B")):
                Finger(root, name=name, translation=[0, 0, 50 * i], valueType='position')
        """))
    tr = translate(scene, out_dir=tmp_path)
    p = _load(tr, tmp_path)
    assert tr.units == "cm-kg-s" and len(p.cables) == 1 and p.mesh.n_nodes == 158  # the Finger's finger.vtk
    assert any(line.startswith("another deformable body at /B (") for line in tr.untranslated)
    assert not any("/B/" in line for line in tr.untranslated)  # the other body is one line, not one per part
    assert not any(k.startswith("softrobots.parts") for k in sys.modules)


def test_units_come_from_the_body_when_gravity_is_unset_or_zero(tmp_path):
    """A 40-unit block with E = 500: 40 mm across and 500 kPa (mm-kg-s) is nearer a soft robot's 10 cm than
    40 cm is; 40 m fits no unit system of a soft robot. Unset, SOFA's default gravity is in scene units."""
    _box_file(tmp_path)
    body = _BODY.format(transform="")
    unset = _scene(tmp_path, body, gravity="None").read_text().replace("    root.gravity = None\n", "")
    (tmp_path / "unset.py").write_text(unset)
    tr = translate(tmp_path / "unset.py", out_dir=tmp_path)
    assert tr.units == "mm-kg-s" and np.allclose(tr.problem["gravity"], [0, -0.00981, 0])
    assert any(n.startswith("gravity is not set: units mm-kg-s taken from the body (a body 0.04 m across, "
                            "E = 5e+05 Pa; also fits: cm-kg-s") for n in tr.notes)
    tr = translate(_scene(tmp_path, body, gravity="[0, 0, 0]"), out_dir=tmp_path)
    assert tr.units == "mm-kg-s" and tr.problem["gravity"] == [0, 0, 0]
    huge = body.replace("youngModulus=500", "youngModulus=5e12")
    with pytest.raises(SceneError, match=r"gravity is zero, and the body's extent 40 .* fits no unit system"):
        translate(_scene(tmp_path, huge, gravity="[0, 0, 0]"), out_dir=tmp_path)


_RIGIDS = """\
from stlib3.physics.rigid import Floor, Cube, Sphere
Floor(root, name='Floor', translation=[0, 0, -5], rotation=[90, 0, 0], isAStaticObject=True)
Cube(root, name='Cube', translation=[30, 0, 20], uniformScale=5)
Cube(root, name='Block', translation=[0, 20, 20], uniformScale=3, isAStaticObject=True)
Sphere(root, name='Ball', translation=[0, -20, 20], uniformScale=3, isAStaticObject=True)
wall = root.addChild('Wall')
wall.addObject('MeshOBJLoader', name='loader', filename='wall.obj', translation=[20, 0, 0])
wall.addObject('MeshTopology', src='@loader')
wall.addObject('MechanicalObject')
wall.addObject('TriangleCollisionModel')
"""


def test_fixed_rigid_objects_become_obstacles_and_free_ones_are_listed(tmp_path):
    """stlib3's Floor (isAStaticObject) -> a plane, a flat collision surface nothing integrates -> a plane with
    its normal towards the body, a Cube with a solver -> a note; a floor that cuts the body -> a note."""
    _box_file(tmp_path)
    (tmp_path / "wall.obj").write_text("v 0 -50 -50\nv 0 50 -50\nv 0 50 50\nv 0 -50 50\nf 1 2 3\nf 1 3 4\n")
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), _RIGIDS), out_dir=tmp_path)
    floor, block, ball, wall = tr.problem["obstacles"]
    # SOFA's mesh/cube.obj spans [-1, 1]^3 and mesh/ball.obj is the unit sphere, times uniformScale
    assert block == {"name": "Block", "box": [[-0.003, 0.017, 0.017], [0.003, 0.023, 0.023]]}
    assert ball == {"name": "Ball", "sphere": {"center": [0.0, -0.02, 0.02], "radius": 0.003}}
    # Floor: +y turned 90 deg about x is +z, through (0, 0, -5) mm; the wall x = 20 mm faces the body (-x)
    assert floor == {"name": "Floor", "plane": {"point": [0, 0, -0.005], "normal": [0.0, 0.0, 1.0]}}
    assert wall["name"] == "Wall" and np.allclose(wall["plane"]["normal"], [-1, 0, 0])
    assert np.allclose(wall["plane"]["point"][0], 0.02)
    assert any(n.startswith("rigid object /Cube moves") for n in tr.notes)
    assert not any("Floor" in line or "Cube" in line or "Wall" in line for line in tr.untranslated)
    p = _load(tr, tmp_path)
    assert [o.kind for o in p.obstacles] == ["plane", "box", "sphere", "plane"]
    cut = _RIGIDS.replace("translation=[0, 0, -5]", "translation=[0, 0, 20]")
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), cut), out_dir=tmp_path)
    assert [o["name"] for o in tr.problem["obstacles"]] == ["Block", "Ball", "Wall"]
    assert "fixed object /Floor: its plane cuts the body at rest; not translated as an obstacle" in tr.notes


def test_a_cable_with_centers_spreads_its_force_over_the_surface_patch(tmp_path):
    """SOFA's CableConstraint ``centers``/``radii``/``method='sphere'`` -> a cable point with ``spread``: the
    force on the nodes sums to the tension along the cable (a closed form: nothing else acts) and falls on
    the boundary nodes within the radius, weighted (r - d)."""
    from casadi_ws.fem.contact import boundary_nodes

    _, m = _box_file(tmp_path)
    body = _BODY.format(transform="").replace(
        "cable.addObject('MechanicalObject', position=[[4, 0, 5], [4, 0, 20], [4, 0, 35]])\n", "").replace(
        "indices=[0, 1, 2], pullPoint=[4, 0, 0]", "centers=[[0, 5, 40]], radii=[6], method='sphere', "
        "pullPoint=[0, 30, 40]")
    tr = translate(_scene(tmp_path, body), out_dir=tmp_path)
    (c,) = tr.problem["cables"]
    assert c["points"] == [[0.0, 0.005, 0.04]] and c["spread"] == 0.006
    model = StaticModel(_load(tr, tmp_path))
    f = np.zeros(model.n_dof)  # 2 N of tension, at rest, on the free dofs (the support takes the rest)
    f[model.free] = model.actuation_matrix(np.zeros(model.n_dof)).T @ np.array([2.0])
    F = f.reshape(-1, 3)
    x = model.mesh.nodes
    b = boundary_nodes(model.mesh)
    d = np.linalg.norm(x[b] - [0, 0.005, 0.04], axis=1)
    near = b[d < 0.006]
    assert set(np.flatnonzero(np.abs(F).sum(1) > 1e-12)) == set(near)
    w = (0.006 - d[d < 0.006]) / (0.006 - d[d < 0.006]).sum()
    xbar = w @ x[near]
    direction = (np.array([0, 0.03, 0.04]) - xbar) / np.linalg.norm([0, 0.03, 0.04] - xbar)
    assert np.allclose(F.sum(0), 2.0 * direction, atol=1e-12)
    assert np.allclose(F[near], w[:, None] * 2.0 * direction, atol=1e-12)
    far = body.replace("centers=[[0, 5, 40]], radii=[6]", "centers=[[0, 5, 37.5]], radii=[1]")  # nodes 2.5 mm off
    with pytest.raises(SceneError, match=r"cables\[0\].spread: no boundary node of the body within 0.001 m of "
                                         r"point 0 \(the nearest is 0.0025 m away\)"):
        translate(_scene(tmp_path, far), out_dir=tmp_path)


def test_rigidify_effector_goals_and_topology_changes_are_said(tmp_path):
    _box_file(tmp_path)
    extra = """\
    from stlib3.physics.mixedmaterial import Rigidify
    Rigidify(root, body, groupIndices=[[0, 1, 2], [3, 4]])
    eff = body.addChild('effector')
    eff.addObject('MechanicalObject', position=[[0, 0, 40]])
    eff.addObject('PositionEffector', indices=[0], effectorGoal=[10, 0, 40])
    eff.addObject('BarycentricMapping')
    body.addObject('TetrahedronSetTopologyModifier')
    """
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), extra), out_dir=tmp_path)
    assert "stlib3 Rigidify makes 5 points of /body rigid in 2 group(s): not modelled, those parts stay elastic " \
           "here" in tr.notes
    assert any(n.startswith("PositionEffector 'PositionEffector' at /body/effector/PositionEffector: its "
                            "effectorGoal") for n in tr.notes)
    assert any(line.startswith("TetrahedronSetTopologyModifier: changes the topology during a simulation")
               for line in tr.untranslated)
    assert tr.problem["end_effector"]["point"] == [0.0, 0.0, 0.04]


def test_a_cavity_a_little_outside_the_body_is_embedded_as_sofa_maps_it(tmp_path):
    """A surface up to 5 % of the body's size outside it is embedded (SOFA's barycentric mapping extrapolates),
    with its embed_tolerance written and a note; further out it is refused as before."""
    _, m = _box_file(tmp_path, size=(20.0, 20.0, 40.0), div=(4, 4, 8))
    cube = box_mesh((8.0, 8.0, 8.0), (1, 1, 1), (-4.0, -4.0, 16.0))
    from casadi_ws.fem.surface import boundary_faces

    faces = boundary_faces(cube)
    for name, grow in (("near.stl", 1.0), ("far.stl", 4.0)):
        pts = cube.nodes.copy()
        pts[pts[:, 0] > 0, 0] += 6.0 + grow  # the +x face pushed past the body's side at x = 10 mm
        meshio.write(tmp_path / name, meshio.Mesh(pts, [("triangle", faces)]), binary=True)
    cavity = """\
    cav = body.addChild('cavity')
    cav.addObject('MeshSTLLoader', name='loader', filename='{}')
    cav.addObject('MeshTopology', src='@loader')
    cav.addObject('MechanicalObject')
    cav.addObject('SurfacePressureConstraint', maxPressure=10)
    cav.addObject('BarycentricMapping')
    """
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), cavity.format("near.stl")), out_dir=tmp_path)
    (c,) = tr.problem["cavities"]
    assert c["embed_tolerance"] == pytest.approx(1.05e-3, rel=1e-3)  # 1 mm out, 5 % more
    assert any("surface vertices lie up to 1 mm outside the body" in n for n in tr.notes)
    _load(tr, tmp_path)
    with pytest.raises(SceneError, match=r"cavities\[0\].surface: vertex .* lies 0.004 m from the mesh"):
        translate(_scene(tmp_path, _BODY.format(transform=""), cavity.format("far.stl")), out_dir=tmp_path)


def test_a_body_that_collides_with_itself_in_sofa_gets_self_contact_auto(tmp_path):
    _box_file(tmp_path)
    collision = """\
    collision = body.addChild('collision')
    collision.addObject('MeshTopology', src='@../loader')
    collision.addObject('MechanicalObject')
    collision.addObject('TriangleCollisionModel', name='tri', selfCollision={flag})
    collision.addObject('PointCollisionModel', selfCollision={flag})
    collision.addObject('IdentityMapping')
"""
    pipeline = """\
    root.addObject('CollisionPipeline')
    root.addObject('BruteForceBroadPhase')
    root.addObject('BVHNarrowPhase')
    root.addObject('LocalMinDistance', alarmDistance=2, contactDistance=0.5)
    root.addObject('CollisionResponse', response='FrictionContactConstraint')
"""
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), collision.format(flag=True) + pipeline),
                   out_dir=tmp_path)
    assert tr.problem["self_contact"] == "auto"
    assert not any("Collision" in line or "LocalMinDistance" in line for line in tr.untranslated)
    assert any("-> self_contact: auto" in n for n in tr.notes)
    assert _load(tr, tmp_path).self_contact_auto is not None
    # selfCollision off: SOFA lets the body pass through itself, and so does the problem, with a note saying how
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), collision.format(flag=False) + pipeline),
                   out_dir=tmp_path)
    assert "self_contact" not in tr.problem
    assert any("selfCollision off" in n and "self_contact: auto" in n for n in tr.notes)
    # no pipeline: SOFA detects nothing
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), collision.format(flag=True)), out_dir=tmp_path)
    assert "self_contact" not in tr.problem and any("no collision pipeline" in n for n in tr.notes)
    # two collision surfaces of one body in different groups collide in SOFA (the Trunk tutorial's selfCollision)
    parts = "".join(f"""\
    part{i} = body.addChild('part{i}')
    part{i}.addObject('MeshTopology', src='@../loader')
    part{i}.addObject('MechanicalObject')
    part{i}.addObject('TriangleCollisionModel', group={group})
    part{i}.addObject('BarycentricMapping')
""" for i, group in enumerate((0, 1)))
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), parts + pipeline), out_dir=tmp_path)
    assert tr.problem["self_contact"] == "auto"
    tr = translate(_scene(tmp_path, _BODY.format(transform=""), parts.replace("group=1", "group=0") + pipeline),
                   out_dir=tmp_path)
    assert "self_contact" not in tr.problem
