"""Where the 4-cable trunk can point (issue 72): its forward-backward cells, the range of tip tilts in each, the
dexterous workspace within a cone about +z; checked against forward points of the same robot; a picture.

    python scripts/bench_orientation.py [--step 0.008] [--cone 20]
        # writes benchmarks/orientation.json, docs/dexterous_trunk4.png and the BENCHMARKS.md section

The check (the issue's): 40 random points of a forward grid (n_d = 8; the ranges' seeds are a 5^4 grid, which
shares only U's corners with it), each one's tilt against the range of the cell its tip lies in.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import machine, write_section  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main():
    import casadi_ws as cw
    from casadi_ws.runtime.executor import model_for
    from casadi_ws.workspace.forward import ForwardSettings, forward
    from casadi_ws.workspace.forward_backward import FBSettings, forward_backward
    from casadi_ws.workspace.orientation import OrientationSettings, attach, orientation_ranges

    ap = argparse.ArgumentParser()
    ap.add_argument("--step", type=float, default=0.008)
    ap.add_argument("--cone", type=float, default=20.0)
    args = ap.parse_args()
    p = cw.load_problem(ROOT / "problems" / "trunk_4cables.yaml")
    m = model_for(p)
    t = time.perf_counter()
    r = forward_backward(p, FBSettings(step=args.step, progress=False), model=m)
    t_fb = time.perf_counter() - t
    axis = np.array([0.0, 0.0, 1.0])
    o = orientation_ranges(m, r, OrientationSettings(reference=axis, cone=args.cone))
    attach(r, o)
    # the issue's check: 40 forward points against their cells' ranges
    fw = forward(p, settings=ForwardSettings(n_d=8, progress=False, maps="none"), model=m)
    pick = np.random.default_rng(0).choice(fw.n_points, size=40, replace=False)
    tilt = np.degrees(np.arccos(np.clip(np.column_stack([fw.maps()[f"axis_{c}"] for c in "xyz"])[pick] @ axis,
                                        -1, 1)))
    index = {tuple(c): i for i, c in enumerate(o.cell.tolist())}
    cells = [index.get(tuple(c)) for c in np.round((fw.points[pick] - o.origin) / o.step).astype(int).tolist()]
    rows = []
    for j, i in zip(range(40), cells):
        if i is None:
            rows.append({"cell": None})
            continue
        excess = max(o.tilt_min[i] - tilt[j], tilt[j] - o.tilt_max[i], 0.0)
        rows.append({"cell": int(i), "tilt": float(tilt[j]), "excess": float(excess),
                     "variation": float(o.variation[i])})
    found = [x for x in rows if x["cell"] is not None]
    dx, om = r.measures["dexterous"], r.measures["orientation"]
    out = {"machine": machine(), "problem": "problems/trunk_4cables.yaml", "step_m": args.step, "cone_deg": args.cone,
           "cells": int(r.n_points), "fb_s": round(t_fb, 1), "orientation_s": round(o.counters["time_s"], 1),
           "counters": {k: v for k, v in o.counters.items() if k != "time_s"}, "orientation": om, "dexterous": dx,
           "check": {"points": 40, "in_a_cell": len(found), "inside_range": sum(x["excess"] <= 0.01 for x in found),
                     "within_variation": sum(x["excess"] <= x["variation"] for x in found),
                     "largest_excess_deg": max((x["excess"] for x in found), default=None),
                     "median_variation_deg": float(np.median([x["variation"] for x in found]))}}
    (ROOT / "benchmarks" / "orientation.json").write_text(json.dumps(out, indent=1, default=float) + "\n")
    picture(r, o, args.cone, ROOT / "docs" / "dexterous_trunk4.png")
    c = out["check"]
    body = "\n".join([
        "## Where the 4-cable trunk can point (issue 72) — `scripts/bench_orientation.py`", "", out["machine"] + ".",
        "",
        f"`problems/trunk_4cables.yaml`, forward-backward at {1e3 * args.step:g} mm: {out['cells']} cells in "
        f"{out['fb_s']:.0f} s; the range of the tip's tilt from +z in every cell "
        f"(`casadi_ws.workspace.orientation`, defaults: seeds from a 5^4 forward grid, one sweep) in "
        f"{out['orientation_s']:.0f} s ({out['counters']['problems']} backward problems, {out['counters']['steps']} "
        f"steps, {out['counters']['factorizations']} LUs).", "",
        f"- tilt from +z over the workspace: {om['tilt_min_deg']:.1f} to {om['tilt_max_deg']:.1f} deg; the widest "
        f"range in one cell {om['widest_range_deg']:.1f} deg; median cell variation {om['median_variation_deg']:.1f} "
        f"deg (the tilt difference to the neighbouring cells' points).",
        f"- dexterous within {args.cone:g} deg of +z: {dx['cells']} of {om['cells']} cells "
        f"({100 * dx['share']:.0f} %), {1e6 * dx['cell_volume']:.1f} cm³ of cells.",
        f"- check against 40 random points of a forward grid (n_d = 8): {c['in_a_cell']} lie in a reached cell; "
        f"{c['inside_range']} have their tilt inside their cell's range, {c['within_variation']} within one cell's "
        f"variation of it (largest excess {c['largest_excess_deg']:.2f} deg, median variation "
        f"{c['median_variation_deg']:.1f} deg).", "",
        "Picture: `docs/dexterous_trunk4.png` (left: each cell coloured by its tilt range; right: the dexterous "
        "cells).",
    ])
    write_section("orientation", body,
                  figure=f"{out['cells']} cells at {1e3 * args.step:g} mm: ranges in {out['orientation_s']:.0f} s "
                         f"(FB {out['fb_s']:.0f} s); {dx['cells']} dexterous within {args.cone:g} deg; "
                         f"{c['within_variation']}/{c['in_a_cell']} forward points within their cell's range",
                  what="orientation ranges and the dexterous workspace, 4-cable trunk",
                  command="python scripts/bench_orientation.py")


def picture(r, o, cone, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    P = (o.origin + o.cell * o.step) * 1e3
    width = o.tilt_max - o.tilt_min
    fig = plt.figure(figsize=(11, 5))
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    s = ax.scatter(P[:, 0], P[:, 1], P[:, 2], c=width, cmap="viridis", s=12)
    fig.colorbar(s, ax=ax, shrink=0.6, label="range of tilt in the cell (deg)")
    ax.set_title("how much the tip can turn, per cell")
    ax2 = fig.add_subplot(1, 2, 2, projection="3d")
    d = o.dexterous
    ax2.scatter(P[~d, 0], P[~d, 1], P[~d, 2], c="lightgray", s=6, label="reached")
    ax2.scatter(P[d, 0], P[d, 1], P[d, 2], c="crimson", s=12, label=f"tip within {cone:g} deg of +z")
    ax2.legend(loc="upper left", fontsize=8)
    ax2.set_title("dexterous workspace")
    for a in (ax, ax2):
        a.set_xlabel("x (mm)")
        a.set_ylabel("y (mm)")
        a.set_zlabel("z (mm)")
        a.view_init(elev=20, azim=-60)
    fig.suptitle(f"trunk_4cables: {len(P)} cells of {1e3 * o.step:g} mm")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
