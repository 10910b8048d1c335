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
    extent = []
    if mesh is not None:
        grid = pv.UnstructuredGrid({pv.CellType.TETRA: mesh.corners}, mesh.nodes * 1e3)
        pl.add_mesh(grid.extract_surface(algorithm="dataset_surface"), color="lightgray", opacity=0.35, show_edges=False)
        extent.append(mesh.nodes * 1e3)
    keys = []  # a text key: pyvista's legend box clips long labels
    for i, r in enumerate(results):
        st = _style(r, i)
        if r.n_points:
            pl.add_points(r.points * 1e3, color=st["color"], point_size=st["size"] + 2,
                          render_points_as_spheres=True)
            extent.append(r.points * 1e3)
        keys.append((f"{st['label']}: {r.n_points} points", st["color"]))
        b = getattr(r, "boundary", None)
        if b is not None and len(b.triangles):
            faces = np.hstack([np.full((len(b.triangles), 1), 3), b.triangles]).ravel()
            pl.add_mesh(pv.PolyData(b.vertices * 1e3, faces), color=st["color"], opacity=0.25, show_edges=False)
            keys.append((f"{st['label']}: " + ("the workspace surface (2 inputs)" if b.method == "input-patch"
                                               else "boundary surface"), st["color"]))
    rest = results[0].rest_tip if results else None
    if rest is not None and np.all(np.isfinite(rest)):
        pl.add_points(np.asarray(rest, float)[None] * 1e3, color="black", point_size=14, render_points_as_spheres=True)
        keys.append(("black: the tip at rest", "black"))
        extent.append(np.asarray(rest, float)[None] * 1e3)
    for i, (text, color) in enumerate(keys):
        pl.add_text(text, position=(20, 20 + 28 * i), font_size=10, color=color)
    P = np.vstack(extent) if extent else np.zeros((1, 3))
    axes = [_nice_axis(lo, hi) for lo, hi in zip(P.min(0), P.max(0))]
    pl.show_grid(xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)", fmt="%g",
                 bounds=[v for a in axes for v in a[:2]], n_xlabels=axes[0][2], n_ylabels=axes[1][2],
                 n_zlabels=axes[2][2])
    pl.add_text(title or "Workspace (mm)", font_size=10, position="upper_left")
    pl.camera_position = "iso"
    pl.camera.zoom(0.8)
    pl.screenshot(str(path))
    pl.close()
    return Path(path)


def _nice_axis(lo: float, hi: float) -> tuple[float, float, int]:
    """(first tick, last tick, number of ticks) of round ticks (1, 2, 2.5 or 5 times a power of ten) spanning
    [lo, hi]: the axes' labels then read 0, 50, 100, not 13.0, 5.3, 23.6."""
    from matplotlib.ticker import MaxNLocator

    if not hi > lo:
        lo, hi = lo - 1.0, hi + 1.0
    t = MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi)
    t = t[(t >= lo - (t[1] - t[0])) & (t <= hi + (t[1] - t[0]))]
    return float(t[0]), float(t[-1]), int(len(t))


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
