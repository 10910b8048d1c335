"""The README's commands run as written (only the output directories moved to a temporary folder)."""

import re
import shlex
import subprocess
import sys

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


@pytest.mark.slow
def test_every_casadi_ws_command_of_the_readme_runs(tmp_path):
    cmds = readme_commands()
    assert len(cmds) >= 7  # equilibrium, solve forward, solve fb, compare, reach x2, follow
    # the Dask recipe's scheduler and workers, started as written (in the background, as the '&' says)
    daemons = [subprocess.Popen(shlex.split(c.rstrip("&").strip()), cwd=REPO, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL) for c in readme_commands(".venv/bin/dask ")]
    assert len(daemons) == 2
    outputs = {}
    try:
        for cmd in cmds:
            args = shlex.split(cmd.replace("results/", f"{tmp_path}/results/"))[1:]
            r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", *args], capture_output=True, text=True,
                               cwd=REPO)
            assert r.returncode == 0, f"{cmd}\n{r.stderr[-2000:]}"
            outputs[cmd] = (args, r.stdout)
    finally:
        for d in daemons:
            d.terminate()
        for d in daemons:
            d.wait(timeout=30)
    assert (tmp_path / "results" / "fb-dask" / "cells.vtu").is_file()
    assert (tmp_path / "results" / "fb" / "cells.vtu").is_file()
    assert (tmp_path / "results" / "compare.png").is_file()
    assert (tmp_path / "results" / "path" / "follow.csv").is_file()

    _check_outputs(outputs, tmp_path)


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

    checked = set()
    for cmd, (args, stdout) in outputs.items():
        kind, path = args[0], args[1]
        if kind == "equilibrium":
            out = json.loads(stdout)
            assert out["converged"] and out["admissible"] and out["stable"] and out["violations"] == []
            np.testing.assert_allclose(out["tip"], tip_at(path, out["u"]), atol=1e-9)
        elif kind == "reach":
            out = json.loads(stdout)
            target = np.array(args[args.index("--target") + 1].split(","), float)
            np.testing.assert_allclose(out["tip"], tip_at(path, out["u"]), atol=1e-8)
            assert abs(np.linalg.norm(np.array(out["tip"]) - target) - out["error"]) < 1e-12
        elif kind == "follow":
            rows = np.loadtxt(args[args.index("--out") + 1] + "/follow.csv", delimiter=",", skiprows=1, ndmin=2)
            for row in rows[::4]:
                np.testing.assert_allclose(row[3:6], tip_at(path, row[8:]), atol=1e-8)
        elif kind == "solve":
            res = cw.load_result(args[args.index("--out") + 1])
            assert res.n_points > 0 and res.admissible.all()
            for k in np.linspace(0, res.n_points - 1, 5).astype(int):
                np.testing.assert_allclose(res.points[k], tip_at(path, res.u[k]), atol=1e-7)
            if "cells" in res.arrays:  # every reported tip lies in its reported cell
                step, origin = float(res.arrays["cell_step"]), res.arrays["grid_origin"]
                np.testing.assert_array_equal(np.round((res.points - origin) / step), res.arrays["cells"])
        else:
            continue
        checked.add(kind)
    assert checked == {"equilibrium", "reach", "follow", "solve"}
