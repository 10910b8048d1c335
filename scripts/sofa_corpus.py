"""SoftRobots' own example scenes through ``casadi-ws import-sofa``: what imports, and what then solves.

    python scripts/sofa_corpus.py PATH/TO/SoftRobots/examples [--commit 69d2b7b] [--no-solve] [--data F] [--no-docs]

Every ``.py`` file under the folder that defines ``createScene`` is imported from its own folder (a fresh
process each, as a user would run the command). A *robot scene* is one whose graph, as SOFA's stand-in records
it, holds a tetrahedral FEM force field and a cable or cavity actuator (``CableConstraint``, ``CableActuator``,
``SurfacePressureConstraint``, ``SurfacePressureActuator``); where the scene cannot be recorded, one whose text
(or that of a module beside it that it imports) names a deformable body (``TetrahedronFEMForceField``,
``ElasticMaterialObject``, SoftRobots' ``Finger``/``Bunny`` parts) and an actuator (those, ``PullingCable``,
``PneumaticCavity``). Each problem
imported is solved at half its input bounds (``admissible_equilibrium``): converged and admissible, or why
not. A scene whose mesh the copy lacks is counted apart. Rows go to benchmarks/sofa_corpus.json; the table to
docs/sofa.md's block ``sofa-corpus`` and the share to README.md's ``sofa-share`` (tests check both against the
data). The repository cannot be fetched in CI: tests/test_sofa_corpus.py runs this survey on the scenes it
ships (tests/data/softrobots_examples/, LGPL).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "benchmarks" / "sofa_corpus.json"
DOC = ROOT / "docs" / "sofa.md"
README = ROOT / "README.md"
BODY = re.compile(r"TetrahedronFEMForceField|TetrahedronHyperelasticityFEMForceField|ElasticMaterialObject|"
                  r"softrobots\.parts")
ACTUATOR = re.compile(r"CableConstraint|CableActuator|SurfacePressureConstraint|SurfacePressureActuator|"
                      r"PullingCable|PneumaticCavity|softrobots\.parts")

CLASSIFY = r"""
import json, sys
from casadi_ws.io.sofa.recorder import record
from casadi_ws.io.sofa.translate import _CABLES, _CAVITIES, _FEM
try:
    types = {o.type for n in record(sys.argv[1]).walk() for o in n.objects}
except Exception as exc:  # the scene cannot be recorded: the text decides
    print(json.dumps(None))
else:
    print(json.dumps(bool(types & set(_FEM) and types & set(_CABLES + _CAVITIES))))
"""

SOLVE = r"""
import json, sys, time
import numpy as np
import casadi_ws as cw
from casadi_ws.solvers.admissible import admissibility, admissible_equilibrium
from casadi_ws.solvers.equilibrium import solve_equilibrium
t = time.perf_counter()
m = cw.StaticModel(cw.load_problem(sys.argv[1]))
u = m.u_min + 0.5 * (m.u_max - m.u_min)
eq, adm, _ = admissible_equilibrium(m, u)
row = {"converged": bool(eq.converged), "status": eq.status_name,
       "violations": None if adm is None else list(adm.violations), "dofs": m.n_dof}
if not eq.converged or adm.violations:
    # why: walk from rest in tenths of the way and say where the path stops or first becomes inadmissible
    q, prev = None, m.u_min.copy()
    for s in np.linspace(0.1, 1.0, 10):
        us = m.u_min + s * (u - m.u_min)
        e = solve_equilibrium(m, us, q0=q, u0=prev)
        v = admissibility(m, e.q, us, e.factorization).violations if e.converged else ()
        if not e.converged or v:
            row["path"] = {"share": round(float(s), 2), "status": e.status_name, "violations": list(v)}
            break
        q, prev = e.q, us
row["time_s"] = time.perf_counter() - t
print(json.dumps(row))
"""


def scenes(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*.py") if "def createScene" in p.read_text(errors="replace"))


IMPORT = re.compile(r"^\s*(?:from|import)\s+([A-Za-z_]\w*)", re.M)


def scene_text(scene: Path) -> str:
    """The scene's text and that of the modules beside it that it imports (a gripper's ``finger.py``)."""
    text = scene.read_text(errors="replace")
    for name in set(IMPORT.findall(text)):
        mod = scene.parent / f"{name}.py"
        if mod.is_file() and mod != scene:
            text += mod.read_text(errors="replace")
    return text


def run(scene: Path, out: Path, solve: bool) -> dict:
    c = subprocess.run([sys.executable, "-c", CLASSIFY, scene.name], cwd=scene.parent, capture_output=True,
                       text=True, timeout=300)
    robot = json.loads((c.stdout.strip().splitlines() or ["null"])[-1])
    if robot is None:
        text = scene_text(scene)
        robot = bool(BODY.search(text) and ACTUATOR.search(text))
    row = {"robot": robot}
    r = subprocess.run([sys.executable, "-m", "casadi_ws.cli", "import-sofa", scene.name, "--out", str(out)],
                       cwd=scene.parent, capture_output=True, text=True, timeout=300)
    lines = r.stderr.strip().splitlines()
    row["imported"] = r.returncode == 0
    row["traceback"] = "Traceback" in r.stderr
    row["reason"] = "" if r.returncode == 0 else (lines[-1] if lines else f"exit {r.returncode}")
    row["missing_mesh"] = "mesh file not found" in row["reason"]
    if r.returncode == 0 and solve:
        s = subprocess.run([sys.executable, "-c", SOLVE, str(out)], cwd=out.parent, capture_output=True, text=True,
                           timeout=1200)
        try:
            row["half_bounds"] = json.loads(s.stdout.strip().splitlines()[-1])
        except (IndexError, json.JSONDecodeError):
            row["half_bounds"] = {"error": (s.stderr.strip().splitlines() or ["no output"])[-1][:200]}
    return row


def cell(row: dict) -> str:
    if not row["imported"]:
        reason = row["reason"].split(": error: ", 1)[-1]
        return "imports: no — " + reason.replace("|", "/")
    h = row.get("half_bounds")
    if h is None:
        return "imports"
    if "error" in h:
        return "imports; half bounds: " + h["error"].replace("|", "/")
    if h["converged"] and not h["violations"]:
        return "imports; half bounds: admissible"
    cell = "imports; half bounds: " + (h["status"] if not h["converged"] else ", ".join(h["violations"]))
    path = h.get("path")
    if path:
        what = ", ".join(path["violations"]) or path["status"]
        cell += f" (on the way from rest: {what} at {path['share']:.0%} of it"
        cell += "; needs self-contact, which the scene does not declare)" if "self_penetration" in what else ")"
    return cell


def survey(examples: Path, solve: bool = True, progress: bool = False) -> dict:
    """Each scene under ``examples`` (relative path) -> its row."""
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes(examples):
            rel = scene.relative_to(examples).as_posix()
            rows[rel] = run(scene, Path(tmp) / (rel.replace("/", "__") + ".yaml"), solve)
            if progress:
                print(rel, json.dumps(rows[rel]), flush=True)
    return rows


def counts(rows: dict) -> dict:
    robots = {k: v for k, v in rows.items() if v["robot"]}
    return {"scenes": len(rows), "robots": len(robots), "imported": sum(v["imported"] for v in robots.values()),
            "solved": sum(bool(v.get("half_bounds", {}).get("converged")) and not v["half_bounds"]["violations"]
                          for v in robots.values()),
            "tracebacks": sum(v["traceback"] for v in rows.values()),
            "missing_mesh": sum(v["missing_mesh"] for v in robots.values())}


def table(data: dict) -> str:
    """docs/sofa.md's block: the counts, then one row per robot scene."""
    rows, c = data["scenes"], counts(data["scenes"])
    missing = f" ({c['missing_mesh']} lack a mesh in the copy)" if c["missing_mesh"] else ""
    lines = [f"SoftRobots `examples/` at {data['commit']}: {c['scenes']} scenes define `createScene`, {c['robots']} "
             f"build a deformable body and an actuator (robot scenes). Of those, **{c['imported']} import** and "
             f"**{c['solved']} solve at half their input bounds** to an admissible equilibrium{missing}; "
             f"{c['tracebacks']} scenes of all {c['scenes']} end in a traceback. Generated by "
             f"`scripts/sofa_corpus.py` (data: benchmarks/sofa_corpus.json).", "",
             "| robot scene | result |", "|---|---|"]
    lines += [f"| `{k}` | {cell(v)} |" for k, v in rows.items() if v["robot"]]
    return "\n".join(lines)


def share(data: dict) -> str:
    """The README's sentence."""
    c = counts(data["scenes"])
    return (f"Of the {c['robots']} robot scenes in SoftRobots' own `examples/` ({data['commit']}), "
            f"{c['imported']} import and {c['solved']} solve at half their input bounds today.")


def replace_block(text: str, name: str, block: str) -> str:
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    return text[: text.index(start)] + f"{start}\n{block}\n{end}" + text[text.index(end) + len(end):]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("examples", type=Path)
    ap.add_argument("--commit", default="69d2b7b", help="the SoftRobots commit the copy is of (recorded)")
    ap.add_argument("--no-solve", action="store_true")
    ap.add_argument("--data", type=Path, default=DATA, help="where the rows go (JSON)")
    ap.add_argument("--no-docs", action="store_true", help="leave docs/sofa.md and README.md as they are")
    args = ap.parse_args()
    data = {"commit": args.commit, "scenes": survey(args.examples, not args.no_solve, progress=True)}
    args.data.parent.mkdir(parents=True, exist_ok=True)
    args.data.write_text(json.dumps(data, indent=1) + "\n")
    if not args.no_docs:
        DOC.write_text(replace_block(DOC.read_text(), "sofa-corpus", table(data)))
        README.write_text(replace_block(README.read_text(), "sofa-share", share(data)))
    print(table(data))


if __name__ == "__main__":
    main()
