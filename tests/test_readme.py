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
    try:
        for cmd in cmds:
            args = shlex.split(cmd.replace("results/", f"{tmp_path}/results/"))[1:]
            r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", *args], capture_output=True, text=True,
                               cwd=REPO)
            assert r.returncode == 0, f"{cmd}\n{r.stderr[-2000:]}"
    finally:
        for d in daemons:
            d.terminate()
        for d in daemons:
            d.wait(timeout=30)
    assert (tmp_path / "results" / "fb-dask" / "cells.vtu").is_file()
    assert (tmp_path / "results" / "fb" / "cells.vtu").is_file()
    assert (tmp_path / "results" / "compare.png").is_file()
    assert (tmp_path / "results" / "path" / "follow.csv").is_file()
