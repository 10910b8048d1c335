"""The workspace's boundary surface, its enclosed volume and its area: the image of the input box's faces.

The reachable set is W = p(U), the image of the box U of inputs under the tip map p(u). Where the map is a
submersion inside U (its Jacobian A = dp/du has rank 3), an interior input maps to an interior point, so
the boundary of W lies in the image of the boundary of U, and (its fibres leaving U) W is the union of the
images of U's 3-dimensional faces. Hence:

* **3 inputs.** If det A keeps one sign over U (checked at every forward-backward point, where A is known)
  and p is one-to-one, the boundary of W is exactly p(dU): the six faces of the box, each sampled on an
  n x n grid of verified equilibria and triangulated. That is a closed surface by construction (faces share
  their edge nodes), oriented outwards by the sign of det A, and its enclosed volume (divergence theorem)
  equals the Jacobian integral  V = int_U |det A| du  up to the triangulation's chord error, O(h^2).
  Where det A changes sign (a fold: its sign at the face nodes, at the method's configurations, or a forward
  grid's turned-over tetrahedra), the surface is instead the union of the images of a grid of U's cells
  (``input-cells``, :mod:`.images`), which stays the boundary whatever the map does.
* **4 or 5 inputs.** Every 2-face of U (two inputs free, the others at a bound) is sampled; a face is kept
  when its triangles lie outside the images of the 3-faces it does not belong to (tested with the closed
  surfaces of those images); the kept faces, oriented by the 3-face they bound, must close (every edge
  shared by exactly two triangles, each way once), which is checked, never assumed. On the 4-cable trunk
  12 of the 24 faces are kept and close (BENCHMARKS.md "Workspace volume").
* **2 inputs.** W is a surface patch: p over U on an n x n grid, with its boundary curve p(dU). It has an
  area and no volume.
* **6 or more inputs**, or a surface that does not close: no surface (C(n,2) 2^(n-2) faces); the volume
  falls back to the cells' (``method: cells``) and the summary says so.

Why not a Hermite-data contouring (e.g. dual contouring) of the forward-backward grid: the 3-cable trunk's
workspace is a curved sheet ~2.5 mm thick, thinner than its 4 mm cells; a grid-based surface cannot
resolve it, the input faces can (docs/methods.md, BENCHMARKS.md).

Error estimate: the faces are sampled on n x n nodes (n odd); the same surface through every other node
((n + 1) / 2) gives a second volume, and for a second-order method the finer one's error is about a third of
their difference; ``volume_error`` reports the whole difference (conservative). ``tolerance`` bounds the
distance from the true boundary to the triangles: half the coarse surface's largest chord error
(:func:`_tolerance`); every verified point of the method is checked against it (``points_outside``).
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass

import numpy as np

from ..fem.spec import ranged_inputs
from ..fem.surface import winding_numbers
from ..solvers.admissible import admissibility
from ..solvers.equilibrium import CONVERGED, solve_equilibrium, tangent_factorization
from ..solvers.sensitivity import second_order, sensitivity
from .boundary_data import Boundary, distance_outside
from .images import kuhn_tetrahedra, orientations, union_of_images

__all__ = ["Boundary", "BoundarySettings", "Seeds", "boundary", "boundary_of", "distance_outside", "two_faces"]

MAX_INPUTS = 5
"""Above this many inputs the number of faces, C(n,2) 2^(n-2), makes the surface too costly."""

MAX_SEEDED_INPUTS = 4
"""Up to this many inputs the face nodes start from the method's reached configurations (:class:`Seeds`)."""


@dataclass
class BoundarySettings:
    """How the boundary surface is built."""

    n: int = 5
    """Nodes per edge of each face of U (odd, >= 3): (n - 1)^2 quadrilaterals, two triangles each. 5 puts
    the 3-cable trunk's volume 0.8 % below its Jacobian integral (BENCHMARKS.md "Workspace volume": -0.77 %)."""
    enabled: bool = True
    """Build the surface with every forward-backward result (``--no-boundary`` turns it off)."""
    fold_n: int = 9
    """Where the map folds (3 inputs): nodes per input of the grid of U whose cells' images make the surface
    (odd, >= 5; a forward grid at least as fine is used as it is). Its error estimate is the difference from
    the grid through every other node: on the 3-cable SOFA trunk with 20 N cables, 139.8 cm^3 at 9 (estimate
    36) and 133.4 at 17 (estimate 6.5) (tests/test_folds.py, docs/methods.md "Folds")."""
    fold_tolerance: float = 0.05
    """Where the map folds: while the error estimate exceeds this share of the volume, the grid is refined
    (2 m - 1 nodes per input: the previous grid's nodes and those between), up to ``fold_max``."""
    fold_max: int = 17
    """The finest fold grid the refinement goes to (17^3 = 4,913 equilibria: ~70 s on the SOFA trunk with 2
    workers)."""


def two_faces(n_u: int):
    """The 2-faces of the box of n_u inputs: (i, j, fixed), ``fixed`` mapping every other input to 0 (its
    lower bound) or 1 (upper)."""
    out = []
    for i, j in itertools.combinations(range(n_u), 2):
        others = [k for k in range(n_u) if k not in (i, j)]
        for side in itertools.product((0, 1), repeat=len(others)):
            out.append((i, j, dict(zip(others, side))))
    return out


def _face_nodes(face, n: int, n_u: int) -> np.ndarray:
    """(n, n, n_u) unit-box coordinates of a face's nodes; axis 0 runs along input i, axis 1 along j."""
    i, j, fixed = face
    s = np.linspace(0.0, 1.0, n)
    g = np.zeros((n, n, n_u))
    for k, v in fixed.items():
        g[..., k] = v
    g[..., i], g[..., j] = s[:, None], s[None, :]
    return g


class Seeds:
    """For each face node the surface will solve, the verified configuration nearest to it in the inputs
    (scaled max-norm) that the method met on its way: its Newton solve then starts one small step away
    instead of from the previous node, a quarter of U's range away. A seed is taken only where it is nearer
    than the nodes solved before. Up to :data:`MAX_SEEDED_INPUTS` inputs. With 4, one configuration per cell
    samples a 3-D subset of U, yet on the 4-cable trunk 192 of the 216 nodes solved had a seed within a tenth
    of the range (10 were 0.3 or more away): 333 LUs against 801 from the previous node, 4.2 s against 10.1 s
    in one process, the same surface (volume within 5e-8). With 5, the ~1000 face nodes' seeds would hold
    as many states.

    ``offer(u, q, S, Q)`` keeps a configuration where it is nearer than the seed so far (q and S by reference,
    S in float32 as a checkpoint holds it, so a resumed run seeds the same; Q, its d2q/du2 where the
    exploration has one, predicts the node to second order, see :func:`_solve_nodes`)."""

    def __init__(self, model, settings: BoundarySettings):
        self.box = _Box(model)
        n_u, n = self.box.n, int(settings.n)
        faces = two_faces(n_u) if 2 <= n_u <= MAX_SEEDED_INPUTS else []  # (2: one face)
        self.nodes = (np.unique(np.concatenate([_face_nodes(f, n, n_u).reshape(-1, n_u) for f in faces]), axis=0)
                      if faces else np.zeros((0, n_u)))
        self.dist = np.full(len(self.nodes), np.inf)
        self.which = np.full(len(self.nodes), -1)
        self.configs: dict = {}  # number -> (u, q, S, Q) of the configurations that are some node's seed
        self._next = 0

    def offer(self, u, q, S, Q=None) -> None:
        if not len(self.nodes) or q is None or S is None:
            return
        d = np.abs(self.nodes - self.box.unit(u)).max(axis=1)
        better = d < self.dist
        if better.any():
            self.dist[better] = d[better]
            self.which[better] = self._next
            self.configs[self._next] = (np.asarray(u, float), q, np.asarray(S, dtype=np.float32),
                                        None if Q is None else np.asarray(Q, dtype=np.float32))
            self._next += 1
            for k in set(self.configs) - set(self.which.tolist()):  # superseded everywhere: its state goes
                del self.configs[k]

    def of(self) -> dict:
        """key of a node -> (u, q, S, Q) of its seed (Q None where the exploration had none)."""
        return {_key(s): self.configs[w] for s, w in zip(self.nodes, self.which) if w >= 0}

    def arrays(self) -> dict:
        """The seeds as checkpoint arrays."""
        used = sorted(self.configs)
        at = {w: k for k, w in enumerate(used)}
        cfg = [self.configs[w] for w in used]
        return {"seed_which": np.array([at.get(w, -1) for w in self.which.tolist()], dtype=np.int64),
                "seed_dist": self.dist, "seed_u": np.array([c[0] for c in cfg]).reshape(len(cfg), len(self.box.lo)),
                "seed_q": np.array([c[1] for c in cfg]).reshape(len(cfg), -1) if cfg else np.zeros((0, 0)),
                "seed_S": np.array([c[2] for c in cfg], dtype=np.float32) if cfg else np.zeros((0, 0, 0), np.float32),
                **_stacked_Q([c[3] for c in cfg])}

    def restore(self, a: dict) -> None:
        if "seed_which" not in a or len(a["seed_which"]) != len(self.nodes):
            return
        self.which, self.dist = a["seed_which"].copy(), a["seed_dist"].copy()
        Q = [None if np.isnan(x).all() else x for x in a["seed_Q"]] if "seed_Q" in a else [None] * len(a["seed_u"])
        self.configs = dict(enumerate(zip(a["seed_u"], a["seed_q"], a["seed_S"], Q)))
        self._next = len(self.configs)


def _stacked_Q(Qs: list) -> dict:
    """The seeds' Q as one checkpoint array (NaN for a seed without), or nothing if none has one."""
    shape = next((Q.shape for Q in Qs if Q is not None), None)
    if shape is None:
        return {}
    return {"seed_Q": np.array([np.full(shape, np.nan, np.float32) if Q is None else Q for Q in Qs], np.float32)}


KEY_SCALE = 720720
"""Nodes are keyed by their unit coordinates times this (exact for every grid whose n - 1 divides it)."""


def _key(s):
    return tuple(np.rint(np.asarray(s) * KEY_SCALE).astype(np.int64).tolist())


def fold_grid_ok(n: int) -> bool:
    """Whether n nodes per input can make a fold grid: odd (the grid through every other node is the coarse
    one), at least 5, and n - 1 dividing :data:`KEY_SCALE` (its nodes keyed exactly)."""
    return n >= 5 and n % 2 == 1 and KEY_SCALE % (n - 1) == 0


class _Box:
    """The box U over the inputs that have a range (an input with u_min = u_max, a cable held at its rest
    length, is no dimension of it): unit coordinates of those inputs, and back to u."""

    def __init__(self, model):
        self.lo = model.u_min
        self.active = ranged_inputs(model.u_min, model.u_max)
        self.span = (model.u_max - model.u_min)[self.active]
        self.n = self.active.size

    def unit(self, u) -> np.ndarray:
        return (np.asarray(u)[..., self.active] - self.lo[self.active]) / self.span

    def u(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        out = np.broadcast_to(self.lo, s.shape[:-1] + self.lo.shape).copy()
        out[..., self.active] += s * self.span
        return out


def _solve_nodes(model, us: np.ndarray, seeds: list | None = None):
    """Equilibria at ``us`` (in continuation order): tips, status, admissibility violations, the number
    of LU factorisations and det dp/du over the inputs with a range (NaN unless there are 3 of them). Each start is the nearest solved node's or seed's (u, q, S, Q) state plus its
    tangent step S du, and Q(du, du) / 2 from a seed that has Q (the exploration's own d2q/du2).

    Why Q: measured on the 4-cable trunk, Newton from every one of the 328 face nodes' seeds took 450 LUs
    (5.4-5.8 s, one process) with it against 614 (7.9 s) with S du alone, none failing either way."""
    tips = np.full((len(us), 3), np.nan)
    dets = np.full(len(us), np.nan)
    box = _Box(model)
    status = np.zeros(len(us), dtype=int)
    viol = np.zeros(len(us), dtype=np.int64)
    done = list(seeds or [])  # (u, q, S, Q)
    span = np.where(model.u_max > model.u_min, model.u_max - model.u_min, 1.0)
    wanted = _starts_of_others(us, done, span)
    n_fac = 0
    for k, u in enumerate(us):
        guess = q0 = u0 = None
        if done:
            near = min(done, key=lambda d: np.abs((d[0] - u) / span).max())
            u0, q0, S, Q = near
            if S is None:  # a node no other was to start from, until a nearer one failed to converge
                S = sensitivity(model, q0, tangent_factorization(model, q0, u0))[1]
                n_fac += 1
            # second-order predictors by differences cost more LUs, measured: (S_a - S_(a - du)) du / 2 268
            # against 196 on the coarse 3-cable trunk (its S from an LU one iterate away); the quadratic through
            # q_(a - du) 531 against 335 on the shipped one (over a quarter of U's range it overshoots)
            step = S @ (u - u0)
            guess = q0 + model.full(step if Q is None else step + second_order(Q, u - u0))
        eq = solve_equilibrium(model, u, q0=q0, u0=u0, guess=guess)
        n_fac += eq.factorizations
        status[k] = eq.status
        if eq.status != CONVERGED:
            continue
        tips[k] = eq.tip
        fac = eq.factorization
        if fac is None:
            fac = tangent_factorization(model, eq.q, eq.u)
        # A at every node (one solve with n_u right-hand sides on the LU at hand): its sign is the fold test
        S = None
        if box.n == 3 or k in wanted:  # (S: only for the nodes others start from, see _starts_of_others)
            A, S = sensitivity(model, eq.q, fac)
            if box.n == 3:
                dets[k] = np.linalg.det(A[:, box.active])
        viol[k] = admissibility(model, eq.q, eq.u, fac).mask
        done.append((u.copy(), eq.q, S if k in wanted else None, None))
    return tips, status, viol, n_fac, dets


def _starts_of_others(us, starts: list, span) -> set:
    """The nodes (indices of ``us``) that a later node will start from, as :func:`_solve_nodes` chooses (the
    nearest of ``starts`` and the nodes before it, the first of equals), if every node converges: only they
    need their S. Why: on the 4-cable trunk 2 of the 216 face nodes start from a node, the others from their
    seeds, and S was 16 % of the surface's time."""
    wanted = set()
    seeds_u = np.array([d[0] for d in starts]).reshape(len(starts), us.shape[1])
    for k in range(1, len(us)):
        d_nodes = np.abs((us[:k] - us[k]) / span).max(axis=1)
        j = int(np.argmin(d_nodes))
        if not len(seeds_u) or d_nodes[j] < np.abs((seeds_u - us[k]) / span).max(axis=1).min():
            wanted.add(j)
    return wanted


def _solve_job(model, us, seeds=None):
    return _solve_nodes(model, us, seeds)


def _order(nodes: list) -> list:
    """Continuation order: greedy nearest neighbour from the lower corner (all inputs at their minimum)."""
    P = np.array(nodes, dtype=float)
    left = list(range(len(P)))
    cur = int(np.argmin(P.sum(1)))
    out = [cur]
    left.remove(cur)
    while left:
        d = np.abs(P[left] - P[cur]).sum(1)
        cur = left[int(np.argmin(d))]
        out.append(cur)
        left.remove(cur)
    return out


def _triangles(n: int, sub: int = 1) -> np.ndarray:
    """Triangles of an n x n node grid (index r * n + c), every ``sub``-th node, counter-clockwise in (r, c)."""
    idx = np.arange(n * n).reshape(n, n)[::sub, ::sub]
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def _signed_volume(V, T) -> float:
    return float(np.einsum("ij,ij->i", V[T[:, 0]], np.cross(V[T[:, 1]], V[T[:, 2]])).sum() / 6.0)


def _area(V, T) -> float:
    return float(0.5 * np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1).sum())


def _closed(T) -> bool:
    """Every edge shared by exactly two triangles, running through them in opposite directions: a closed,
    consistently oriented surface."""
    from ..fem.surface import edge_report

    return edge_report(T) == (0, 0)


def _outward(face, three_face) -> int:
    """+1 if the face's (i, j) parametrisation points out of the 3-face ``(free inputs a < b < c, fixed)``."""
    i, j, fixed = face
    free = three_face[0]
    k = next(x for x in free if x not in (i, j))
    order = [free.index(i), free.index(j), free.index(k)]
    cyclic = order in ([0, 1, 2], [1, 2, 0], [2, 0, 1])
    return (1 if cyclic else -1) * (1 if fixed[k] == 1 else -1)


def _three_faces(faces):
    """The 3-faces (free triple, fixed) and, for each, its six 2-faces' indices."""
    index = {(f[0], f[1], tuple(sorted(f[2].items()))): m for m, f in enumerate(faces)}
    out = []
    n_u = len(faces[0][2]) + 2
    for free in itertools.combinations(range(n_u), 3):
        others = [k for k in range(n_u) if k not in free]
        for side in itertools.product((0, 1), repeat=len(others)):
            fixed = dict(zip(others, side))
            members = []
            for a, b in itertools.combinations(free, 2):
                c = next(x for x in free if x not in (a, b))
                for v in (0, 1):
                    members.append(index[(a, b, tuple(sorted({**fixed, c: v}.items())))])
            out.append((list(free), fixed, members))
    return out


def boundary(model, settings: BoundarySettings | None = None, executor=None, problem=None,
             known: tuple | None = None, seeds: Seeds | None = None, samples: tuple | None = None) -> Boundary:
    """The boundary of the workspace p(U) (see the module's docstring).

    ``executor`` (with ``problem``) solves the face nodes in parallel; ``known`` = (u, tips) of verified
    equilibria to take instead of solving (e.g. a forward grid whose nodes include the faces' nodes);
    ``seeds``: verified configurations to start the nodes' Newton solves from (:class:`Seeds`); ``samples`` =
    (u, det dp/du) at the method's verified configurations, read for the sign of det A (a fold).
    """
    settings = settings or BoundarySettings()
    n = int(settings.n)
    if n < 3 or n % 2 == 0:
        raise ValueError(f"boundary: n must be odd and >= 3, got {n}")
    n_u = _Box(model).n
    if n_u < 2 or n_u > MAX_INPUTS:
        why = (f"{n_u} inputs with a range, C(n,2) 2^(n-2) = {len(two_faces(n_u)) if n_u <= 12 else 'too many'} "
               f"faces" if n_u > MAX_INPUTS else "fewer than two inputs with a range")
        return Boundary(np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros((0, model.n_u)), "none",
                        notes=[f"no boundary surface ({why}): no volume (cell_volume counts the cells)"])
    if not fold_grid_ok(int(settings.fold_n)):
        raise ValueError(f"boundary: fold_n must be odd, >= 5 and n - 1 must divide {KEY_SCALE}, got {settings.fold_n}")
    nodes = _Nodes(model, executor, problem, known, seeds.of() if seeds is not None else {}, settings)
    known_keys = set(nodes.tip)
    b = _surface(nodes, n, samples)
    b.counters = {"solved_nodes": len(nodes.used - known_keys), "known_nodes": len(nodes.used & known_keys),
                  "seeded_nodes": len((nodes.used - known_keys) & set(nodes.seeds)),
                  "factorizations": nodes.factorizations}
    return b


def _surface(nodes, n, samples=None) -> Boundary:
    n_u = nodes.box.n
    if n_u == 2:
        out = nodes.solve([(0, 1, {})], n)
        return out if isinstance(out, Boundary) else _patch(*out, n)
    faces = two_faces(n_u)
    # a fold the method's samples (or a forward grid) show already: the grid holds the faces' nodes
    fold = nodes.fold(samples) if n_u == 3 else {}
    if fold:
        return _folded_surface(nodes, fold)
    # 4 or more inputs: which faces bound the workspace, and their orientation, from a 3 x 3 sampling
    screen = nodes.solve(faces, n if n_u == 3 else 3)
    if isinstance(screen, Boundary):
        return screen
    fold = nodes.fold(samples) if n_u == 3 else {}  # and det A at the face nodes
    if fold:
        return _folded_surface(nodes, fold)
    keep, flip, notes = _orient(*screen, faces)
    if n_u > 3:
        notes.append(f"{len(keep)} of {len(faces)} faces of U bound the workspace")
    if not keep:
        return Boundary(screen[0], np.zeros((0, 3), int), screen[1], "none", violations=screen[2],
                        notes=notes + ["no face of U lies on the workspace's boundary"])
    out = nodes.solve([faces[m] for m in keep], n) if n_u > 3 else screen
    if isinstance(out, Boundary):
        return out
    V, U, vmask, face_tris = out
    if n_u == 3:
        face_tris = [[face_tris[sub][m] for m in keep] for sub in (0, 1)]
    tol = max(_tolerance(V, _face_grid(T)) for T in face_tris[0])
    b = _closed_surface(V, U, [[T[:, ::-1] if f else T for T, f in zip(face_tris[sub], [flip[m] for m in keep])]
                               for sub in (0, 1)], vmask, notes, tol)
    if np.any(b.violations):
        b.notes.append(f"{np.count_nonzero(b.violations)} of {len(b.violations)} surface vertices are not "
                       f"admissible equilibria: the surface bounds the image of U, which is larger than the "
                       f"admissible workspace there")
    return b


class _Nodes:
    """The face nodes' equilibria, each solved once (in parallel over the executor's workers)."""

    def __init__(self, model, executor, problem, known, seeds, settings=None):
        self.model, self.executor, self.problem, self.seeds = model, executor, problem, seeds
        settings = settings or BoundarySettings()
        self.fold_n, self.fold_max = int(settings.fold_n), int(settings.fold_max)
        self.fold_tolerance = float(settings.fold_tolerance)
        self.box = _Box(model)
        self.tip, self.viol, self.det = {}, {}, {}
        self.used = set()  # the nodes of every face asked for
        self.factorizations = 0
        if known is not None:  # (u, tips[, admissibility violations])
            viol = known[2] if len(known) > 2 else np.zeros(len(known[0]), dtype=np.int64)
            for u, p, v in zip(np.asarray(known[0]), np.asarray(known[1]), viol):
                if np.all(np.isfinite(p)):
                    self.tip[_key(self.box.unit(u))] = np.asarray(p, float)
                    self.viol[_key(self.box.unit(u))] = int(v)
        self.known_n = self._known_grid()

    def _known_grid(self) -> int:
        """n if the known nodes hold a whole n x n x n grid of U (a forward grid, n odd >= 5), else 0."""
        n = round(len(self.tip) ** (1.0 / 3.0)) if self.box.n == 3 else 0
        if not fold_grid_ok(n):
            return 0
        return n if all(_key(s) in self.tip for s in _grid_nodes(n)) else 0

    def fold(self, samples=None) -> dict:
        """Evidence that det dp/du changes sign over U (3 inputs), from the turned-over tetrahedra of a known
        grid, det A at the face nodes solved here and at the method's ``samples`` = (u, det A); {} if none.
        Why a relative threshold: det A is a product of three columns each ~1e-6 accurate, so a sign is read
        only where |det A| is above 1e-6 of the largest."""
        out, where = {}, []
        if self.known_n:
            n = self.known_n
            grid = _grid_nodes(n)
            sign = orientations(np.array([self.tip[_key(s)] for s in grid]), n)
            pos, neg = np.count_nonzero(sign > 0), np.count_nonzero(sign < 0)
            if pos and neg:
                out.update(grid_tetrahedra_positive=int(pos), grid_tetrahedra_negative=int(neg))
                minority = sign == (-1 if neg <= pos else 1)
                where.append(self.box.u(grid[kuhn_tetrahedra(n)[minority]].mean(axis=1)))
        u = [self.box.u(np.array(k) / KEY_SCALE) for k in self.det]
        d = list(self.det.values())
        if samples is not None:
            u += list(np.asarray(samples[0], float))
            d += list(np.asarray(samples[1], float))
        d, u = np.asarray(d, float), np.asarray(u, float).reshape(len(d), len(self.model.u_min))
        ok = np.isfinite(d)
        d, u = d[ok], u[ok]
        d = np.where(np.abs(d) > 1e-6 * np.abs(d).max(initial=0.0), d, 0.0)
        pos, neg = np.count_nonzero(d > 0), np.count_nonzero(d < 0)
        if pos and neg:
            out.update(det_positive=int(pos), det_negative=int(neg))
            where.append(u[d < 0] if neg <= pos else u[d > 0])
        if out:
            w = np.vstack(where)
            out["inputs"] = w[np.linspace(0, len(w) - 1, min(8, len(w))).astype(int)].tolist()
        return out

    def solve_nodes(self, nodes) -> int:
        """Solve the ``nodes`` (unit coordinates) not known yet; the number that did not converge."""
        keys = {}
        for s in nodes:
            keys.setdefault(_key(s), s)
        self.used |= set(keys)
        todo = [k for k in keys if k not in self.tip]
        if todo:
            order = [todo[m] for m in _order([keys[k] for k in todo])]
            workers = getattr(self.executor, "workers", 1) if self.executor is not None else 1
            chunks = [c for c in np.array_split(np.arange(len(order)), workers) if len(c)]
            # each piece gets the seeds of its own nodes (a configuration seeding several is sent once)
            jobs = [(self.box.u(np.array([keys[order[m]] for m in c])),
                     list({id(sd): sd for sd in (self.seeds.get(order[m]) for m in c) if sd is not None}.values()))
                    for c in chunks]
            if self.executor is None or len(jobs) == 1 and workers == 1:
                answers = [_solve_nodes(self.model, *job) for job in jobs]
            else:
                answers = self.executor.map(_solve_job, self.problem, jobs)
            for c, (tips, status, v, n_fac, dets) in zip(chunks, answers):
                self.factorizations += n_fac
                for m, t, st, vv, d in zip(c, tips, status, v, dets):
                    if st == CONVERGED:
                        self.tip[order[m]], self.viol[order[m]], self.det[order[m]] = t, vv, d
        return sum(k not in self.tip for k in keys)

    def sweep(self, m: int) -> int:
        """Solve an m x m x m grid of U by the forward method's sweep (continuation along grid lines with its
        predictors, over the executor's workers); the number of nodes that did not converge. Why not
        :meth:`solve_nodes`: on the folded 3-cable SOFA trunk its nearest-node continuation took 10,720 LUs
        for the 9^3 grid (44 s, 2 workers), the sweep 18.6 s."""
        from .forward import ForwardSettings, forward

        fw = forward(self.problem, settings=ForwardSettings(n_d=m, progress=False, maps="none"),
                     model=self.model, executor=self.executor)
        self.factorizations += int(fw.counters.get("factorizations", 0))
        for u, p, v in itertools.chain(zip(fw.u, fw.points, fw._violations()),
                                       zip(fw.arrays["excluded_u"], fw.arrays["excluded_points"],
                                           fw.arrays["excluded_violations"])):
            k = _key(self.box.unit(u))
            self.tip[k], self.viol[k] = np.asarray(p, float), int(v)
        keys = {_key(s) for s in _grid_nodes(m)}
        self.used |= keys
        return sum(k not in self.tip for k in keys)

    def solve(self, faces, n):
        """(V, U, violations, face triangles [fine, every other node]) over ``faces``' n x n nodes, or a
        :class:`Boundary` saying that some did not converge."""
        n_u = self.box.n
        grids = [_face_nodes(f, n, n_u).reshape(-1, n_u) for f in faces]
        keys = {}
        for g in grids:
            for s in g:
                keys.setdefault(_key(s), s)
        self.solve_nodes(list(keys.values()))
        names = list(keys)
        index = {k: m for m, k in enumerate(names)}
        V = np.array([self.tip.get(k, np.full(3, np.nan)) for k in names])
        U = self.box.u(np.array([keys[k] for k in names]))
        vmask = np.array([self.viol.get(k, 0) for k in names], dtype=np.int64)
        failed = int(np.count_nonzero(~np.isfinite(V[:, 0])))
        if failed:
            return Boundary(V, np.zeros((0, 3), int), U, "none", violations=vmask, failed=failed,
                            notes=[f"{failed} face nodes did not converge: no boundary surface; the volume is "
                                   f"the cells'"])
        ids = [np.array([index[_key(s)] for s in g]) for g in grids]
        return V, U, vmask, [[i[_triangles(n, sub)] for i in ids] for sub in (1, 2)]


def _grid_nodes(n: int) -> np.ndarray:
    """(n^3, 3) unit coordinates of an n x n x n grid of U, node (i n + j) n + k."""
    s = np.linspace(0.0, 1.0, n)
    return np.stack(np.meshgrid(s, s, s, indexing="ij"), axis=-1).reshape(-1, 3)


def _folded_surface(nodes, fold) -> Boundary:
    """3 inputs whose map folds: the union of the images of an m x m x m grid's cells (:mod:`.images`), m the
    known forward grid's if at least ``fold_n`` (every other node of it down to ``fold_max``), else ``fold_n``;
    the volume's error from the union through every other node."""
    m = nodes.known_n if nodes.known_n >= nodes.fold_n else nodes.fold_n
    while m > nodes.fold_max and fold_grid_ok((m + 1) // 2) and (m + 1) // 2 >= nodes.fold_n:
        m = (m + 1) // 2  # a finer forward grid's nodes, every other one: the boolean's cost grows as m^3
    why = (f"det dp/du changes sign over U (the map folds over itself: {_fold_words(fold)}), so the images of "
           f"U's faces are not the workspace's boundary")
    coarse, refined = None, []
    while True:
        grid = _grid_nodes(m)
        keys = [_key(s) for s in grid]
        known = all(k in nodes.tip for k in keys)
        failed = nodes.sweep(m) if not known and nodes.problem is not None else nodes.solve_nodes(grid)
        if failed:
            return Boundary(np.zeros((0, 3)), np.zeros((0, 3), int), np.zeros((0, nodes.model.n_u)), "none",
                            failed=failed, fold=fold,
                            notes=[f"{why}; {failed} of the {m}^3 grid nodes that would bound it did not converge: "
                                   f"no volume (cell_volume counts the cells)"])
        P = np.array([nodes.tip[k] for k in keys])
        fine = union_of_images(P, m)
        if coarse is None:  # (refined: the previous grid is every other node of this one)
            coarse = union_of_images(P.reshape(m, m, m, 3)[::2, ::2, ::2].reshape(-1, 3), (m + 1) // 2)
        error = abs(fine["volume"] - coarse["volume"])
        if error <= nodes.fold_tolerance * fine["volume"] or 2 * m - 1 > nodes.fold_max:
            break
        refined.append(f"{m}^3 ({fine['volume'] * 1e6:.4g} cm^3 +- {error * 1e6:.2g})")
        coarse, m = fine, 2 * m - 1
    V, T = fine["vertices"], fine["triangles"]
    # vertices at grid nodes carry their inputs and admissibility; where sheets cross there are none
    from scipy.spatial import cKDTree

    dist, j = cKDTree(P).query(V)
    at = dist <= 1e-9 * max(float(np.ptp(P, axis=0).max()), 1e-300)
    U = np.full((len(V), nodes.model.n_u), np.nan)
    U[at] = nodes.box.u(grid[j[at]])
    vmask = np.zeros(len(V), dtype=np.int64)
    vmask[at] = [nodes.viol.get(keys[i], 0) for i in j[at]]
    fold.update(jacobian_integral=fine["jacobian_integral"], turned_over=fine["turned_over"],
                tetrahedra=fine["tetrahedra"], grid=m)
    notes = [f"{why}: the surface is the union of the images of the {(m - 1) ** 3} cells of a {m}^3 grid of U "
             f"(their tetrahedra, {fine['turned_over']} of {fine['tetrahedra']} turned over); the integral of "
             f"|det dp/du| over U, {fine['jacobian_integral'] * 1e6:.4g} cm^3, counts the overlapping sheets "
             f"twice" + (f"; refined from {', '.join(refined)} whose error estimate was above "
                         f"{100 * nodes.fold_tolerance:g} % of the volume" if refined else "")]
    b = Boundary(V, T, U, "input-cells", closed=_closed(T), volume=fine["volume"],
                 volume_error=error, area=_area(V, T),
                 tolerance=_grid_tolerance(P.reshape(m, m, m, 3)), violations=vmask, notes=notes, fold=fold)
    if not b.closed:
        b.method, b.volume, b.volume_error = "none", None, None
        b.notes.append("the union's surface does not close: no volume (cell_volume counts the cells)")
    bad = int(np.count_nonzero(vmask[at]))
    if bad:
        b.notes.append(f"{bad} of the surface's {np.count_nonzero(at)} vertices at grid nodes are not admissible "
                       f"equilibria: the surface bounds the image of U, which is larger than the admissible "
                       f"workspace there")
    return b


def _fold_words(fold) -> str:
    parts = []
    if "det_positive" in fold:
        parts.append(f"{fold['det_positive']} of its samples positive, {fold['det_negative']} negative")
    if "grid_tetrahedra_positive" in fold:
        parts.append(f"{min(fold['grid_tetrahedra_positive'], fold['grid_tetrahedra_negative'])} of the forward "
                     f"grid's {fold['grid_tetrahedra_positive'] + fold['grid_tetrahedra_negative']} tetrahedra "
                     f"turned over")
    return "; ".join(parts)


def _grid_tolerance(P) -> float:
    """:func:`_tolerance` of a 3-D grid of tips (m, m, m, 3): half the largest distance between a node and the
    chord of its two neighbours two nodes away, along each axis of the grid."""
    d = [np.linalg.norm(np.moveaxis(P, a, 0)[1:-1:2] - 0.5 * (np.moveaxis(P, a, 0)[:-2:2] + np.moveaxis(P, a, 0)[2::2]),
                        axis=-1).max(initial=0.0) for a in range(3)]
    return 0.5 * float(max(d))


def _patch(V, U, vmask, face_tris, n) -> Boundary:
    """2 inputs: the surface W itself, with its boundary curve."""
    T = face_tris[0][0]
    ring = [(r, 0) for r in range(n)] + [(n - 1, c) for c in range(1, n)] + \
           [(r, n - 1) for r in range(n - 2, -1, -1)] + [(0, c) for c in range(n - 2, 0, -1)]
    grid_ids = _grid_ids(V, U, n)
    curve = np.array([grid_ids[r, c] for r, c in ring])
    a, a2 = _area(V, T), _area(V, face_tris[1][0])
    return Boundary(V, T, U, "input-patch", closed=False, volume=0.0, volume_error=0.0, area=a,
                    tolerance=_tolerance(V, grid_ids), curve=curve, violations=vmask,
                    notes=[f"2 inputs: the workspace is a surface (area {a * 1e4:.3g} cm^2; "
                           f"{abs(a - a2) * 1e4:.2g} cm^2 from the surface through every other node)"])


def _grid_ids(V, U, n):
    """The vertex ids of a 2-input patch as an (n, n) array."""
    lo, hi = U.min(0), U.max(0)
    free = hi > lo  # the two inputs with a range
    rc = np.rint((U[:, free] - lo[free]) / (hi - lo)[free] * (n - 1)).astype(int)
    ids = np.zeros((n, n), dtype=int)
    ids[rc[:, 0], rc[:, 1]] = np.arange(len(U))
    return ids


def _tolerance(V, ids) -> float:
    """Half the largest distance between a node and the chord of its two neighbours two nodes away, along
    the grid and along the triangles' diagonals: the coarse surface's chord error, of which a second-order
    surface through all nodes keeps about a quarter (the factor 2 is margin: on the 3-cable trunk at 8 mm,
    verified points lay up to 0.46 of it outside)."""
    P = V[ids]
    d = [np.linalg.norm(P[1:-1:2] - 0.5 * (P[:-2:2] + P[2::2]), axis=-1),
         np.linalg.norm(P[:, 1:-1:2] - 0.5 * (P[:, :-2:2] + P[:, 2::2]), axis=-1),
         np.linalg.norm(P[1:-1:2, 1:-1:2] - 0.5 * (P[:-2:2, :-2:2] + P[2::2, 2::2]), axis=-1)]
    return 0.5 * float(max(x.max(initial=0.0) for x in d))


def _orient(V, U, vmask, face_tris, faces):
    """(kept faces, flip per face, notes): each 3-face's image is bounded by its six 2-faces oriented out of
    the box and flipped where det A < 0 (the sign of the enclosed volume); a kept face is oriented out of an
    image it bounds, the workspace lying on that image's side."""
    images, signs = [], set()  # per 3-face: {face: flipped?}, the fine triangles outward
    for free, fixed, members in _three_faces(faces):
        flips = {m: _outward(faces[m], (free, fixed)) < 0 for m in members}
        T = np.vstack([face_tris[0][m][:, ::-1] if f else face_tris[0][m] for m, f in flips.items()])
        signs.add(_signed_volume(V, T) > 0)
        if _signed_volume(V, T) < 0:
            flips, T = {m: not f for m, f in flips.items()}, T[:, ::-1]
        images.append((flips, T))
    notes = []
    if len(signs) > 1:
        notes.append("det dp/du has different signs on different 3-faces of U: the surface may not be the "
                     "boundary")
    keep = list(range(len(faces))) if len(images) == 1 else _kept_faces(V, faces, face_tris, images)
    flip = {}
    for flips, _ in images:
        for m, f in flips.items():
            flip.setdefault(m, f)
    return keep, flip, notes


def _closed_surface(V, U, face_tris, vmask, notes, tol) -> Boundary:
    Tf, Tc = np.vstack(face_tris[0]), np.vstack(face_tris[1])
    used = np.unique(Tf)
    remap = -np.ones(len(V), dtype=int)
    remap[used] = np.arange(len(used))
    V2, U2, Tf2, Tc2, vm = V[used], U[used], remap[Tf], remap[Tc], vmask[used]
    if not (_closed(Tf2) and _closed(Tc2)):
        return Boundary(V2, Tf2, U2, "none", closed=False, area=_area(V2, Tf2), violations=vm,
                        notes=notes + ["the faces of U that bound the workspace do not close: no volume from "
                                       "the surface: no volume (cell_volume counts the cells)"])
    vol, vol_c = _signed_volume(V2, Tf2), _signed_volume(V2, Tc2)
    return Boundary(V2, Tf2, U2, "input-faces", closed=True, volume=vol, volume_error=abs(vol - vol_c),
                    area=_area(V2, Tf2), tolerance=tol, violations=vm, notes=notes)


def _face_grid(T):
    """The (n, n) vertex ids of a face, from its triangles as :func:`_triangles` makes them."""
    k = len(T) // 2
    n = int(round(np.sqrt(k))) + 1
    ids = np.zeros((n, n), dtype=int)
    a, b, c, d = T[:k, 0], T[:k, 1], T[:k, 2], T[k:, 2]
    r, cc = np.divmod(np.arange(k), n - 1)
    ids[r, cc], ids[r + 1, cc], ids[r + 1, cc + 1], ids[r, cc + 1] = a, b, c, d
    return ids


def _kept_faces(V, faces, face_tris, images) -> list:
    """The faces most of whose triangles' centroids lie outside the images of the 3-faces they do not
    bound, by the images' winding numbers around them. Why not VTK's ray casting (``select_interior_points``)
    or libigl's winding numbers: the few hundred centroids of a 4-input screen take 10-20 ms here against 0.1 s
    there plus the library's import (0.14 s, 0.12 s), with both workers idle."""
    cents = [V[face_tris[0][m]].mean(axis=1) for m in range(len(faces))]
    allc = np.vstack(cents)
    owner = np.repeat(np.arange(len(faces)), [len(c) for c in cents])
    inside_any = np.zeros(len(owner), dtype=bool)
    for tris, T in images:
        inside_any |= (np.abs(winding_numbers(V, T, allc)) > 0.5) & ~np.isin(owner, list(tris))
    share_out = np.bincount(owner, weights=~inside_any, minlength=len(faces)) / np.bincount(owner)
    return [m for m in range(len(faces)) if share_out[m] > 0.5]


def boundary_of(result, problem, model=None, settings: BoundarySettings | None = None, executor=None) -> Boundary:
    """The boundary of an existing result's workspace (the command ``casadi-ws boundary``).

    A forward result's grid holds every face node when its n_d is odd (n = n_d, nothing to solve); other
    nodes are solved on ``problem``'s model. The result's points are then checked against the surface.
    """
    from ..fem.model import StaticModel

    settings = settings or BoundarySettings()
    known = None
    if result.method == "forward":
        n_d = int(result.settings.get("n_d", 0))
        if n_d >= 3 and n_d % 2 == 1 and settings.n == BoundarySettings.n:
            settings = dataclasses.replace(settings, n=n_d)
        # the excluded (inadmissible) points too: they are equilibria of U's grid, and the grid is whole with them
        ex = result.arrays
        known = (np.vstack([result.u, np.asarray(ex.get("excluded_u", np.zeros((0, result.u.shape[1]))))]),
                 np.vstack([result.points, np.asarray(ex.get("excluded_points", np.zeros((0, 3))))]),
                 np.concatenate([result._violations(), np.asarray(ex.get("excluded_violations", []), np.int64)]))
    model = model or StaticModel(problem)
    dets = result.arrays.get("map_det_A")  # forward-backward's configurations: det A's sign shows a fold
    samples = (result.u, dets) if dets is not None and len(dets) == result.n_points else None
    b = boundary(model, settings, executor=executor, problem=problem, known=known, samples=samples)
    b.check_points(result.points)
    return b
