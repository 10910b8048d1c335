"""Pictures of workspaces: the publication's three-view drawing (Figs. 11-13) and a 3-D render.

Both overlay several results (e.g. forward points in blue, forward-backward cells in gray with its points
in red) over the robot's rest shape, drawn faintly. Lengths are shown in millimetres.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["STYLES", "three_views", "workspace_3d"]

STYLES = {
    "forward": dict(color="tab:blue", label="forward", size=4, alpha=0.6),
    "forward-backward": dict(color="tab:red", label="forward-backward", size=6, alpha=0.9),
}
_VIEWS = (("Oxy", 0, 1), ("Ozy", 2, 1), ("Ozx", 2, 0))
_AXES = "xyz"


def _style(result, i):
    base = STYLES.get(result.method, dict(color=f"C{i}", label=result.method, size=4, alpha=0.7))
    return dict(base)


def _outline(ax, nodes, a, b):
    from scipy.spatial import ConvexHull

    pts = nodes[:, [a, b]] * 1e3
    try:
        hull = ConvexHull(pts)
        ax.fill(*pts[hull.vertices].T, color="0.85", alpha=0.5, lw=0.5, ec="0.6", zorder=0, label="robot at rest")
    except Exception:  # flat projection: no hull
        ax.plot(*pts.T, ",", color="0.7", zorder=0)


def three_views(results, path, mesh=None, title: str | None = None, labels=None):
    """Save the Oxy, Ozy and Ozx projections of ``results`` (one or several) to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = results if isinstance(results, (list, tuple)) else [results]
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.2))
    for ax, (name, a, b) in zip(axes, _VIEWS):
        if mesh is not None:
            _outline(ax, mesh.nodes, a, b)
        for i, r in enumerate(results):
            st = _style(r, i)
            if labels is not None:
                st["label"] = labels[i]
            cells = r.arrays.get("cells_centres")
            if cells is not None and len(cells):
                from matplotlib.collections import PatchCollection
                from matplotlib.patches import Rectangle

                h = float(r.arrays["cell_step"]) * 1e3
                xy = np.unique(np.round(cells[:, [a, b]] * 1e3 / h).astype(np.int64), axis=0) * h
                boxes = [Rectangle((x - h / 2, y - h / 2), h, h) for x, y in xy]
                ax.add_collection(PatchCollection(boxes, facecolor="0.55", edgecolor="none", alpha=0.35,
                                                  zorder=1, label=f"{st['label']} cells"))
            if r.n_points:
                ax.scatter(r.points[:, a] * 1e3, r.points[:, b] * 1e3, s=st["size"], c=st["color"],
                           alpha=st["alpha"], lw=0, zorder=2 + i, label=f"{st['label']} ({r.n_points} points)")
            ax.plot(*(r.rest_tip[[a, b]] * 1e3), "k+", ms=10, zorder=10)
        ax.set_title(f"{name} plane")
        ax.set_xlabel(f"{_AXES[a]} (mm)")
        ax.set_ylabel(f"{_AXES[b]} (mm)")
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    handles, labs = axes[0].get_legend_handles_labels()
    fig.legend(handles, labs, loc="lower center", ncol=max(1, len(labs)), frameon=False)
    fig.suptitle(title or "Reachable workspace of the end-effector (+: tip at rest)")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return Path(path)


def workspace_3d(results, path, mesh=None, title: str | None = None):
    """Save an off-screen 3-D render of the rest robot and the workspace clouds to ``path`` (PNG)."""
    results = results if isinstance(results, (list, tuple)) else [results]
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        return _render_pyvista(results, path, mesh, title)
    except Exception:  # no OpenGL context on this machine: a matplotlib 3-D scatter says the same
        return _render_matplotlib(results, path, mesh, title)


def _render_pyvista(results, path, mesh, title):
    import pyvista as pv

    pl = pv.Plotter(off_screen=True, window_size=(1200, 900))
    if mesh is not None:
        grid = pv.UnstructuredGrid({pv.CellType.TETRA: mesh.corners}, mesh.nodes * 1e3)
        pl.add_mesh(grid.extract_surface(algorithm="dataset_surface"), color="lightgray", opacity=0.35, show_edges=False)
    for i, r in enumerate(results):
        st = _style(r, i)
        if r.n_points:
            pl.add_points(r.points * 1e3, color=st["color"], point_size=st["size"] + 2,
                          render_points_as_spheres=True)
        # a text key: pyvista's legend box clips long labels
        pl.add_text(f"{st['label']}: {r.n_points} points", position=(20, 20 + 28 * i), font_size=10,
                    color=st["color"])
    pl.show_grid(xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)")
    pl.add_text(title or "Workspace (mm)", font_size=10, position="upper_left")
    pl.camera_position = "iso"
    pl.camera.zoom(0.8)
    pl.screenshot(str(path))
    pl.close()
    return Path(path)


def _render_matplotlib(results, path, mesh, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(9, 8))
    ax = fig.add_subplot(projection="3d")
    if mesh is not None:
        ax.scatter(*(mesh.nodes.T * 1e3), s=1, c="0.8", alpha=0.3)
    for i, r in enumerate(results):
        st = _style(r, i)
        ax.scatter(*(r.points.T * 1e3), s=st["size"], c=st["color"], label=st["label"])
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.legend()
    ax.set_title(title or "Workspace (mm)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
