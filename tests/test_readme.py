"""The README's commands run as written (only the output directories moved to a temporary folder)."""

import re
import shlex
import subprocess
import sys

import pytest
from conftest import REPO


def readme_commands() -> list[str]:
    text = (REPO / "README.md").read_text()
    cmds = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            line = line.split(" #")[0].strip()
            if line.startswith(".venv/bin/casadi-ws "):
                cmds.append(line)
    return cmds


@pytest.mark.slow
def test_every_casadi_ws_command_of_the_readme_runs(tmp_path):
    cmds = readme_commands()
    assert len(cmds) >= 7  # equilibrium, solve forward, solve fb, compare, reach x2, follow
    for cmd in cmds:
        args = shlex.split(cmd.replace("results/", f"{tmp_path}/results/"))[1:]
        r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", *args], capture_output=True, text=True, cwd=REPO)
        assert r.returncode == 0, f"{cmd}\n{r.stderr[-2000:]}"
    assert (tmp_path / "results" / "fb" / "cells.vtu").is_file()
    assert (tmp_path / "results" / "compare.png").is_file()
    assert (tmp_path / "results" / "path" / "follow.csv").is_file()
