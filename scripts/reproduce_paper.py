"""Reproduce the publication's Section 6: three trunk scenarios, Table 1 and Figs. 11-14.

    python scripts/reproduce_paper.py [--quick] [--out results/paper] [--workers 2]
    make paper

For the 2-, 3- and 4-cable trunks of problems/:
  - forward method: n_d = 100 in full for 2 cables. For 3 and 4 cables, as the publication did, the time
    of n_d = 100 is extrapolated from a measured sample (whole grid lines of the n_d = 100 grid, each
    started cold, at random positions of the other actuators): clearly marked as an estimate. A full forward
    run at a coarser n_d is the comparison cloud;
  - forward-backward method with the default settings;
  - agreement (strict cell recall first, then the lenient within-one-cell measures, Hausdorff, volumes), three views like Figs. 11-13, Fig. 14 (operations
    and time vs n_u, log scale), Table 1 side by side with the publication's, and report.md.
The qualitative claims are tested by the data and the report states where they hold and where not.
``--quick`` uses a coarser mesh, grids and steps (a few minutes); one test runs it.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

import casadi_ws as cw
from casadi_ws.workspace.compare import compare
from casadi_ws.workspace.forward import ForwardSettings, forward, sweep
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward
from casadi_ws.runtime.executor import one_blas_thread
from casadi_ws.io.plots import three_views

ROOT = Path(__file__).resolve().parents[1]
# Table 1 of the publication: forward operations, FB feasible points, forward time (s), FB time (s)
PAPER = {2: (1e4, 635, 1463.0, 757.0), 3: (1e6, 1941, 1.46e5, 2063.0), 4: (1e8, 3667, 1.46e7, 3733.0)}
PAPER_FB_DETAIL = {2: (37, 1680), 3: (44, 5466), 4: (42, 10626)}  # iterations, explored W_Ed


def load(n, quick):
    text = (ROOT / "problems" / f"trunk_{n}cables.yaml").read_text()
    if quick:
        text = text.replace("resolution: 1.0", "resolution: 0.5")
    return cw.problem_from_dict(__import__("yaml").safe_load(text), f"problems/trunk_{n}cables.yaml", ROOT)


def forward_sampler(problem, n_d, n_lines, seed=0):
    """A function timing the n_d grid once: (time per point in one process, points, failures), measured on
    consecutive grid lines as the full sweep visits them: in a random plane of the last two actuators,
    n_lines + 1 lines in snake order; the first one (a cold start, which a full sweep pays once per worker
    slice) is timed apart and left out."""
    model = cw.StaticModel(problem)
    rng = np.random.default_rng(seed)
    axis = np.linspace(0.0, 1.0, n_d)
    fixed = rng.integers(0, n_d, size=problem.n_u - 2)
    k0 = int(rng.integers(0, n_d - n_lines - 1))
    lines = []
    for i, k in enumerate(range(k0, k0 + n_lines + 1)):
        last = axis if i % 2 == 0 else axis[::-1]
        frac = np.column_stack([np.tile(axis[fixed], (n_d, 1)), np.full(n_d, axis[k]), last])
        lines.append(model.u_min + frac * (model.u_max - model.u_min))
    settings = ForwardSettings(n_d=n_d, progress=False)
    with one_blas_thread():
        sweep(model, lines[0][:2], settings)  # loads the compiled kernels, which a cold line must not be charged

    def once():
        with one_blas_thread():
            t0 = time.perf_counter()
            sweep(model, lines[0], settings)
            t_first = time.perf_counter() - t0
            t0 = time.perf_counter()
            status = sweep(model, np.vstack(lines), settings).status
            t_all = time.perf_counter() - t0
        points = n_lines * n_d
        return (t_all - t_first) / points, points, int(np.sum(status[n_d:] != 0))

    return once


def sample_forward(problems: dict, n_d, n_lines, repeats):
    """{n_u: forward_sampler's result} for every problem, each the fastest of ``repeats`` rounds that take
    the problems in turn. Why: a few lines timed beside other processes (the tests) came out 4x off either
    way, and a load that changes between one problem's timing and the next's moves their ratio; contention
    only ever adds time, and in turns every problem meets the same load. A round whose time per point is not
    positive is taken only if no other is."""
    samplers = {n: forward_sampler(pb, n_d, n_lines) for n, pb in problems.items()}
    best = {}
    for _ in range(repeats):
        for n, once in samplers.items():
            r = once()
            # a stall during the first line alone (timed apart and subtracted) can leave a round's time per
            # point at or below zero (seen: -18 ms beside another test run): never the fastest one
            if n not in best or r[0] > 0 and (best[n][0] <= 0 or r[0] < best[n][0]):
                best[n] = r
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="coarse mesh, grids and steps: a few minutes")
    ap.add_argument("--out", default=str(ROOT / "results" / "paper"))
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    q = args.quick
    n_full = 11 if q else 100  # forward n_d of the publication (2 cables in full)
    coarse = {2: 11 if q else 100, 3: 5 if q else 15, 4: 4 if q else 8}
    lines = 2 if q else 10
    step = 0.008 if q else 0.004

    rows, agreement = [], {}
    t_start = time.perf_counter()
    # per point measured the same way for every n_u (warm, one process), so the claim compares like with like
    samples = sample_forward({n: load(n, q) for n in (2, 3, 4)}, n_full, lines, repeats=5 if q else 2)
    for n in (2, 3, 4):
        pb = load(n, q)
        print(f"--- {n} cables: {pb.mesh.n_nodes} nodes", flush=True)
        # forward: the comparison cloud (n_d = 100 in full for 2 cables)
        fw = forward(pb, settings=ForwardSettings(n_d=coarse[n], workers=args.workers, progress=False))
        fw.save(out / f"forward_{n}cables")
        per_point = samples[n][0]
        if coarse[n] == n_full:
            fw_time, fw_ops, estimated = fw.timings["total"], fw.counters["points"], False
        else:
            fw_ops = n_full**n
            fw_time = per_point * fw_ops / args.workers  # with the same number of processes
            estimated = True
        fb = forward_backward(pb, FBSettings(step=step, workers=args.workers, progress=False))
        fb.save(out / f"fb_{n}cables")
        agreement[n] = compare(fw, fb)
        three_views([fw, fb], out / f"three_views_{n}cables.png", pb.mesh,
                    title=f"Scenario {n - 1}: {n} cables - forward (blue, n_d = {coarse[n]}) vs "
                          f"forward-backward (gray cells, red points, s = {step * 1e3:g} mm)")
        rows.append(dict(n_u=n, fw_ops=fw_ops, fw_time=fw_time, fw_estimated=estimated, fw_per_point=per_point,
                         fb_feasible=fb.counters["feasible"], fb_explored=fb.counters["explored"],
                         fb_iterations=fb.counters["iterations"], fb_time=fb.timings["total"],
                         fw_cloud_nd=coarse[n], fw_cloud_points=fw.n_points, fw_cloud_time=fw.timings["total"]))
        print(json.dumps(rows[-1]), json.dumps(agreement[n]), flush=True)

    write_table(out, rows)
    write_fig14(out, rows)
    write_report(out, rows, agreement, args, time.perf_counter() - t_start, step, n_full)
    print(f"wrote {out}/: table1.md table1.csv fig14_operations.png fig14_time.png three_views_*.png report.md")


def write_table(out, rows):
    head = ["scenario", "n_u", "forward operations", "forward-backward operations (feasible W_Es)",
            "forward time (s)", "forward-backward time (s)", "paper forward ops", "paper FB ops",
            "paper forward time (s)", "paper FB time (s)", "speed-up vs paper FB", "forward / FB time (ours)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    csv = [",".join(head)]
    for i, r in enumerate(rows):
        p = PAPER[r["n_u"]]
        est = "≈ " if r["fw_estimated"] else ""
        vals = [str(i + 1), str(r["n_u"]), f"{r['fw_ops']:.0e}", str(r["fb_feasible"]),
                f"{est}{r['fw_time']:.3g}", f"{r['fb_time']:.1f}", f"{p[0]:.0e}", str(p[1]), f"{p[2]:.3g}",
                f"{p[3]:.0f}", f"{p[3] / r['fb_time']:.0f}x", f"{r['fw_time'] / r['fb_time']:.3g}"]
        lines.append("| " + " | ".join(vals) + " |")
        csv.append(",".join(v.replace("≈ ", "~") for v in vals))
    lines.append("")
    lines.append("≈: extrapolated from a measured sample of the n_d = 100 grid, as in the publication.")
    (out / "table1.md").write_text("\n".join(lines) + "\n")
    (out / "table1.csv").write_text("\n".join(csv) + "\n")


def write_fig14(out, rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    nu = [r["n_u"] for r in rows]
    for what, ours_fw, ours_fb, paper_fw, paper_fb, ylabel in (
            ("operations", [r["fw_ops"] for r in rows], [r["fb_feasible"] for r in rows],
             [PAPER[n][0] for n in nu], [PAPER[n][1] for n in nu], "operations"),
            ("time", [r["fw_time"] for r in rows], [r["fb_time"] for r in rows],
             [PAPER[n][2] for n in nu], [PAPER[n][3] for n in nu], "time (s)")):
        fig, ax = plt.subplots(figsize=(6, 4.5))
        ax.semilogy(nu, ours_fw, "o-", color="tab:blue", label="forward (casadi-ws)")
        ax.semilogy(nu, ours_fb, "s-", color="tab:red", label="forward-backward (casadi-ws)")
        ax.semilogy(nu, paper_fw, "o--", color="tab:blue", alpha=0.45, label="forward (publication)")
        ax.semilogy(nu, paper_fb, "s--", color="tab:red", alpha=0.45, label="forward-backward (publication)")
        for r, y in zip(rows, ours_fw):
            if r["fw_estimated"]:
                ax.annotate("estimate", (r["n_u"], y), textcoords="offset points", xytext=(5, -12), fontsize=8)
        ax.set_xticks(nu)
        ax.set_xlabel("number of actuators n_u")
        ax.set_ylabel(ylabel)
        ax.set_title(f"Fig. 14: {what} vs n_u")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / f"fig14_{what}.png", dpi=130)
        plt.close(fig)


def write_report(out, rows, agreement, args, total, step, n_full):
    import casadi
    import scipy

    fw_growth = [rows[i + 1]["fw_ops"] / rows[i]["fw_ops"] for i in range(2)]
    fb_growth = [rows[i + 1]["fb_feasible"] / rows[i]["fb_feasible"] for i in range(2)]
    fbt_growth = [rows[i + 1]["fb_time"] / rows[i]["fb_time"] for i in range(2)]
    per_point = [r["fw_per_point"] for r in rows]
    claims = []  # (claim, holds, text)

    def claim(name, holds, text):
        claims.append({"claim": name, "holds": bool(holds), "text": text.replace("{verdict}", "holds" if holds
                                                                              else "does NOT hold")})

    # the claim is about growth: a time per point that rises with n_u makes the time grow faster still, so it
    # fails only if the time per point falls by more than 3x per added actuator (growth below n_d / 3)
    pp_growth = [per_point[i + 1] / per_point[i] for i in range(2)]
    claim("forward time grows as n_d^n_u", min(pp_growth) > 1 / 3,
          f"Forward operations grow as n_d^n_u: x{fw_growth[0]:.0f} and x{fw_growth[1]:.0f} per added "
          f"actuator (n_d = {n_full}), by construction. The forward time per point (warm, one process) goes "
          + " -> ".join(f"{p * 1e3:.1f}" for p in per_point) + " ms, so forward time grows "
          f"x{fw_growth[0] * pp_growth[0]:.0f} and x{fw_growth[1] * pp_growth[1]:.0f} per added actuator, of the "
          "order of n_d (the claim fails if it falls below n_d / 3): {verdict}.")
    claim("forward-backward grows much more slowly", all(g < 10 for g in fb_growth),
          f"Forward-backward operations grow much more slowly: x{fb_growth[0]:.1f} and "
          f"x{fb_growth[1]:.1f} per added actuator (time x{fbt_growth[0]:.1f}, x{fbt_growth[1]:.1f}): "
          "{verdict}. They grow with the workspace's size, which grows "
          "with n_u here too (a 2-cable workspace is a surface, a 3- or 4-cable one a volume), so the "
          "growth is not flat as Fig. 14 suggests but far below the forward method's.")
    for n, a in agreement.items():
        ok = a["cells_a_in_b"] >= 0.98
        claim(f"{n} cables: the two workspaces coincide", ok,
              f"{n} cables, the two workspaces coincide: forward-backward reports {a['cells_both']} of the "
              f"{a['cells_a']} grid cells the forward cloud occupies (strict recall {a['cells_a_in_b']:.3f}), "
              f"{100 * a['points_a_in_b_cells']:.1f} % of the forward points lie in its cells, Hausdorff "
              f"{a['hausdorff'] * 1e3:.2f} mm: {{verdict}}" + ("." if ok else " (recall below 0.98)."))
    (out / "claims.json").write_text(json.dumps(claims, indent=2) + "\n")
    nodes = load(2, args.quick).mesh
    text = f"""# Reproduction of the publication's Section 6 {'(quick mode)' if args.quick else ''}

Generated by `scripts/reproduce_paper.py{' --quick' if args.quick else ''}` (`make paper`) in {total / 60:.1f} min.

Machine: {platform.processor() or platform.machine()}, {__import__('os').cpu_count()} cores, Python
{platform.python_version()}, CasADi {casadi.__version__}, NumPy {np.__version__}, SciPy {scipy.__version__};
{args.workers} worker processes. Mesh: generated trunk, {nodes.n_nodes} nodes, {nodes.n_tets} tetrahedra
(corotational, E = 18 MPa, nu = 0.45, gravity). Forward-backward: uniform grid step {step * 1e3:g} mm, default
settings. The publication used an Intel Xeon at 3.5 GHz, 16 GB.

## Table 1

{(out / 'table1.md').read_text()}
Forward-backward detail (ours vs publication):

| n_u | iterations | explored W_Ed | feasible W_Es |
|---|---|---|---|
""" + "\n".join(f"| {r['n_u']} | {r['fb_iterations']} ({PAPER_FB_DETAIL[r['n_u']][0]}) | {r['fb_explored']} "
                 f"({PAPER_FB_DETAIL[r['n_u']][1]}) | {r['fb_feasible']} ({PAPER[r['n_u']][1]}) |" for r in rows) + f"""

The grid step of the publication is not given, so the counts compare in kind, not one to one.

## Claims, tested by the data

{chr(10).join("- " + c["text"] for c in claims)}

## Agreement (forward cloud vs forward-backward cells)

Strict measures on the forward-backward grid first (`casadi_ws.compare`): the share of the cells the forward
cloud occupies that forward-backward reports (recall), the share of forward points lying in reported cells,
and the share of reported cells holding a forward point; then the lenient ones, labelled.

| n_u | forward cloud (n_d, points) | forward cells | FB cells | recall (strict) | forward points in FB cells | FB cells with a forward point | coverage within one cell | precision within one cell | Hausdorff (mm) | cells × s³ forward (cm^3) | cells × s³ FB (cm^3) |
|---|---|---|---|---|---|---|---|---|---|---|---|
""" + "\n".join(f"| {n} | {r['fw_cloud_nd']}, {r['fw_cloud_points']} | {a['cells_a']} | {a['cells_b']} | "
                 f"{a['cells_a_in_b']:.3f} | {a['points_a_in_b_cells']:.3f} | {a['cells_b_in_a']:.3f} | "
                 f"{a['coverage_within_one_cell']:.3f} | {a['precision_within_one_cell']:.3f} | "
                 f"{a['hausdorff'] * 1e3:.2f} | {a['cell_volume_a'] * 1e6:.3f} | {a['cell_volume_b'] * 1e6:.3f} |"
                 for (n, a), r in zip(agreement.items(), rows)) + """

The cells × s³ columns count occupied grid cells (one cell thick for the 2-cable surface): not volumes of the workspace. A forward cloud coarser than the
grid leaves cells between its points empty, so its volume and the share of FB cells holding a forward point
understate the agreement; the recall does not depend on that.

## Figures

- `fig14_operations.png`, `fig14_time.png`: Fig. 14, ours (solid) and the publication's (dashed).
- `three_views_{2,3,4}cables.png`: Figs. 11-13.
- Result directories `forward_*`, `fb_*` (points.csv, points.vtu, cells.vtu, boundary.vtu for ParaView).
"""
    (out / "report.md").write_text(text)


if __name__ == "__main__":
    main()
