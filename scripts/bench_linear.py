"""The linear solvers (solvers/linear.py) at the sizes users have: factorisations, one equilibrium, and
forward-backward, SuperLU against PARDISO in the same run.

    python scripts/bench_linear.py                 # everything (~30 min on 2 cores), then BENCHMARKS.md
    python scripts/bench_linear.py --only fact     # one part: fact | eq | fb | fine
    python scripts/bench_linear.py --only mumps    # MUMPS (CasADi's Linsol) against PARDISO and SuperLU: own section
    python scripts/bench_linear.py --write         # BENCHMARKS.md's section from results/bench_linear.json

Meshes: the shipped 2-cable trunk with linear tetrahedra (resolution 1.0: 2646 free dofs) and with 10-node
ones at resolution 0.5 (4374), 1.0 (18252: problems/trunk_2cables_fine.yaml) and 1.5 (~52k, factorisation
only). Each scenario runs in a fresh process, so that its peak memory (the process and its workers,
ru_maxrss) is its own.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from benchlib import machine, peak_mb, run_in_fresh_process, trunk_variant, write_section

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "results" / "bench_linear.json"
U = np.array([40.0, 20.0])
MESHES = {"linear, res 1.0": (1, 1.0), "10-node, res 0.5": (2, 0.5), "10-node, res 1.0": (2, 1.0),
          "10-node, res 1.5": (2, 1.5)}
FB_PROBLEMS = ["trunk_2cables_order2"]  # symmetric K; the 4-node trunks' unsymmetric K stays on SuperLU (auto)


def fact(mesh: str) -> dict:
    """K at the equilibrium at U, factorised by each backend and precision, with 1 and 2 threads."""
    from threadpoolctl import threadpool_limits

    from casadi_ws import StaticModel, solve_equilibrium
    from casadi_ws.solvers.linear import factorize

    m = StaticModel(trunk_variant(None, *MESHES[mesh], linear="pardiso"))
    eq = solve_equilibrium(m, U)
    K = m.residual_and_tangent(eq.q, eq.u)[1].tocsc()
    b = np.random.default_rng(0).standard_normal(K.shape[0])
    row = {"dofs": int(K.shape[0]), "nnz": int(K.nnz)}
    for solver in ("superlu", "pardiso"):
        for single in ((True, False) if solver == "superlu" else (False,)):  # PARDISO: double precision always
            for threads in ((1,) if solver == "superlu" else (1, 2)):
                if solver == "superlu" and K.shape[0] > 30000 and not single:
                    continue  # minutes per factorisation: the single-precision row says enough
                with threadpool_limits(threads, user_api="blas"):
                    factorize(K, single, solver=solver)  # the ordering / analysis of the pattern, once
                    times = []
                    for _ in range(2 if K.shape[0] > 30000 else 3):
                        t = time.perf_counter()
                        lu = factorize(K, single, solver=solver)
                        times.append(time.perf_counter() - t)
                    t = time.perf_counter()
                    x = lu.solve(b)
                    ts = time.perf_counter() - t
                key = f"{solver} {'single' if single else 'double'} {threads}t"
                row[key] = {"factorise": min(times), "solve": ts,
                            "error": float(np.linalg.norm(K @ x - b) / np.linalg.norm(b))}
                del lu
    row["peak_mb"] = peak_mb()
    return row


def mumps(mesh: str) -> dict:
    """K at the equilibrium at U factorised by MUMPS through CasADi's ``Linsol`` (unsymmetric and symmetric
    mode), by PARDISO and by SuperLU (double precision), one thread each; best of 3 after a first one."""
    import casadi as ca
    from threadpoolctl import threadpool_limits

    from casadi_ws import StaticModel, solve_equilibrium
    from casadi_ws.solvers.linear import factorize

    m = StaticModel(trunk_variant(None, *MESHES[mesh], linear="pardiso"))
    e = solve_equilibrium(m, U)
    K = m.residual_and_tangent(e.q, e.u)[1].tocsc()
    K.sort_indices()
    n = K.shape[0]
    b = np.random.default_rng(0).standard_normal(n)
    row = {"dofs": int(n), "nnz": int(K.nnz)}
    pattern = ca.Sparsity(n, n, K.indptr.tolist(), K.indices.tolist())
    Kdm = ca.DM(pattern, K.data)
    with threadpool_limits(1, user_api="blas"):
        for symmetric in (False, True):
            ls = ca.Linsol("mumps", "mumps", pattern, {"symmetric": symmetric})
            ls.sfact(Kdm)
            times = []
            for _ in range(4):
                t = time.perf_counter()
                ls.nfact(Kdm)
                times.append(time.perf_counter() - t)
            t = time.perf_counter()
            x = np.array(ls.solve(Kdm, ca.DM(b))).ravel()
            row[f"mumps {'symmetric' if symmetric else 'unsymmetric'}"] = {
                "factorise": min(times[1:]), "solve": time.perf_counter() - t,
                "error": float(np.linalg.norm(K @ x - b) / np.linalg.norm(b))}
            del ls
        for solver in ("pardiso", "superlu"):
            factorize(K, solver=solver)
            times = []
            for _ in range(3):
                t = time.perf_counter()
                lu = factorize(K, solver=solver)
                times.append(time.perf_counter() - t)
            t = time.perf_counter()
            lu.solve(b)
            row[solver] = {"factorise": min(times), "solve": time.perf_counter() - t}
    row["peak_mb"] = peak_mb()
    return row


def write_mumps(res: dict) -> None:
    lines = [f"{res['machine']}; `scripts/bench_linear.py --only mumps`, one fresh process per mesh, one thread. "
             "K as in the section above (the 2-cable trunk's tangent at u = (40, 20) N, 10-node corotational: "
             "symmetric). MUMPS is CasADi's (`casadi.Linsol(..., 'mumps', ...)`, the solver CasADi 3.8.2's wheel "
             "ships; its analysis once per pattern, `nfact` timed); PARDISO as `solver.linear: pardiso` "
             "(L D L^T); SuperLU in double precision.", "",
             "| mesh | dofs | nnz(K) | MUMPS unsymmetric: factorise / solve | MUMPS symmetric: factorise / solve "
             "| PARDISO: factorise / solve | SuperLU double: factorise / solve |", "|---|---|---|---|---|---|---|"]
    for k, r in res.get("mumps", {}).items():
        def pair(key):
            return f"{1e3 * r[key]['factorise']:.0f} / {1e3 * r[key]['solve']:.1f} ms"
        lines.append(f"| {k} | {r['dofs']} | {r['nnz'] / 1e6:.2f} M | {pair('mumps unsymmetric')} | "
                     f"{pair('mumps symmetric')} | {pair('pardiso')} | {pair('superlu')} |")
    lines += ["", "MUMPS' symmetric factorisation is as fast as PARDISO's at 4k dofs, slower at 18k and faster at "
              "47k (within ~15 % each way). But a solve through CasADi's interface costs as much as the "
              "factorisation, where PARDISO's costs 1/20 to 1/45 of it, and Newton, the sensitivities and the "
              "curvature make 5-15 solves per factorisation. So MUMPS would not pay without a binding of its "
              "own, and PARDISO stays the backend for symmetric K (`auto`).", "",
              "PARDISO's own settings, tried by hand the same day on the same K (iparm; factorisation, best of 4): "
              "AMD instead of METIS 21.2 against 23.5 ms at 4374 dofs and 286 against 277 ms at 18252; "
              "without the two-level factorisation, 21.9 and 272 ms; parallel nested dissection 22.9 and 275 ms; "
              "iparm[23] = 10 111.7 and 280 ms. None is beyond the run-to-run spread except the last, which is "
              "worse, so METIS stays."]
    write_section("linear-mumps", "## MUMPS against PARDISO and SuperLU (issue: accurate models at interactive "
                  "speed) — `scripts/bench_linear.py --only mumps`\n\n" + "\n".join(lines) + "\n")


def eq(mesh: str, solver: str) -> dict:
    """One equilibrium from rest at U (the issue's measurement), kernels compiled beforehand."""
    from casadi_ws import StaticModel, solve_equilibrium

    m = StaticModel(trunk_variant(None, *MESHES[mesh], linear=solver))
    solve_equilibrium(m, np.array([1.0, 1.0]))  # first factorisation of the pattern: ordering / analysis
    t = time.perf_counter()
    e = solve_equilibrium(m, U)
    return {"time": time.perf_counter() - t, "iterations": e.iterations, "lus": e.factorizations,
            "converged": bool(e.converged), "dofs": int(m.n_free), "peak_mb": peak_mb()}


def fb(name: str, solver: str) -> dict:
    from casadi_ws import StaticModel
    from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

    pb = trunk_variant(name, linear=solver)
    m = StaticModel(pb)
    t = time.perf_counter()
    r = forward_backward(pb, FBSettings(progress=False, workers=2), model=m)
    dt = time.perf_counter() - t
    return {"time": dt, "cells": int(len(r.points)), "dofs": int(m.n_free), "peak_mb": peak_mb(),
            "counters": {k: v for k, v in r.counters.items() if isinstance(v, (int, float))}}


def _run_one(args) -> dict:
    return run_in_fresh_process(__file__, args)


def run(only: str | None) -> dict:
    res = json.loads(OUT.read_text()) if OUT.exists() else {}
    res["machine"] = machine()
    if only in (None, "fact"):
        res["fact"] = {k: _run_one(["fact", k]) for k in MESHES}
    if only in (None, "eq"):
        res["eq"] = {f"{k} {s}": _run_one(["eq", k, s]) for k in list(MESHES)[:3] for s in ("superlu", "auto")}
    if only in (None, "fb"):
        res["fb"] = {f"{p} {s}": _run_one(["fb", p, s]) for p in FB_PROBLEMS for s in ("superlu", "auto")}
    if only == "mumps":
        res["mumps"] = {k: _run_one(["mumps", k]) for k in list(MESHES)[1:]}
    if only in (None, "fine"):
        res["fine"] = {"trunk_2cables_fine auto": _run_one(["fb", "trunk_2cables_fine", "auto"])}
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(json.dumps(res, indent=1))
    return res


def _pairs(table: dict, keys, cell, memory: bool = False) -> list[str]:
    """Rows of SuperLU against auto for the keys both were run for."""
    rows = []
    for k in keys:
        a, b = table.get(f"{k} superlu"), table.get(f"{k} auto")
        if a and b:
            rows.append(f"| {k} | {a['dofs']} | {cell(a)} | {cell(b)} | {a['time'] / b['time']:.1f}x |"
                        + (f" {b['peak_mb']:.0f} MB |" if memory else ""))
    return rows


def write(res: dict) -> None:
    lines = [f"{res['machine']}; `scripts/bench_linear.py`, one fresh process per row (peak memory: the process and "
             "its workers). K is the tangent at the equilibrium at u = (40, 20) N of the 2-cable trunk "
             "(corotational: the 10-node K is symmetric to 1e-16 and PARDISO factorises it as symmetric indefinite; the "
             "4-node K is 0.5 % unsymmetric and gets PARDISO's LU).", "",
             "Factorisation of K (best of 3; the ordering / analysis of the pattern excluded: it is done once per "
             "model), and the solve error ||K x - b|| / ||b|| (single precision: before the refinement Newton "
             "and the sensitivities do):", "",
             "| mesh | dofs | nnz(K) | SuperLU single | SuperLU double | PARDISO (double) 1 / 2 threads | "
             "peak memory |", "|---|---|---|---|---|---|---|"]
    for k, r in res.get("fact", {}).items():
        def ms(key):
            return f"{1e3 * r[key]['factorise']:.0f} ms" if key in r else "—"
        lines.append(f"| {k} | {r['dofs']} | {r['nnz'] / 1e6:.2f} M | {ms('superlu single 1t')} | "
                     f"{ms('superlu double 1t')} | {ms('pardiso double 1t')} / {ms('pardiso double 2t')} | "
                     f"{r['peak_mb']:.0f} MB |")
    lines += ["", "One equilibrium from rest at u = (40, 20) N (Newton; 2 threads for PARDISO and the element "
              "kernels). `auto` is PARDISO for the 10-node trunks' symmetric K and SuperLU for the 4-node trunk's "
              "unsymmetric one:", "", "| mesh | dofs | SuperLU: time, its / LUs | auto: time, its / LUs | ratio |",
              "|---|---|---|---|---|"]
    lines += _pairs(res.get("eq", {}), MESHES, lambda r: f"{r['time']:.2f} s, {r['iterations']} / {r['lus']}")
    lines += ["", "Forward-backward at the default step, 2 worker processes (one thread each):", "",
              "| problem | dofs | SuperLU: time, cells | auto: time, cells | ratio | peak memory (auto) |",
              "|---|---|---|---|---|---|"]
    lines += _pairs(res.get("fb", {}), FB_PROBLEMS, lambda r: f"{r['time']:.1f} s, {r['cells']}", memory=True)
    for k, r in res.get("fine", {}).items():
        lines.append(f"| trunk_2cables_fine | {r['dofs']} | — | {r['time']:.1f} s, {r['cells']} | — | "
                     f"{r['peak_mb']:.0f} MB |")
    fb = {**res.get("fb", {}), **res.get("fine", {})}
    per_cell = [f"{k.split()[0]} ({k.split()[1]}): {r['counters'].get('factorizations', 0) / max(r['cells'], 1):.2f} "
                f"LUs and {r['time'] / max(r['cells'], 1):.2f} s per reached cell" for k, r in fb.items()]
    lines += ["", "Per reached cell (2 workers): " + "; ".join(per_cell) + ".",
              "", "Where the time went (py-spy, `trunk_2cables_order2` FB in one process, 2026-12-02): before the "
              "stiffness was built per quadrature point, element kernels 45 %, PARDISO factorisations 22 %, "
              "solves 15 % (181 s under the profiler); after it, factorisations 28 %, kernels 31 % (of which "
              "the tangent refined at each answer, 13 %), solves 19 % (147 s under the profiler, 144 s without, "
              "the same 965 cells and 1591 LUs). The 18k-dof FB had PARDISO 42 %, kernels 35 % before it.",
              "", "This run (2026-12-02 evening) had the machine to itself; the run of the same morning, which "
              "this section replaces, shared it with a test (its rows were 1.5-3x slower: 18k-dof equilibrium "
              "10.3 s, FB 1370 s and 221 s). The ratio of the kernel change alone is the one-process profile "
              "above (~1.25x on the 4374-dof FB); the rest of the difference is the load."]
    write_section("linear", "## Linear solvers (issue: accurate models at interactive speed) — "
                  "`scripts/bench_linear.py`\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=["fact", "eq", "fb", "fine", "mumps"])
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--one", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        kind, *rest = json.loads(a.one)
        print(json.dumps({"fact": fact, "eq": eq, "fb": fb, "mumps": mumps}[kind](*rest)))
    elif a.write:
        write(json.loads(OUT.read_text()))
    elif a.only == "mumps":
        write_mumps(run(a.only))
    else:
        write(run(a.only))
