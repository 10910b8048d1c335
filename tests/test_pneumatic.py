"""The shipped pneumatic robot (problems/pneunet_finger.yaml): both methods find the same workspace.

Its forward-backward run is the README's command, run as written here rather than in test_readme (which
leaves it to this test, test_readme.RUN_ELSEWHERE)."""

import numpy as np
import pytest
from conftest import REPO

from casadi_ws import ForwardSettings, StaticModel, compare, forward, load_problem, load_result


@pytest.mark.slow
def test_finger_forward_backward_finds_every_cell_the_forward_cloud_occupies(tmp_path):
    """The README's command for the finger, run as written (test_readme leaves it to this test), then its
    FB workspace against a forward cloud."""
    from test_readme import command_chains, run_chain

    chain, = command_chains(elsewhere=True)
    assert "pneunet_finger.yaml" in chain[0] and "--workers 2" in chain[0]
    outputs = run_chain(chain, tmp_path)
    args, _ = outputs[chain[0]]
    fb = load_result(args[args.index("--out") + 1])
    assert fb.settings["step"] == 5e-4
    pb = load_problem(REPO / "problems" / "pneunet_finger.yaml")
    assert [(a.kind, a.name) for a in pb.actuators] == [("cavity", "left"), ("cavity", "right")]
    m = StaticModel(pb)
    # n_d = 15 as in BENCHMARKS.md ("pneumatic"). The workspace is a thin sheet lying along a grid plane
    # (x ~ 60.5 mm): with n_d = 10 two cloud points fall 0.003 cell inside a cell whose reachable part is
    # that sliver, and FB reports the neighbour instead (recall 44/45)
    fw = forward(pb, settings=ForwardSettings(n_d=15, progress=False, workers=2), model=m)
    assert fw.n_failed == 0
    c = compare(fw, fb)
    assert c["cells_a_in_b"] >= 0.98, c  # strict recall on FB's grid
    # the tip bends down (-z) by more than a centimetre and the rows steer it sideways (y)
    assert fw.points[:, 2].min() < m.p0[2] - 0.01
    assert np.ptp(fw.points[:, 1]) > 5e-4
