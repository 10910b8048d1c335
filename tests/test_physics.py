"""Equilibria against beam theory.

Linear tetrahedra are too stiff in bending ("shear locking"): the error of a bent beam falls like 1/n^2
with n elements across the thickness (measured: ~39 %, 13 %, 6 % for n = 2, 4, 6). The tests therefore
check (a) that the error falls with refinement, (b) a stated bound on the finest mesh, and (c) that the
Richardson extrapolation of the two finest meshes (assuming the h^2 rate) lands within a few percent of
the analytic answer, which is what "converges to beam theory" means.
"""

import numpy as np
import pytest
from conftest import cantilever

from casadi_ws import StaticModel, solve_equilibrium


def _tip_loads(problem, total):
    """Spread a tip force evenly over the nodes of the tip face."""
    x = problem.mesh.nodes
    tip = x[x[:, 2] > x[:, 2].max() - 1e-12]
    return [(p, np.asarray(total, float) / len(tip)) for p in tip]


def _cantilever_tip(n, model, P, nu=0.0):
    pb = cantilever(n=n, model=model, nu=nu)
    pb.point_loads = _tip_loads(pb, [P, 0.0, 0.0])
    eq = solve_equilibrium(StaticModel(pb), np.zeros(0))
    assert eq.converged, eq.status_name
    return eq.tip - pb.end_effector


def test_materials_agree_under_small_load():
    P = 1e-4  # tip deflection ~ 1e-4 of the length: geometric and material nonlinearity negligible
    d = {m: _cantilever_tip(2, m, P, nu=0.3) for m in ("linear", "corotational", "neohookean")}
    ref = np.linalg.norm(d["linear"])
    for m in ("corotational", "neohookean"):
        assert np.linalg.norm(d[m] - d["linear"]) < 2e-3 * ref, m


def test_linear_cantilever_converges_to_euler_bernoulli():
    E, L, h, P = 1e6, 0.2, 0.02, 1e-3
    exact = P * L**3 / (3 * E * h**4 / 12)  # shear deformation adds 0.6 % at L/h = 10: below the bounds
    errs, tips = [], []
    for n in (2, 4, 6):
        d = _cantilever_tip(n, "linear", P)
        assert abs(d[1]) < 1e-9 * exact and abs(d[2]) < 1e-3 * exact
        tips.append(d[0])
        errs.append(abs(d[0] - exact) / exact)
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 0.10
    richardson = (36 * tips[2] - 16 * tips[1]) / 20
    assert abs(richardson - exact) / exact < 0.03


def _arc(n, theta=1.1, model="corotational"):
    """Cable at constant offset d, tension T: pure bending moment T d and compression T.

    Beam theory: a circular arc of curvature k = T d / (E I) on the shortened length L (1 - T / (E A)).
    """
    E, L, slender = 1e6, 0.2, 20
    h = L / slender
    d = 0.3 * h
    I, A = h**4 / 12, h * h
    T = theta / L * E * I / d
    pb = cantilever(n=n, slender=slender, model=model, nu=0.3, E=E, L=L, cable_offset=d)
    eq = solve_equilibrium(StaticModel(pb), [T])
    assert eq.converged, eq.status_name
    k = T * d / (E * I)
    th = k * L * (1 - T / (E * A))
    exact = np.array([(1 - np.cos(th)) / k, 0.0, np.sin(th) / k])
    assert np.degrees(th) >= 60  # a large bend, as asked
    return eq.tip, exact, np.linalg.norm(exact - pb.end_effector)


@pytest.mark.slow
def test_cable_bends_beam_into_circular_arc():
    tips, errs = [], []
    for n in (2, 4, 6):
        tip, exact, disp = _arc(n)
        tips.append(tip)
        errs.append(np.linalg.norm(tip - exact) / disp)
        assert abs(tip[1]) < 0.02 * disp  # the bend stays in the cable's plane
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 0.08
    richardson = (36 * tips[2] - 16 * tips[1]) / 20
    assert np.linalg.norm(richardson - exact) / disp < 0.03
