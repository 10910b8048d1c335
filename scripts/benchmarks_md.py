"""BENCHMARKS.md from benchmarks/history.jsonl: today's figure per benchmark; benchmarks/latest.md: each one's
latest run in full.

Every run of a benchmark script is one row of the history (``key``, ``family``, ``date``, ``what``,
``command``, ``figure``, ``machine`` and the run's ``markdown`` section); :func:`benchlib.write_section`
appends the row and calls :func:`write`. The pages show, per family, the latest row (by date, then by
order in the file); the rows before it stay in the history (``--show KEY`` prints one). A test checks that
both pages are what this script makes of the history, so they cannot drift from the data.

    python scripts/benchmarks_md.py            # rewrite BENCHMARKS.md and benchmarks/latest.md
    python scripts/benchmarks_md.py --show fb-ab-issue-63
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HISTORY = REPO / "benchmarks" / "history.jsonl"
PAGE = REPO / "BENCHMARKS.md"
SECTIONS = REPO / "benchmarks" / "latest.md"

INTRO = """# Benchmarks

Speed and accuracy as measured by the scripts in `scripts/` (tests check behaviour, not timings). Each run is a
row of `benchmarks/history.jsonl`; this page is made from it by `python scripts/benchmarks_md.py`: the
table gives today's figure per benchmark (its name is the key the docs quote), and each links to the
benchmark's latest run in full (its machine, mesh, settings and every figure) in `benchmarks/latest.md`. Earlier
runs (A/B comparisons of one commit against another, reruns on other machines) stay in the history:
`python scripts/benchmarks_md.py --show KEY` (the names the docs quote, e.g. "fb-ab-seeds", are keys). This
machine is shared: the same code's timings vary by up to
~30 % between runs, so A/B rows interleave both codes in one session."""


def read(path: Path = HISTORY) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def latest(rows: list[dict]) -> list[dict]:
    """The latest row of each family, in the order the families first appear."""
    out: dict[str, dict] = {}
    for r in rows:
        f = r["family"]
        if f not in out or (r.get("date") or "") >= (out[f].get("date") or ""):
            out[f] = r
    return list(out.values())


def _anchor(title: str) -> str:
    """GitHub's anchor of a heading."""
    t = re.sub(r"[^\w\- ]", "", title.lower().replace("`", ""))
    return t.replace(" ", "-")


def page(rows: list[dict]) -> str:
    """BENCHMARKS.md: the table of today's figures."""
    lines = [INTRO, "", "## Today's figure per benchmark", "",
             "| benchmark | latest figure | machine, date | command |", "|---|---|---|---|"]
    seen: dict[str, int] = {}
    for r in latest(rows):
        anchor = _anchor(r["markdown"].splitlines()[0].lstrip("# ").strip())
        seen[anchor] = seen.get(anchor, -1) + 1
        if seen[anchor]:  # GitHub numbers a repeated heading's anchor
            anchor = f"{anchor}-{seen[anchor]}"
        older = sum(x["family"] == r["family"] for x in rows) - 1
        lines.append(f"| [{r['what']}](benchmarks/latest.md#{anchor}) (`{r['family']}`"
                     f"{f', {older} earlier runs' if older else ''}) | {r['figure']} | {r['machine']}, {r['date']} | "
                     f"{('`' + r['command'] + '`') if r['command'] else '–'} |")
    return "\n".join(lines) + "\n"


def sections(rows: list[dict]) -> str:
    """benchmarks/latest.md: each benchmark's latest run in full."""
    lines = ["# Benchmarks: each one's latest run", "",
             "Made from `history.jsonl` by `python scripts/benchmarks_md.py`; today's figures are in "
             "[BENCHMARKS.md](../BENCHMARKS.md)."]
    for r in latest(rows):
        lines += ["", r["markdown"].rstrip()]
    return "\n".join(lines) + "\n"


def write(path: Path = PAGE, history: Path = HISTORY, sections_path: Path = SECTIONS) -> None:
    rows = read(history)
    path.write_text(page(rows))
    sections_path.write_text(sections(rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--show", metavar="KEY", help="print the run KEY's section from the history")
    args = ap.parse_args()
    if args.show:
        rows = [r for r in read() if r["key"] == args.show]
        if not rows:
            raise SystemExit(f"{HISTORY}: no run {args.show!r}; keys: {', '.join(r['key'] for r in read())}")
        print(rows[-1]["markdown"])
        return
    write()
    print(f"wrote {PAGE} and {SECTIONS}")


if __name__ == "__main__":
    main()
