"""An interactive, self-contained HTML page of a workspace result (plotly; works offline, no server).

The page shows the robot at rest (its outer surface), its obstacles, the workspace's boundary surface
(translucent), and the reported points coloured by a map chosen from a menu (effort, steerability,
compliance, tilt, contact with obstacles, u1..un), with
the summary's numbers beside it. plotly.js is embedded in the file (~4.6 MB), so it opens anywhere.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from ..fem.surface import boundary_faces
from ..workspace.result import _json_default

__all__ = ["write_report"]

_UNITS = {"effort": "", "steerability": "m per input unit", "compliance": "m/N", "tilt": "deg", "contact": "N"}


def _figure(result, mesh, obstacles=()):
    import plotly.graph_objects as go

    from .scene import obstacle_surface

    traces = []
    if len(obstacles):
        P = result.points if result.n_points else np.zeros((1, 3))
        X = np.vstack([P] + ([np.asarray(mesh.nodes, float)] if mesh is not None else []))
        lo, hi = X.min(axis=0), X.max(axis=0)
        for ob in obstacles:
            V, T = obstacle_surface(ob, lo - 0.25 * (hi - lo), hi + 0.25 * (hi - lo))
            traces.append(go.Mesh3d(x=V[:, 0], y=V[:, 1], z=V[:, 2], i=T[:, 0], j=T[:, 1], k=T[:, 2],
                                    color="sienna", opacity=0.4, name=f"obstacle {ob.name}", showlegend=True,
                                    hoverinfo="skip"))
    if mesh is not None:
        X, T = np.asarray(mesh.nodes, float), boundary_faces(mesh)[:, :3]
        traces.append(go.Mesh3d(x=X[:, 0], y=X[:, 1], z=X[:, 2], i=T[:, 0], j=T[:, 1], k=T[:, 2],
                                color="lightgray", opacity=0.35, name="robot at rest", showlegend=True,
                                hoverinfo="skip"))
    b = result.boundary
    if b is not None and len(b.triangles):
        V, T = b.vertices, b.triangles
        traces.append(go.Mesh3d(x=V[:, 0], y=V[:, 1], z=V[:, 2], i=T[:, 0], j=T[:, 1], k=T[:, 2],
                                color="steelblue", opacity=0.3, name="workspace boundary", showlegend=True,
                                flatshading=True, hoverinfo="skip"))
    maps = result.maps()
    options = {name: maps[name] for name in ("effort", "steerability", "compliance", "tilt", "contact")
               if np.any(np.isfinite(maps[name])) and (name != "contact" or len(obstacles))}
    for i in range(result.u.shape[1] if result.u.ndim == 2 else 0):
        options[f"u{i + 1}"] = result.u[:, i]
    names = list(options) or ["none"]
    first = options.get(names[0], np.zeros(result.n_points))
    P = result.points
    traces.append(go.Scatter3d(x=P[:, 0], y=P[:, 1], z=P[:, 2], mode="markers", name="reached points",
                               marker=dict(size=3, color=first, colorscale="Viridis", showscale=True,
                                           colorbar=dict(title=names[0])),
                               text=[f"{names[0]}: {v:.4g}" for v in first], hoverinfo="text+x+y+z"))
    fig = go.Figure(traces)
    k = len(traces) - 1
    buttons = [dict(label=f"{name} ({_UNITS.get(name, 'input')})".replace(" ()", ""), method="restyle",
                    args=[{"marker.color": [options[name]], "marker.colorbar.title.text": name,
                           "text": [[f"{name}: {v:.4g}" for v in options[name]]]}, [k]])
               for name in options]
    fig.update_layout(
        scene=dict(aspectmode="data", xaxis_title="x (m)", yaxis_title="y (m)", zaxis_title="z (m)",
                   camera=dict(eye=dict(x=2.2, y=-2.2, z=1.4))),
        margin=dict(l=0, r=0, t=40, b=0), height=720, legend=dict(x=0, y=0, yanchor="bottom"),
        title=f"{result.problem.get('name', '')}: {result.method} workspace (colour: menu at the top left; "
              f"click a legend entry to hide it)",
        updatemenus=[dict(buttons=buttons, x=0.0, y=1.0, xanchor="left", yanchor="top", showactive=True)]
        if buttons else [])
    return fig


def _table(result) -> str:
    s = result.summary()
    m = s.get("measures") or {}
    b = s.get("boundary") or {}
    f = s.get("failures") or {"failed": s["n_failed"]}
    rows = [("method", s["method"]), ("reported points", s["n_points"])] + [
        (k.replace("_", " "), v) for k, v in f.items() if v or k == "failed"] + [("time", f"{s['time_s']:.1f} s")]
    if m.get("volume") is not None:
        err = m.get("volume_error")
        rows.append(("volume", f"{m['volume'] * 1e6:.4g} cm³" + (f" ± {err * 1e6:.2g}" if err else "")
                     + " (boundary)"))
    if m.get("cell_volume") is not None:
        rows.append(("cells × s³", f"{m['cell_volume'] * 1e6:.4g} cm³ ({m['cells']} cells of "
                                   f"{m['cell_step'] * 1e3:.3g} mm)"))
    if m.get("area") is not None:
        rows.append(("area", f"{m['area'] * 1e4:.4g} cm²"))
    if m.get("length") is not None:
        rows.append(("length", f"{m['length'] * 1e3:.4g} mm"))
    if b:
        rows.append(("boundary", f"{b['method']}, {b['triangles']} triangles, closed: {b['closed']}, "
                                 f"tolerance {b['tolerance'] * 1e3:.3g} mm"))
    if m.get("extents"):
        lo, hi = np.asarray(m["extents"])
        rows.append(("extents", " × ".join(f"{(h - l) * 1e3:.1f}" for l, h in zip(lo, hi)) + " mm"))
    for w in s.get("warnings", []):
        rows.append(("warning", w))
    cells = "".join(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>" for k, v in rows)
    return f'<table id="summary">{cells}</table>'


def write_report(result, path: str | Path, mesh=None, obstacles=()) -> Path:
    """Write the page for ``result`` (and the robot's ``mesh`` at rest and the problem's ``obstacles``, if
    given) to ``path``."""
    import plotly.io as pio

    path = Path(path)
    fig = _figure(result, mesh, obstacles)
    plot = pio.to_html(fig, full_html=False, include_plotlyjs=True, div_id="workspace",
                       config={"displaylogo": False, "responsive": True})
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>casadi-ws: {html.escape(result.problem.get('name', ''))}</title>
<style>body{{font-family:sans-serif;margin:0;display:flex;flex-wrap:wrap}} #view{{flex:3 1 640px}}
#side{{flex:1 1 320px;padding:1em}} th{{text-align:left;padding-right:1em;vertical-align:top}}
td{{font-variant-numeric:tabular-nums}}</style></head>
<body><div id="view">{plot}</div><div id="side"><h2>Summary</h2>{_table(result)}
<p>Colour: choose a map in the menu above the view. Maps: effort (RMS input fraction), steerability
(smallest singular value of dp/du), compliance (largest eigenvalue of C K⁻¹ Cᵀ, m/N), tilt (deg), contact
(the force the obstacles exert on the body, N; with obstacles).
Drag to rotate, scroll to zoom.</p>
<script type="application/json" id="summary-json">{html.escape(json.dumps(result.summary(), default=_json_default))}</script>
</div></body></html>
"""
    path.write_text(page, encoding="utf-8")
    return path
