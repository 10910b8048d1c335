"""Forward-backward method on the 2-, 3- and 4-cable trunks (publication, Section 6), both backward solvers.

    python scripts/bench_fb.py [--step 0.004] [--backward reduced ipopt] [--problems 2 3 4]

Records in BENCHMARKS.md, per scenario and backward formulation: time, iterations, explored points (W_Ed),
feasible points (W_Es), backward solves, time per explored point, and the split between the steps.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import casadi_ws as cw
from benchlib import best_of, machine, write_section
from casadi_ws.workspace.backward import BackwardSettings
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

ROOT = Path(__file__).resolve().parents[1]
PAPER = {2: (757, 37, 1680, 635), 3: (2063, 44, 5466, 1941), 4: (3733, 42, 10626, 3667)}


def reference_lu(model) -> float:
    """Seconds for one LU factorisation + solve of K at u = u_min (best of 5): the machine's speed today."""
    from casadi_ws.solvers.equilibrium import factorize

    eq = cw.solve_equilibrium(model, model.u_min)
    _, K, _ = model.residual_and_tangent(eq.q, model.u_min)
    b = np.ones(model.n_free)
    return best_of(lambda: factorize(K).solve(b), 5)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--step", type=float, default=0.004)
    ap.add_argument("--backward", nargs="+", default=["reduced", "ipopt"])
    ap.add_argument("--problems", type=int, nargs="+", default=[2, 3, 4])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--section", default="fb")
    args = ap.parse_args()
    rows = []
    lu_ms = []
    for n in args.problems:
        pb = cw.load_problem(ROOT / "problems" / f"trunk_{n}cables.yaml")
        model = cw.StaticModel(pb)
        lu_ms.append(1e3 * reference_lu(model))
        for form in args.backward:
            s = FBSettings(step=args.step, backward=BackwardSettings(formulation=form), progress=False,
                           workers=args.workers)
            r = forward_backward(pb, s, model=model)
            c, t = r.counters, r.timings
            rows.append((n, form, r, c, t))
            print(n, form, f"{t['total']:.1f}s", c, flush=True)
    lines = [
        f"## Forward-backward method (issue: forward-backward) — `scripts/bench_fb.py --step {args.step}`",
        "",
        f"Machine: {machine()}.",
        f"Problems: `problems/trunk_{{2,3,4}}cables.yaml` (1029 nodes, 4320 tetrahedra, corotational, gravity), "
        f"uniform grid step s_Ed = {args.step * 1e3:g} mm, {args.workers} worker process(es), default settings "
        f"(prefilter 0.1 cell, reduced solves stop inside the cell or give up 0.05 cell outside it; see docs/methods.md).",
        f"This shared machine's speed varies by up to ~30 % between runs: one LU factorisation (double precision) + solve of K, "
        f"measured in this run before each scenario, took {' / '.join(f'{t:.1f}' for t in lu_ms)} ms.",
        "",
        "| n_u | backward | time (s) | iterations | explored W_Ed | feasible W_Es | backward solves | equilibrium solves | LU / reached cell | ms / explored point | step 1 / 3 (s) | publication: time, iterations, W_Ed, W_Es |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, form, r, c, t in rows:
        p = PAPER[n]
        lines.append(
            f"| {n} | {form} | {t['total']:.1f} | {c['iterations']} | {c['explored']} | {c['feasible']} "
            f"| {c['backward_solves']} | {c['equilibrium_solves']} | {c['factorizations'] / c['feasible']:.2f} "
            f"| {1e3 * t['total'] / max(c['explored'], 1):.1f} "
            f"| {t['step1_interval']:.1f} / {t['step3_backward']:.1f} | {p[0]} s, {p[1]}, {p[2]}, {p[3]} |")
    lines += ["", "The publication's grid step is not stated, so its counts compare in kind, not one to one."]
    write_section(args.section, "\n".join(lines))


if __name__ == "__main__":
    main()
