"""The robot beside its workspace in ParaView: the body at rest and its actuators, as VTK files.

``robot.vtu``      the mesh at rest (``tetra`` or ``tetra10`` cells), with the fixed components as point data
``actuators.vtu``  cables as polylines (pull point first) and cavity surfaces as ``triangle`` or
                   ``triangle6`` cells, with the actuator's index (``actuator``, in input order) as cell data
``obstacles.vtu``  the obstacles' surfaces as triangles (a plane as a square the size of the scene), with
                   the obstacle's index (``obstacle``, in file order) as cell data; only with obstacles
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["obstacle_surface", "write_scene"]


def obstacle_surface(ob, lower: np.ndarray, upper: np.ndarray):
    """(vertices, triangles) of an obstacle's surface for pictures; a plane as the square through the
    projection of the box [lower, upper]'s centre, as wide as the box's diagonal."""
    import pyvista as pv

    p = ob.params
    if ob.kind == "surface":
        return np.asarray(p["vertices"], float), np.asarray(p["triangles"])
    if ob.kind == "plane":
        centre = 0.5 * (lower + upper)
        centre = centre - ((centre - p["point"]) @ p["normal"]) * p["normal"]
        size = float(np.linalg.norm(upper - lower))
        s = pv.Plane(center=centre, direction=p["normal"], i_size=size, j_size=size, i_resolution=1, j_resolution=1)
    elif ob.kind == "box":
        s = pv.Box(bounds=(p["lower"][0], p["upper"][0], p["lower"][1], p["upper"][1], p["lower"][2], p["upper"][2]))
    elif ob.kind == "sphere":
        s = pv.Sphere(radius=p["radius"], center=p["center"], theta_resolution=32, phi_resolution=16)
    else:  # a capped cylinder
        axis = p["b"] - p["a"]
        s = pv.Cylinder(center=0.5 * (p["a"] + p["b"]), direction=axis, radius=p["radius"],
                        height=float(np.linalg.norm(axis)), resolution=32, capping=True)
    s = s.triangulate()
    return np.asarray(s.points, float), s.faces.reshape(-1, 4)[:, 1:]


def write_scene(problem, directory: str | Path) -> list[str]:
    """Write robot.vtu, actuators.vtu and obstacles.vtu (if any) into ``directory``; returns the names
    written."""
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
    names = ["robot.vtu"]
    if points:
        meshio.write(d / "actuators.vtu", meshio.Mesh(np.vstack(points), blocks, cell_data={"actuator": index}))
        names.append("actuators.vtu")
    obstacles = getattr(problem, "obstacles", [])
    if obstacles:
        lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
        V, T, owner, offset = [], [], [], 0
        for i, ob in enumerate(obstacles):
            v, t = obstacle_surface(ob, lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo))
            V.append(v)
            T.append(offset + t)
            owner.append(np.full(len(t), i))
            offset += len(v)
        meshio.write(d / "obstacles.vtu", meshio.Mesh(np.vstack(V), [("triangle", np.vstack(T))],
                                                      cell_data={"obstacle": [np.concatenate(owner)]}))
        names.append("obstacles.vtu")
    return names
