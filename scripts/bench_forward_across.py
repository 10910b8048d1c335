"""Forward at three inputs: planes interpolated across planes, lines across lines, against every line solved.

    python scripts/bench_forward_across.py [--nd 30] [--workers 2] [--problem trunk_3cables]

The same code four ways in one run: ``across=1`` (every line solved), lines interpolated across lines only
with stride and across 2 (the default until 2026-12-03: planes swept one by one), stride and across n_d // 10
(the default until 2026-12-04; the cube's planes interpolated across planes) and the default (stride n_d // 6,
across n_d // 10). Records time per point, Newton solves,
factorisations, interpolations and how many failed verification, peak memory, and the largest distance
between the runs' points.
"""

from __future__ import annotations

import argparse
import importlib
import resource
import time
from pathlib import Path

import numpy as np
from benchlib import machine, write_section

import casadi_ws as cw
from casadi_ws.workspace.forward import ForwardSettings, across_stride, forward, line_stride

REPO = Path(__file__).resolve().parents[1]
fw = importlib.import_module("casadi_ws.workspace.forward")  # the package exports a function of that name


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nd", type=int, default=30)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--problem", default="trunk_3cables")
    args = ap.parse_args()
    pb = cw.load_problem(REPO / "problems" / f"{args.problem}.yaml")
    runs, peak = {}, {}
    ways = {"every line solved (across 1, stride n_d // 10)": (dict(across=1, stride=args.nd // 10), None),
            "lines across lines, stride 2 (default until 2026-12-03)": (dict(stride=2, across=2), 0),
            "planes across planes too, stride and across n_d // 10 (default until 2026-12-04)":
                (dict(stride=args.nd // 10, across=args.nd // 10), None),
            "default: stride n_d // 6 (n_d // 10 after a line whose interpolations failed), across n_d // 10":
                ({}, None)}
    cube_states = fw.CUBE_STATES
    for label, (kw, cube) in ways.items():
        fw.CUBE_STATES = cube_states if cube is None else cube  # 0: no cube fits, planes are swept one by one
        s = ForwardSettings(n_d=args.nd, workers=args.workers, progress=False, **kw)
        t = time.perf_counter()
        runs[label] = (forward(pb, settings=s), time.perf_counter() - t)
        # the workers, joined when the run ends, are this process's children: their largest resident set
        peak[label] = (resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
                       resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
        print(label, f"{runs[label][1]:.1f} s", runs[label][0].counters, flush=True)
    fw.CUBE_STATES = cube_states
    n = args.nd ** pb.n_u
    rows = []
    for label, (r, dt) in runs.items():
        c = r.counters
        rows.append(f"| {label} | {dt:.1f} s | {1e3 * dt / n:.2f} ms | "
                    f"{c['solves']} | {c['factorizations']} | "
                    f"{c['interpolated']} ({c['interpolation_failed']} failed) | "
                    f"{r.n_points} | {peak[label][0]:.0f} / {peak[label][1]:.0f} MB |")
    ref = next(iter(runs.values()))[0]
    gaps = [float(np.abs(ref.points - r.points).max()) if np.array_equal(ref.u, r.u) else float("nan")
            for r, _ in list(runs.values())[1:]]
    d = ForwardSettings(n_d=args.nd)
    k = f"stride {line_stride(d, args.nd)}, across {across_stride(d, pb.n_u, args.nd)}"
    body = "\n".join([
        "## Forward at three inputs: planes across planes, lines across lines — "
        f"`scripts/bench_forward_across.py --nd {args.nd}`",
        "", f"{machine()}. `problems/{args.problem}.yaml`, n_d = {args.nd} ({n} points), {args.workers} worker "
        f"processes, the same code four ways (the default at this n_d: {k}).", "",
        "| sweep | time | per point | Newton solves | LUs | interpolated (failed verification) | points | "
        "peak memory: largest worker so far / main process |", "|---|---|---|---|---|---|---|---|", *rows, "",
        f"Same inputs reached by all four: {all(np.isfinite(gaps))}; largest distance to the every-line run's "
        f"points {', '.join(f'{g:.1e}' for g in gaps)} m. Peak memory of the workers is the largest of the "
        "runs so far (the operating system keeps one maximum for a process's children); the main process holds "
        "the swept planes' states and sends the workers those their planes interpolate from. Until 2026-12-03 a "
        "plane kept every Newton point's LU to its end (12 GB per worker, killed by the OOM killer)."])
    write_section("forward-across", body)


if __name__ == "__main__":
    main()
