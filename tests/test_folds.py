"""Workspaces that fold (issue 71): where det dp/du changes sign over U the images of U's faces are not the
workspace's boundary; the surface is then the union of the images of U's grid cells (casadi_ws/workspace/
images.py), checked here against a map whose image volume is known in closed form."""

from types import SimpleNamespace

import numpy as np
import pytest

from casadi_ws.workspace.boundary import BoundarySettings, _Nodes, boundary, distance_outside
from casadi_ws.workspace.images import folded_share, kuhn_tetrahedra, tetrahedron_volumes, union_of_images


def folded_tip(U, a=(0.3, 0.2)):
    """x = u1, y = u2, z = t^2 + c t with t = 2 u3 - 1 and c = a1 u1 + a2 u2: over t in [-1, 1] z runs from
    -c^2/4 (t = -c/2, inside U: the fold det dp/du = 2 (2 t + c) = 0) to 1 + c, so the image over (u1, u2)
    has height (1 + c/2)^2, while the faces u3 = 0, 1 map to z = 1 - c and 1 + c."""
    t = 2 * U[:, 2] - 1
    c = a[0] * U[:, 0] + a[1] * U[:, 1]
    return np.column_stack([U[:, 0], U[:, 1], t * t + c * t])


def folded_volume(a=(0.3, 0.2)):
    """int_0^1 int_0^1 (1 + (a1 u1 + a2 u2) / 2)^2 du1 du2, in closed form."""
    b1, b2 = a[0] / 2, a[1] / 2
    return 1 + b1 + b2 + b1**2 / 3 + b2**2 / 3 + b1 * b2 / 2


def grid(n):
    s = np.linspace(0.0, 1.0, n)
    return np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1).reshape(-1, 3)


UNIT_BOX = SimpleNamespace(u_min=np.zeros(3), u_max=np.ones(3), n_u=3)


def test_kuhn_tetrahedra_tile_the_cube():
    U = grid(4)
    v = tetrahedron_volumes(U, kuhn_tetrahedra(4))
    assert np.all(v > 0) and v.sum() == pytest.approx(1.0)
    assert folded_share(U, 4) == (0, len(v))


@pytest.mark.parametrize("n", [9, 17])
def test_a_map_with_a_known_fold_gets_its_volume(n):
    """Through boundary() as a forward grid reaches it: the fold is found, the volume is within 1 % of the
    closed form, the error estimate covers the error, every image point is inside the surface."""
    U = grid(n)
    b = boundary(UNIT_BOX, BoundarySettings(n=n), known=(U, folded_tip(U)))
    exact = folded_volume()
    assert b.method == "input-cells" and b.closed and b.encloses
    assert b.fold["grid_tetrahedra_negative"] > 0 and b.fold["grid_tetrahedra_positive"] > 0
    assert abs(b.volume - exact) < 0.01 * exact
    assert abs(b.volume - exact) <= b.volume_error
    assert b.fold["jacobian_integral"] > 1.5 * exact  # the fold's two sheets counted twice: not the volume
    inside = folded_tip(np.random.default_rng(0).random((2000, 3)))
    assert np.all(distance_outside(b, inside) <= b.tolerance)
    # and points off the image are outside: above the top, below the fold's envelope
    off = np.array([[0.5, 0.5, 1.0 + 0.25 + 0.05], [0.5, 0.5, -0.25**2 / 4 - 0.05]])
    assert np.all(distance_outside(b, off) > 0.0)


def test_the_faces_alone_get_a_folded_map_wrong():
    """The surface of the faces' images (what was built before) misses the fold's envelope: its enclosed
    volume is far from the image's. Why the fold test matters."""
    from casadi_ws.workspace.boundary import _face_nodes, _triangles, _signed_volume, two_faces

    n = 9
    V, T = [], []
    for f in two_faces(3):
        g = _face_nodes(f, n, 3).reshape(-1, 3)
        T.append(_triangles(n) + len(V) * n * n)
        V.append(folded_tip(g))
    assert abs(abs(_signed_volume(np.vstack(V), np.vstack(T))) - folded_volume()) > 0.2 * folded_volume()


def test_a_map_without_a_fold_keeps_the_faces_surface():
    U = grid(9)
    P = U + 0.1 * U**2  # det > 0 everywhere; each axis maps [0, 1] onto [0, 1.1]
    b = boundary(UNIT_BOX, BoundarySettings(n=9), known=(U, P))
    assert b.method == "input-faces" and not b.fold
    assert b.volume == pytest.approx(1.1**3, rel=1e-3)


def test_signs_of_the_methods_samples_reveal_a_fold():
    """A forward-backward run passes det A at its configurations: mixed signs are a fold, even where the
    face nodes alone show none; a sign below 1e-6 of the largest |det A| is not read."""
    nodes = _Nodes(UNIT_BOX, None, None, None, {})
    u = np.random.default_rng(1).random((10, 3))
    assert not nodes.fold((u, np.full(10, 2.0)))
    assert not nodes.fold((u, np.r_[np.full(9, 2.0), -1e-7]))
    fold = nodes.fold((u, np.r_[np.full(9, 2.0), -0.5]))
    assert fold["det_negative"] == 1 and fold["inputs"][0] == pytest.approx(u[9].tolist())


def test_union_of_turned_over_tetrahedra_counts_overlaps_once():
    """z = |2 u3 - 1| folds U's two halves onto one unit cube (exactly, the kink on grid nodes): the union is
    the cube, the sum of |volumes| twice it, half the tetrahedra turned over."""
    U = grid(5)
    r = union_of_images(np.column_stack([U[:, 0], U[:, 1], np.abs(2 * U[:, 2] - 1)]), 5)
    assert r["volume"] == pytest.approx(1.0, rel=1e-9)
    assert r["jacobian_integral"] == pytest.approx(2.0, rel=1e-9)
    assert r["turned_over"] == r["tetrahedra"] // 2


def test_a_map_that_wraps_onto_itself_is_joined_without_overlaps():
    """theta over 1.5 turns in steps of 90 degrees: det dp/du keeps one sign but the image overlaps itself,
    so a block of one sign is not one solid. The piecewise-linear image is the annulus between squares of
    circumradius 1 and 2, height 1: volume 8 - 2 = 6 exactly, counted once (the sheets sum to 9); the
    tetrahedra joined one by one agree within the boolean's tolerance."""
    import manifold3d

    from casadi_ws.workspace.images import _FACES

    n = 7
    U = grid(n)
    r, th = 1 + U[:, 0], 3 * np.pi * U[:, 1]
    P = np.column_stack([r * np.cos(th), r * np.sin(th), U[:, 2]])
    got = union_of_images(P, n)
    T = kuhn_tetrahedra(n)
    v = tetrahedron_volumes(P, T)
    T = np.where((v < 0)[:, None], T[:, [0, 2, 1, 3]], T)
    one_by_one = manifold3d.Manifold.batch_boolean(
        [manifold3d.Manifold(manifold3d.Mesh64(vert_properties=np.ascontiguousarray(P[t]),
                                               tri_verts=_FACES.astype(np.uint32))) for t in T],
        manifold3d.OpType.Add).volume()
    assert got["volume"] == pytest.approx(6.0, rel=1e-9)
    assert got["jacobian_integral"] == pytest.approx(9.0, rel=1e-9)
    assert one_by_one == pytest.approx(6.0, rel=1e-3)


def test_a_forward_grid_with_excluded_points_is_still_whole():
    """A forward result reports its inadmissible points apart (excluded_*); boundary_of gives them back with their
    violations, so the grid is whole (its tetrahedra show the fold) and the surface's vertices say which are
    not admissible."""
    from types import SimpleNamespace as NS

    from casadi_ws.workspace.boundary import boundary_of

    U = grid(9)
    P = folded_tip(U)
    bad = np.zeros(len(U), dtype=bool)
    bad[::7] = True
    result = NS(method="forward", settings={"n_d": 9}, u=U[~bad], points=P[~bad], n_points=int((~bad).sum()),
                arrays={"excluded_u": U[bad], "excluded_points": P[bad],
                        "excluded_violations": np.full(bad.sum(), 4, np.int64)},
                _violations=lambda: np.zeros(int((~bad).sum()), np.int64))
    b = boundary_of(result, None, model=UNIT_BOX)
    assert b.method == "input-cells" and b.fold["grid_tetrahedra_negative"] > 0
    assert abs(b.volume - folded_volume()) < 0.01 * folded_volume()
    assert np.count_nonzero(b.violations) > 0
