"""Mesh a PneuNets-style bending finger with Gmsh: problems/meshes/pneunet_finger.vtu.

    python scripts/mesh_pneunet_finger.py [--size 0.0016] [--out problems/meshes/pneunet_finger.vtu]

A silicone block along +x (clamped at x = 0) with two rows of chambers side by side (left: y < W/2,
right: y > W/2), each row's chambers joined by a channel along their floor: two closed cavities. Slots
open at the top separate neighbouring chambers. Under pressure the chambers' thin end walls bulge into
the slots and push each other apart at the top, while the stiff base layer
(z < BASE, a strain-limiting layer: problems/pneunet_finger.yaml gives it a larger Young's modulus) does
not stretch, so the finger bends down (-z); pressurising one row more than the other also twists it
sideways. The mesh conforms to the base layer's top face. All parameters in SI units (metres); needs the
optional dependency ``gmsh`` (``pip install -e '.[mesh]'``). The shipped problem does not.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Finger:
    length: float = 0.060
    """Length along x, m."""
    width: float = 0.016
    """Width along y, m (two rows of chambers)."""
    height: float = 0.012
    """Height along z, m, base layer included."""
    base: float = 0.002
    """Thickness of the strain-limiting base layer (z < base), m."""
    floor: float = 0.0012
    """Silicone between the base layer and the chambers, m."""
    chambers: int = 6
    """Chambers per row."""
    chamber_length: float = 0.004
    """Chamber size along x, m."""
    wall: float = 0.0012
    """Thickness of the chambers' walls (ends, sides, top), m."""
    gap: float = 0.0015
    """Slot between neighbouring chambers' end walls, open at the top, m: the walls bulge into it and push
    each other apart."""
    start: float = 0.006
    """x where the first chamber's wall begins (the clamped part before it), m."""
    channel: float = 0.0012
    """Side of the square channel joining a row's chambers along their floor, m."""

    @property
    def pitch(self) -> float:
        return self.chamber_length + 2 * self.wall + self.gap


def build(f: Finger, size: float, path: Path) -> None:
    import gmsh
    import meshio

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("pneunet_finger")
        occ = gmsh.model.occ
        body = occ.addBox(0, 0, 0, f.length, f.width, f.height)
        z0 = f.base + f.floor
        hz = f.height - f.wall - z0
        row_w = (f.width - 3 * f.wall) / 2  # two rows, three walls across
        holes = []
        for row in range(2):
            y0 = f.wall + row * (row_w + f.wall)
            xs = [f.start + k * f.pitch + f.wall for k in range(f.chambers)]
            boxes = [occ.addBox(x, y0, z0, f.chamber_length, row_w, hz) for x in xs]
            x_begin, x_end = xs[0] + f.chamber_length / 2, xs[-1] + f.chamber_length / 2
            chan = occ.addBox(x_begin, y0 + row_w / 2 - f.channel / 2, z0, x_end - x_begin, f.channel, f.channel)
            fused, _ = occ.fuse([(3, boxes[0])], [(3, b) for b in boxes[1:]] + [(3, chan)])
            holes += fused
        # slots between the chambers, across the whole width, from above the channel's roof to the top
        z_slot = z0 + f.channel + f.wall
        for k in range(f.chambers - 1):
            x = f.start + k * f.pitch + 2 * f.wall + f.chamber_length
            holes.append((3, occ.addBox(x, 0, z_slot, f.gap, f.width, f.height - z_slot)))
        cut, _ = occ.cut([(3, body)], holes)
        # a cut plane at the base layer's top, so elements do not straddle the two materials
        layer = occ.addBox(0, 0, 0, f.length, f.width, f.base)
        occ.fragment(cut, [(3, layer)])
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", size / 2.5)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.model.mesh.generate(3)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, enodes = gmsh.model.mesh.getElementsByType(4)
    finally:
        gmsh.finalize()
    index = {int(t): i for i, t in enumerate(tags)}
    X = np.asarray(coords).reshape(-1, 3)
    cells = np.array([index[int(t)] for t in enodes]).reshape(-1, 4)
    used = np.unique(cells)
    remap = -np.ones(len(X), dtype=np.int64)
    remap[used] = np.arange(used.size)
    path.parent.mkdir(parents=True, exist_ok=True)
    meshio.write(path, meshio.Mesh(X[used], [("tetra", remap[cells])]))
    print(f"wrote {path}: {used.size} nodes, {len(cells)} tetrahedra")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=float, default=0.002, help="largest element edge, m")
    ap.add_argument("--out", type=Path, default=ROOT / "problems" / "meshes" / "pneunet_finger.vtu")
    for fl in fields(Finger):
        ap.add_argument(f"--{fl.name.replace('_', '-')}", type=type(fl.default), default=fl.default)
    args = ap.parse_args()
    f = Finger(**{fl.name: getattr(args, fl.name) for fl in fields(Finger)})
    build(f, args.size, args.out)


if __name__ == "__main__":
    main()
