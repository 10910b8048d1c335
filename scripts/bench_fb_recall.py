"""Does forward-backward find every cell the forward cloud occupies? Strict recall on the FB grid, and cost.

    python scripts/bench_fb_recall.py [--problems trunk_2cables trunk_3cables ...] [--workers 2] [--step 0.004]
    python scripts/bench_fb_recall.py --problems trunk_2cables_fine --nd 41 --section fb-recall-fine

For each problem, the forward cloud at the n_d of issue 13 (2 cables: 100, 3: 30, 4: 12; cached under
results/bench_cache/, since it takes minutes) and the forward-backward result with default settings. Records
in BENCHMARKS.md: strict recall (share of forward-occupied cells FB reports), the share of forward points in
FB cells, FB cells the cloud does not occupy, FB time, factorisations per reached cell, adopted cells.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import casadi_ws as cw
from benchlib import machine, write_section

ROOT = Path(__file__).resolve().parents[1]
ND = {2: 100, 3: 30, 4: 12}
DEFAULT = ["trunk_2cables", "trunk_3cables", "trunk_4cables", "sofa_trunk_2cables"]


def forward_cloud(name, problem, n_d, workers):
    cache = ROOT / "results" / "bench_cache" / f"{name}_nd{n_d}"
    if (cache / "summary.json").is_file():
        r = cw.load_result(cache)
        if r.problem.get("n_nodes") == problem.mesh.n_nodes:
            return r
    r = cw.forward(problem, settings=cw.ForwardSettings(n_d=n_d, workers=workers, progress=False))
    r.save(cache)
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--problems", nargs="+", default=DEFAULT)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--step", type=float, default=0.004)
    ap.add_argument("--section", default="fb-recall")
    ap.add_argument("--nd", type=int, help="the forward cloud's n_d (default: 100 / 30 / 12 for 2 / 3 / 4 inputs)")
    args = ap.parse_args()
    rows = []
    for name in args.problems:
        pb = cw.load_problem(ROOT / "problems" / f"{name}.yaml")
        n_d = args.nd or ND[pb.n_u]
        t = time.perf_counter()
        fw = forward_cloud(name, pb, n_d, args.workers)
        t_fw = time.perf_counter() - t
        fb = cw.forward_backward(pb, cw.FBSettings(step=args.step, workers=args.workers, progress=False))
        c = cw.compare(fw, fb)
        k = fb.counters
        rows.append((name, pb, n_d, fw, fb, c))
        print(f"{name}: recall {c['cells_a_in_b']:.3f} ({c['cells_both']}/{c['cells_a']}), points in FB cells "
              f"{c['points_a_in_b_cells']:.4f}, FB cells {c['cells_b']}, FB {fb.timings['total']:.1f} s, "
              f"{k['factorizations'] / max(k['feasible'], 1):.2f} LU/cell, adopted {k.get('adopted', 0)} "
              f"(forward {t_fw:.0f} s)", flush=True)
    lines = [
        f"## Forward-backward completeness (issue: FB that misses nothing) — `scripts/bench_fb_recall.py --step {args.step}`",
        "",
        f"Machine: {machine()}. {args.workers} worker processes, default settings, grid step {args.step * 1e3:g} mm.",
        "Recall is strict: the share of the grid cells occupied by the forward cloud that forward-backward reports,",
        "on the forward-backward grid (computed by `casadi_ws.compare`, `cells_a_in_b`).",
        "",
        "| problem | n_u | forward n_d (points) | forward cells | FB cells | recall | forward points in FB cells | FB cells without a forward point | FB time (s) | LU / reached cell | adopted cells |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, pb, n_d, fw, fb, c in rows:
        k = fb.counters
        lines.append(f"| `{name}` | {pb.n_u} | {n_d} ({fw.n_points}) | {c['cells_a']} | {c['cells_b']} | "
                     f"{c['cells_a_in_b']:.3f} | {c['points_a_in_b_cells']:.4f} | {c['cells_b'] - c['cells_both']} | "
                     f"{fb.timings['total']:.1f} | {k['factorizations'] / max(k['feasible'], 1):.2f} | "
                     f"{k.get('adopted', 0)} |")
    lines += ["", "FB cells without a forward point lie between the points of a cloud coarser than the grid "
                  "(3 and 4 cables), or are reached by FB where the cloud has no sample."]
    write_section(args.section, "\n".join(lines))


if __name__ == "__main__":
    main()
