"""Forward-backward with and without the second-order predictor (``BackwardSettings.second_order``).

    python scripts/bench_second_order.py [--problems trunk_2cables trunk_4cables trunk_2cables_order2]

Each reached cell computes its curvature Q = d2q/du2 (n_u(n_u + 1) residuals and a solve) so that the backward
solves starting from it need one LU; without it they start from the linear predictor. Which costs less depends on
the price of a residual against an LU and on n_u. Same run, same machine, 2 worker processes, default step.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from benchlib import machine, write_section

import casadi_ws as cw
from casadi_ws.workspace.backward import BackwardSettings
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

REPO = Path(__file__).resolve().parents[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", nargs="+", default=["trunk_2cables", "trunk_4cables", "trunk_2cables_order2"])
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    rows = []
    for name in args.problems:
        pb = cw.load_problem(REPO / "problems" / f"{name}.yaml")
        m = cw.StaticModel(pb)
        runs = {}
        for second in (True, False):
            s = FBSettings(progress=False, workers=args.workers, backward=BackwardSettings(second_order=second))
            t = time.perf_counter()
            r = forward_backward(pb, s, model=m)
            runs[second] = (time.perf_counter() - t, r)
            print(name, second, f"{runs[second][0]:.1f} s", len(r.points), flush=True)
        (t2, a), (t1, b) = runs[True], runs[False]
        cells_a, cells_b = ({tuple(c) for c in r.arrays["cells"]} for r in (a, b))
        rows.append(f"| `{name}` | {m.n_u} | {m.n_free} | {t2:.1f} s, {a.counters['factorizations_per_cell']:.2f} | "
                    f"{t1:.1f} s, {b.counters['factorizations_per_cell']:.2f} | {len(cells_a)} / {len(cells_b)} "
                    f"({len(cells_a ^ cells_b)}) | {t1 / t2:.2f} |")
    body = "\n".join([
        "## Forward-backward with and without the second-order predictor — `scripts/bench_second_order.py`", "",
        f"{machine()}. Default step, {args.workers} worker processes, the boundary surface included; "
        "`BackwardSettings.second_order` on (the default) and off.", "",
        "| problem | n_u | free dofs | with Q: time, LUs per cell | without: time, LUs per cell | cells with / without "
        "(differing) | time without / with |", "|---|---|---|---|---|---|---|", *rows])
    write_section("second-order", body)


if __name__ == "__main__":
    main()
