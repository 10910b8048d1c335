"""Shared helpers of the benchmark scripts: machine description and BENCHMARKS.md sections."""

from __future__ import annotations

import os
import platform
import re
import resource
import time
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "BENCHMARKS.md"


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import casadi
    import numpy
    import scipy

    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, CasADi {casadi.__version__}, "
            f"NumPy {numpy.__version__}, SciPy {scipy.__version__}; measured {time.strftime('%Y-%m-%d')}")


def best_of(fn, repeat: int = 5) -> float:
    """Smallest wall time of ``repeat`` calls, seconds."""
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def write_section(name: str, body: str, figure: str | None = None, what: str | None = None,
                  command: str | None = None) -> None:
    """Record a run: append the section ``body`` as a row ``name`` of benchmarks/history.jsonl and rewrite
    BENCHMARKS.md from it (scripts/benchmarks_md.py). ``figure``: its headline in one line (the table's);
    ``what`` and ``command`` default to the family's earlier row. The family of ``name`` is that of an
    earlier row of the same name, else the A/B comparisons' (``fb-ab``) for their names, else ``name``."""
    import json

    import benchmarks_md

    rows = benchmarks_md.read() if benchmarks_md.HISTORY.exists() else []
    same = [r for r in rows if r["key"] == name]
    family = same[-1]["family"] if same else (
        "fb-ab" if name.startswith(("fb-ab", "fb-admissible", "fb-boundary")) else name)
    before = [r for r in rows if r["family"] == family]
    dates = re.findall(r"20\d\d-\d\d-\d\d", body)
    m = re.search(r"(AMD EPYC|Intel[^,]*|[^,]*CPU[^,]*), (\d+) cores", machine())
    row = {"key": name, "family": family, "date": max(dates) if dates else time.strftime("%Y-%m-%d"),
           "what": what or (before[-1]["what"] if before else body.strip().splitlines()[0].lstrip("# ")[:70]),
           "command": command if command is not None else (before[-1]["command"] if before else ""),
           "figure": figure or "see its section", "machine": f"{m.group(1)}, {m.group(2)} cores" if m else "",
           "markdown": body.strip()}
    with open(benchmarks_md.HISTORY, "a") as f:
        f.write(json.dumps(row, ensure_ascii=False) + "\n")
    benchmarks_md.write()
    print(f"recorded run '{name}' in {benchmarks_md.HISTORY} and rewrote {BENCHMARKS}")


def trunk_variant(name: str | None = None, order: int | None = None, res: float | None = None, linear: str = "auto"):
    """A shipped problem (default: the 2-cable trunk) with another element order and mesh resolution, and the
    linear solver ``linear``."""
    import yaml

    from casadi_ws.io.problem import problem_from_dict

    path = Path(__file__).resolve().parents[1] / "problems" / f"{name or 'trunk_2cables'}.yaml"
    d = yaml.safe_load(path.read_text())
    if order is not None:
        d["mesh"] = {**d["mesh"], "resolution": res, "order": order}
    d["solver"] = {**(d.get("solver") or {}), "linear": linear}
    return problem_from_dict(d, f"{name} {order} {res}")


def peak_mb() -> float:
    """The largest resident set of this process or of its children that have ended (its workers), MB."""
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, kids) / 1024


def run_in_fresh_process(script: str, args: list) -> dict:
    """``script --one <args as JSON>`` in a fresh interpreter (so that its peak memory is its own); the JSON
    its last line prints."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, script, "--one", json.dumps(args)], capture_output=True, text=True,
                         cwd=Path(script).resolve().parent)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-3000:])
    # (the last JSON line: MUMPS writes "JOB=-2" lines to the C stdout when a solver is destroyed)
    return json.loads([ln for ln in out.stdout.strip().splitlines() if ln.startswith("{")][-1])
