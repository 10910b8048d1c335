"""Dask against the built-in process pool, and 1 -> 2 workers, on the shipped 2-cable trunk.

    python scripts/bench_dask.py [--nd 60] [--write]

Forward (n_d^2 points) and forward-backward (4 mm grid) with: this process alone; a pool of 2 spawned
processes (``ProcessExecutor``, what ``--workers 2`` starts); a ``distributed.LocalCluster`` of 2
single-threaded workers (``DaskExecutor``). Start-up (workers building their models) is timed apart.
Also the transfer cost of one task: a round trip of an empty job through each executor.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import casadi_ws as cw


def _noop(model):
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nd", type=int, default=60)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    pb = cw.default_problem()
    m = cw.StaticModel(pb)
    fs = cw.ForwardSettings(n_d=args.nd, progress=False)
    bs = cw.FBSettings(step=0.004, progress=False)
    rows = []
    for name, make in (("serial", lambda: cw.SerialExecutor(m)),
                       ("process pool, 2", lambda: cw.ProcessExecutor(2, pb)),
                       ("Dask LocalCluster, 2", lambda: cw.DaskExecutor(workers=2, problem=pb))):
        t = time.perf_counter()
        ex = make()
        list(ex.map_unordered(_noop, pb, [()] * 2 * ex.workers))  # workers have built their models
        start = time.perf_counter() - t
        t = time.perf_counter()
        list(ex.map_unordered(_noop, pb, [()] * 200))
        per_task = (time.perf_counter() - t) / 200
        t = time.perf_counter()
        f = cw.forward(pb, settings=fs, model=m, executor=ex)
        tf = time.perf_counter() - t
        t = time.perf_counter()
        b = cw.forward_backward(pb, bs, model=m, executor=ex)
        tb = time.perf_counter() - t
        ex.close()
        rows.append((name, start, per_task, tf, tb, f.n_points, b.n_points))
        print(rows[-1], flush=True)
    if args.write:
        from benchlib import machine, write_section

        s = rows[0]
        lines = ["## Dask as the execution engine (issue: design studies) — `scripts/bench_dask.py`", "",
                 f"Machine: {machine()}. `trunk_2cables` (2646 free dofs); forward n_d = {args.nd} "
                 f"({s[5]} points), forward-backward 4 mm ({s[6]} cells). Start: until every worker has "
                 "built its model. Per task: mean round trip of an empty job (200 jobs).", "",
                 "| executor | start (s) | per task (ms) | forward (s) | speed-up | forward-backward (s) | speed-up |",
                 "|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r[0]} | {r[1]:.1f} | {1e3 * r[2]:.2f} | {r[3]:.1f} | {s[3] / r[3]:.2f} | "
                         f"{r[4]:.1f} | {s[4] / r[4]:.2f} |")
        lines += ["", "Decision and what it means at scale: see the note kept in BENCHMARKS.md (rewrite it from the "
                  "new numbers)."]
        write_section("dask", "\n".join(lines))


if __name__ == "__main__":
    main()
