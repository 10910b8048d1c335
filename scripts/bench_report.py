"""The report page of every shipped problem (issue 65): its size with and without the deformed robots, and what
solving those robots again after the run costs against the run itself.

Each problem with inputs is solved by the forward method at the grid a first look would use (n_d so that the
grid has at most ~150 points, 16 for the pinch gripper whose equilibria cost seconds; inputs held at one
value are no axis), written with ``write_outputs`` as
``casadi-ws solve`` writes it (shapes of up to 200 points, solved again: the runs keep no states), and the page
written once more without shapes.

    python scripts/bench_report.py      # writes benchmarks/report_sizes.json and the BENCHMARKS.md section
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import machine, write_section  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
POINTS = 150


def main():
    import casadi_ws as cw
    from casadi_ws.io.output import write_outputs
    from casadi_ws.io.report import write_report
    from casadi_ws.workspace.forward import ForwardSettings, forward, grid_inputs

    files = sorted(ROOT.glob("problems/*.yaml")) + sorted(ROOT.glob("problems/sofa/*/*.yaml"))
    rows = []
    for f in files:
        try:
            p = cw.load_problem(f)
        except cw.ProblemError:  # a study file beside the problems
            continue
        k = grid_inputs(p)
        if not k:
            continue
        # the pinch gripper's equilibria (10-node jaws pressing on each other) cost seconds each: 4^2 points
        n_d = 4 if p.self_contact else max(3, int(POINTS ** (1 / k)))
        if n_d**k > 3 * POINTS:  # the SOFA trunk: 8 inputs, 3^8 points of slow displacement-driven equilibria
            print(json.dumps({"problem": str(f.relative_to(ROOT)), "skipped": f"{k} inputs: {n_d}^{k} points"}))
            continue
        t = time.perf_counter()
        r = forward(p, settings=ForwardSettings(n_d=n_d, progress=False))
        run = time.perf_counter() - t
        with tempfile.TemporaryDirectory() as d:
            write_outputs(r, p, d)
            with_shapes = (Path(d) / "report.html").stat().st_size
            bare = write_report(r, Path(d) / "bare.html", p.mesh, getattr(p, "obstacles", []))
            without = bare.stat().st_size
        row = {"problem": str(f.relative_to(ROOT)), "nodes": int(p.mesh.n_nodes), "inputs": k, "n_d": n_d,
               "points": int(r.n_points), "run_s": round(run, 2), "shapes": int(r.counters.get("shapes", 0)),
               "shapes_s": round(r.timings.get("shapes", 0.0), 2), "mb_with": round(with_shapes / 1e6, 2),
               "mb_without": round(without / 1e6, 2)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    record(rows)


def record(rows):
    """benchmarks/report_sizes.json and the BENCHMARKS.md section from the rows of a run."""
    out = {"machine": machine(), "rows": rows}
    (ROOT / "benchmarks" / "report_sizes.json").write_text(json.dumps(out, indent=1) + "\n")
    lines = ["## The report page of every shipped problem (issue 65) — `scripts/bench_report.py`", "",
             out["machine"] + ".", "",
             "Forward at n_d with at most ~150 grid points (16 for the pinch gripper, whose equilibria with its jaws "
             "pressing on each other cost seconds; inputs held at one value are no axis), written as "
             "`casadi-ws solve` writes it: the deformed robot at up to 200 points, solved again after the run "
             "(`casadi_ws.workspace.states.states_at`, each from the nearest one solved before it with a "
             "first-order predictor, kept where its tip is the reported point within 1 µm).", "",
             "| problem | nodes | inputs | n_d | points | run | robots drawn | solving them again | page | "
             "page without robots |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| `{r['problem']}` | {r['nodes']} | {r['inputs']} | {r['n_d']} | {r['points']} | "
                     f"{r['run_s']:.1f} s | {r['shapes']} | {r['shapes_s']:.1f} s | {r['mb_with']:.1f} MB | "
                     f"{r['mb_without']:.1f} MB |")
    lines += ["", "Not run: `problems/sofa/trunk/trunk.yaml` (8 inputs: 3^8 equilibria of the displacement-driven "
              "trunk, whose self-penetration at full strokes is issue 69's)."]
    largest = max(rows, key=lambda r: r["mb_with"])
    write_section("report-sizes", "\n".join(lines),
                  figure=f"pages {min(r['mb_with'] for r in rows):.1f}-{largest['mb_with']:.1f} MB with up to "
                         f"200 robots ({len(rows)} problems)",
                  what="the report page's size and its robots' cost, per shipped problem",
                  command="python scripts/bench_report.py")


if __name__ == "__main__":
    main()
