"""An interactive, self-contained HTML page of a workspace result (plotly; works offline, no server).

The page shows the robot at rest (its outer surface), its obstacles, the workspace's boundary surface
(translucent), and the reported points coloured by a map chosen from a menu (effort, steerability,
compliance, tilt, contact with obstacles, u1..un), with
the summary's numbers beside it. plotly.js is embedded in the file (~4.6 MB), so it opens anywhere.

Clicking a point shows its tip, inputs and intensities (with units), contact force and admissibility, and the robot
deformed there: the boundary surface's vertices of up to :data:`MAX_SHAPES` points (fewer where they would exceed
:data:`SHAPE_BYTES`), float32 in base64, from the
states the run kept (``--store-states``) or else solved again after the run (:func:`casadi_ws.io.output.write_outputs`);
a point outside that subset shows the nearest one's, saying so (measured: trunk_2cables at n_d = 21, 441 points,
5.1 MB without shapes, 6.9 MB with 200).
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from ..fem.surface import boundary_faces
from ..workspace.result import _json_default

__all__ = ["write_report"]

_UNITS = {"effort": "fraction of the input range", "steerability": "mm per input unit", "compliance": "mm/N",
          "tilt": "deg", "contact": "N"}
_SCALE = {"steerability": 1e3, "compliance": 1e3}  # m -> mm, as the axes
MM = 1e3


def _up(result) -> dict:
    """The view's up axis: against gravity where the problem has it (the SOFA finger hangs along -y), else +z."""
    g = np.asarray(result.problem.get("gravity") or [0.0, 0.0, 0.0], float)
    if not np.any(g):
        return dict(x=0, y=0, z=1)
    k = int(np.argmax(np.abs(g)))
    up = np.zeros(3)
    up[k] = -np.sign(g[k])
    return dict(x=up[0], y=up[1], z=up[2])


def _inputs(result) -> list[tuple[str, str]]:
    """(label, unit) of each input: the actuator's name and its unit."""
    acts = result.problem.get("actuators") or []
    n = result.u.shape[1] if result.u.ndim == 2 else 0
    return [(acts[i].get("name", f"u{i + 1}") if i < len(acts) else f"u{i + 1}",
             acts[i].get("unit", "") if i < len(acts) else "") for i in range(n)]


def _figure(result, mesh, obstacles=(), shapes=None):
    import plotly.graph_objects as go

    from .scene import obstacle_surface

    traces = []
    if len(obstacles):
        P = result.points if result.n_points else np.zeros((1, 3))
        X = np.vstack([P] + ([np.asarray(mesh.nodes, float)] if mesh is not None else []))
        lo, hi = X.min(axis=0), X.max(axis=0)
        for ob in obstacles:
            V, T = obstacle_surface(ob, lo - 0.25 * (hi - lo), hi + 0.25 * (hi - lo))
            V = V * MM
            traces.append(go.Mesh3d(x=V[:, 0], y=V[:, 1], z=V[:, 2], i=T[:, 0], j=T[:, 1], k=T[:, 2],
                                    color="sienna", opacity=0.4, name=f"obstacle {ob.name}", showlegend=True,
                                    hoverinfo="skip"))
    if mesh is not None:
        X, T = np.asarray(mesh.nodes, float) * MM, boundary_faces(mesh)[:, :3]
        traces.append(go.Mesh3d(x=X[:, 0], y=X[:, 1], z=X[:, 2], i=T[:, 0], j=T[:, 1], k=T[:, 2],
                                color="lightgray", opacity=0.35, name="robot at rest", showlegend=True,
                                hoverinfo="skip"))
    b = result.boundary
    if b is not None and len(b.triangles):
        V, T = b.vertices * MM, b.triangles
        traces.append(go.Mesh3d(x=V[:, 0], y=V[:, 1], z=V[:, 2], i=T[:, 0], j=T[:, 1], k=T[:, 2],
                                color="steelblue", opacity=0.3, name="workspace boundary", showlegend=True,
                                flatshading=True, hoverinfo="skip"))
    if "point_axis_at_min" in result.arrays:
        traces.append(go.Scatter3d(x=[], y=[], z=[], mode="lines", line=dict(color="royalblue", width=6),
                                   name="tip axis range at the clicked point", visible=False, hoverinfo="skip"))
    if shapes is not None:
        X, T = np.asarray(mesh.nodes, float) * MM, boundary_faces(mesh)[:, :3]
        traces.append(go.Mesh3d(x=X[:, 0], y=X[:, 1], z=X[:, 2], i=T[:, 0], j=T[:, 1], k=T[:, 2],
                                color="darkorange", opacity=0.5, name="robot at the clicked point", showlegend=True,
                                visible=False, hoverinfo="skip"))
    maps = result.maps()
    options = {}  # label with its unit -> values
    for name in ("effort", "steerability", "compliance", "tilt", "contact"):
        if np.any(np.isfinite(maps[name])) and (name != "contact" or len(obstacles)):
            options[f"{name} ({_UNITS[name]})"] = np.asarray(maps[name], float) * _SCALE.get(name, 1.0)
    if "tilt_min" in maps:  # the orientation ranges (--orientation): each point's cell's
        options["tilt range in the cell (deg)"] = maps["tilt_max"] - maps["tilt_min"]
        options["smallest tilt in the cell (deg)"] = maps["tilt_min"]
        options["largest tilt in the cell (deg)"] = maps["tilt_max"]
    for i, (label, unit) in enumerate(_inputs(result)):
        options[f"{label} ({unit or 'input'})"] = result.u[:, i]
    names = list(options) or ["none"]
    first = options.get(names[0], np.zeros(result.n_points))
    P = result.points * MM
    traces.append(go.Scatter3d(x=P[:, 0], y=P[:, 1], z=P[:, 2], mode="markers", name="reached points",
                               marker=dict(size=3, color=first, colorscale="Viridis", showscale=True,
                                           colorbar=dict(title=dict(text=names[0], side="right"))),
                               text=[f"{names[0]}: {v:.4g}" for v in first],
                               hovertemplate="%{text}<br>x %{x:.2f} mm, y %{y:.2f} mm, z %{z:.2f} mm<extra></extra>"))
    fig = go.Figure(traces)
    k = len(traces) - 1
    buttons = [dict(label=name, method="restyle",
                    args=[{"marker.color": [options[name]], "marker.colorbar.title.text": name,
                           "text": [[f"{name}: {v:.4g}" for v in options[name]]]}, [k]])
               for name in options]
    fig.update_layout(
        scene=dict(aspectmode="data", xaxis_title="x (mm)", yaxis_title="y (mm)", zaxis_title="z (mm)",
                   camera=dict(up=_up(result), eye=_eye(_up(result)))),
        margin=dict(l=0, r=0, t=40, b=0), height=720, legend=dict(x=0, y=0, yanchor="bottom"),
        title=f"{result.problem.get('name', '')}: {result.method} workspace (colour: menu at the top left; "
              f"click a legend entry to hide it)",
        updatemenus=[dict(buttons=buttons, x=0.0, y=1.0, xanchor="left", yanchor="top", showactive=True)]
        if buttons else [])
    return fig


MAX_SHAPES = 200
"""Most points whose deformed robot the page holds (evenly spread over the points where there are more)."""


SHAPE_BYTES = 4_000_000
"""Most bytes of float32 vertices the page holds for the deformed robots (before base64): a robot with a large
boundary gets fewer shapes (the PneuNets finger's 144 shapes made a 12.8 MB page)."""


def shape_count(mesh, limit: int = MAX_SHAPES) -> int:
    """How many deformed robots the page holds: ``limit``, fewer where their boundary vertices would exceed
    :data:`SHAPE_BYTES`."""
    if mesh is None:
        return 0
    n = np.unique(boundary_faces(mesh)[:, :3]).size
    return int(min(limit, SHAPE_BYTES // (12 * max(n, 1))))


def shape_points(result, limit: int = MAX_SHAPES) -> np.ndarray:
    """The indices of the points whose deformed robot the page draws: ``limit`` spread evenly over the points
    (in the order the run reports them), or all of them where there are fewer."""
    n = result.n_points
    if not n or limit <= 0:
        return np.zeros(0, dtype=int)
    return np.unique(np.linspace(0, n - 1, min(limit, n)).round().astype(int))


def _shapes(result, mesh, states=None):
    """(indices of the points, their deformed boundary vertices in mm as float32 (k, v, 3), the vertices' mesh
    nodes): from ``states`` = (indices, nodal states) where given (solved again after the run,
    :func:`casadi_ws.workspace.states.states_at`), else where the run kept its states (``--store-states``),
    else None."""
    if mesh is None or not result.n_points:
        return None
    if states is None:
        if result.states is None:
            return None
        pick = shape_points(result, shape_count(mesh))
        Q = np.asarray(result.states)[pick]
    else:
        pick, Q = states
        if not len(pick):
            return None
    nodes = np.unique(boundary_faces(mesh)[:, :3])
    X = np.asarray(mesh.nodes, float)[nodes]
    Q = np.asarray(Q)[:, : 3 * mesh.n_nodes].reshape(len(pick), -1, 3)[:, nodes]
    return np.asarray(pick, dtype=int), ((X[None] + Q) * MM).astype(np.float32), nodes


def _range_axes(result) -> list:
    """Per point: the tip's axis at the two ends of its cell's range [[x, y, z], [x, y, z]] (None where not
    solved), for the page to draw the cone of directions at a clicked point."""
    lo, hi = result.arrays["point_axis_at_min"], result.arrays["point_axis_at_max"]
    return [np.round([a, b], 5).tolist() if np.all(np.isfinite([a, b])) else None for a, b in zip(lo, hi)]


def _details(result, mesh, shapes=None) -> dict:
    """What the page shows for a clicked point: its inputs and intensities with units, maps, admissibility,
    and where kept its deformed robot (the boundary surface's vertices, float32, mm, base64)."""
    import base64

    from ..solvers.admissible import decode

    maps = result.maps()
    viol = result._violations()
    out = {"inputs": [f"{n} ({u})" for n, u in _inputs(result)], "u": np.asarray(result.u, float).round(9).tolist(),
           "intensities": np.asarray(maps["intensities"], float).round(9).tolist(),
           "tip_mm": (np.asarray(result.points) * MM).round(4).tolist(),
           "contact_N": np.asarray(maps["contact"], float).round(6).tolist(),
           "admissible": [", ".join(decode(int(v))) or "yes" for v in viol], "max_shapes": MAX_SHAPES,
           "tilt": np.nan_to_num(np.asarray(maps["tilt"], float)).round(4).tolist()}
    if "tilt_min" in maps:
        rng = np.column_stack([maps["tilt_min"], maps["tilt_max"]]).round(3)
        out["tilt_range"] = [[None if not np.isfinite(v) else float(v) for v in r] for r in rng]
        out["axes"] = _range_axes(result)
        span = np.ptp(np.asarray(result.points), axis=0).max() if result.n_points else 0.0
        out["axis_mm"] = float(0.15 * span * MM) or 10.0
    if shapes is not None:
        pick, V, nodes = shapes
        out["shape_of"] = {int(i): k for k, i in enumerate(pick)}
        out["shape_vertices"] = int(V.shape[1])
        out["shapes"] = base64.b64encode(V.tobytes()).decode()
        out["shape_nodes"] = nodes.tolist()
        out["n_nodes"] = int(mesh.n_nodes)
    return out


_CLICK_JS = """
<script>
(function () {
  var gd = document.getElementById('workspace');
  var d = JSON.parse(document.getElementById('points-json').textContent);
  var shapes = null;
  if (d.shapes) {
    var bin = atob(d.shapes), buf = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) buf[i] = bin.charCodeAt(i);
    shapes = new Float32Array(buf.buffer);
  }
  function show(k) {
    var rows = '<tr><th>tip</th><td>' + d.tip_mm[k].map(function (v) { return v.toFixed(2); }).join(', ') + ' mm</td></tr>';
    for (var j = 0; j < d.inputs.length; j++)
      rows += '<tr><th>' + d.inputs[j] + '</th><td>' + d.u[k][j].toPrecision(4) + ' (intensity ' + d.intensities[k][j].toPrecision(4) + ')</td></tr>';
    rows += '<tr><th>contact</th><td>' + d.contact_N[k].toPrecision(3) + ' N</td></tr>';
    rows += '<tr><th>admissible</th><td>' + d.admissible[k] + '</td></tr>';
    rows += '<tr><th>tilt</th><td>' + d.tilt[k].toFixed(2) + ' deg</td></tr>';
    var cone = gd.data.findIndex(function (t) { return t.name === 'tip axis range at the clicked point'; });
    if (d.tilt_range && d.tilt_range[k][0] !== null) {
      rows += '<tr><th>tilt in its cell</th><td>' + d.tilt_range[k][0].toFixed(2) + ' to ' + d.tilt_range[k][1].toFixed(2) + ' deg (blue: the axis at each end)</td></tr>';
      var ax = d.axes[k];
      if (cone >= 0 && ax) {
        var p = d.tip_mm[k], L = d.axis_mm, cx = [], cy = [], cz = [];
        for (var e = 0; e < 2; e++) { cx.push(p[0], p[0] + L * ax[e][0], null); cy.push(p[1], p[1] + L * ax[e][1], null); cz.push(p[2], p[2] + L * ax[e][2], null); }
        Plotly.restyle(gd, {x: [cx], y: [cy], z: [cz], visible: true}, [cone]);
      }
    }
    var robot = gd.data.findIndex(function (t) { return t.name === 'robot at the clicked point'; });
    var s = d.shape_of ? d.shape_of[k] : undefined, at = k;
    if (robot >= 0 && s === undefined && d.shape_of) {
      // the page holds a subset of the shapes: draw the nearest point's, and say so
      var best = Infinity;
      for (var key in d.shape_of) {
        var t = d.tip_mm[key], e = d.tip_mm[k];
        var dist = Math.hypot(t[0] - e[0], t[1] - e[1], t[2] - e[2]);
        if (dist < best) { best = dist; at = +key; }
      }
      s = d.shape_of[at];
    }
    if (robot >= 0 && s !== undefined) {
      var n = d.shape_vertices, o0 = 3 * s * n;
      // interior nodes are no triangle's corner: placed on a drawn vertex, they leave the view's extent alone
      var x = new Array(d.n_nodes).fill(shapes[o0]), y = new Array(d.n_nodes).fill(shapes[o0 + 1]),
          z = new Array(d.n_nodes).fill(shapes[o0 + 2]);
      for (var v = 0; v < n; v++) {
        var node = d.shape_nodes[v], o = 3 * (s * n + v);
        x[node] = shapes[o]; y[node] = shapes[o + 1]; z[node] = shapes[o + 2];
      }
      Plotly.restyle(gd, {x: [x], y: [y], z: [z], visible: true}, [robot]);
      rows += '<tr><th>robot</th><td>' + (at === k ? 'drawn (orange)' : 'drawn (orange) at point ' + at + ', ' + best.toFixed(2)
        + ' mm away: the page holds the shapes of ' + Object.keys(d.shape_of).length + ' of ' + d.tip_mm.length + ' points') + '</td></tr>';
    } else {
      rows += '<tr><th>robot</th><td>not in this page (casadi-ws solve and write_outputs store up to ' + d.max_shapes + ' shapes)</td></tr>';
    }
    document.getElementById('point').innerHTML = '<h3>Point ' + k + '</h3><table id="point-table">' + rows + '</table>';
  }
  gd.on('plotly_click', function (ev) {
    var p = ev.points[0];
    if (p && gd.data[p.curveNumber].name === 'reached points') show(p.pointNumber);
  });
  window.casadiWsShow = show;
})();
</script>
"""


def _eye(up: dict) -> dict:
    """A view from above and to the side, with ``up`` up."""
    u = np.array([up["x"], up["y"], up["z"]], float)
    side = np.array([2.2, -2.2, 2.2]) * (1 - np.abs(u))
    e = side + 1.4 * u
    return dict(x=e[0], y=e[1], z=e[2])


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
                     + (" (the map folds: union of the images of U's grid cells)" if m.get("folded")
                        else " (boundary)")))
    if m.get("volume_upper") is not None:
        rows.append(("volume bounds", (f"{m['volume_lower'] * 1e6:.4g} (cells with all 26 neighbours) to "
                                       if m.get("volume_lower") is not None else "at most ")
                     + f"{m['volume_upper'] * 1e6:.4g} cm³ (∫|det dp/du|)"))
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


def write_report(result, path: str | Path, mesh=None, obstacles=(), states=None) -> Path:
    """Write the page for ``result`` (and the robot's ``mesh`` at rest and the problem's ``obstacles``, if
    given) to ``path``; ``states`` = (point indices, their nodal states) gives the deformed robot at those
    points where the result kept no states (:func:`casadi_ws.io.output.write_outputs` solves them)."""
    import plotly.io as pio

    path = Path(path)
    shapes = _shapes(result, mesh, states)
    fig = _figure(result, mesh, obstacles, shapes)
    plot = pio.to_html(fig, full_html=False, include_plotlyjs=True, div_id="workspace",
                       config={"displaylogo": False, "responsive": True})
    points_json = json.dumps(_details(result, mesh, shapes)).replace("</", "<\\/")  # inside <script>: no "</"
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>casadi-ws: {html.escape(result.problem.get('name', ''))}</title>
<style>body{{font-family:sans-serif;margin:0;display:flex;flex-wrap:wrap}}
#view{{flex:1 1 600px;min-width:0;max-width:100%}} #view .js-plotly-plot{{width:100%}}
#side{{flex:0 0 340px;order:2;padding:1em;box-sizing:border-box;overflow-wrap:anywhere}}
th{{text-align:left;padding-right:1em;vertical-align:top;white-space:nowrap}}
td{{font-variant-numeric:tabular-nums}}</style></head>
<body><div id="side"><h2>Summary</h2>{_table(result)}
<p>Colour: choose a map in the menu above the view. Maps: effort (RMS input fraction), steerability
(smallest singular value of dp/du, mm per input unit), compliance (largest eigenvalue of C K⁻¹ Cᵀ, mm/N), tilt
(deg), contact (the force the obstacles exert on the body, N; with obstacles), and each input by its
actuator's name and unit. Coordinates in mm; the view's up is against gravity.
Drag to rotate, scroll to zoom. Click a point: its inputs, intensities, contact and admissibility below, and the
deformed robot (stored for up to {MAX_SHAPES} points; elsewhere the nearest of them is drawn, and named).</p>
<div id="point"></div>
<script type="application/json" id="points-json">{points_json}</script>
<script type="application/json" id="summary-json">{html.escape(json.dumps(result.summary(), default=_json_default))}</script>
</div><div id="view">{plot}</div>{_CLICK_JS}</body></html>
"""
    path.write_text(page, encoding="utf-8")
    return path
