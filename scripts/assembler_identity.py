"""Bit-identity of the model's assembly across a refactoring: the same states give the same numbers.

    PYTHONPATH=<old checkout> python scripts/assembler_identity.py record /tmp/base.npz
    python scripts/assembler_identity.py compare /tmp/base.npz [--json out.json]
    python scripts/assembler_identity.py digest /tmp/base.npz tests/data/assembler_base.npz
    python scripts/assembler_identity.py retake tests/data/assembler_base.npz   # same states, the code now

``digest`` keeps of a record what tests/test_terms.py checks on every run, for the problems of ``DIGESTED``:
the states, and per quantity its SHA-256 (bit-identity) or, for the two whose summation order changed (R of
``residual_and_tangent``: the internal forces and loads now summed as in ``residual``; the stability
matrix: the prescribed actuators' held block summed as contact's), three projections on fixed random vectors,
to be met within 1e-14 of the quantity's scale.

``record`` (run with the code before the change on the path) solves, for every problem file of problems/ and
problems/sofa/*/, three states -- rest; the equilibrium at mid-range inputs; and at the inputs' upper bounds
(where contact, a prescribed quantity or self-contact acts, the state that has it) -- and stores them with what
the model gives there: R and its scale, R, K and dR/du of residual_and_tangent, tangent(), the stability
matrix, the Hessian of lam . R (a fixed random lam) and the reported contacts. ``compare`` evaluates the same
quantities at the stored states with the code on the path now and prints, per problem and quantity, whether
they are bit-identical and else the largest difference relative to the quantity's largest entry (for R, to
the residual's scale ||H^T u + F|| where that is larger: at an equilibrium R is round-off).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp

import casadi_ws as cw

ROOT = Path(__file__).resolve().parents[1]
QUANTITIES = ("R", "scale", "R2", "K", "dRdu", "Kt", "stab", "Hqq", "Hqu", "contacts")


DIGESTED = ("finger", "finger_object", "trunk_table", "trunk_2cables", "pneunet_finger", "pinch_gripper")
ROUNDOFF = ("R2", "stab")
"""Quantities whose summation order changed (see the module): compared by projections within 1e-14."""

MATRICES = ("K", "Kt", "stab", "Hqq")


def problems() -> list[Path]:
    files = [f for f in sorted((ROOT / "problems").glob("*.yaml")) if "cables:" in f.read_text()
             or "cavities:" in f.read_text()]
    return files + sorted((ROOT / "problems" / "sofa").glob("*/*.yaml"))


def _sparse(A) -> np.ndarray:
    """A sparse matrix as one array: its CSC triplets (duplicates summed, indices sorted), explicit zeros kept
    (the pattern is part of what must not change)."""
    A = sp.csc_matrix(A)
    A.sum_duplicates()
    A.sort_indices()
    return np.concatenate([[A.shape[0], A.shape[1], A.nnz], A.indptr, A.indices, A.data]).astype(float)


def evaluate(model, q, u) -> dict:
    R, scale = model.residual(q, u, with_scale=True)
    R2, K, dRdu = model.residual_and_tangent(q, u)
    lam = np.random.default_rng(0).standard_normal(model.n_free)
    Hqq, Hqu = model.residual_hessian(q, u, lam)
    return {"R": R, "scale": np.array([scale]), "R2": R2, "K": _sparse(K), "dRdu": np.asarray(dRdu),
            "Kt": _sparse(model.tangent(q, u)), "stab": _sparse(model.stability_matrix(q, u)), "Hqq": _sparse(Hqq),
            "Hqu": np.asarray(Hqu), "contacts": json.dumps(model.contacts(q), sort_keys=True)}


def states(model) -> list[tuple[str, np.ndarray, np.ndarray]]:
    out = [("rest", np.zeros(model.n_dof), model.u_min.copy())]
    for label, f in (("mid", 0.5), ("upper", 1.0)):
        u = model.u_min + f * (model.u_max - model.u_min)
        eq = cw.solve_equilibrium(model, u)
        out.append((label, eq.q, u))
    return out


def record(path: str) -> None:
    data = {}
    for f in problems():
        model = cw.StaticModel(cw.load_problem(f))
        for label, q, u in states(model):
            key = f"{f.stem}/{label}"
            data[f"{key}/q"], data[f"{key}/u"] = q, u
            for name, value in evaluate(model, q, u).items():
                data[f"{key}/{name}"] = np.array(value) if name == "contacts" else value
        print(f"recorded {f.stem}", file=sys.stderr, flush=True)
    np.savez_compressed(path, **data)


def compare(path: str) -> list[dict]:
    base = np.load(path)
    rows = []
    for f in problems():
        model = cw.StaticModel(cw.load_problem(f))
        for label in ("rest", "mid", "upper"):
            key = f"{f.stem}/{label}"
            if f"{key}/q" not in base:
                continue
            now = evaluate(model, base[f"{key}/q"], base[f"{key}/u"])
            row = {"problem": f.stem, "state": label}
            for name in QUANTITIES:
                old = base[f"{key}/{name}"]
                if name == "contacts":
                    row[name] = "identical" if str(old) == now[name] else f"differ: {old} vs {now[name]}"
                    continue
                new = now[name]
                if name in ("K", "Kt", "stab", "Hqq") and old.shape == new.shape and not np.array_equal(old, new):
                    nnz = int(old[2])
                    if not np.array_equal(old[: -nnz], new[: -nnz]):
                        row[name] = "pattern differs"
                        continue
                if old.shape != new.shape:
                    row[name] = f"shape {old.shape} -> {new.shape}"
                elif np.array_equal(old, new):
                    row[name] = "identical"
                else:
                    if name in ("K", "Kt", "stab", "Hqq"):
                        nnz = int(old[2])
                        old, new = old[-nnz:], new[-nnz:]
                    ref = max(float(np.abs(old).max()), 1e-300)
                    if name in ("R", "R2"):
                        # at an equilibrium R is round-off of the forces it balances: judged, as Newton judges
                        # it, against the residual's scale ||H^T u + F|| (the stored ``scale``)
                        ref = max(ref, float(base[f"{key}/scale"][0]))
                    row[name] = float(np.abs(old - new).max() / ref)
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def digest_of(name: str, value) -> str:
    import hashlib

    data = str(value).encode() if name == "contacts" else np.ascontiguousarray(value, dtype=float).tobytes()
    return hashlib.sha256(data).hexdigest()


def projections(name: str, value: np.ndarray) -> np.ndarray:
    """Three numbers v_k . x (a vector) or v_k . A w_k (a matrix stored by :func:`_sparse`), v, w fixed."""
    if name in ("K", "Kt", "stab", "Hqq"):
        n, m, nnz = (int(x) for x in value[:3])
        A = sp.csc_matrix((value[-nnz:], value[3 + m + 1: 3 + m + 1 + nnz].astype(np.int64),
                           value[3: 3 + m + 1].astype(np.int64)), shape=(n, m))
        rng = np.random.default_rng(1)
        return np.array([rng.standard_normal(n) @ (A @ rng.standard_normal(m)) for _ in range(3)])
    rng = np.random.default_rng(1)
    return np.array([rng.standard_normal(value.size) @ value.ravel() for _ in range(3)])


def pattern_of(value: np.ndarray) -> str:
    """The SHA-256 of a matrix's pattern (shape, column pointers, row indices), as :func:`_sparse` stores it."""
    import hashlib

    m, nnz = int(value[1]), int(value[2])
    return hashlib.sha256(np.ascontiguousarray(value[: 3 + m + 1 + nnz]).tobytes()).hexdigest()


def _digests(key: str, values: dict) -> dict:
    """What the test keeps of the quantities at one state: their SHA-256, and for all but the contacts three
    projections (:func:`projections`) and, for a matrix, its pattern's SHA-256: the compiled element kernels
    round differently on another CPU (FMA), so across machines the values are compared within round-off and
    the patterns to the bit."""
    data = {}
    for name in QUANTITIES:
        value = values[name]
        data[f"{key}/{name}"] = np.array(digest_of(name, str(value) if name == "contacts" else value))
        if name != "contacts":
            data[f"{key}/{name}/proj"] = projections(name, value)
        if name in MATRICES:
            data[f"{key}/{name}/pattern"] = np.array(pattern_of(value))
    return data


def digest(path: str, out: str) -> None:
    base = np.load(path)
    data = {}
    for f in problems():
        if f.stem not in DIGESTED:
            continue
        for label in ("rest", "mid", "upper"):
            key = f"{f.stem}/{label}"
            data[f"{key}/q"], data[f"{key}/u"] = base[f"{key}/q"], base[f"{key}/u"]
            data.update(_digests(key, {name: base[f"{key}/{name}"] for name in QUANTITIES}))
    np.savez_compressed(out, **data)


def retake(path: str) -> None:
    """The digests of ``path`` (tests/data/assembler_base.npz) taken again with the code on the path at the same
    stored states: after a change that moves the sums by round-off, or to add projections and patterns."""
    old = np.load(path)
    data = {}
    for f in problems():
        if f.stem not in DIGESTED:
            continue
        model = cw.StaticModel(cw.load_problem(f))
        for label in ("rest", "mid", "upper"):
            key = f"{f.stem}/{label}"
            q, u = old[f"{key}/q"], old[f"{key}/u"]
            data[f"{key}/q"], data[f"{key}/u"] = q, u
            data.update(_digests(key, evaluate(model, q, u)))
    np.savez_compressed(path, **data)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["record", "compare", "digest", "retake"])
    ap.add_argument("path")
    ap.add_argument("out", nargs="?", help="digest: the file to write")
    ap.add_argument("--json", default=None, help="compare: write the rows here too")
    args = ap.parse_args()
    if args.mode == "record":
        record(args.path)
        return
    if args.mode == "digest":
        digest(args.path, args.out)
        return
    if args.mode == "retake":
        retake(args.path)
        return
    rows = compare(args.path)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
    worst = max((v for r in rows for k, v in r.items() if isinstance(v, float)), default=0.0)
    shapes = [f"{r['problem']}/{r['state']}" for r in rows for v in r.values() if isinstance(v, str)
              and v not in ("identical",) and not v.startswith(("identical",)) and v != r["problem"]
              and v != r["state"]]
    print(f"largest relative difference: {worst:.2e}; not identical in value or shape: {shapes or 'none'}")


if __name__ == "__main__":
    main()
