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


def write_section(name: str, body: str) -> None:
    """Replace (or append) the section between the markers of ``name`` in BENCHMARKS.md."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    text = BENCHMARKS.read_text() if BENCHMARKS.exists() else "# Benchmarks\n\nWritten by the scripts in `scripts/`; rerun them to refresh a section.\n"
    block = f"{start}\n{body.rstrip()}\n{end}"
    if start in text:
        text = re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    BENCHMARKS.write_text(text)
    print(f"wrote section '{name}' of {BENCHMARKS}")


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
