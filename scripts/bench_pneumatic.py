"""The shipped pneumatic finger (problems/pneunet_finger.yaml): an equilibrium, and its workspace by both
methods with 2 worker processes, compared strictly.

    python scripts/bench_pneumatic.py [--nd 15] [--write] [--pictures]

Records in BENCHMARKS.md ("pneumatic"): equilibrium from rest at both pressures' upper bounds and a
warm-started 2 kPa step, forward (n_d^2 points) and forward-backward times, cells, strict recall.
``--pictures`` also writes docs/img/pneunet_finger_three_views.png (forward vs forward-backward).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import casadi_ws as cw

ROOT = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nd", type=int, default=15)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--pictures", action="store_true")
    args = ap.parse_args()
    pb = cw.load_problem(ROOT / "problems" / "pneunet_finger.yaml")
    t = time.perf_counter()
    m = cw.StaticModel(pb)
    build = time.perf_counter() - t
    t = time.perf_counter()
    top = cw.solve_equilibrium(m, m.u_max)
    cold = time.perf_counter() - t
    mid = cw.solve_equilibrium(m, 0.5 * m.u_max)
    t = time.perf_counter()
    step = cw.solve_equilibrium(m, mid.u + 2e3, q0=mid.q, u0=mid.u)
    warm = time.perf_counter() - t
    assert top.converged and step.converged
    fw = cw.forward(pb, settings=cw.ForwardSettings(n_d=args.nd, progress=False, workers=2), model=m)
    fb = cw.forward_backward(pb, cw.FBSettings(step=pb.workspace["step"], progress=False, workers=2), model=m)
    c = cw.compare(fw, fb)
    rows = {"free dofs": m.n_free, "model build (s)": build,
            "equilibrium from rest at u_max, both 40 kPa (s)": cold,
            "continuation steps there": top.load_steps, "equilibrium, warm 2 kPa step (s)": warm,
            "tip at u_max, rest (mm)": f"{np.round(1e3 * top.tip, 2).tolist()}, {np.round(1e3 * m.p0, 2).tolist()}",
            f"forward, n_d = {args.nd} ({fw.n_points} points) (s)": fw.timings["total"],
            f"forward-backward, step {1e3 * pb.workspace['step']:g} mm (s)": fb.timings["total"],
            "forward-occupied cells / FB cells": f"{c['cells_a']} / {c['cells_b']}",
            "strict recall (cells_a_in_b)": c["cells_a_in_b"],
            "forward points in FB cells": c["points_a_in_b_cells"],
            "FB LU factorisations per reached cell": fb.counters.get("factorizations_per_cell")}
    for k, v in rows.items():
        print(f"{k}: {v}")
    if args.pictures:
        from casadi_ws.io.plots import three_views, workspace_3d

        three_views([fw, fb], ROOT / "docs" / "img" / "pneunet_finger_three_views.png",
                    title="PneuNets finger: forward (blue) vs forward-backward (gray cells, red points)")
        workspace_3d(fb, ROOT / "docs" / "img" / "pneunet_finger_3d.png", pb.mesh,
                     title="PneuNets finger: forward-backward workspace")
    if args.write:
        from benchlib import machine, write_section

        body = ["## Pneumatic finger (issue: pneumatic cavities) — `scripts/bench_pneumatic.py`", "",
                f"Machine: {machine()}. `problems/pneunet_finger.yaml`: 3653 nodes, 12882 linear tetrahedra, "
                "neo-Hookean, two cavities (0 to 40 kPa), gravity; 2 worker processes.", "",
                "| measure | value |", "|---|---|"]
        body += [f"| {k} | {v:.3g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in rows.items()]
        write_section("pneumatic", "\n".join(body))


if __name__ == "__main__":
    main()
