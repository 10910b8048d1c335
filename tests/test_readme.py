"""The README's commands run as written (only the output directories moved to a temporary folder).

The commands are split into chains: a command that reads what an earlier one wrote (``compare results/fw
results/fb``) runs after it in the same test, and independent chains are separate tests, so that ``make
test``'s workers share them out. The Dask recipe's scheduler and workers (port 8786, as written) are
started once per test process, for the chains that name the scheduler; those chains form one xdist group.
"""

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO


def readme_commands(prefix: str = ".venv/bin/casadi-ws ") -> list[str]:
    text = (REPO / "README.md").read_text()
    cmds = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            line = line.split(" #")[0].strip()
            if line.startswith(prefix):
                cmds.append(line)
    return cmds


def _paths(cmd: str) -> tuple[set, set]:
    """(results paths the command writes, results paths it reads)."""
    args = shlex.split(cmd)
    writes = {args[i + 1] for i, a in enumerate(args[:-1]) if a in ("--out", "--plot")}
    reads = {a for a in args if a.startswith("results/") and a not in writes}
    return writes, reads


RUN_ELSEWHERE = {"pneunet_finger.yaml": "test_pneumatic.py"}
"""Commands that another test runs as written and checks more closely (it compares the finger's FB with a
forward cloud): running them here too would solve the same workspace twice in `make test`."""


def command_chains(elsewhere: bool = False) -> list[list[str]]:
    """The README's commands grouped so that a command runs after those whose results it reads; those of
    :data:`RUN_ELSEWHERE` left out (or only those, with ``elsewhere``)."""
    cmds = [c for c in readme_commands() if any(k in c for k in RUN_ELSEWHERE) == elsewhere and not _is_certs(c)]
    chain = list(range(len(cmds)))  # union-find over command indices

    def root(i):
        while chain[i] != i:
            i = chain[i]
        return i

    written = {}
    for i, cmd in enumerate(cmds):
        writes, reads = _paths(cmd)
        for path in reads:
            for w, j in written.items():
                if path == w or path.startswith(w + "/"):
                    chain[root(i)] = root(j)
        for w in writes:
            written[w] = i
    groups: dict[int, list[str]] = {}
    for i, cmd in enumerate(cmds):
        groups.setdefault(root(i), []).append(cmd)
    return list(groups.values())


def _chain_id(chain: list[str]) -> str:
    args = shlex.split(chain[0])
    return f"{args[1]}-{args[2].rsplit('/', 1)[-1]}-{'-'.join(a.lstrip('-') for a in args[3:5])}"


def _needs_scheduler(chain: list[str]) -> bool:
    return any("--scheduler" in c for c in chain)


def _is_certs(cmd: str) -> bool:
    """The Dask recipe's credentials command: run with the scheduler and workers (:func:`dask_daemons`), once."""
    return shlex.split(cmd)[1] == "cluster-certs"


def _tls(cmd: str, folder) -> str:
    """The command with the recipe's credentials folder ``tls`` (after --out or --tls, or before a '/') moved to
    ``folder``."""
    cmd = re.sub(r"(?<=--out )tls(?=\s|$)|(?<=--tls )tls(?=\s|$)", str(folder), cmd)
    return re.sub(r"(?<![\w/.:-])tls/", f"{folder}/", cmd)


@pytest.fixture(scope="module")
def dask_daemons(tmp_path_factory):
    """The Dask recipe as written: its credentials (in a temporary folder), then its scheduler and workers (in
    the background, as the '&' says). Yields the credentials folder."""
    folder = tmp_path_factory.mktemp("dask") / "tls"
    (certs,) = [c for c in readme_commands() if _is_certs(c)]
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", *shlex.split(_tls(certs, folder))[1:]], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 0 and (folder / "cluster-key.pem").stat().st_mode & 0o077 == 0, r.stderr
    daemons = [subprocess.Popen(shlex.split(_tls(c, folder).rstrip("&").strip()), cwd=REPO, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL) for c in readme_commands(".venv/bin/dask ")]
    assert len(daemons) == 2
    yield folder
    for d in daemons:
        d.terminate()
    for d in daemons:
        d.wait(timeout=30)


def test_the_readme_shows_every_kind_of_command_and_a_test_runs_each():
    kinds = {shlex.split(c)[1] for c in readme_commands()}
    assert {"equilibrium", "solve", "compare", "report", "boundary", "reach", "follow", "study",
            "import-sofa"} <= kinds
    assert sum(len(c) for c in command_chains() + command_chains(elsewhere=True)) + sum(
        map(_is_certs, readme_commands())) == len(readme_commands())
    for key, module in RUN_ELSEWHERE.items():  # the other test finds its command in the README and runs it
        text = (REPO / "tests" / module).read_text()
        assert "run_chain(" in text and key in text, module


@pytest.mark.slow
@pytest.mark.parametrize("chain", [pytest.param(c, id=_chain_id(c),
                                                marks=[pytest.mark.xdist_group("dask")] if _needs_scheduler(c) else [])
                                   for c in command_chains()])
def test_every_casadi_ws_command_of_the_readme_runs(chain, tmp_path, request):
    if _needs_scheduler(chain):
        folder = request.getfixturevalue("dask_daemons")
        chain = [_tls(c, folder) for c in chain]
    run_chain(chain, tmp_path)


def run_chain(chain: list[str], tmp_path) -> dict:
    """Run the commands as written (outputs under tmp_path) and check what they printed and wrote."""
    outputs = {}
    for cmd in chain:
        args = shlex.split(cmd.replace("results/", f"{tmp_path}/results/"))[1:]
        r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", *args], capture_output=True, text=True,
                           cwd=REPO)
        assert r.returncode == 0, f"{cmd}\n{r.stderr[-2000:]}"
        outputs[cmd] = (args, r.stdout)
        for i, a in enumerate(args[:-1]):  # what --out / --plot names is there
            if a in ("--out", "--plot"):
                assert Path(args[i + 1]).exists(), f"{cmd}: wrote no {args[i + 1]}"
    _check_outputs(outputs, tmp_path)
    return outputs


def _check_outputs(outputs, tmp_path):
    """What the commands printed and wrote, against equilibria solved here, independently of the command."""
    import json

    import numpy as np

    import casadi_ws as cw
    from casadi_ws.solvers.equilibrium import solve_equilibrium

    models = {}

    def model(path):
        if path not in models:
            models[path] = cw.StaticModel(cw.load_problem(REPO / path))
        return models[path]

    def tip_at(path, u):
        eq = solve_equilibrium(model(path), np.asarray(u, float))
        assert eq.converged
        return eq.tip

    for cmd, (args, stdout) in outputs.items():
        kind, path = args[0], args[1]
        if kind == "equilibrium":
            out = json.loads(stdout)
            assert out["converged"] and out["admissible"] and out["stable"] and out["violations"] == []
            np.testing.assert_allclose(out["tip"], tip_at(path, out["u"]), atol=1e-9)
            eq = solve_equilibrium(model(path), np.asarray(out["u"], float))
            assert out["orientation"]["tilt"] == pytest.approx(model(path).tip_frame.orientation(eq.q)["tilt"], abs=1e-6)
        elif kind == "reach":
            out = json.loads(stdout)
            target = np.array(args[args.index("--target") + 1].split(","), float)
            np.testing.assert_allclose(out["tip"], tip_at(path, out["u"]), atol=1e-8)
            assert abs(np.linalg.norm(np.array(out["tip"]) - target) - out["error"]) < 1e-12
        elif kind == "follow":
            rows = np.loadtxt(args[args.index("--out") + 1] + "/follow.csv", delimiter=",", skiprows=1, ndmin=2)
            for row in rows[::4]:
                np.testing.assert_allclose(row[3:6], tip_at(path, row[8:-5]), atol=1e-8)  # (then tilt, roll, axis)
        elif kind == "solve":
            res = cw.load_result(args[args.index("--out") + 1])
            assert res.n_points > 0 and res.admissible.all()
            for k in np.linspace(0, res.n_points - 1, 5).astype(int):
                np.testing.assert_allclose(res.points[k], tip_at(path, res.u[k]), atol=1e-7)
            if "--orientation" in args:  # every cell's range solved, its ends verified equilibria in the cell
                o = res.measures["orientation"]
                assert o["solved"] == o["cells"] == res.n_points and 0 < res.measures["dexterous"]["cells"] < o["cells"]
                assert Path(args[args.index("--out") + 1], "dexterous.vtu").exists()
                k = int(np.nanargmax(res.maps()["tilt_max"]))
                i = [tuple(c) for c in res.arrays["orientation_cells"].tolist()].index(
                    tuple(np.round((res.points[k] - res.arrays["grid_origin"]) / res.arrays["cell_step"]).astype(int)))
                tip = tip_at(path, res.arrays["orientation_u_at_max"][i])
                centre = res.arrays["grid_origin"] + res.arrays["orientation_cells"][i] * res.arrays["cell_step"]
                assert np.all(np.abs(tip - centre) <= res.arrays["cell_step"] * (0.5 + 1e-9))
                _forward_points_in_their_ranges(model(path), res)
            if "cells" in res.arrays:  # every reported tip lies in its reported cell
                step, origin = float(res.arrays["cell_step"]), res.arrays["grid_origin"]
                np.testing.assert_array_equal(np.round((res.points - origin) / step), res.arrays["cells"])


def _forward_points_in_their_ranges(m, res):
    """Issue 72's check: 20 random points of an n_d = 8 grid of U, each solved from rest (the contact-free trunk
    has one equilibrium per input: tests/test_branch.py), have their tilt from the reference within their cell's
    range, up to the cell's variation."""
    import numpy as np

    from casadi_ws.solvers.equilibrium import solve_equilibrium

    a = res.arrays
    ref, step, origin = a["orientation_reference"], float(a["cell_step"]), a["grid_origin"]
    index = {tuple(c): i for i, c in enumerate(a["orientation_cells"].tolist())}
    rng = np.random.default_rng(0)
    inside = found = 0
    for _ in range(20):
        u = m.u_min + rng.integers(0, 8, m.n_u) / 7 * (m.u_max - m.u_min)
        eq = solve_equilibrium(m, u)
        i = index.get(tuple(np.round((eq.tip - origin) / step).astype(int).tolist()))
        if not eq.converged or i is None:
            continue
        found += 1
        tilt = np.degrees(np.arccos(np.clip(m.tip_frame.axis(eq.q) @ ref, -1, 1)))
        lo, hi, var = a["orientation_tilt_min"][i], a["orientation_tilt_max"][i], a["orientation_variation"][i]
        assert lo - var <= tilt <= hi + var, (u, tilt, lo, hi, var)
        inside += bool(lo - 0.01 <= tilt <= hi + 0.01)
    assert found >= 18 and inside >= 0.9 * found  # (forward-backward's cells miss a few of the grid's tips)


def test_the_readme_python_script_runs_as_written(tmp_path):
    """The README's ```python block, saved as a script and run from a folder with the problems (the results
    it saves land there)."""
    block, = re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(), flags=re.S)
    (tmp_path / "problems").symlink_to(REPO / "problems")
    (tmp_path / "script.py").write_text(block)
    r = subprocess.run([sys.executable, "script.py"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "coverage" in r.stdout and (tmp_path / "results" / "fb" / "summary.json").exists()
    s = json.loads((tmp_path / "results" / "fb" / "summary.json").read_text())
    assert s["measures"]["cells"] > 0 and s["boundary"] is not None  # the API's one call measures the result
    assert (tmp_path / "results" / "fb" / "report.html").exists()


def test_the_readmes_counts_of_bad_input_files_are_the_corpus():
    import re

    text = " ".join((REPO / "README.md").read_text().split())
    m = re.search(r"`tests/bad_inputs/` holds (\d+) such problem files and `tests/bad_inputs/studies/` (\d+) study", text)
    assert m, "the README's sentence on the bad-input corpus moved: update this test"
    assert int(m.group(1)) == len(list((REPO / "tests" / "bad_inputs").glob("*.yaml")))
    assert int(m.group(2)) == len(list((REPO / "tests" / "bad_inputs" / "studies").glob("*.yaml")))


def test_benchmarks_md_is_made_from_the_history():
    """BENCHMARKS.md is scripts/benchmarks_md.py's page of benchmarks/history.jsonl, so the figures it shows
    are the recorded runs', and every benchmark's latest run has a headline figure, a machine and a date."""
    sys.path.insert(0, str(REPO / "scripts"))
    import benchmarks_md

    rows = benchmarks_md.read()
    assert (REPO / "BENCHMARKS.md").read_text() == benchmarks_md.page(rows), \
        "BENCHMARKS.md differs from the history: run python scripts/benchmarks_md.py"
    assert (REPO / "benchmarks" / "latest.md").read_text() == benchmarks_md.sections(rows), \
        "benchmarks/latest.md differs from the history: run python scripts/benchmarks_md.py"
    assert len((REPO / "BENCHMARKS.md").read_text().splitlines()) < 300
    for r in benchmarks_md.latest(rows):
        assert r["figure"] and r["machine"] and re.fullmatch(r"20\d\d-\d\d-\d\d", r["date"]), r["key"]


def test_the_readmes_number_of_drawn_robots_is_the_reports():
    from casadi_ws.io.report import MAX_SHAPES

    text = " ".join((REPO / "README.md").read_text().split())
    assert f"the page holds the shapes of up to {MAX_SHAPES} points" in text


def test_the_readmes_dexterous_numbers_are_the_benchmarks():
    import json

    b = json.loads((REPO / "benchmarks" / "orientation.json").read_text())
    text = " ".join((REPO / "README.md").read_text().split())
    d, c = b["dexterous"], b["check"]
    assert (f"At {1e3 * b['step_m']:g} mm: {b['cells']} cells, {d['cells']} of them ({1e6 * d['cell_volume']:.1f} cm³ "
            f"of cells) where the tip can point within {b['cone_deg']:g}° of +z; the ranges took "
            f"{b['orientation_s']:.0f} s after the {b['fb_s']:.0f} s of forward-backward, and "
            f"{c['inside_range']} of {c['points']} points") in text
