"""The objects the shipped contact problems touch, as closed triangle surfaces: an egg for the SoftRobots
finger to press on (problems/finger_object.yaml).

    python scripts/mesh_objects.py [--out problems/meshes]

Written with pyvista (no Gmsh needed), in millimetres (the problem reads them with ``units: mm``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pyvista as pv

from casadi_ws.fem.surface import edge_report


def egg(centre=(-75.0, 32.0, 7.5), radii=(14.0, 12.0, 20.0), resolution=32) -> pv.PolyData:
    """An ellipsoid (mm), slightly pointed along x: the object the finger closes on."""
    s = pv.ParametricEllipsoid(*radii, u_res=resolution, v_res=resolution, w_res=resolution).triangulate()
    s = s.clean()
    x = np.asarray(s.points)
    x[:, 0] *= 1.0 + 0.15 * x[:, 0] / radii[0]  # one end blunter than the other
    s.points = x + np.asarray(centre)
    return s.compute_normals(auto_orient_normals=True, consistent_normals=True, split_vertices=False)


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    s = egg()
    tris = s.faces.reshape(-1, 4)[:, 1:]
    open_edges, misoriented = edge_report(tris)
    assert open_edges == 0 and misoriented == 0, (open_edges, misoriented)
    path = out / "egg.stl"
    pv.PolyData(np.asarray(s.points), s.faces).save(path, binary=True)
    print(f"wrote {path}: {s.n_points} vertices, {len(tris)} triangles (mm)")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("problems/meshes"))
    main(p.parse_args().out)
