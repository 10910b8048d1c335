"""The objects the shipped contact problems touch, as closed triangle surfaces: an egg for the SoftRobots
finger to press on (problems/finger_object.yaml); and the body of a pinch gripper whose two jaws press on
each other (problems/pinch_gripper.yaml, self-contact), as linear tetrahedra.

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


def pinch_gripper(cell=5.0):
    """A block 100 x 20 x 30 mm (cells of ``cell`` mm, 6 tetrahedra each) with a 10 mm slot from x = 20 mm
    between two 10 mm jaws; the upper jaw ends at x = 90 mm, so its tip lands on the lower jaw's face, not
    on its corner. Returns (nodes (mm), tetrahedra)."""
    from casadi_ws.fem.mesh import box_mesh

    m = box_mesh((100.0, 20.0, 30.0), (int(100 / cell), int(20 / cell), int(30 / cell)))
    c = m.nodes[m.tets].mean(axis=1)
    slot = (c[:, 0] > 20.0) & (c[:, 2] > 10.0) & (c[:, 2] < 20.0)
    short = (c[:, 0] > 90.0) & (c[:, 2] > 20.0)
    tets = m.tets[~(slot | short)]
    used, tets = np.unique(tets, return_inverse=True)
    return m.nodes[used], tets.reshape(-1, 4)


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    s = egg()
    tris = s.faces.reshape(-1, 4)[:, 1:]
    open_edges, misoriented = edge_report(tris)
    assert open_edges == 0 and misoriented == 0, (open_edges, misoriented)
    path = out / "egg.stl"
    pv.PolyData(np.asarray(s.points), s.faces).save(path, binary=True)
    print(f"wrote {path}: {s.n_points} vertices, {len(tris)} triangles (mm)")
    import meshio

    nodes, tets = pinch_gripper()
    path = out / "pinch_gripper.vtu"
    meshio.write(path, meshio.Mesh(nodes, [("tetra", tets)]))
    print(f"wrote {path}: {len(nodes)} nodes, {len(tets)} tetrahedra (mm)")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("problems/meshes"))
    main(p.parse_args().out)
