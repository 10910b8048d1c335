"""Cost of the material laws on the 10-node trunk (problems/trunk_2cables_order2.yaml: 1701 nodes, 960
tetrahedra): one residual and tangent, one equilibrium at u = (40, 20) N from rest, for every law; and
forward-backward at the default step with the corotational law and with a Yeoh silicone.

Every law is given the trunk's small-strain stiffness (E = 18 MPa, nu = 0.45, so mu0 = 6.2 MPa), so that the
same cable tensions bend each about as far; the strain-energy laws add their own stiffening (Yeoh C20 =
C10 / 10; Ogden alpha = 1.3, 5, -2). Kernels are compiled before timing (once per machine).

    python scripts/bench_materials.py [--no-fb]
    python scripts/bench_materials.py --compile    # only: each new kernel's size and compile time, printed
"""

from __future__ import annotations

import resource
import sys
import time
from pathlib import Path

import numpy as np
import yaml
from benchlib import best_of, machine, write_section

from casadi_ws import StaticModel, solve_equilibrium
from casadi_ws.io.problem import problem_from_dict
from casadi_ws.workspace.forward_backward import FBSettings, forward_backward

REPO = Path(__file__).resolve().parents[1]
E, NU = 1.8e7, 0.45
MU = E / (2 * (1 + NU))
LAWS = {
    "corotational": {"model": "corotational", "young_modulus": E, "poisson_ratio": NU},
    "neohookean": {"model": "neohookean", "young_modulus": E, "poisson_ratio": NU},
    "mooney_rivlin": {"model": "mooney_rivlin", "c10": 0.4 * MU, "c01": 0.1 * MU, "poisson_ratio": NU},
    "yeoh": {"model": "yeoh", "c10": MU / 2, "c20": MU / 20, "poisson_ratio": NU},
    "ogden, 3 terms": {"model": "ogden", "mu": [0.9 * MU, 0.05 * MU, 0.05 * MU], "alpha": [1.3, 5.0, -2.0],
                       "poisson_ratio": NU},
    "yeoh, mixed": {"model": "yeoh", "c10": MU / 2, "c20": MU / 20, "poisson_ratio": NU, "formulation": "mixed"},
    "yeoh, nu = 0.49 (mixed)": {"model": "yeoh", "c10": MU / 2, "c20": MU / 20, "poisson_ratio": 0.49,
                                "formulation": "mixed"},
    "yeoh, nu = 0.49 (taylor_hood)": {"model": "yeoh", "c10": MU / 2, "c20": MU / 20, "poisson_ratio": 0.49,
                                      "formulation": "taylor_hood"},
}


FB_LAWS = ("corotational", "yeoh", "yeoh, nu = 0.49 (mixed)", "yeoh, nu = 0.49 (taylor_hood)")


def problem(material: dict):
    d = yaml.safe_load((REPO / "problems" / "trunk_2cables_order2.yaml").read_text())
    d["material"] = dict(material, density=1100)
    return problem_from_dict(d, f"trunk_2cables_order2 ({material['model']})")


def equilibria() -> list[str]:
    rows = ["| law | kernel | residual + tangent | equilibrium from rest | Newton its / LUs | tip (mm) |",
            "|---|---|---|---|---|---|"]
    u = np.array([40.0, 20.0])
    for name, mat in LAWS.items():
        pb = problem(mat)
        m = StaticModel(pb)
        q0 = np.zeros(m.n_dof)
        t_rk = best_of(lambda: m.residual_and_tangent(q0 + 1e-4, u), 5)
        eq = solve_equilibrium(m, u)
        assert eq.converged, (name, eq.status_name)
        t_eq = best_of(lambda: solve_equilibrium(m, u), 3)
        tip = ", ".join(f"{1e3 * x:.1f}" for x in eq.tip)
        rows.append(f"| {name} | `{m.element_groups[0].model}` | {t_rk * 1e3:.0f} ms | {t_eq:.2f} s | "
                    f"{eq.iterations} / {eq.factorizations} | ({tip}) |")
        print(rows[-1], flush=True)
    return rows


def fb_runs() -> list[str]:
    rows = ["| law | FB time (2 workers) | cells | backward solves | peak memory of this process |",
            "|---|---|---|---|---|"]
    for name in FB_LAWS:
        pb = problem(LAWS[name])
        m = StaticModel(pb)
        t = time.perf_counter()
        r = forward_backward(pb, FBSettings(progress=False, workers=2), model=m)
        dt = time.perf_counter() - t
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        rows.append(f"| {name} | {dt:.1f} s | {r.n_points} | {r.counters['backward_solves']} | {rss:.0f} MB |")
        print(rows[-1], flush=True)
    return rows


def compile_times() -> None:
    """Each strain-energy kernel's SX size and compile time, into an empty cache."""
    import os
    import tempfile

    os.environ["CASADI_WS_CACHE"] = tempfile.mkdtemp()
    from casadi_ws.fem.elements import TET4, TET10
    from casadi_ws.fem.kernels import ElementBatch
    from casadi_ws.fem.materials import element_functions

    for element in (TET4, TET10):
        for kernel in ("mooney_rivlin", "yeoh", "ogden3", "yeoh_mixed", "ogden3_mixed"):
            if element is TET4 and kernel.endswith("_mixed"):
                continue  # one quadrature point: the same element
            funs = element_functions(kernel, element)
            cells = []
            for name in ("force", "stiffness", "hessian_vector"):
                t = time.perf_counter()
                batch = ElementBatch(funs[name])
                cells.append(f"{name} {funs[name].n_nodes() / 1e3:.1f}k nodes, {time.perf_counter() - t:.1f} s "
                             f"({batch.backend})")
            print(f"| {element.name} | {kernel} | " + " | ".join(cells) + " |", flush=True)


def main() -> None:
    if "--compile" in sys.argv:
        return compile_times()
    body = [f"Machine: {machine()}.", "",
            "`python scripts/bench_materials.py`: the 10-node trunk (`trunk_2cables_order2`, 1701 nodes, 960 "
            "tetrahedra, 4374 free dofs) with each law at the trunk's small-strain stiffness (E = 18 MPa, "
            "nu = 0.45; Yeoh C20 = C10/10, Ogden alpha = 1.3, 5, -2); u = (40, 20) N; residual and tangent "
            "best of 5, equilibrium best of 3, kernels compiled beforehand.", ""]
    body += equilibria()
    if "--no-fb" not in sys.argv:
        body += ["", "Forward-backward at the problem's default step, 2 worker processes:", ""]
        body += fb_runs()
    write_section("materials", "## Material laws (scripts/bench_materials.py)\n\n" + "\n".join(body))


if __name__ == "__main__":
    main()
