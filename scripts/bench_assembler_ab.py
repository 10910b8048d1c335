"""The model's assembly, equilibria and forward of this tree against an earlier revision, interleaved.

    python scripts/bench_assembler_ab.py --base 9a8164e [--rounds 5] [--section assembler-ab]

Issue "one assembler" bounds the refactoring at 3 % slower than the commit before it. This machine's speed
drifts by more than that between runs, so each round runs the base and this tree (in turn first) in fresh processes (the
base checked out into a temporary git worktree, imported first on sys.path), and the figure is the median
over rounds of this tree's time divided by the base's in the same round. Per problem of ``PROBLEMS``: the
fastest of 100 calls of ``residual_and_tangent``, ``tangent`` and ``residual(with_scale=True)`` at the equilibrium
at mid-range inputs, and 12 equilibria from rest along the diagonal of the input box; and forward
on trunk_2cables at n_d = 100 (one worker). Forward-backward: scripts/bench_fb_ab.py with the same base.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchlib import machine, write_section

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ["trunk_2cables", "trunk_2cables_order2", "trunk_4cables", "trunk_table", "finger_object",
            "pneunet_finger", "pinch_gripper"]

RUNNER = r"""
import json, sys, time
import numpy as np
tree, root, names = sys.argv[1], sys.argv[2], sys.argv[3].split(",")
sys.path.insert(0, tree)
import casadi_ws as cw
from casadi_ws.workspace.forward import ForwardSettings, forward
assert cw.__file__.startswith(tree)

def fastest(f, n=100):
    # the fastest of n calls: what the code costs, without the other tenants of a shared machine
    f()
    ts = []
    for _ in range(n):
        t = time.perf_counter(); f(); ts.append(time.perf_counter() - t)
    return float(np.min(ts))

out = {}
for name in names:
    pb = cw.load_problem(f"{root}/problems/{name}.yaml")
    m = cw.StaticModel(pb)
    u = m.u_min + 0.5 * (m.u_max - m.u_min)
    q = cw.solve_equilibrium(m, u).q
    row = {"residual_and_tangent": fastest(lambda: m.residual_and_tangent(q, u)),
           "tangent": fastest(lambda: m.tangent(q, u)),
           "residual": fastest(lambda: m.residual(q, u, with_scale=True))}
    t = time.perf_counter()
    for s in np.linspace(0.1, 1.0, 12):
        cw.solve_equilibrium(m, m.u_min + s * (m.u_max - m.u_min))
    row["equilibria"] = time.perf_counter() - t
    out[name] = row
pb = cw.load_problem(f"{root}/problems/trunk_2cables.yaml")
t = time.perf_counter()
forward(pb, 100, ForwardSettings(progress=False, workers=1))
out["forward_nd100"] = time.perf_counter() - t
print(json.dumps(out))
"""


def run(tree: Path, names: list[str]) -> dict:
    # one thread on one core: the kernels' thread pool and BLAS would otherwise share two cores with whatever
    # else runs, and the ratios scatter by +-30 %
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env.pop("PYTHONPATH", None)
    p = subprocess.run(["taskset", "-c", "1", sys.executable, "-c", RUNNER, str(tree), str(ROOT), ",".join(names)],
                       capture_output=True, text=True, check=True, env=env)
    return json.loads(p.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="git revision to compare with (the commit before the change)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--problems", nargs="+", default=PROBLEMS)
    ap.add_argument("--section", default="assembler-ab")
    ap.add_argument("--from-log", type=Path, default=None, help="rows printed by an earlier run: no measuring")
    args = ap.parse_args()
    if args.from_log:
        rounds = [json.loads(line) for line in args.from_log.read_text().splitlines() if line.startswith('{"round"')]
        return report(args, rounds)
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), args.base], check=True,
                       capture_output=True)
        try:
            rounds = []
            for k in range(args.rounds):
                if k % 2 == 0:  # ABBA: a drift of the machine's speed within a round cancels over two
                    a, b = run(base, args.problems), run(ROOT, args.problems)
                else:
                    b, a = run(ROOT, args.problems), run(base, args.problems)
                rounds.append({"round": k, "base": a, "this": b})
                print(json.dumps(rounds[-1]), flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)], check=True)
    report(args, rounds)


def report(args, rounds: list[dict]) -> None:
    keys = [(n, q) for n in args.problems for q in ("residual_and_tangent", "tangent", "residual", "equilibria")]
    lines = ["| problem | quantity | base (median of rounds, ms) | this tree (median of rounds, ms) | ratio this / base (median of "
             "rounds) | the ratios' range over rounds | the base's own spread over rounds (slowest / fastest) |",
             "|---|---|---|---|---|---|---|"]
    worst = 0.0
    for n, q in keys + [("trunk_2cables", "forward_nd100")]:
        get = (lambda r: r[q]) if q == "forward_nd100" else (lambda r: r[n][q])
        a = np.array([get(r["base"]) for r in rounds])
        b = np.array([get(r["this"]) for r in rounds])
        ratio = float(np.median(b / a))
        worst = max(worst, ratio)
        label = "forward n_d = 100 (one worker), s" if q == "forward_nd100" else q
        scale = 1.0 if q == "forward_nd100" else 1e3
        lines.append(f"| `{n}` | {label} | {np.median(a) * scale:.3g} | {np.median(b) * scale:.3g} | {ratio:.3f} | "
                     f"{np.min(b / a):.3f}-{np.max(b / a):.3f} | {np.max(a) / np.min(a):.3f} |")
    body = "\n".join([
        f"## One assembler: the model's sums against the commit before (`scripts/bench_assembler_ab.py --base "
        f"{args.base}`)",
        "",
        f"Machine: {machine()}. {len(rounds)} rounds, each the base and this tree in fresh processes, in turn first; "
        f"the ratio is "
        f"the median over rounds of the two times of one round. Times of K and R at the equilibrium at mid-range "
        f"inputs (the fastest of 100 calls), one thread on one core, of 12 equilibria from rest along the input box's diagonal, of forward on "
        f"trunk_2cables at n_d = 100. Largest ratio: {worst:.3f}. The same code's times vary by the last column "
        f"between rounds on this shared machine (a virtual machine whose neighbours are not ours): a ratio within "
        f"that spread is not a difference this benchmark can resolve.",
        "",
        *lines,
    ])
    write_section(args.section, body)
    print(body)


if __name__ == "__main__":
    main()
