"""What an adaptive (two-level, octree-like) grid could save forward-backward on the shipped trunks.

    python scripts/bench_adaptive.py [--problems trunk_2cables trunk_3cables trunk_4cables] [--step 0.004]

An adaptive grid explores coarse cells (``factor`` fine cells a side) first and solves fine cells only where a
coarse cell is not interior; a coarse cell is interior when it and its 26 coarse neighbours are reached. The
fine cells inside interior coarse cells are the only ones it saves, at the price of the coarse exploration.
This script runs the uniform forward-backward (default settings, 2 workers, boundary surface off) and counts,
from its reached cells: the cells that survive one and two erosions (a cell whose 26 neighbours are all
reached survives one), and per factor the coarse cells, the interior ones, the fine cells they hold, and the
backward targets a two-level grid would need at best (coarse cells + fine cells outside interior coarse ones;
its true count also has the unreached neighbours of both levels). Odd factors keep the coarse cells centred
on fine ones (the grid is anchored at the initial tip); factor 2 groups fine cells 2 x 2 x 2 from even indices.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np
from benchlib import machine, write_section

import casadi_ws as cw
from casadi_ws.workspace.boundary import BoundarySettings
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

REPO = Path(__file__).resolve().parents[1]
RING = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)])


def interior(cells: set) -> set:
    return {c for c in cells if all(tuple(np.add(c, d)) in cells for d in RING)}


def coarse_index(cell, factor: int) -> tuple:
    k = np.asarray(cell)
    return tuple((np.floor(k / factor) if factor % 2 == 0 else np.round(k / factor)).astype(int).tolist())


def two_level(cells: set, factor: int) -> dict:
    of = {c: coarse_index(c, factor) for c in cells}
    coarse = set(of.values())
    inner = interior(coarse)
    saved = sum(1 for c in cells if of[c] in inner)
    return {"coarse": len(coarse), "interior": len(inner), "saved": saved,
            "two_level": len(coarse) + len(cells) - saved}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", nargs="+", default=["trunk_2cables", "trunk_3cables", "trunk_4cables"])
    ap.add_argument("--step", type=float, default=None, help="grid step, m (default: the problem's)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    rows = []
    for name in args.problems:
        pb = cw.load_problem(REPO / "problems" / f"{name}.yaml")
        s = FBSettings(progress=False, workers=args.workers, step=args.step,
                       boundary=BoundarySettings(enabled=False))
        t = time.perf_counter()
        r = forward_backward(pb, s)
        dt = time.perf_counter() - t
        cells = {tuple(int(v) for v in c) for c in r.arrays["cells"]}
        once = interior(cells)
        row = {"problem": name, "n_u": pb.n_u, "step": float(r.arrays["cell_step"]), "time": dt,
               "cells": len(cells), "eroded1": len(once), "eroded2": len(interior(once)),
               "factors": {f: two_level(cells, f) for f in (2, 3)}}
        print(row, flush=True)
        rows.append(row)
    lines = [f"{machine()}. Uniform forward-backward, default settings, "
             f"{args.workers} worker processes, boundary surface off; counts from its reached cells.", "",
             "| problem | n_u | step | reached cells | surviving 1 / 2 erosions | factor 2: coarse cells, interior, "
             "fine cells saved, two-level targets at best | factor 3: the same | uniform time |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        f2, f3 = r["factors"][2], r["factors"][3]
        lines.append(f"| `{r['problem']}` | {r['n_u']} | {r['step'] * 1e3:.3g} mm | {r['cells']} | {r['eroded1']} / "
                     f"{r['eroded2']} | {f2['coarse']}, {f2['interior']}, {f2['saved']}, {f2['two_level']} | "
                     f"{f3['coarse']}, {f3['interior']}, {f3['saved']}, {f3['two_level']} | {r['time']:.1f} s |")
    lines += ["", "A coarse cell is interior when it and its 26 coarse neighbours are reached; a two-level grid "
              "saves the fine cells inside interior coarse cells and pays for the coarse ones, so it needs fewer "
              "targets than the uniform grid only where its two-level targets at best are fewer than the reached "
              "cells. Why it was not built: docs/methods.md, \"An adaptive grid\"."]
    write_section("adaptive", "## What an adaptive grid could save (issue: accurate models at interactive speed) — "
                  "`scripts/bench_adaptive.py`\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
