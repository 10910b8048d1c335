"""SoftRobots' own example scenes through ``casadi-ws import-sofa``: what imports, and what then solves.

    python scripts/sofa_corpus.py PATH/TO/SoftRobots/examples [--commit 69d2b7b] [--no-solve]

Every ``.py`` file under the folder that defines ``createScene`` is imported from its own folder (a fresh
process each, as a user would run the command); a *robot scene* is one whose text builds a deformable body
(``TetrahedronFEMForceField``, ``TetrahedronHyperelasticityFEMForceField``, ``ElasticMaterialObject``, or
SoftRobots' ``Finger``/``Bunny`` parts), itself or in a module beside it that it imports, and an actuator (``CableConstraint``, ``CableActuator``,
``SurfacePressureConstraint``, ``SurfacePressureActuator``, ``PullingCable``, ``PneumaticCavity``). Each problem
imported is solved at half its input bounds (``admissible_equilibrium``): converged and admissible, or why
not. A scene whose mesh the copy lacks is counted apart. Rows go to benchmarks/sofa_corpus.json; the table to
docs/sofa.md's section ``sofa-corpus`` (the repository cannot be fetched in CI: the tests ship the scenes they
need, under problems/sofa/ and tests/).
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
BODY = re.compile(r"TetrahedronFEMForceField|TetrahedronHyperelasticityFEMForceField|ElasticMaterialObject|"
                  r"softrobots\.parts")
ACTUATOR = re.compile(r"CableConstraint|CableActuator|SurfacePressureConstraint|SurfacePressureActuator|"
                      r"PullingCable|PneumaticCavity|softrobots\.parts")

SOLVE = r"""
import json, sys, time
import casadi_ws as cw
from casadi_ws.solvers.admissible import admissible_equilibrium
t = time.perf_counter()
m = cw.StaticModel(cw.load_problem(sys.argv[1]))
u = m.u_min + 0.5 * (m.u_max - m.u_min)
eq, adm, _ = admissible_equilibrium(m, u)
print(json.dumps({"converged": bool(eq.converged), "status": eq.status_name,
                  "violations": None if adm is None else list(adm.violations), "dofs": m.n_dof,
                  "time_s": time.perf_counter() - t}))
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
    text = scene_text(scene)
    row = {"robot": bool(BODY.search(text) and ACTUATOR.search(text))}
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
        return "imports: no — " + reason.replace("|", "/")[:160]
    h = row.get("half_bounds")
    if h is None:
        return "imports"
    if "error" in h:
        return "imports; half bounds: " + h["error"].replace("|", "/")
    if not h["converged"]:
        return f"imports; half bounds: {h['status']}"
    return "imports; half bounds: " + ("admissible" if not h["violations"] else ", ".join(h["violations"]))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("examples", type=Path)
    ap.add_argument("--commit", default="69d2b7b", help="the SoftRobots commit the copy is of (recorded)")
    ap.add_argument("--no-solve", action="store_true")
    args = ap.parse_args()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes(args.examples):
            rel = scene.relative_to(args.examples).as_posix()
            rows[rel] = run(scene, Path(tmp) / (rel.replace("/", "__") + ".yaml"), not args.no_solve)
            print(rel, json.dumps(rows[rel]), flush=True)
    DATA.parent.mkdir(exist_ok=True)
    DATA.write_text(json.dumps({"commit": args.commit, "scenes": rows}, indent=1) + "\n")
    robots = {k: v for k, v in rows.items() if v["robot"]}
    imported = sum(v["imported"] for v in robots.values())
    solved = sum(bool(v.get("half_bounds", {}).get("converged")) and not v["half_bounds"]["violations"]
                 for v in robots.values())
    tracebacks = sum(v["traceback"] for v in rows.values())
    lines = [f"SoftRobots `examples/` at {args.commit}: {len(rows)} scenes define `createScene`, {len(robots)} build a "
             f"deformable body and an actuator (robot scenes). Of those, **{imported} import** and **{solved} solve "
             f"at half their input bounds** to an admissible equilibrium; {tracebacks} scenes of all {len(rows)} end "
             f"in a traceback. Generated by `scripts/sofa_corpus.py` (data: benchmarks/sofa_corpus.json).", "",
             "| robot scene | result |", "|---|---|"]
    lines += [f"| `{k}` | {cell(v)} |" for k, v in robots.items()]
    text = DOC.read_text()
    start, end = "<!-- sofa-corpus:start -->", "<!-- sofa-corpus:end -->"
    block = f"{start}\n" + "\n".join(lines) + f"\n{end}"
    if start in text:
        text = text[: text.index(start)] + block + text[text.index(end) + len(end):]
    else:
        text = text.rstrip("\n") + "\n\n## SoftRobots' examples\n\n" + block + "\n"
    DOC.write_text(text)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
