"""One robot, one answer: forward's points do not depend on the stride, the number of workers or the executor,
and each equals the quasi-static equilibrium from rest at its inputs; forward-backward's points too
(docs/methods.md "One answer per input").

    python scripts/branch_consistency.py [--problems trunk_table pinch_gripper ...] [--nd N] [--sample 60]

For each shipped problem (default: every problem file in problems/ with inputs): forward on the full grid
(n_d by the number of inputs, or --nd) with Newton at every point (stride 1, one worker), at the default
stride (one worker; stride 3 and across 3 where the default solves every point at that n_d) and the same on two
worker processes; the largest distance between the tips
the runs report at the same inputs, the points each run excluded or failed, LUs per point and time. The
reference is `quasi_static` from rest (steps of a tenth of the way) at every grid input, or at --sample of them
spread over the grid; and forward-backward (two workers, the default step) against `quasi_static` at the inputs
of --sample of its points (not for `pinch_gripper`: forward-backward with self-contact is another issue's). Each
problem's row replaces its earlier one in benchmarks/branch_consistency.json, from which the section
"branch-consistency" of BENCHMARKS.md is written; the rows are printed as JSON too.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import casadi_ws as cw
from benchlib import machine, write_section
from casadi_ws import quasi_static
from casadi_ws.solvers.admissible import admissible_equilibrium
from casadi_ws.workspace.forward import ForwardSettings, forward, input_grid, line_stride

ROOT = Path(__file__).resolve().parents[1]
N_D = {1: 41, 2: 21, 3: 9, 4: 6}
"""Grid values per input by the number of inputs (about 40-1300 points)."""
SLOW = {"pinch_gripper": 7, "trunk_2cables_fine": 9}
"""Problems whose equilibria take seconds: a coarser grid, and at most 20 inputs compared with the path."""
NO_FB = {"pinch_gripper"}
"""Forward-backward with self-contact takes hours (docs/methods.md "Self-contact"): not run here."""
DATA = ROOT / "benchmarks" / "branch_consistency.json"


def shipped() -> list[str]:
    names = []
    for f in sorted((ROOT / "problems").glob("*.yaml")):
        text = f.read_text()
        if "cables:" in text or "cavities:" in text:
            names.append(f.stem)
    return names


def _tips_by_u(result) -> dict:
    return {tuple(np.round(u, 12)): p for u, p in zip(result.u, result.points)}


def run(name: str, nd: int | None, sample: int, fb: bool) -> dict:
    problem = cw.load_problem(ROOT / "problems" / f"{name}.yaml")
    model = cw.StaticModel(problem)
    nd = nd or SLOW.get(name) or N_D[problem.n_u]
    out = {"problem": name, "n_u": problem.n_u, "n_d": nd, "dofs": int(model.n_free), "runs": {}}
    results = {}
    interpolating = {}
    if line_stride(ForwardSettings(n_d=nd), nd) == 1:  # the default solves every point at this n_d
        interpolating = dict(stride=3, across=3 if problem.n_u >= 3 else None)
    runs = [("stride 1", ForwardSettings(n_d=nd, stride=1, progress=False)),
            ("default", ForwardSettings(n_d=nd, progress=False, **interpolating)),
            ("default, 2 workers", ForwardSettings(n_d=nd, workers=2, progress=False, **interpolating))]
    for label, settings in runs:
        t = time.perf_counter()
        r = forward(problem, settings=settings, model=model if settings.workers == 1 else None)
        dt = time.perf_counter() - t
        results[label] = r
        c = r.counters
        out["runs"][label] = {"stride": settings.stride, "across": settings.across, "points": int(r.n_points),
                              "failed": int(r.n_failed),
                              "excluded": int(len(r.arrays.get("excluded_violations", []))),
                              "lu_per_point": c["factorizations"] / c["points"], "time_s": dt,
                              "branch_checks": c["branch_checks"], "branch_paths": c["branch_paths"],
                              "path_dependent": c["path_dependent"]}
    ref_run = _tips_by_u(results["stride 1"])
    gaps = {}
    for label, r in results.items():
        other = _tips_by_u(r)
        common = set(ref_run) & set(other)
        gaps[label] = max((float(np.linalg.norm(ref_run[k] - other[k])) for k in common), default=float("nan"))
    out["max_tip_gap_to_stride_1_m"] = gaps
    us = input_grid(model.u_min, model.u_max, nd)
    sample = min(sample, 20) if name in SLOW else sample
    pick = np.unique(np.linspace(0, len(us) - 1, min(sample, len(us))).round().astype(int)) if sample else \
        np.arange(len(us))
    worst, direct, missing = 0.0, 0.0, 0
    t = time.perf_counter()
    for i in pick:
        key = tuple(np.round(us[i], 12))
        ref = quasi_static(model, us[i])
        rest = admissible_equilibrium(model, us[i])[0]  # what `casadi-ws equilibrium` prints: Newton from rest
        if ref.converged and rest.converged:
            direct = max(direct, float(np.linalg.norm(rest.tip - ref.tip)))
        for r in results.values():
            tip = _tips_by_u(r).get(key)
            if tip is None or not ref.converged:
                missing += 1
                continue
            worst = max(worst, float(np.linalg.norm(tip - ref.tip)))
    out["quasi_static"] = {"inputs": int(len(pick)), "max_tip_gap_m": worst, "not_compared": missing,
                           "direct_solve_gap_m": direct, "time_s": time.perf_counter() - t}
    if fb and name not in NO_FB:
        t = time.perf_counter()
        res = cw.forward_backward(problem, cw.FBSettings(workers=2, progress=False))
        t_fb = time.perf_counter() - t
        pick = np.unique(np.linspace(0, res.n_points - 1, min(sample, res.n_points)).round().astype(int))
        worst = 0.0
        for i in pick:
            ref = quasi_static(model, res.u[i])
            worst = max(worst, float(np.linalg.norm(res.points[i] - ref.tip))) if ref.converged else np.inf
        out["forward_backward"] = {"points": int(res.n_points), "compared": int(len(pick)), "max_tip_gap_m": worst,
                                   "path_dependent": res.counters.get("path_dependent", 0), "time_s": t_fb}
    return out


def table(rows: list[dict]) -> str:
    lines = ["| problem | n_d | stride 1: points / excluded / LUs per point | default (or stride 3, across 3, "
             "where the default solves every point) | the same, 2 workers | "
             "largest tip gap between runs | gap to the path from rest (inputs) | "
             "Newton from rest: gap to the path | "
             "FB: gap to the path from rest (points) | path-dependent |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cells = []
        for label in ("stride 1", "default", "default, 2 workers"):
            x = r["runs"][label]
            how = f", stride {x['stride']}" + (f" across {x['across']}" if x.get("across") else "") \
                if label != "stride 1" and x.get("stride") else ""
            cells.append(f"{x['points']} / {x['excluded']} / {x['lu_per_point']:.2f} ({x['time_s']:.0f} s{how})")
        gap = max(r["max_tip_gap_to_stride_1_m"].values())
        fb = r.get("forward_backward")
        fb_cell = f"{fb['max_tip_gap_m']:.1e} m ({fb['compared']} of {fb['points']})" if fb else "—"
        dep = sum(x["path_dependent"] for x in r["runs"].values()) + (fb["path_dependent"] if fb else 0)
        lines.append(f"| `{r['problem']}` | {r['n_d']} | " + " | ".join(cells) +
                     f" | {gap:.1e} m | {r['quasi_static']['max_tip_gap_m']:.1e} m ({r['quasi_static']['inputs']}) "
                     f"| {r['quasi_static']['direct_solve_gap_m']:.1e} m | {fb_cell} | {dep} |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", nargs="*", default=None, help="default: every shipped problem with inputs")
    ap.add_argument("--nd", type=int, default=None)
    ap.add_argument("--sample", type=int, default=60, help="inputs compared with the path from rest (0: all)")
    ap.add_argument("--no-fb", action="store_true")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--table-only", action="store_true", help="run nothing: write the section from the stored rows")
    args = ap.parse_args()
    stored = json.loads(DATA.read_text()) if DATA.exists() else {}
    for name in [] if args.table_only else (args.problems or shipped()):
        row = run(name, args.nd, args.sample, not args.no_fb)
        row["machine"] = machine()
        print(json.dumps(row), flush=True)
        if not args.no_write:
            stored[name] = row
            DATA.parent.mkdir(exist_ok=True)
            DATA.write_text(json.dumps(stored, indent=1) + "\n")
    if args.no_write:
        return
    rows = [stored[k] for k in sorted(stored)]
    body = "\n".join([
        "## One answer per input (issue: one robot, one answer) — `scripts/branch_consistency.py`",
        "",
        f"Machine: {rows[-1]['machine']} (each row: its own date in benchmarks/branch_consistency.json).",
        "Forward on each shipped problem's full grid with Newton at every point (stride 1), at the default stride, "
        "and at the default stride on two worker processes; the largest distance between the tips two runs "
        "report at the same inputs, and between every run's tip and `quasi_static` from rest (the definition of "
        "a reported point: the inputs raised along the straight path from rest in steps of a tenth of the way) "
        "at evenly spread grid inputs, and there Newton from rest (what `casadi-ws equilibrium` prints: "
        "`admissible_equilibrium`) against it; forward-backward (two workers, the default step) against "
        "`quasi_static` at the inputs of evenly spread points. Times are wall times of one run each; the "
        "three runs' points and the grid's inputs: n_d^n_u.",
        "",
        table(rows),
    ])
    write_section("branch-consistency", body)


if __name__ == "__main__":
    main()
