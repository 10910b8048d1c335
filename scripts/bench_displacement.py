"""Displacement control against force control on the shipped 2-cable trunk: one equilibrium and the
forward-backward method, the same trunk driven by tensions in [0, 100] N or by shortenings in [0, s100]
(s100: a cable's shortening under 100 N alone, so both boxes reach about as far); plus the imported
SoftRobots finger and trunk (one equilibrium each).

    python scripts/bench_displacement.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from benchlib import best_of, machine

from casadi_ws import StaticModel, solve_equilibrium
from casadi_ws.io.problem import load_problem
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

REPO = Path(__file__).resolve().parents[1]


def main():
    print(machine())
    pf = load_problem(REPO / "problems" / "trunk_2cables.yaml")
    mf = StaticModel(pf)
    s100 = []
    for i in range(2):
        u = np.zeros(2)
        u[i] = 100.0
        s100.append(float((mf.rest_quantities - mf.actuator_states(solve_equilibrium(mf, u).q))[i]))
    pd = load_problem(REPO / "problems" / "trunk_2cables.yaml")
    for c, s in zip(pd.actuators, s100):
        c.control, c.u_min, c.u_max = "displacement", 0.0, s
    md = StaticModel(pd)
    print(f"s100 = {np.round(np.array(s100) * 1e3, 3)} mm")
    eq = solve_equilibrium(mf, np.array([60.0, 30.0]))
    d = mf.rest_quantities - mf.actuator_states(eq.q)
    for name, m, u in (("force", mf, np.array([60.0, 30.0])), ("displacement", md, d)):
        e = solve_equilibrium(m, u)
        t = best_of(lambda: solve_equilibrium(m, u), 3)
        print(f"one equilibrium from rest, {name}: {t * 1e3:.0f} ms, {e.iterations} iterations, {e.factorizations} LUs")
    for name, pb, m in (("force", pf, mf), ("displacement", pd, md)):
        t = time.perf_counter()
        fb = forward_backward(pb, FBSettings(step=0.004, progress=False), model=m)
        total = time.perf_counter() - t
        c = fb.counters
        print(f"FB {name}: {total:.1f} s ({fb.timings['boundary']:.1f} s boundary), {fb.n_points} cells, "
              f"{c['factorizations']} LUs ({c['factorizations_per_cell']:.2f}/cell), "
              f"{c['equilibrium_solves']} equilibria, volume {fb.measures.get('volume', float('nan')) * 1e6:.2f} cm3")
    for scene in ("finger/finger.yaml", "trunk/trunk.yaml"):
        p = load_problem(REPO / "problems" / "sofa" / scene)
        m = StaticModel(p)
        u = 0.5 * m.u_max if "finger" in scene else np.r_[0.3 * m.u_max[0], np.zeros(7)]
        t = time.perf_counter()
        e = solve_equilibrium(m, u)
        print(f"{scene}: u = {np.round(u * 1e3, 2)} mm: {e.status_name}, {time.perf_counter() - t:.2f} s, "
              f"{e.iterations} iterations, {e.factorizations} LUs")


if __name__ == "__main__":
    main()
