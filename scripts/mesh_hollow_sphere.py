"""Mesh a thick-walled hollow sphere with Gmsh (the cavity test's meshes in tests/meshes/).

    python scripts/mesh_hollow_sphere.py [--inner 0.01] [--outer 0.02] [--size 0.004 0.0025] [--order 1]

Writes tests/meshes/hollow_sphere_<size in mm>mm[_o2].vtu: tetrahedra only (``tetra`` or ``tetra10``, whose
mid-edge nodes Gmsh places on the curved spheres). Needs the optional dependency ``gmsh``
(``pip install -e '.[mesh]'``); the shipped meshes do not.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "tests" / "meshes"


def hollow_sphere(inner: float, outer: float, size: float, order: int, path: Path) -> None:
    import gmsh
    import meshio

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("hollow_sphere")
        occ = gmsh.model.occ
        big = occ.addSphere(0, 0, 0, outer)
        small = occ.addSphere(0, 0, 0, inner)
        occ.cut([(3, big)], [(3, small)])
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size / 2)
        gmsh.option.setNumber("Mesh.ElementOrder", order)
        gmsh.option.setNumber("Mesh.SecondOrderLinear", 0)  # mid-edge nodes on the spheres
        gmsh.option.setNumber("Mesh.HighOrderOptimize", 2)  # untangle elements curving inwards
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        etype = 4 if order == 1 else 11
        _, enodes = gmsh.model.mesh.getElementsByType(etype)
    finally:
        gmsh.finalize()
    index = {int(t): i for i, t in enumerate(tags)}
    X = np.asarray(coords).reshape(-1, 3)
    n = 4 if order == 1 else 10
    cells = np.array([index[int(t)] for t in enodes]).reshape(-1, n)
    if order == 2:  # gmsh's 10-node order: edges 01, 12, 20, 30, 32, 31; VTK's: 01, 12, 02, 03, 13, 23
        cells = cells[:, [0, 1, 2, 3, 4, 5, 6, 7, 9, 8]]
    used = np.unique(cells)
    remap = -np.ones(len(X), dtype=np.int64)
    remap[used] = np.arange(used.size)
    meshio.write(path, meshio.Mesh(X[used], [("tetra" if order == 1 else "tetra10", remap[cells])]))
    print(f"wrote {path}: {used.size} nodes, {len(cells)} tetrahedra")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--inner", type=float, default=0.01)
    ap.add_argument("--outer", type=float, default=0.02)
    ap.add_argument("--size", type=float, nargs="+", default=[0.004, 0.0025])
    ap.add_argument("--order", type=int, default=1)
    args = ap.parse_args()
    for h in args.size:
        suffix = "_o2" if args.order == 2 else ""
        hollow_sphere(args.inner, args.outer, h, args.order, OUT / f"hollow_sphere_{1e3 * h:g}mm{suffix}.vtu")


if __name__ == "__main__":
    main()
