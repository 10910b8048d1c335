"""study.png: every objective against every design variable, and the Pareto front for two objectives."""

from __future__ import annotations

import numpy as np

from .spec import MEASURES

__all__ = ["study_plot"]

# shown in units a designer reads at a glance (the CSV stays in SI)
_DISPLAY = {"m^3": (1e6, "cm^3"), "m^2": (1e4, "cm^2"), "m": (1e3, "mm")}


def _label(measure: str) -> tuple[float, str]:
    unit = MEASURES[measure][0]
    scale, shown = _DISPLAY.get(unit, (1.0, unit))
    return scale, f"{measure} ({shown})" if shown else measure


def study_plot(result, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    study, recs = result.study, result.trials
    objs, vars_ = study.objectives, study.variables
    pareto_panel = len(objs) == 2
    ncol = len(vars_) + pareto_panel
    fig = plt.figure(figsize=(3.2 * ncol + (1.5 if pareto_panel else 0), 2.8 * len(objs) + 0.6))
    gs = fig.add_gridspec(len(objs), ncol, width_ratios=[1] * len(vars_) + ([1.6] if pareto_panel else []))
    ok = [r for r in recs if r.status == "complete"]
    for i, o in enumerate(objs):
        scale, label = _label(o.measure)
        for j, v in enumerate(vars_):
            ax = fig.add_subplot(gs[i, j])
            for group, style in (([r for r in ok if r.feasible and not r.pareto], dict(c="tab:blue")),
                                 ([r for r in ok if r.pareto], dict(c="tab:red")),
                                 ([r for r in ok if not r.feasible], dict(facecolors="none", edgecolors="gray"))):
                if group:
                    x = [r.params[v.path] for r in group]
                    ax.scatter(x, [scale * r.measures[o.measure] for r in group], s=22, **style)
            if v.log:
                from matplotlib.ticker import NullFormatter

                ax.set_xscale("log")
                ax.set_xticks(np.geomspace(v.low, v.high, 3))  # the log formatter's own labels overlap
                ax.xaxis.set_major_formatter(lambda x, _: f"{x:.3g}")
                ax.xaxis.set_minor_formatter(NullFormatter())
            if i == len(objs) - 1:
                ax.set_xlabel(v.path, fontsize=8)
            if j == 0:
                ax.set_ylabel(f"{o.direction[:3]}. {label}", fontsize=8)
            ax.tick_params(labelsize=7)
    if pareto_panel:
        ax = fig.add_subplot(gs[:, -1])
        (sa, la), (sb, lb) = _label(objs[0].measure), _label(objs[1].measure)
        feas = [r for r in ok if r.feasible]
        ax.scatter([sa * r.measures[objs[0].measure] for r in feas], [sb * r.measures[objs[1].measure] for r in feas],
                   c="tab:blue", s=22, label="feasible designs")
        front = sorted([r for r in ok if r.pareto], key=lambda r: r.measures[objs[0].measure])
        if front:
            ax.plot([sa * r.measures[objs[0].measure] for r in front], [sb * r.measures[objs[1].measure] for r in front],
                    "o-", c="tab:red", label="Pareto front")
        bad = [r for r in ok if not r.feasible]
        if bad:
            ax.scatter([sa * r.measures[objs[0].measure] for r in bad], [sb * r.measures[objs[1].measure] for r in bad],
                       facecolors="none", edgecolors="gray", s=22, label="infeasible")
        if result.best is not None:
            b = result.best
            ax.scatter([sa * b.measures[objs[0].measure]], [sb * b.measures[objs[1].measure]], marker="*", s=200,
                       c="gold", edgecolors="k", zorder=5, label=f"best.yaml (trial {b.number})")
        ax.set_xlabel(f"{objs[0].direction[:3]}. {la}")
        ax.set_ylabel(f"{objs[1].direction[:3]}. {lb}")
        ax.legend(fontsize=7)
        ax.set_title("Pareto front", fontsize=9)
    failed = len(recs) - len(ok)
    red = "Pareto-optimal" if len(objs) > 1 else "best"
    fig.suptitle(f"study {study.name}: {len(recs)} trials ({failed} failed, not shown); red: {red}, "
                 f"hollow: infeasible", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
