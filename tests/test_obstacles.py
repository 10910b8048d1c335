"""Obstacles in the problem file: their shapes' signed distances against closed forms, the validation of
their input. Contact with them: tests/test_contact.py."""

import meshio
import numpy as np
import pytest

from casadi_ws import ProblemError, problem_from_dict
from casadi_ws.fem.contact import Obstacle


def test_signed_distances_of_every_shape_against_closed_forms(tmp_path):
    x = np.array([[0.0, 0.0, 2.0], [0.0, 0.0, 0.5], [3.0, 4.0, 0.0]])
    plane = Obstacle("plane", "p", {"point": np.zeros(3), "normal": np.array([0.0, 0.0, 1.0])})
    assert np.allclose(plane.distance(x), [2.0, 0.5, 0.0])
    sphere = Obstacle("sphere", "s", {"center": np.zeros(3), "radius": 1.0})
    assert np.allclose(sphere.distance(x), [1.0, -0.5, 4.0])
    box = Obstacle("box", "b", {"lower": -np.ones(3), "upper": np.ones(3)})
    assert np.allclose(box.distance(x), [1.0, -0.5, np.hypot(2.0, 3.0)])
    cyl = Obstacle("cylinder", "c", {"a": np.array([0, 0, -1.0]), "b": np.array([0, 0, 1.0]), "radius": 1.0})
    assert np.allclose(cyl.distance(x), [1.0, -0.5, 4.0])
    # a closed surface: the same unit box as triangles; VTK's distance to it, sign inside negative
    import pyvista as pv

    cube = pv.Cube(x_length=2, y_length=2, z_length=2).triangulate()
    tris = cube.faces.reshape(-1, 4)[:, 1:]
    surf = Obstacle("surface", "f", {"vertices": np.asarray(cube.points), "triangles": tris})
    assert np.allclose(surf.distance(x), [1.0, -0.5, np.hypot(2.0, 3.0)], atol=1e-9)


BASE = {"mesh": {"generate": "box", "size": [0.01, 0.01, 0.06], "divisions": [2, 2, 6], "origin": [-0.005, -0.005, 0]},
        "material": {"young_modulus": 1e6, "poisson_ratio": 0.3}, "fixed": {"box": [-1, -1, -1, 1, 1, 0.0001]},
        "cables": [{"points": [[0.004, 0, 0.01], [0.004, 0, 0.06]], "pull_point": [0.004, 0, 0], "u_max": 5}]}


def test_obstacles_are_read_and_described(tmp_path):
    import pyvista as pv

    pv.Sphere(radius=0.01, center=(0.05, 0, 0.03)).save(tmp_path / "ball.stl")
    p = problem_from_dict({**BASE, "obstacles": [
        {"name": "table", "plane": {"point": [0, -0.02, 0], "normal": [0, 1, 0]}},
        {"box": [[0.02, -0.01, 0], [0.03, 0.01, 0.01]]},
        {"sphere": {"center": [-0.03, 0, 0.03], "radius": 0.01}},
        {"cylinder": {"a": [0, 0.03, 0], "b": [0, 0.03, 0.06], "radius": 0.005}},
        {"name": "ball", "surface": {"file": "ball.stl"}}]}, "p.yaml", tmp_path)
    assert [o.kind for o in p.obstacles] == ["plane", "box", "sphere", "cylinder", "surface"]
    assert p.obstacles[0].name == "table" and p.obstacles[1].name == "obstacle2"
    assert p.obstacles[4].distance(np.array([[0.05, 0, 0.03]]))[0] == pytest.approx(-0.01, rel=0.01)


@pytest.mark.parametrize("obstacle, message", [
    ({"plane": {"point": [0, 0, 0], "normal": [0, 0, 0]}}, "obstacles[0].plane.normal: must not be the zero vector"),
    ({"sphere": {"center": [0, 0, 0.03], "radius": 0.001}}, "obstacles[0]: obstacle 'obstacle1' lies inside the body at rest"),
    ({"sphere": {"center": [0, 0, 0.07], "radius": 0.0101}}, "obstacles[0]: obstacle 'obstacle1' holds part of the body at rest"),
    ({"box": [[0, 0, 0], [1, 1, 0]]}, "obstacles[0].box: the box is flat"),
    ({"cylinder": {"a": [0, 0, 0], "b": [0, 0, 0], "radius": 1}}, "obstacles[0].cylinder: its end points a and b coincide"),
    ({"plane": {"point": [0, 0, 0], "normal": [0, 0, 1]}, "sphere": {"center": [0, 0, 0], "radius": 1}},
     "obstacles[0]: expected exactly one shape"),
    ({"surface": {"file": "open.stl"}}, "not a closed, consistently oriented triangle surface"),
    ({"pillar": {}}, "obstacles[0].pillar: unknown key"),
])
def test_bad_obstacles_are_one_line(tmp_path, obstacle, message):
    meshio.write(tmp_path / "open.stl", meshio.Mesh(np.eye(3), [("triangle", np.array([[0, 1, 2]]))]), binary=True)
    with pytest.raises(ProblemError) as exc:
        problem_from_dict({**BASE, "obstacles": [obstacle]}, "p.yaml", tmp_path)
    assert message in str(exc.value) and "\n" not in str(exc.value)


def test_a_problem_with_a_surface_obstacle_still_pickles_once_its_model_is_built():
    """Forward-backward on worker processes pickles the problem (and fingerprints it) after the model is built;
    the finger under the egg failed there with "cannot pickle 'AABB' object" (libigl's tree, a cache)."""
    import pickle

    from casadi_ws import StaticModel, load_problem
    from casadi_ws.runtime.run_state import problem_fingerprint

    from conftest import REPO

    problem = load_problem(REPO / "problems" / "finger_object.yaml")
    before = problem_fingerprint(problem)
    model = StaticModel(problem)
    model.residual(np.zeros(model.n_dof), np.zeros(model.n_u))  # builds the egg's trees
    assert problem_fingerprint(problem) == before
    again = pickle.loads(pickle.dumps(problem))
    x = np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5]])
    np.testing.assert_array_equal(again.obstacles[0].gap(x)[0], problem.obstacles[0].gap(x)[0])
