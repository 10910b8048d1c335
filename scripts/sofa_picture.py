"""The README's picture of an imported SOFA scene: the SoftRobots finger, imported by ``casadi-ws
import-sofa``, at five shortenings of its displacement-controlled cable, with the tip's path over the whole
stroke (docs/sofa_finger.png).

    python scripts/sofa_picture.py [--out docs/sofa_finger.png]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

from casadi_ws import StaticModel, solve_equilibrium  # noqa: E402
from casadi_ws.fem.surface import boundary_faces  # noqa: E402
from casadi_ws.io.problem import load_problem  # noqa: E402
from casadi_ws.io.sofa import import_scene  # noqa: E402

SCENE = Path(__file__).resolve().parents[1] / "problems" / "sofa" / "finger" / "Finger.py"


def main(out: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        problem_file = Path(tmp) / "finger.yaml"
        import_scene(SCENE, problem_file)
        problem = load_problem(problem_file)
    model = StaticModel(problem)
    faces = boundary_faces(problem.mesh)[:, :3]
    fig, ax = plt.subplots(figsize=(8, 4.2))
    shares = np.linspace(0.0, 1.0, 5)
    colours = plt.cm.viridis(np.linspace(0.1, 0.9, len(shares)))
    q, u0 = None, None
    for share, colour in zip(shares, colours):
        u = share * model.u_max
        eq = solve_equilibrium(model, u, q0=q, u0=u0)
        q, u0 = eq.q, u
        x = model.positions(eq.q) * 1e3
        tension = model.intensities(eq.q, u)[0]
        ax.add_collection(PolyCollection(x[faces][:, :, :2], facecolor=colour, edgecolor="none", alpha=0.25))
        ax.plot([], [], color=colour, lw=6, alpha=0.5,
                label=f"shortening {u[0] * 1e3:.1f} mm, tension {tension:.2f} N")
    path = []
    for share in np.linspace(0.0, 1.0, 41):
        u = share * model.u_max
        eq = solve_equilibrium(model, u, q0=q, u0=u0)
        q, u0 = eq.q, u
        path.append(model.tip(eq.q) * 1e3)
    path = np.array(path)
    ax.plot(path[:, 0], path[:, 1], "k-", lw=1.2, label="tip over the stroke (verified equilibria)")
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("SoftRobots' Finger.py imported: gravity, displacement-controlled cable (side view)")
    ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=Path("docs/sofa_finger.png"))
    main(p.parse_args().out)
