"""Time per solve of the NLP library's problems on the shipped 2-cable trunk, and of an equilibrium by
casadi.rootfinder against the built-in Newton.

    python scripts/bench_nlp.py [--resolution 1.0] [--write]

- ``reach``: from the rest equilibrium to 8 targets (tips of random inputs, 3 mm off them so some are
  not reachable), each solve from rest as the command line does; the first solve (building the solver)
  is reported apart.
- ``backward``: the forward-backward's backward problem (8) by IPOPT, from an equilibrium to targets one
  grid step (4 mm) away in each of the 6 neighbour directions.
- ``equilibrium``: a 5 N step of both cables from an equilibrium, by each Newton (``solver.newton``).
Uses only the public API, so the same script times an older checkout (PYTHONPATH=that checkout).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import casadi_ws as cw
from casadi_ws.io.problem import DEFAULT_PROBLEM
from casadi_ws.workspace.backward import backward


def _problem(resolution: float, newton: str | None = None):
    d = dict(DEFAULT_PROBLEM)
    d["mesh"] = {**d["mesh"], "resolution": resolution}
    if newton:
        d["solver"] = {**(d.get("solver") or {}), "newton": newton}
    return cw.problem_from_dict(d, "<bench>")


def measure(resolution: float, newton: bool) -> dict:
    m = cw.StaticModel(_problem(resolution))
    rng = np.random.default_rng(0)
    targets = []
    for _ in range(9):
        u = rng.uniform(m.u_min, m.u_max)
        targets.append(cw.solve_equilibrium(m, u).tip + rng.normal(size=3) * 0.003)
    out = {"n_free": int(m.n_free)}

    t = time.perf_counter()
    first = cw.reach(m, targets[0])
    out["reach_first_s"] = time.perf_counter() - t
    times, its = [], []
    for tg in targets[1:]:
        t = time.perf_counter()
        r = cw.reach(m, tg)
        times.append(time.perf_counter() - t)
        its.append(r.iterations)
    out["reach_s"] = float(np.mean(times))
    out["reach_iterations"] = float(np.mean(its))
    out["reach_first_iterations"] = first.iterations

    eq = cw.solve_equilibrium(m, np.array([40.0, 20.0]))
    settings = cw.BackwardSettings(formulation="ipopt")
    backward(m, eq.tip + [0.004, 0, 0], eq.q, eq.u, settings=settings)  # builds the solver
    times, its = [], []
    for d in np.vstack([np.eye(3), -np.eye(3)]) * 0.004:
        t = time.perf_counter()
        b = backward(m, eq.tip + d, eq.q, eq.u, settings=settings)
        times.append(time.perf_counter() - t)
        its.append(b.iterations)
    out["backward_ipopt_s"] = float(np.mean(times))
    out["backward_ipopt_iterations"] = float(np.mean(its))

    if newton:
        for kind in ("builtin", "rootfinder"):
            mk = cw.StaticModel(_problem(resolution, kind))
            e0 = cw.solve_equilibrium(mk, np.array([40.0, 20.0]))
            steps = [np.array([45.0, 25.0]), np.array([35.0, 15.0]), np.array([45.0, 15.0])]
            cw.solve_equilibrium(mk, steps[0], q0=e0.q, u0=e0.u)  # builds the rootfinder
            times = []
            for u in steps:
                t = time.perf_counter()
                e = cw.solve_equilibrium(mk, u, q0=e0.q, u0=e0.u)
                times.append(time.perf_counter() - t)
                assert e.converged
            out[f"equilibrium_{kind}_s"] = float(np.mean(times))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--no-newton", action="store_true", help="skip the rootfinder comparison (older checkouts)")
    ap.add_argument("--write", action="store_true", help="write the section of BENCHMARKS.md")
    args = ap.parse_args()
    res = measure(args.resolution, not args.no_newton)
    print(json.dumps(res, indent=1))
    if args.write:
        from benchlib import machine, write_section

        body = [f"## NLP library and rootfinder (issue: CasADi-native model) — `scripts/bench_nlp.py`", "",
                f"Machine: {machine()}. Shipped 2-cable trunk, mesh resolution {args.resolution} "
                f"({res['n_free']} free dofs), corotational, IPOPT with MUMPS, one process.", "",
                "| measure | value |", "|---|---|"]
        body += [f"| {k} | {v:.4g} |" if isinstance(v, float) else f"| {k} | {v} |" for k, v in res.items()]
        write_section("nlp", "\n".join(body))


if __name__ == "__main__":
    main()
