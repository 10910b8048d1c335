"""The shipped design study (problems/study_trunk3.yaml) on 1 and 2 workers: process pool and Dask.

    python scripts/bench_study.py [--write]

Each run starts a fresh study in a temporary directory and times it end to end (workers started, every
trial, trials.csv, study.png, best/). The trials are the same designs in every run (the sampler is
seeded and told results in the same order only with one worker: with two, which trial finishes first
decides what the sampler has seen, so the designs after the first generation may differ).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import casadi_ws as cw

STUDY = Path(__file__).resolve().parents[1] / "problems" / "study_trunk3.yaml"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    study = cw.load_study(STUDY)
    rows = []
    for name, make in (("this process", lambda: None),
                       ("process pool, 2", lambda: cw.ProcessExecutor(2)),
                       ("Dask LocalCluster, 2", lambda: cw.DaskExecutor(workers=2))):
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            ex = make()
            res = cw.run_study(study, Path(tmp) / "out", executor=ex, progress=False)
            if ex is not None:
                ex.close()
            total = time.perf_counter() - t
        trial_s = sum(r.time_s for r in res.trials)
        best = res.best
        rows.append((name, total, trial_s, len(res.trials), res.n_complete, sum(r.pareto for r in res.trials),
                     best.measures["volume"] * 1e6, best.measures["reach_tension"]))
        print(rows[-1], flush=True)
    if args.write:
        from benchlib import machine, write_section

        lines = ["## Design study (issue: design studies) — `scripts/bench_study.py`", "",
                 f"Machine: {machine()}. `problems/study_trunk3.yaml`: {study.trials} trials of the 3-cable trunk "
                 f"(mesh resolution 0.7, 375 nodes), forward-backward at 8 mm and one `reach` each, NSGA-II. Total: "
                 "the whole study, workers' start included; trials: the sum of the trials' own times.", "",
                 "| executor | total (s) | speed-up | sum of trial times (s) | trials | complete | Pareto | "
                 "best: volume (cm³), tension (N) |", "|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r[0]} | {r[1]:.1f} | {rows[0][1] / r[1]:.2f} | {r[2]:.1f} | {r[3]} | {r[4]} | {r[5]} | "
                         f"{r[6]:.0f}, {r[7]:.1f} |")
        lines += ["", "A trial is a whole workspace run (3–10 s here), so the per-task transfer (~3 ms on Dask, "
                  "BENCHMARKS \"dask\") is lost in it. What costs on 2 cores is CPU: the same trials take "
                  "longer in two processes than in one (memory bandwidth), and longer still in Dask workers, "
                  "whose scheduler, nanny and event-loop threads share the two cores; on a cluster with a core "
                  "per worker that share disappears. With one worker the sampler sees every result before "
                  "its next design, with two it does not, so the designs after the first generation differ "
                  "(and so does the best one). `--workers N` uses the process pool; `--scheduler` Dask."]
        write_section("study", "\n".join(lines))


if __name__ == "__main__":
    main()
