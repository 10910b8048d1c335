"""Forward at three inputs: lines interpolated across lines against every line solved, in one run.

    python scripts/bench_forward_across.py [--nd 30] [--workers 2] [--problem trunk_3cables]

The same code with ``across=1`` (every line solved: the sweep before lines were interpolated across) and with
the default ``across``; records time per point, Newton solves, factorisations, interpolations and how many
failed verification, and the largest distance between the two runs' points.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np
from benchlib import machine, write_section

import casadi_ws as cw
from casadi_ws.workspace.forward import ForwardSettings, across_stride, forward

REPO = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nd", type=int, default=30)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--problem", default="trunk_3cables")
    args = ap.parse_args()
    pb = cw.load_problem(REPO / "problems" / f"{args.problem}.yaml")
    runs, peak = {}, {}
    for across in (1, None):
        s = ForwardSettings(n_d=args.nd, workers=args.workers, across=across, progress=False)
        t = time.perf_counter()
        runs[across] = (forward(pb, settings=s), time.perf_counter() - t)
        # the workers, joined when the run ends, are this process's children: their largest resident set
        peak[across] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        print(across, f"{runs[across][1]:.1f} s", runs[across][0].counters, flush=True)
    n = args.nd ** pb.n_u
    rows = []
    for across, (r, dt) in runs.items():
        c = r.counters
        k = across_stride(ForwardSettings(n_d=args.nd), pb.n_u, args.nd) if across is None else across
        rows.append(f"| {k}{' (default)' if across is None else ''} | {dt:.1f} s | {1e3 * dt / n:.2f} ms | "
                    f"{c['solves']} | {c['factorizations']} | {c['interpolated']} ({c['interpolation_failed']} failed) | "
                    f"{r.n_points} | {peak[across]:.0f} MB |")
    (a, _), (b, _) = runs[1], runs[None]
    same = np.array_equal(a.u, b.u)
    gap = float(np.abs(a.points - b.points).max()) if same else float("nan")
    body = "\n".join([
        f"## Forward at three inputs: lines interpolated across lines — `scripts/bench_forward_across.py --nd {args.nd}`",
        "", f"{machine()}. `problems/{args.problem}.yaml`, n_d = {args.nd} ({n} points), {args.workers} worker "
        "processes, the same code with `across = 1` (every line of a plane solved, as before) and the default.", "",
        "| across | time | per point | Newton solves | LUs | interpolated (failed verification) | points | "
        "peak memory (largest worker so far) |", "|---|---|---|---|---|---|---|---|", *rows, "",
        f"Same inputs reached: {same}; largest distance between the two runs' points {gap:.1e} m. Peak memory is "
        "the largest worker of the runs so far (the operating system keeps one maximum for a process's children). "
        "Until 2026-12-03 the default run was killed by the OOM killer: a plane kept every Newton point's LU to "
        "its end, 12 GB per worker."])
    write_section("forward-across", body)


if __name__ == "__main__":
    main()
