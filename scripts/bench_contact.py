"""Contact against no contact, on the shipped contact problems: SoftRobots' finger under an egg
(problems/finger_object.yaml) and the 2-cable trunk pulled onto a table (problems/trunk_table.yaml).
Each is timed with its obstacles and with them removed (``obstacles = []``, the same problem otherwise):
one equilibrium (from rest, and warm-started from a neighbour), the forward method, and for the trunk
forward-backward at its default step. Self-contact: the pinch gripper (problems/pinch_gripper.yaml) with
its jaws' pair and without (``self_contact = []``): equilibria, the tangent's size and one LU, forward.

    python scripts/bench_contact.py [--self-contact-only]
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from benchlib import best_of, machine

from casadi_ws import StaticModel, solve_equilibrium
from casadi_ws.io.problem import load_problem
from casadi_ws.workspace.forward import ForwardSettings, forward
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

REPO = Path(__file__).resolve().parents[1]


def _pair(name):
    a = load_problem(REPO / "problems" / name)
    b = load_problem(REPO / "problems" / name)
    b.obstacles = []
    return (("with obstacles", a, StaticModel(a)), ("without", b, StaticModel(b)))


def equilibria(name, u, u_near):
    for label, _, m in _pair(name):
        e = solve_equilibrium(m, u)
        t_cold = best_of(lambda: solve_equilibrium(m, u), 3)
        near = solve_equilibrium(m, u_near)
        w = solve_equilibrium(m, u, q0=near.q, u0=u_near)
        t_warm = best_of(lambda: solve_equilibrium(m, u, q0=near.q, u0=u_near), 3)
        touching = sum(c["points"] for c in m.contacts(e.q))
        print(f"{name} {label} (free dofs {m.n_free}, contact points {m.n_con}): u = {u}: from rest "
              f"{t_cold * 1e3:.0f} ms ({e.iterations} it, {e.factorizations} LUs, {e.load_steps} load steps), "
              f"warm from {u_near} {t_warm * 1e3:.0f} ms ({w.iterations} it, {w.factorizations} LUs); "
              f"{touching} points pressing")


def workspaces(name, nd, fb):
    for label, pb, m in _pair(name):
        t = time.perf_counter()
        fw = forward(pb, nd, ForwardSettings(progress=False), model=m)
        t_fw = time.perf_counter() - t
        touching = int(np.count_nonzero(fw.maps()["contact"] > 0))  # pressing on an obstacle
        line = (f"{name} {label}: forward n_d = {nd}: {t_fw:.1f} s, {fw.n_points} points "
                f"({touching} in contact), {fw.n_failed} failed")
        if fb:
            t = time.perf_counter()
            r = forward_backward(pb, FBSettings(progress=False), model=m)
            c = r.counters
            line += (f"; FB (step {r.settings['step'] * 1e3:.2f} mm): {time.perf_counter() - t:.1f} s, {r.n_points} cells, "
                     f"{c['factorizations_per_cell']:.2f} LUs/cell, {c['backward_solves']} backward solves")
        print(line)


def self_contact():
    import sys

    from scipy.sparse.linalg import splu

    a = load_problem(REPO / "problems" / "pinch_gripper.yaml")
    b = load_problem(REPO / "problems" / "pinch_gripper.yaml")
    b.self_contact = []
    for label, pb in (("with self-contact", a), ("without", b)):
        m = StaticModel(pb)
        for u in ([1.5, 0.0], [0.0, 1.5], [1.5, 1.5], [0.5, 0.0]):
            u = np.array(u)
            e = solve_equilibrium(m, u)
            t = best_of(lambda: solve_equilibrium(m, u), 2)
            pressing = sum(c["points"] for c in m.contacts(e.q))
            print(f"gripper {label} (free dofs {m.n_free}): u = {u}: {t:.2f} s ({e.iterations} it, "
                  f"{e.factorizations} LUs, {e.load_steps} load steps), {pressing} points pressing", flush=True)
        _, K, _ = m.residual_and_tangent(e.q, u)
        t_lu = best_of(lambda: splu(K.tocsc()), 2)
        t_r = best_of(lambda: m.residual(e.q, u), 5)
        t_k = best_of(lambda: m.residual_and_tangent(e.q, u), 3)
        print(f"gripper {label}: tangent nnz {K.nnz}, one LU {t_lu:.2f} s, residual {t_r * 1e3:.1f} ms, "
              f"residual and tangent {t_k * 1e3:.0f} ms", flush=True)
        t0 = time.perf_counter()
        fw = forward(pb, 5, ForwardSettings(progress=False), model=m)
        print(f"gripper {label}: forward n_d = 5: {time.perf_counter() - t0:.1f} s, {fw.n_points} points, "
              f"{fw.n_failed} failed", flush=True)
        sys.stdout.flush()


def main():
    import sys

    print(machine())
    if "--self-contact-only" in sys.argv:
        self_contact()
        return
    equilibria("finger_object.yaml", np.array([0.016]), np.array([0.015]))
    equilibria("finger_object.yaml", np.array([0.010]), np.array([0.009]))
    equilibria("trunk_table.yaml", np.array([40.0, 80.0]), np.array([40.0, 75.0]))
    equilibria("trunk_table.yaml", np.array([40.0, 20.0]), np.array([40.0, 15.0]))
    workspaces("finger_object.yaml", 41, fb=False)
    workspaces("trunk_table.yaml", 21, fb=True)
    self_contact()


if __name__ == "__main__":
    main()
