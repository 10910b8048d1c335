import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from casadi_ws import Cable, Material, Problem, box_mesh, trunk_cable, trunk_mesh
from casadi_ws.fem.mesh import quadratic
from casadi_ws.io.problem import nodes_in_box, nodes_on_plane

# compiled element kernels are cached per machine; keep the tests' cache out of the user's home if asked
os.environ.setdefault("CASADI_WS_CACHE", str(Path(tempfile.gettempdir()) / "casadi-ws-test-cache"))

REPO = Path(__file__).resolve().parents[1]
# SOFA's meshes, shipped with the repository (SoftRobots plugin scenes): the trunk with the problems, the
# finger and diamond with the tests
SOFA_TRUNK = REPO / "problems" / "meshes" / "trunk.vtk"
MESHES = REPO / "tests" / "meshes"


def script(name: str):
    """A script of scripts/ imported as a module (its functions are what tests check)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def nodes_inside_other_tetrahedra(m, q, depth=0.01):
    """An audit independent of the package's: every boundary node against every tetrahedron (its straight
    corner tetrahedron) that does not hold it, by barycentric coordinates; no broad phase, no rest distance."""
    from casadi_ws.fem.surface import boundary_faces

    x = m.positions(q)
    tets = m.mesh.tets[:, :4]
    c = x[tets]
    Tinv = np.linalg.inv(np.stack([c[:, 1] - c[:, 0], c[:, 2] - c[:, 0], c[:, 3] - c[:, 0]], axis=2))
    inside = []
    for n in np.unique(boundary_faces(m.mesh)[:, :3]):
        lam = np.einsum("mij,mj->mi", Tinv, x[n] - c[:, 0])
        bary = np.column_stack([1.0 - lam.sum(axis=1), lam])
        if np.any(np.all(bary > depth, axis=1) & ~np.any(m.mesh.tets == n, axis=1)):
            inside.append(int(n))
    return inside


def chromium():
    """Debian's chromium for the report's page tests, or skip (``make test`` installs it with apt)."""
    import shutil

    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.skip("no chromium on this machine (make test installs Debian's chromium with apt; it failed)")
    return exe


def click_points(clicks, trace: str) -> list:
    """Open each (page file, point index) of ``clicks`` in headless Chromium at 1280x720, click that reported
    point, and return per click (the #point panel's text, the trace named ``trace`` as [visible, x, y, z] or
    None); a page error fails the test."""
    from playwright.sync_api import sync_playwright

    seen = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium(), args=[
            "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"])
        for page_file, k in clicks:
            page = browser.new_page(viewport={"width": 1280, "height": 720})
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(page_file.as_uri())
            page.wait_for_selector("#workspace .gl-container canvas", timeout=60000)
            page.evaluate("""k => { const gd = document.getElementById('workspace');
                const c = gd.data.findIndex(t => t.name === 'reached points');
                gd.emit('plotly_click', {points: [{curveNumber: c, pointNumber: k}]}); }""", k)
            page.wait_for_timeout(300)
            text = page.locator("#point").inner_text()
            drawn = page.evaluate("""name => { const t = document.getElementById('workspace').data.find(
                t => t.name === name); return t ? [t.visible, Array.from(t.x), Array.from(t.y),
                Array.from(t.z)] : null; }""", trace)
            assert not errors, errors
            seen.append((text, drawn))
            page.close()
        browser.close()
    return seen


def cantilever(n=2, slender=10, model="linear", nu=0.3, E=1e6, L=0.2, cable_offset=None, loads=(), order=1):
    """A square beam along +z clamped at z = 0, n elements across, cubic elements (order 2: 10-node
    tetrahedra)."""
    h = L / slender
    mesh = box_mesh((h, h, L), (n, n, slender * n), (-h / 2, -h / 2, 0.0))
    if order == 2:
        mesh = quadratic(mesh)
    cables = []
    if cable_offset is not None:
        zs = np.linspace(L / (slender * n), L, slender * n)
        pts = np.column_stack([np.full_like(zs, cable_offset), np.zeros_like(zs), zs])
        cables = [Cable(pts, np.array([cable_offset, 0.0, 0.0]), 0.0, 1e3, "arc")]
    return Problem(mesh, Material(model, E, nu), nodes_on_plane(mesh, [0, 0, 0], [0, 0, 1]), cables,
                   np.array([0.0, 0.0, L]), point_loads=list(loads), name="cantilever")


def small_trunk(model="corotational", n_cables=2, gravity=True, resolution=0.5):
    mesh = trunk_mesh(resolution=resolution)
    cables = [trunk_cable(0, "long"), trunk_cable(90, "long"), trunk_cable(180, "short", u_max=150),
              trunk_cable(270, "short", u_max=150)][:n_cables]
    return Problem(mesh, Material(model, 1.8e7, 0.45, 1100.0), nodes_in_box(mesh, [-1, -1, -1], [1, 1, 0.02]),
                   cables, np.array([0.0, 0.0, 0.195]),
                   gravity=np.array([0.0, -9.81, 0.0]) if gravity else np.zeros(3), name="small_trunk")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def coarse_problem_file(tmp_path):
    """The shipped 2-cable trunk at mesh resolution 0.5, written to tmp_path (for command-line tests)."""
    text = (REPO / "problems" / "trunk_2cables.yaml").read_text().replace("resolution: 1.0", "resolution: 0.5")
    p = tmp_path / "coarse.yaml"
    p.write_text(text)
    return p


def run_cli(*args):
    """``casadi-ws ARGS`` in a subprocess, output captured."""
    return subprocess.run([sys.executable, "-m", "casadi_ws.cli", *map(str, args)], capture_output=True, text=True)


def pytest_collection_modifyitems(config, items):
    """The slow tests first (a stable sort): `make test`'s two workers take tests in order, and a long test
    handed out last keeps one worker busy while the other idles."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
