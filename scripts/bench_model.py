"""Cost of the static model's building blocks on the shipped trunk problems.

    python scripts/bench_model.py [--resolution R ...]

Records in BENCHMARKS.md: model build time, f_int and K evaluation, one LU factorisation and one solve of
K, and one warm-started equilibrium after a 1 N step of one cable.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import casadi_ws as cw
from casadi_ws.io.problem import DEFAULT_PROBLEM
from benchlib import best_of, machine, write_section
from casadi_ws.solvers.equilibrium import factorize


def measure(resolution: float, model_name: str) -> dict:
    d = dict(DEFAULT_PROBLEM)
    d["mesh"] = {**d["mesh"], "resolution": resolution}
    d["material"] = {**d["material"], "model": model_name}
    pb = cw.problem_from_dict(d, "<bench>")
    t = time.perf_counter()
    m = cw.StaticModel(pb)
    build = time.perf_counter() - t
    u = np.array([40.0, 20.0])
    eq = cw.solve_equilibrium(m, u)
    q = eq.q
    f_int = best_of(lambda: m.internal_force(q), 20)
    K_el = best_of(lambda: m.element_stiffness(q), 10)
    _, K, _ = m.residual_and_tangent(q, u)
    full = best_of(lambda: m.residual_and_tangent(q, u), 10)
    fac = best_of(lambda: factorize(K), 5)
    lu = factorize(K)
    b = np.ones(m.n_free)
    solve = best_of(lambda: lu.solve(b), 20)
    step = np.array([41.0, 20.0])
    warm = best_of(lambda: cw.solve_equilibrium(m, step, q0=q, u0=u), 5)
    w = cw.solve_equilibrium(m, step, q0=q, u0=u)
    warm_fac = best_of(lambda: cw.solve_equilibrium(m, step, q0=q, u0=u, fac=eq.factorization), 5)
    wf = cw.solve_equilibrium(m, step, q0=q, u0=u, fac=eq.factorization)
    return dict(res=resolution, mat=model_name, nodes=pb.mesh.n_nodes, tets=pb.mesh.n_tets, dofs=m.n_free,
                nnz=K.nnz, backend=m.backend, build=build, f=f_int, K_el=K_el, full=full, fac=fac, solve=solve,
                warm=warm, warm_its=w.iterations, warm_nfac=w.factorizations, warm_fac=warm_fac,
                warm_fac_its=wf.iterations, warm_fac_nfac=wf.factorizations)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--resolution", type=float, nargs="+", default=[1.0, 1.5])
    ap.add_argument("--materials", nargs="+", default=["corotational", "neohookean", "linear"])
    args = ap.parse_args()
    rows = []
    for r in args.resolution:
        for mat in args.materials:
            rows.append(measure(r, mat))
            print(rows[-1])
    ms = lambda s: f"{1e3 * s:.2f}"
    lines = [
        "## Static model (issue: foundation) — `scripts/bench_model.py`",
        "",
        f"Machine: {machine()}.",
        "Problem: the built-in 2-cable trunk (`problems/trunk_2cables.yaml`) at the given mesh resolution, "
        "state = the equilibrium at u = (40, 20) N; the warm-started solve is u = (41, 20) N from it. "
        "Times are the best of several runs, in milliseconds; element kernels compiled to C (`backend`).",
        "",
        "| resolution | material | nodes / tets | free dofs | nnz(K) | build model | f_int | K (elements) | R, K, dR/du with cables | LU factorise K | LU solve | warm solve, fresh LU (its / LUs) | warm solve, reused LU (its / LUs) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['res']} | {r['mat']} | {r['nodes']} / {r['tets']} | {r['dofs']} | {r['nnz']} | {ms(r['build'])} "
            f"| {ms(r['f'])} | {ms(r['K_el'])} | {ms(r['full'])} | {ms(r['fac'])} | {ms(r['solve'])} "
            f"| {ms(r['warm'])} ({r['warm_its']} / {r['warm_nfac']}) | {ms(r['warm_fac'])} ({r['warm_fac_its']} / {r['warm_fac_nfac']}) |")
    lines += ["", "Build time includes generating and (first time on a machine) compiling the element kernels; "
              "later runs load them from the cache."]
    write_section("model", "\n".join(lines))


if __name__ == "__main__":
    main()
