"""Problem files and the command line."""

import json
import subprocess
import sys

import numpy as np
import pytest
import yaml
from conftest import REPO

from casadi_ws import ProblemError, default_problem, load_problem, problem_from_dict
from casadi_ws.io.problem import DEFAULT_PROBLEM

PROBLEMS = sorted((REPO / "problems").glob("trunk_*cables.yaml"))


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "casadi_ws.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=REPO)


def test_shipped_problems_follow_the_paper():
    bounds = {2: [100, 100], 3: [100, 100, 150], 4: [100, 100, 150, 150]}
    assert len(PROBLEMS) == 3
    for path in PROBLEMS:
        pb = load_problem(path)
        assert pb.material.young_modulus == 1.8e7 and pb.material.poisson_ratio == 0.45
        np.testing.assert_array_equal(pb.u_max, bounds[pb.n_u])
        np.testing.assert_array_equal(pb.u_min, 0)


def test_builtin_default_is_the_shipped_two_cable_file():
    a, b = default_problem(), load_problem(REPO / "problems" / "trunk_2cables.yaml")
    np.testing.assert_array_equal(a.mesh.nodes, b.mesh.nodes)
    np.testing.assert_array_equal(a.fixed_nodes, b.fixed_nodes)
    np.testing.assert_array_equal(a.end_effector, b.end_effector)
    np.testing.assert_array_equal(a.gravity, b.gravity)
    assert a.material == b.material
    for ca, cb in zip(a.cables, b.cables):
        np.testing.assert_array_equal(ca.points, cb.points)
        assert (ca.u_min, ca.u_max) == (cb.u_min, cb.u_max)


@pytest.mark.parametrize("path", PROBLEMS, ids=lambda p: p.stem)
def test_cli_equilibrium_on_every_shipped_problem(path):
    n_u = load_problem(path).n_u
    r = run_cli("equilibrium", path, "--u", ",".join(["30"] * n_u))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["converged"] is True and len(out["tip"]) == 3
    assert out["residual"] < 1e-8 and out["iterations"] >= 1
    assert 0.15 < out["tip"][2] < 0.2  # metres


def _bad(tmp_path, mutate):
    d = yaml.safe_load(yaml.safe_dump(DEFAULT_PROBLEM))
    mutate(d)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


@pytest.mark.parametrize("mutate,fragment", [
    (lambda d: d["material"].update(poisson_ratio=0.5), "material.poisson_ratio: must be < 0.5"),
    (lambda d: d["material"].update(young_modulus=-1), "material.young_modulus: must be > 0"),
    (lambda d: d["material"].update(modle="linear"), "material.modle: unknown key (did you mean 'model'?)"),
    (lambda d: d["cables"][0].update(u_min=50, u_max=10), "cables[0].u_min: lower bound 50"),
    (lambda d: d.update(fixed={"box": [[1, 1, 1], [2, 2, 2]]}), "fixed.box: selects no node"),
    (lambda d: d["cables"].append({"points": [[0.001, 0, 0.1]]}), "cables[2].points: a cable needs at least two"),
    (lambda d: d["cables"].append({"points": [[0.001, 0, 0.1], [0.5, 0, 0.1]]}), "cables[2].points[1]: point"),
    (lambda d: d.update(end_effector=[0.1, 0.1, 0.1]), "end_effector: point"),
    (lambda d: d.update(gravity=[0, float("nan"), 0]), "gravity[1]: expected a finite number"),
    (lambda d: d.update(mesh={"file": "nowhere.vtk"}), "mesh.file: "),
])
def test_bad_problem_gives_one_line_error_and_exit_code_2(tmp_path, mutate, fragment):
    p = _bad(tmp_path, mutate)
    with pytest.raises(ProblemError) as exc:
        load_problem(p)
    assert fragment in str(exc.value) and str(p) in str(exc.value)
    r = run_cli("equilibrium", p, "--u", "1,2")
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and fragment in r.stderr and "Traceback" not in r.stderr


def test_malformed_yaml_and_wrong_u(tmp_path):
    p = tmp_path / "broken.yaml"
    p.write_text("mesh: [unclosed\n")
    r = run_cli("equilibrium", p, "--u", "1")
    assert r.returncode == 2 and "malformed YAML: line" in r.stderr
    r = run_cli("equilibrium", REPO / "problems" / "trunk_2cables.yaml", "--u", "1,2,3")
    assert r.returncode == 2 and "has 2 actuator(s), got 3" in r.stderr
    r = run_cli("solve", REPO / "problems" / "trunk_2cables.yaml", "--shapes", "-1", "--out", p.parent / "x")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "--shapes: expected an integer >= 0" in r.stderr


def test_numbers_written_without_exponent_sign_are_accepted():
    d = yaml.safe_load(yaml.safe_dump(DEFAULT_PROBLEM))
    d["material"]["young_modulus"] = "2e6"  # how PyYAML reads `young_modulus: 2e6`
    assert problem_from_dict(d).material.young_modulus == 2e6


def test_version_is_the_packages_and_help_names_each_inputs_unit():
    import tomllib

    from casadi_ws import __version__

    with open(REPO / "pyproject.toml", "rb") as f:
        assert tomllib.load(f)["project"]["version"] == __version__
    r = run_cli("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"casadi-ws {__version__}"
    r = run_cli("equilibrium", "--help")
    assert all(w in " ".join(r.stdout.split()) for w in ("tension in N", "shortening in m", "pressure in Pa"))


def test_the_demo_reports_measures_and_boundary_and_its_result_takes_the_boundary_command(tmp_path):
    r = run_cli("demo", "--nd", "3", "--out", tmp_path / "demo")
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "demo" / "summary.json").read_text())
    assert s["measures"]["area"] > 0 and s["measures"]["volume"] is None  # two inputs: a surface
    assert s["boundary"]["method"] == "input-patch"
    r = run_cli("boundary", tmp_path / "demo", "--n", "3")  # the built-in problem is found again
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["area"] > 0
