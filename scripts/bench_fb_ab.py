"""Forward-backward time of this tree against an earlier revision, interleaved on the same machine.

    python scripts/bench_fb_ab.py [--base 03d6aab] [--problems 2 3 4] [--repeats 1]
    python scripts/bench_fb_ab.py --base 8569c8e --problems 2 3 trunk_2cables_order2 trunk_2cables_fine

The issue that set "no slower than 15 / 37 / 82 s" measured those times on another day; this machine's
speed varies by up to ~30 % between runs. So both codes run here, one after the other per problem (base,
this tree, base, ...), 2 workers, default settings, and the section records both. The base revision is
checked out into a temporary git worktree and imported from there (same virtual environment).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from benchlib import machine, write_section

ROOT = Path(__file__).resolve().parents[1]

# run in a subprocess, with the tree to measure first on sys.path (worker processes inherit it)
RUNNER = r"""
import json, resource, sys, time
tree, problem = sys.argv[1], sys.argv[2]
sys.path.insert(0, tree)
import casadi_ws as cw
try:  # the layout before the sub-packages first: the editable install's finder would resolve a missing
    # sub-package of an old tree to this one
    from casadi_ws.forward_backward import FBSettings, forward_backward
except ImportError:
    from casadi_ws.workspace.forward_backward import FBSettings, forward_backward
assert cw.__file__.startswith(tree) and forward_backward.__code__.co_filename.startswith(tree)
pb = cw.load_problem(problem)
t = time.perf_counter()
r = forward_backward(pb, FBSettings(workers=2, progress=False))
c = r.counters
b = getattr(r, "boundary", None)
# the largest resident set of this process or of a worker (the pool's have ended), as benchlib.peak_mb
peak = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
print(json.dumps({"time": time.perf_counter() - t, "cells": c["feasible"], "lu": c["factorizations"],
                  "peak_mb": peak / 1024,
                  "excluded": c.get("excluded"), "boundary_s": r.timings.get("boundary"),
                  "volume": None if b is None or b.volume is None else abs(b.volume)}))
"""


def run(tree: Path, problem: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", RUNNER, str(tree), str(problem)], capture_output=True, text=True,
                         cwd=tree)
    if out.returncode != 0:
        raise SystemExit(f"{tree}: {problem.name} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--base", default="03d6aab", help="git revision to compare with (default: the code of "
                    "the day the FB-completeness issue was filed)")
    ap.add_argument("--problems", nargs="+", default=["2", "3", "4"],
                    help="n for problems/trunk_<n>cables.yaml, or the name of a file in problems/")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--section", default="fb-ab")
    ap.add_argument("--issue", default="FB that misses nothing", help="the issue named in the section's title")
    args = ap.parse_args()
    base_rev = subprocess.run(["git", "rev-parse", "--short", args.base], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    head_rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True,
                           text=True, check=True).stdout.strip()
    head_rev += " with uncommitted changes" if dirty else ""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "--detach", "-f", str(base), args.base], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            for n in args.problems:
                problem = ROOT / "problems" / (f"trunk_{n}cables.yaml" if n.isdigit() else f"{n}.yaml")
                old, new = [], []
                for _ in range(args.repeats):
                    old.append(run(base, problem))
                    new.append(run(ROOT, problem))
                    print(n, old[-1], new[-1], flush=True)
                rows.append((n, old, new))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)

    def cell(rs):
        t = sum(r["time"] for r in rs) / len(rs)
        excluded = rs[0].get("excluded")
        removed = "" if excluded is None else (
            ", removed: " + (", ".join(f"{k} {v}" for k, v in excluded.items() if v) or "none"))
        b = rs[0].get("boundary_s")
        surface = "" if b is None else (f", of which boundary {sum(r['boundary_s'] for r in rs) / len(rs):.1f} s"
                                        + (f" (volume {rs[0]['volume'] * 1e6:.2f} cm³)" if rs[0]["volume"] else ""))
        peak = "" if "peak_mb" not in rs[0] else f", peak {max(r['peak_mb'] for r in rs):.0f} MB"
        return (f"{t:.1f} s, {rs[0]['cells']} cells, {rs[0]['lu'] / rs[0]['cells']:.2f} LU / cell{removed}{surface}"
                f"{peak}")

    lines = [
        f"## Forward-backward, this code against `{base_rev}` (issue: {args.issue}) — "
        f"`scripts/bench_fb_ab.py --base {args.base}`",
        "",
        f"Machine: {machine()}. Problems in `problems/`, each at its default grid step, 2 worker processes, "
        f"default settings. Runs interleaved (base, this code) per problem, {args.repeats} of each; times are "
        f"means; peak: the largest resident set of the run's process or a worker. This code: `{head_rev}`.",
        "",
        f"| problem | `{base_rev}` | this code | time ratio |",
        "|---|---|---|---|",
    ]
    for n, old, new in rows:
        ratio = sum(r["time"] for r in new) / sum(r["time"] for r in old)
        name = f"`trunk_{n}cables`" if n.isdigit() else f"`{n}`"
        lines.append(f"| {name} | {cell(old)} | {cell(new)} | {ratio:.2f} |")
    write_section(args.section, "\n".join(lines))


if __name__ == "__main__":
    main()
