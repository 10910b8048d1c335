"""The README's pictures of contact: SoftRobots' finger closing on an egg (problems/finger_object.yaml) at
five shortenings of its cable, with the egg's push; the workspace of the trunk pulled onto a table
(problems/trunk_table.yaml) by the forward method, side view, with the table; and the pinch gripper
(problems/pinch_gripper.yaml) whose jaws press on each other (self-contact), at four pairs of tensions.

    python scripts/contact_pictures.py [--out docs]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

from casadi_ws import StaticModel, solve_equilibrium  # noqa: E402
from casadi_ws.fem.surface import boundary_faces  # noqa: E402
from casadi_ws.io.problem import load_problem  # noqa: E402
from casadi_ws.workspace.forward import ForwardSettings, forward  # noqa: E402

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def finger(out: Path) -> None:
    problem = load_problem(PROBLEMS / "finger_object.yaml")
    model = StaticModel(problem)
    egg = problem.obstacles[0].params
    faces = boundary_faces(problem.mesh)[:, :3]
    fig, ax = plt.subplots(figsize=(8, 4.6))
    ax.add_collection(PolyCollection(egg["vertices"][egg["triangles"]][:, :, :2] * 1e3, facecolor="0.8",
                                     edgecolor="none"))
    shares = np.linspace(0.0, 1.0, 5)
    colours = plt.cm.viridis(np.linspace(0.1, 0.9, len(shares)))
    q, u0 = None, None
    for share, colour in zip(shares, colours):
        u = share * model.u_max
        eq = solve_equilibrium(model, u, q0=q, u0=u0)
        q, u0 = eq.q, u
        x = model.positions(eq.q) * 1e3
        (c,) = model.contacts(eq.q)
        ax.add_collection(PolyCollection(x[faces][:, :, :2], facecolor=colour, edgecolor="none", alpha=0.3))
        ax.plot([], [], color=colour, lw=6, alpha=0.5,
                label=f"shortening {u[0] * 1e3:.0f} mm: tension {model.intensities(eq.q, u)[0]:.2f} N, "
                      f"egg pushes {np.linalg.norm(c['force']):.2f} N")
    ax.plot([], [], color="0.8", lw=6, label="the egg (STL, rigid)")
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title("SoftRobots' finger closing on an egg: frictionless contact (side view)")
    ax.legend(loc="lower left", fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "contact_finger.png", dpi=120)
    plt.close(fig)


def trunk(out: Path) -> None:
    problem = load_problem(PROBLEMS / "trunk_table.yaml")
    model = StaticModel(problem)
    res = forward(problem, 21, ForwardSettings(progress=False), model=model)
    table = problem.obstacles[0].params["point"][1]
    touching = res.maps()["contact"] > 0  # N, pressing on the table
    fig, ax = plt.subplots(figsize=(7, 4.2))
    p = res.points * 1e3
    ax.scatter(p[~touching, 0], p[~touching, 1], s=6, c="tab:blue", label="tip, free")
    ax.scatter(p[touching, 0], p[touching, 1], s=6, c="tab:red", label="tip, the trunk pressing on the table")
    x0, x1 = ax.get_xlim()
    ax.fill_between([x0, x1], table * 1e3 - 4, table * 1e3, color="0.75", label="table")
    ax.set_xlim(x0, x1)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"Trunk above a table: forward workspace, {res.n_points} verified tips (front view)")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(out / "contact_trunk_table.png", dpi=120)
    plt.close(fig)


def gripper(out: Path) -> None:
    problem = load_problem(PROBLEMS / "pinch_gripper.yaml")
    model = StaticModel(problem)
    faces = boundary_faces(problem.mesh)[:, :3]
    inputs = ([0.0, 0.0], [1.5, 0.0], [0.0, 1.5], [1.5, 1.5])
    fig, axes = plt.subplots(1, len(inputs), figsize=(12, 3.4), sharey=True)
    for ax, u in zip(axes, inputs):
        eq = solve_equilibrium(model, np.array(u))
        x = model.positions(eq.q) * 1e3
        (c,) = model.contacts(eq.q)
        ax.add_collection(PolyCollection(x[faces][:, :, [0, 2]], facecolor="tab:blue", edgecolor="none",
                                         alpha=0.15))
        tip = model.tip(eq.q) * 1e3
        ax.plot(tip[0], tip[2], "k+", ms=8)
        title = f"tensions {u[0]:.1f}, {u[1]:.1f} N"
        if c["points"]:
            title += f"\njaws press: {np.linalg.norm(c['force']):.3f} N"
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.autoscale()
        ax.set_xlabel("x (mm)")
    axes[0].set_ylabel("z (mm)")
    fig.suptitle("Pinch gripper: one body, its jaws in frictionless self-contact (side view, + the end-effector)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "contact_gripper.png", dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("--out", type=Path, default=Path("docs"))
    out = a.parse_args().out
    finger(out)
    trunk(out)
    gripper(out)
    print(f"wrote {out}/contact_finger.png, {out}/contact_trunk_table.png, {out}/contact_gripper.png")
