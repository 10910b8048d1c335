"""Convergence of linear (TET4) and quadratic (TET10) tetrahedra against closed forms: the table of
docs/methods.md ("Element order").

    python scripts/convergence_order.py [--n 1 2 3 4] [--out results/convergence_order.json]

Cases (tests/test_physics.py builds the same beams and checks the 2-element-across column):
- cable arc, kappa L = 1: a cable at offset d = 0.3 h along a square cantilever (L/h = 20), tension T bends
  it into a circular arc (tests/test_physics.py, arc_closed_form: the finite-strain reading of beam
  theory that each law implies);
- elastica, P L^2 / EI = 1 and 2: a dead tip load perpendicular to a square cantilever (L/h = 10, nu = 0),
  the elastica solved to 1e-10 by scipy's solve_bvp.
Error: |tip - closed form| / |closed-form tip displacement|. Time: one equilibrium from rest (continuation
included), one process.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))

from conftest import cantilever  # noqa: E402
from test_physics import arc_closed_form  # noqa: E402
from test_physics import elastica_case as physics_elastica  # noqa: E402

from casadi_ws import StaticModel, solve_equilibrium  # noqa: E402


def arc_case(n, model, order):
    E, L, slender = 1e6, 0.2, 20
    h = L / slender
    d = 0.3 * h
    I, A = h**4 / 12, h * h
    T = 1.0 / L * E * I / d
    pb = cantilever(n=n, slender=slender, model=model, nu=0.3, E=E, L=L, cable_offset=d, order=order)
    return pb, np.array([T]), arc_closed_form(T, d, E, I, A, L, model)


def elastica_case(n, model, order, PL2_EI):
    pb, exact = physics_elastica(n, PL2_EI, model, order)
    return pb, np.zeros(0), exact


CASES = {"arc kL=1": lambda n, m, o: arc_case(n, m, o),
         "elastica PL2/EI=1": lambda n, m, o: elastica_case(n, m, o, 1.0),
         "elastica PL2/EI=2": lambda n, m, o: elastica_case(n, m, o, 2.0)}


def run(ns, models, orders, cases=tuple(CASES)):
    rows = []
    for case in cases:
        make = CASES[case]
        for model in models:
            for order in orders:
                for n in ns:
                    pb, u, exact = make(n, model, order)
                    m = StaticModel(pb)
                    t = time.perf_counter()
                    eq = solve_equilibrium(m, u)
                    dt = time.perf_counter() - t
                    err = float(np.linalg.norm(eq.tip - exact) / np.linalg.norm(exact - pb.end_effector))
                    row = dict(case=case, material=model, order=order, n=n, dofs=int(m.n_free),
                               error=err if eq.converged else None, time_s=dt, newton=eq.iterations)
                    print(json.dumps(row), flush=True)
                    rows.append(row)
    return rows


def table(rows) -> str:
    out = ["| case | material | order | elements across | free dofs | tip error | time per equilibrium (s) |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        err = "failed" if r["error"] is None else f"{100 * r['error']:.2f} %"
        out.append(f"| {r['case']} | {r['material']} | {r['order']} | {r['n']} | {r['dofs']} | {err} | "
                   f"{r['time_s']:.2f} |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--materials", nargs="+", default=["corotational", "neohookean"])
    ap.add_argument("--orders", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--out", default="results/convergence_order.json")
    args = ap.parse_args()
    rows = run(args.n, args.materials, args.orders, args.cases)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(rows, indent=1))
    print(table(rows))


if __name__ == "__main__":
    main()
