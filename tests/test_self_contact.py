"""Self-contact: one body pressing on itself, checked against beam theory (two cantilevers of one body,
joined at their clamped root, the upper pushed onto the lower), Newton's third law, the admissibility check,
and finite differences."""

import json
from pathlib import Path

import meshio
import numpy as np
import pytest
import yaml

from casadi_ws import StaticModel, problem_from_dict, solve_equilibrium
from casadi_ws.cli import main
from casadi_ws.fem.mesh import _hex_grid_to_tets, _orient
from casadi_ws.solvers.admissible import admissibility

L, B, T, E, GAP = 0.2, 0.01, 0.01, 1e6, 0.002
"""Two slender beams of one body (m, Pa): L/T = 20, the upper GAP above the lower, both clamped at x = 0."""
EI = E * B * T**3 / 12


def _beams(tmp_path: Path, contact=True, order=2, divisions=(20, 2, 2), load=None) -> dict:
    """One body: two beams (the upper of length L, the lower ~1.25 L, so that the upper's tip lands on the
    lower's face, not on its corner) joined by a root block behind x = 0, which is clamped; a tip load on the
    upper twice what closes the gap. One structured grid with the slot's cells left out (conforming)."""
    n, ny, nz = divisions
    dx = L / n
    xs = dx * np.arange(-1, n * 5 // 4 + 1)  # the root block's cell, then the beams
    ys = np.linspace(-B / 2, B / 2, ny + 1)
    zs = np.concatenate([np.linspace(0, T, nz + 1), T + GAP + np.linspace(0, T, nz + 1)])
    Z, Y, X = np.meshgrid(zs, ys, xs, indexing="ij")
    nodes = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    tets = _orient(nodes, _hex_grid_to_tets((len(xs) - 1, ny, len(zs) - 1)))
    c = nodes[tets].mean(axis=1)
    slot = (c[:, 0] > 0) & (c[:, 2] > T) & (c[:, 2] < T + GAP)
    beyond = (c[:, 0] > L) & (c[:, 2] > T + GAP)
    used, tets = np.unique(tets[~(slot | beyond)], return_inverse=True)
    meshio.write(tmp_path / "beams.vtu", meshio.Mesh(nodes[used], [("tetra", tets.reshape(-1, 4))]))
    P = 2 * GAP * 3 * EI / L**3 if load is None else load
    d = {"mesh": {"file": "beams.vtu", "order": order},
         "material": {"young_modulus": E, "poisson_ratio": 0.0, "model": "linear"},
         "fixed": {"box": [-1, -1, -1, 1e-6, 1, 1]},  # the root block and the beams' ends
         "loads": [{"point": [L, 0, 1.5 * T + GAP], "force": [0, 0, -P]}],
         "cables": [{"points": [[0.1, 0, 0.002], [0.15, 0, 0.002]], "pull_point": [0, 0, 0.002], "u_max": 0.01}],
         "end_effector": [L, 0, 1.5 * T + GAP]}
    if contact:
        d["self_contact"] = [{"name": "beams", "points": {"box": [-1, -1, T + GAP / 2, 1, 1, T + 1.5 * GAP]},
                              "surface": {"box": [-1, -1, -1, 1, 1, T + GAP / 2]}}]
    return d


def _node(m, x):
    return int(np.argmin(np.linalg.norm(m.mesh.nodes - np.asarray(x), axis=1)))


def test_stacked_cantilevers_share_the_load_as_beam_theory_says(tmp_path):
    """The free upper tip would sink 2 GAP, through the lower beam; with self-contact the tips meet and the
    contact force R satisfies (P - R) L^3 / 3EI = R L^3 / 3EI + GAP: R = 3 EI GAP / (2 L^3)."""
    m = StaticModel(problem_from_dict(_beams(tmp_path), str(tmp_path / "beams.yaml"), tmp_path))
    eq = solve_equilibrium(m, np.zeros(1))
    assert eq.converged
    (c,) = m.contacts(eq.q)
    R = 3 * EI * GAP / (2 * L**3)
    assert c["kind"] == "self" and c["name"] == "beams" and c["points"] > 0 and c["beyond_reach"] == 0
    assert c["force"][2] == pytest.approx(R, rel=0.02)  # measured +0.26 %
    x = m.positions(eq.q)
    lower, upper = x[_node(m, [L, 0, T])], x[_node(m, [L, 0, T + GAP])]
    assert lower[2] - T == pytest.approx(-R * L**3 / (3 * EI), rel=0.02)
    assert upper[2] - T - GAP == pytest.approx(-(2 * GAP * 3 * EI / L**3 - R) * L**3 / (3 * EI), rel=0.02)
    # what the surface pushes on the points, the points push back on the surface: the forces sum to zero
    f = m.contact_forces(eq.q)[: m.n_mech].reshape(-1, 3)
    assert np.abs(f.sum(axis=0)).max() <= 1e-9 * R
    term = m.contact_terms()[0]
    assert term.geometry(m, eq.q).g.min() >= -1e-9 * T  # no point enters the lower beam
    assert admissibility(m, eq.q, np.zeros(1), eq.factorization).admissible

    free = StaticModel(problem_from_dict(_beams(tmp_path, contact=False), str(tmp_path / "free.yaml"), tmp_path))
    eq_free = solve_equilibrium(free, np.zeros(1))
    y = free.positions(eq_free.q)
    assert y[_node(free, [L, 0, T + GAP])][2] < y[_node(free, [L, 0, T])][2] - 0.5 * GAP  # passes through
    # the audit compares regions however close at rest: the beams passing through each other are refused
    assert "self_penetration" in admissibility(free, eq_free.q, np.zeros(1), eq_free.factorization).violations


def test_equilibrium_json_reports_the_self_contact(tmp_path, capsys):
    (tmp_path / "beams.yaml").write_text(yaml.safe_dump(_beams(tmp_path, order=1, divisions=(10, 1, 1),
                                                               load=6 * 2 * GAP * 3 * EI / L**3)))
    assert main(["equilibrium", str(tmp_path / "beams.yaml"), "--u", "0"]) == 0
    out = json.loads(capsys.readouterr().out)
    (c,) = out["contacts"]
    assert c["kind"] == "self" and c["points"] > 0 and c["force"][2] > 0


def _pressed_state(m, forces: bool):
    """A state near contact: the upper beam bent down onto the lower, a little noise, and contact forces."""
    rng = np.random.default_rng(1)
    q = np.zeros(m.n_dof)
    x = m.mesh.nodes
    up = x[:, 2] > T + GAP / 2
    q[: m.n_mech].reshape(-1, 3)[:, 2] = -np.where(up, 2.2, 0.6) * GAP * (x[:, 0] / L) ** 2
    q[m.free[: m.n_free_mech]] += 1e-5 * rng.standard_normal(m.n_free_mech)
    if forces:
        q[m.n_mech:] = 1e-3 * rng.random(m.n_con)
    return q, rng


def test_self_contact_tangent_and_hessian_match_finite_differences(tmp_path):
    m = StaticModel(problem_from_dict(_beams(tmp_path, order=1, divisions=(10, 1, 1)), str(tmp_path / "b.yaml"),
                                      tmp_path))
    u, h = np.zeros(1), 1e-7
    q, rng = _pressed_state(m, forces=True)
    assert m.contact_terms()[0].geometry(m, q).g.min() < 1e-4  # some points are close to the surface
    _, K, _ = m.residual_and_tangent(q, u)
    K = K.toarray()
    rows = m.contact_terms()[0].rows
    for j in [rows.start, rows.start + 5, rows.stop - 1] + list(rng.choice(m.n_free_mech, 8, replace=False)):
        dq = np.zeros(m.n_dof)
        dq[m.free[j]] = h
        fd = (m.residual(q + dq, u) - m.residual(q - dq, u)) / (2 * h)
        assert np.abs(fd - K[:, j]).max() <= 1e-6 * np.abs(K[:, j]).max()
    # the Hessian of lam . R; without contact forces the left-out third derivatives of the distance vanish
    q, rng = _pressed_state(m, forces=False)
    lam = rng.standard_normal(m.n_free)
    Hqq = m.residual_hessian(q, u, lam)[0].toarray()
    for j in [rows.start, rows.start + 5] + list(rng.choice(m.n_free_mech, 6, replace=False)):
        dq = np.zeros(m.n_dof)
        dq[m.free[j]] = h
        fd = (m.residual_and_tangent(q + dq, u)[1].T @ lam - m.residual_and_tangent(q - dq, u)[1].T @ lam) / (2 * h)
        assert np.abs(fd - Hqq[:, j]).max() <= 1e-5 * max(np.abs(Hqq[:, j]).max(), 1.0)
