"""scripts/reproduce_paper.py --quick runs end to end, so the reproduction script cannot rot."""

import csv
import json
import subprocess
import sys

import pytest
from conftest import REPO


@pytest.mark.slow
def test_reproduce_paper_quick(tmp_path):
    r = subprocess.run([sys.executable, str(REPO / "scripts" / "reproduce_paper.py"), "--quick", "--out",
                        str(tmp_path), "--workers", "1"], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr[-2000:]
    for f in ("table1.md", "table1.csv", "fig14_operations.png", "fig14_time.png", "report.md",
              "three_views_2cables.png", "three_views_3cables.png", "three_views_4cables.png"):
        assert (tmp_path / f).is_file(), f
    rows = list(csv.reader((tmp_path / "table1.csv").open()))
    assert len(rows) == 4 and rows[0][1] == "n_u"
    report = (tmp_path / "report.md").read_text()
    assert "Claims, tested by the data" in report and "coverage" in report
    # every claim of the report must hold on the data, and the report must say what the data say
    claims = json.loads((tmp_path / "claims.json").read_text())
    assert len(claims) == 5
    for c in claims:
        assert c["holds"], c["text"]
        assert c["text"] in report and "does NOT hold" not in c["text"]
