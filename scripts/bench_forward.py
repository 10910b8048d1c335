"""Forward method on the 2-cable trunk with n_d = 100 (10^4 equilibria), as in the publication's Section 6.1.

    python scripts/bench_forward.py [--nd 100] [--workers 1] [--resolution 1.0]

Records in BENCHMARKS.md the total time, time per point, Newton iterations and factorisations per point,
and, measured in the same run on the same mesh, the time of one sparse LU factorisation + solve of K.
"""

from __future__ import annotations

import argparse

import numpy as np

import casadi_ws as cw
from casadi_ws.io.problem import DEFAULT_PROBLEM
from benchlib import best_of, machine, write_section
from casadi_ws.solvers.equilibrium import factorize
from casadi_ws.workspace.forward import ForwardSettings, forward, line_stride


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--nd", type=int, default=100)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--predictor", default="extrapolate")
    ap.add_argument("--stride", type=int, default=None, help="default: ForwardSettings' (n_d // 6, <= 8)")
    ap.add_argument("--section", default="forward")
    args = ap.parse_args()
    d = dict(DEFAULT_PROBLEM)
    d["mesh"] = {**d["mesh"], "resolution": args.resolution}
    pb = cw.problem_from_dict(d, "problems/trunk_2cables.yaml")
    model = cw.StaticModel(pb)
    eq = cw.solve_equilibrium(model, [50.0, 50.0])
    _, K, _ = model.residual_and_tangent(eq.q, [50.0, 50.0])
    b = np.ones(model.n_free)
    t_fac = best_of(lambda: factorize(K).solve(b), 5)
    settings = ForwardSettings(n_d=args.nd, workers=args.workers, predictor=args.predictor, stride=args.stride,
                               progress=True)
    res = forward(pb, settings=settings, model=model if args.workers == 1 else None)
    c, t = res.counters, res.timings
    n = c["points"]
    stride = line_stride(settings, args.nd)
    body = "\n".join([
        f"## Forward method (issue: forward) — `scripts/bench_forward.py --nd {args.nd} --workers {args.workers}`",
        "",
        f"Machine: {machine()}.",
        f"Problem: `trunk_2cables` (corotational, E = 18 MPa, nu = 0.45, gravity), mesh resolution {args.resolution}: "
        f"{pb.mesh.n_nodes} nodes, {pb.mesh.n_tets} tetrahedra, {model.n_free} free dofs; U = [0, 100] N^2, "
        f"n_d = {args.nd} ({n} equilibria), predictor `{args.predictor}`, stride {stride}, tolerance {pb.solver.tolerance:g} "
        f"(relative residual), {args.workers} worker process(es).",
        "",
        "| quantity | value |",
        "|---|---|",
        f"| total time (model build + sweep) | {t['total']:.1f} s |",
        f"| sweep time | {t['sweep']:.1f} s |",
        f"| time per point (wall) | {1e3 * t['sweep'] / n:.1f} ms |",
        f"| points solved by Newton / verified by interpolation (of which then Newton) | {c['solves'] - c['interpolation_failed']} / {c['interpolated']} ({c['interpolation_failed']}) |",
        f"| Newton iterations per point | {c['newton_iterations'] / n:.2f} |",
        f"| LU factorisations per point | {c['factorizations'] / n:.2f} |",
        f"| failed points | {res.n_failed} |",
        f"| one LU factorisation + solve of K (same mesh, same run) | {1e3 * t_fac:.1f} ms |",
        f"| per-point cost / one factorisation | {t['sweep'] / n / t_fac * args.workers:.2f} (per core) |",
        "| publication (Section 6.1, Intel Xeon 3.5 GHz) | 1463 s for 10^4 points |",
        "",
        f"Maps: `{settings.maps}` (every point's steerability and compliance from a double-precision LU at its "
        f"state polished by one Newton step, the default; `maps: interpolated` takes the Newton points' LUs only).",
    ])
    write_section(args.section, body, figure=f"{t['total']:.1f} s for {n} equilibria ({1e3 * t['sweep'] / n:.1f} ms "
                                              f"per point, {args.workers} workers, maps {settings.maps}), against the "
                                              f"publication's 1463 s")


if __name__ == "__main__":
    main()
