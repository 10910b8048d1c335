"""Cost against accuracy of the element order on the shipped 2-cable trunk: which mesh should a problem use?

    python scripts/bench_order.py [--fb] [--write]

For linear tetrahedra at several mesh resolutions and quadratic ones at one or two, against a fine
reference (quadratic, resolution 1.0; resolution 1.5, 52k dofs, took over 15 min per equilibrium set with
SuperLU and was dropped):
- the tip at four fixed tensions (error in mm, and relative to the tip's displacement from rest);
- time per equilibrium: a warm-started 5 N step of both cables from an equilibrium (mean of 3);
- with ``--fb``: the forward-backward workspace (grid step 4 mm, 2 workers): cells, volume and time, the
  volume against the finest quadratic run's.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import casadi_ws as cw
from casadi_ws.io.problem import DEFAULT_PROBLEM

TENSIONS = [np.array(u, float) for u in ([50.0, 0.0], [100.0, 0.0], [100.0, 100.0], [30.0, 70.0])]
CONFIGS = [(1, 0.5), (1, 1.0), (1, 1.5), (1, 2.0), (2, 0.5), (2, 0.75)]
REFERENCE = (2, 1.0)
FB_CONFIGS = [(1, 0.5), (1, 1.0), (1, 1.5), (2, 0.5), (2, 0.75)]


def problem(order: int, resolution: float):
    d = dict(DEFAULT_PROBLEM)
    d["mesh"] = {**d["mesh"], "resolution": resolution, "order": order}
    return cw.problem_from_dict(d, f"<order {order}, resolution {resolution}>")


def tips(order, resolution):
    m = cw.StaticModel(problem(order, resolution))
    out, prev = [], None
    for u in TENSIONS:
        eq = cw.solve_equilibrium(m, u) if prev is None else cw.solve_equilibrium(m, u, q0=prev.q, u0=prev.u)
        assert eq.converged, (order, resolution, u)
        out.append(eq.tip)
        prev = eq
    base = cw.solve_equilibrium(m, np.array([40.0, 20.0]))
    times = []
    for du in ([5.0, 5.0], [-5.0, -5.0], [5.0, -5.0]):
        t = time.perf_counter()
        e = cw.solve_equilibrium(m, base.u + du, q0=base.q, u0=base.u)
        times.append(time.perf_counter() - t)
        assert e.converged
    return m, np.array(out), float(np.mean(times))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fb", action="store_true")
    ap.add_argument("--out", default="results/bench_order.json")
    ap.add_argument("--write", action="store_true", help="write BENCHMARKS.md's section from --out, no runs")
    args = ap.parse_args()
    if args.write:
        write(json.loads(Path(args.out).read_text()))
        return
    t0 = time.perf_counter()
    _, ref, ref_dt = tips(*REFERENCE)
    print(f"reference {REFERENCE}: {time.perf_counter() - t0:.0f} s", flush=True)
    rest = cw.StaticModel(problem(1, 0.5)).p0
    rows = []
    for order, res in CONFIGS + [REFERENCE]:
        m, t, dt = (cw.StaticModel(problem(order, res)), ref, ref_dt) if (order, res) == REFERENCE \
            else tips(order, res)
        err = np.linalg.norm(t - ref, axis=1)
        row = dict(order=order, resolution=res, nodes=int(m.n_nodes), dofs=int(m.n_free),
                   tip_error_mm=(1e3 * err).tolist(),
                   tip_error_rel=(err / np.linalg.norm(ref - rest, axis=1)).tolist(), equilibrium_s=dt)
        if args.fb and (order, res) in FB_CONFIGS:
            s = cw.FBSettings(step=0.004, progress=False, workers=2)
            t0 = time.perf_counter()
            r = cw.forward_backward(m.problem, s, model=m)
            row.update(fb_s=time.perf_counter() - t0, fb_cells=int(len(r.points)),
                       fb_volume_cm3=float(len(r.points) * 0.004 ** 3 * 1e6))
        print(json.dumps(row), flush=True)
        rows.append(row)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(rows, indent=1))


def write(rows) -> None:
    from benchlib import machine, write_section

    ref = [r for r in rows if (r["order"], r["resolution"]) == REFERENCE][0]
    fb_ref = max((r for r in rows if "fb_volume_cm3" in r), key=lambda r: (r["order"], r["resolution"]))
    lines = ["## Element order on the trunk: cost against accuracy (issue: quadratic tetrahedra) — "
             "`scripts/bench_order.py --fb`", "",
             f"Machine: {machine()}. `problems/trunk_2cables.yaml` (corotational, ν = 0.45, gravity) at several "
             f"mesh resolutions and element orders. Reference: order {REFERENCE[0]} at resolution {REFERENCE[1]} "
             f"({ref['dofs']} free dofs). Tip error: at tensions (50, 0), (100, 0), (100, 100), (30, 70) N, "
             "relative to the reference tip's displacement from rest. Equilibrium: a warm-started 5 N step of "
             "both cables (mean of 3). FB: grid step 4 mm, 2 worker processes. Another job shared the machine "
             "during part of these runs: times are indicative (~±30 %).", "",
             "| order | resolution | nodes | free dofs | tip error (mean, max) | equilibrium (s) | FB time (s) | FB cells | FB volume (cm³) | volume / finest FB's |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        rel = np.asarray(r["tip_error_rel"])
        fb = (f"{r['fb_s']:.0f} | {r['fb_cells']} | {r['fb_volume_cm3']:.1f} | "
              f"{r['fb_volume_cm3'] / fb_ref['fb_volume_cm3']:.2f}") if "fb_s" in r else "– | – | – | –"
        err = "reference" if r is ref else f"{100 * rel.mean():.1f} %, {100 * rel.max():.1f} %"
        lines.append(f"| {r['order']} | {r['resolution']} | {r['nodes']} | {r['dofs']} | {err} | "
                     f"{r['equilibrium_s']:.2f} | {fb} |")
    write_section("element-order", "\n".join(lines))


if __name__ == "__main__":
    main()
