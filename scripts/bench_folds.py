"""A workspace that folds (issue 71): the SOFA trunk with three long cables at 20 N
(problems/sofa_trunk_3cables.yaml), whose map from tensions to tip folds over itself.

Measured, each from its own runs (nothing read from an earlier output):
* the reference: the union of the images of a forward grid's cells at 5^3, 9^3, 17^3 and 33^3 (a refinement
  sequence; the 33^3 one is the reference, its change from 17^3 an estimate of what it still misses) and the
  integral of |det dp/du| (the sum of the tetrahedra's |volume|, an upper bound);
* forward at n_d = 9 and forward-backward at 8 mm (2 workers, their default surfaces): volume, its stated
  error against the reference's distance, the points checked against the surface;
* probes at 16 surface vertices spread over the forward-backward surface (farthest-point sampling): the
  target 2 mm (and 0.5 mm) along the inward and the outward vertex normal, each reached by ``reach`` from the
  equilibrium at the grid node nearest the vertex and, if that fails, nearest the target. An inward target is
  counted only where it lies inside the surface (a sheet thinner than the depth puts it outside on the
  other side), an outward one only where it lies outside;
* the unfolded 3-cable trunk (problems/trunk_3cables.yaml) at n_d = 9: the faces' surface as before.

Writes benchmarks/folds.json and the section "folds" of BENCHMARKS.md. About 15 minutes on 2 cores.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import machine, write_section  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PROBLEM = REPO / "problems" / "sofa_trunk_3cables.yaml"


def grid_tips(fw, n):
    """The forward result's tips as an (n^3, 3) array in the grid's node order."""
    lo, hi = np.asarray(fw.problem["u_min"]), np.asarray(fw.problem["u_max"])
    ijk = np.rint((fw.u - lo) / (hi - lo) * (n - 1)).astype(int)
    P = np.full((n**3, 3), np.nan)
    P[(ijk[:, 0] * n + ijk[:, 1]) * n + ijk[:, 2]] = fw.points
    return P


def spread(V, k, seed=0):
    """k vertices spread over V by farthest-point sampling."""
    rng = np.random.default_rng(seed)
    out = [int(rng.integers(len(V)))]
    d = np.linalg.norm(V - V[out[0]], axis=1)
    for _ in range(k - 1):
        out.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(V - V[out[-1]], axis=1))
    return np.array(out)


def vertex_normals(V, T):
    n = np.zeros_like(V)
    f = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])  # area-weighted, outward
    for i in range(3):
        np.add.at(n, T[:, i], f)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def probes(model, b, nodes_u, nodes_p, depths=(0.002, 0.0005), k=16):
    import casadi_ws as cw
    from casadi_ws.workspace.boundary import distance_outside

    normals = vertex_normals(b.vertices, b.triangles)
    picks = spread(b.vertices, k)
    out = {}
    for depth in depths:
        rows = []
        for i in picks:
            for side, sign in (("inside", -1.0), ("outside", 1.0)):
                target = b.vertices[i] + sign * depth * normals[i]
                d = float(distance_outside(b, target[None])[0])
                if (side == "inside") != (d < 0):
                    rows.append({"vertex": int(i), "side": side, "counted": False, "distance_outside": d})
                    continue
                best = None
                for start in (b.vertices[i], target):
                    j = int(np.argmin(np.linalg.norm(nodes_p - start, axis=1)))
                    eq = cw.solve_equilibrium(model, nodes_u[j])
                    r = cw.reach(model, target, q0=eq.q, u0=eq.u, settings=cw.ReachSettings(tolerance=1e-5))
                    if best is None or r.error < best.error:
                        best = r
                    if r.reachable:
                        break
                rows.append({"vertex": int(i), "side": side, "counted": True, "distance_outside": d,
                             "reached": bool(best.reachable), "error": float(best.error)})
        counted = [r for r in rows if r["counted"]]
        ok = [r for r in counted if r["reached"] == (r["side"] == "inside")]
        out[f"{depth * 1e3:g} mm"] = {"probes": rows, "counted": len(counted), "as_expected": len(ok),
                                      "inside_counted": sum(r["side"] == "inside" for r in counted),
                                      "outside_counted": sum(r["side"] == "outside" for r in counted)}
    return out


def main():
    import casadi_ws as cw
    from casadi_ws.workspace.boundary import boundary_of
    from casadi_ws.workspace.images import union_of_images

    problem = cw.load_problem(PROBLEM)
    model = cw.StaticModel(problem)
    data = {"machine": machine(), "problem": str(PROBLEM.relative_to(REPO))}
    with cw.ProcessExecutor(2) as ex:
        # the reference: unions of finer grids' cell images
        ref = {}
        for n in (5, 9, 17, 33):
            t = time.perf_counter()
            fw = cw.forward(problem, n_d=n, settings=cw.ForwardSettings(progress=False, maps="interpolated"),
                            model=model, executor=ex)
            assert fw.n_points == n**3, f"forward n_d = {n}: {fw.n_failed} failed"
            r = union_of_images(grid_tips(fw, n), n)
            ref[n] = {"volume_cm3": r["volume"] * 1e6, "jacobian_integral_cm3": r["jacobian_integral"] * 1e6,
                      "turned_over": r["turned_over"], "tetrahedra": r["tetrahedra"],
                      "time_s": time.perf_counter() - t}
            if n == 9:
                fw9 = fw
            del fw
            print(n, ref[n])
        V_ref = ref[33]["volume_cm3"]
        data["reference"] = {"unions": ref, "volume_cm3": V_ref,
                             "uncertainty_cm3": abs(ref[33]["volume_cm3"] - ref[17]["volume_cm3"])}

        runs = {}
        t = time.perf_counter()
        fw9.boundary = boundary_of(fw9, problem, model=model, executor=ex)
        b = fw9.boundary
        runs["forward n_d = 9"] = {"volume_cm3": b.volume * 1e6, "volume_error_cm3": b.volume_error * 1e6,
                                   "method": b.method, "boundary_s": time.perf_counter() - t,
                                   "grid": b.fold.get("grid"), **b.checks}
        t = time.perf_counter()
        fb = cw.forward_backward(problem, cw.FBSettings(step=0.008, progress=False), model=model, executor=ex)
        t_fb = time.perf_counter() - t
        b = fb.boundary
        m = cw.measures(fb)
        runs["forward-backward 8 mm"] = {"volume_cm3": b.volume * 1e6, "volume_error_cm3": b.volume_error * 1e6,
                                         "method": b.method, "time_s": t_fb,
                                         "boundary_s": fb.timings.get("boundary"), "points": fb.n_points,
                                         "volume_upper_cm3": b.fold.get("jacobian_integral", np.nan) * 1e6,
                                         "volume_lower_cm3": len_interior(m, fb), "area_cm2": b.area * 1e4,
                                         "tolerance_mm": b.tolerance * 1e3, "grid": b.fold.get("grid"), **b.checks}
        for name, r in runs.items():
            r["error_vs_reference_pct"] = 100 * (r["volume_cm3"] - V_ref) / V_ref
            r["estimate_covers"] = abs(r["volume_cm3"] - V_ref) <= r["volume_error_cm3"]
            print(name, r)
        data["runs"] = runs
        data["probes"] = probes(model, fb.boundary, fw9.u, fw9.points)
        for k, v in data["probes"].items():
            print("probes", k, {x: v[x] for x in v if x != "probes"})

        t3 = cw.load_problem(REPO / "problems" / "trunk_3cables.yaml")
        fw3 = cw.forward(t3, n_d=9, settings=cw.ForwardSettings(progress=False), executor=ex)
        b3 = boundary_of(fw3, t3, executor=ex)
        data["unfolded"] = {"problem": "problems/trunk_3cables.yaml", "method": b3.method,
                            "volume_cm3": b3.volume * 1e6, "fold": b3.fold}
        print("unfolded", data["unfolded"])
    (REPO / "benchmarks" / "folds.json").write_text(json.dumps(data, indent=1, default=float) + "\n")
    f, r = data["runs"]["forward n_d = 9"], data["reference"]
    out = data["probes"]["2 mm"]["probes"]
    write_section("folds", section(data), what="Folding workspace volume, SOFA trunk with 3 cables",
                  command="scripts/bench_folds.py",
                  figure=f"volume {f['volume_cm3']:.1f} cm³ ±{f['volume_error_cm3']:.1f} "
                         f"({f['error_vs_reference_pct']:+.1f} % against {r['volume_cm3']:.1f} cm³ at 33³) by forward "
                         f"n_d = 9 and forward-backward 8 mm; outward probes "
                         f"{sum(not p['reached'] for p in out if p['counted'] and p['side'] == 'outside')} of "
                         f"{sum(p['counted'] and p['side'] == 'outside' for p in out)} not reached")


def len_interior(m, fb):
    return m.get("volume_lower", 0.0) * 1e6 if m.get("volume_lower") is not None else None


def section(d) -> str:
    r, f, b, p = d["reference"], d["runs"]["forward n_d = 9"], d["runs"]["forward-backward 8 mm"], d["probes"]
    u = r["unions"]
    lines = [
        "## A workspace that folds (issue 71) — `scripts/bench_folds.py`",
        "",
        f"{d['machine']}. `{d['problem']}`: SOFA's trunk mesh (709 nodes), three long cables at 0/90/270°, "
        f"0–20 N; 2 workers. Data: `benchmarks/folds.json`.",
        "",
        "Reference: the union of the images of a forward grid's cells (`casadi_ws/workspace/images.py`) under "
        "refinement, and the sum of their tetrahedra's |volume| (∫|det dp/du|, an upper bound):",
        "",
        "| grid | union, cm³ | ∫\\|det\\|, cm³ | tetrahedra turned over |",
        "|---|---|---|---|",
        *[f"| {n}³ | {u[n]['volume_cm3']:.1f} | {u[n]['jacobian_integral_cm3']:.1f} | "
          f"{u[n]['turned_over']} of {u[n]['tetrahedra']} |" for n in u],
        "",
        f"| run (default settings) | fold grid | volume, cm³ | stated error | against {r['volume_cm3']:.1f} (33³) | "
        f"estimate covers | points outside |",
        "|---|---|---|---|---|---|---|",
        *[f"| {name} | {x['grid']}³ | {x['volume_cm3']:.1f} | ±{x['volume_error_cm3']:.1f} | "
          f"{x['error_vs_reference_pct']:+.1f} % | {'yes' if x['estimate_covers'] else 'no'} | "
          f"{x.get('points_outside', '–')} of {x.get('points_checked', '–')} |" for name, x in d["runs"].items()],
        "",
        "The fold grid starts at 9³ and is refined while the stated error is above 5 % of the volume "
        "(`BoundarySettings.fold_tolerance`), up to 17³.",
        "",
        f"Forward-backward: {b['time_s']:.0f} s in all, the surface {b['boundary_s']:.0f} s; bounds beside its "
        f"volume: lower {b['volume_lower_cm3']} cm³ (cells with all 26 neighbours reached), upper "
        f"{b['volume_upper_cm3']:.1f} cm³.",
        "",
        "Probes at 16 vertices spread over the forward-backward surface (`reach` to the target along the vertex "
        "normal; a probe is counted where its target lies on the expected side of the surface):",
        "",
        "| depth | counted inside / outside | as expected (inside reached, outside not) | the others: distance "
        "left to the target |",
        "|---|---|---|---|",
        *[f"| {k} | {v['inside_counted']} / {v['outside_counted']} | {v['as_expected']} of {v['counted']} | "
          + (", ".join(f"{r['side']} {r['error'] * 1e3:.2f} mm" for r in v["probes"]
                       if r["counted"] and r["reached"] != (r["side"] == "inside")) or "–") + " |"
          for k, v in p.items()],
        "",
        f"The surface's stated tolerance is {b['tolerance_mm']:.1f} mm; the workspace is a shell about "
        f"{2 * b['volume_cm3'] / b['area_cm2'] * 10:.1f} mm thick on average (2 x volume / area), so most targets "
        f"2 mm inward leave it on the other side and are not counted.",
        "",
        f"Unfolded (`{d['unfolded']['problem']}`, n_d = 9): method `{d['unfolded']['method']}`, "
        f"{d['unfolded']['volume_cm3']:.2f} cm³, no fold seen.",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
