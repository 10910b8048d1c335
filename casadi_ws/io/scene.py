"""The robot beside its workspace in ParaView: the body at rest and its actuators, as VTK files.

``robot.vtu``      the mesh at rest (``tetra`` or ``tetra10`` cells), with the fixed components as point data
``actuators.vtu``  cables as polylines (pull point first) and cavity surfaces as ``triangle`` or
                   ``triangle6`` cells, with the actuator's index (``actuator``, in input order) as cell data
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["write_scene"]


def write_scene(problem, directory: str | Path) -> list[str]:
    """Write robot.vtu and actuators.vtu into ``directory``; returns the names written."""
    import meshio

    d = Path(directory)
    mesh = problem.mesh
    cell = "tetra10" if mesh.tets.shape[1] == 10 else "tetra"
    fixed = problem.fixed_dofs().astype(np.int8)
    meshio.write(d / "robot.vtu", meshio.Mesh(mesh.nodes, [(cell, mesh.tets)], point_data={"fixed": fixed}))
    points, blocks, index = [], [], []
    offset = 0
    for i, a in enumerate(problem.actuators):
        if a.kind == "cable":
            P = a.polyline()
            blocks.append(("line", offset + np.column_stack([np.arange(len(P) - 1), np.arange(1, len(P))])))
        elif a.kind == "cavity":
            P = a.rest_points()
            tri = np.asarray(a.triangles)
            blocks.append(("triangle6" if tri.shape[1] == 6 else "triangle", offset + tri))
        else:
            continue
        points.append(P)
        index.append(np.full(len(blocks[-1][1]), i))
        offset += len(P)
    if not points:
        return ["robot.vtu"]
    meshio.write(d / "actuators.vtu", meshio.Mesh(np.vstack(points), blocks, cell_data={"actuator": index}))
    return ["robot.vtu", "actuators.vtu"]
