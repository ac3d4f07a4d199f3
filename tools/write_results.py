"""Render ``docs/results.md`` from the benchmarks' own outputs, ``benchmarks/results/*.json``.

One section per benchmark (its anchor is the benchmark's name, e.g. ``docs/results.md#scenario``): where and how it
was measured (commit, CPU, cores, BLAS library and kernel, load average, arguments, date), then its tables and its
figures as the benchmark wrote them. Nothing here is typed by hand: run a benchmark (``make bench`` runs them all),
then this script; ``tests/test_docs.py`` fails when the file differs from what this script renders, and when the
README quotes a figure this file does not hold.

Run: ``python tools/write_results.py [--check]`` (``--check``: exit 1 if docs/results.md is out of date).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS_DIR = ROOT / "benchmarks" / "results"
RESULTS_MD = ROOT / "docs" / "results.md"

HEADER = """# Measured results

Every figure below was written by a benchmark into `benchmarks/results/<name>.json` and rendered by
`tools/write_results.py`; none is copied by hand. Speed figures are CPU time on one core unless a name says
`wall`; the load average beside them says how busy the machine was (a shared machine is slower, and its numbers
scatter). Re-measure with `make bench` (every benchmark, default arguments) or one benchmark with its own
arguments, then `python tools/write_results.py`. Speed benchmarks take `--check`: they compare a new measurement
with the stored one (made with the same arguments) and exit 1 when it is more than 1.5x worse; `make bench-check`
runs them all, each with the arguments of its stored figure.
"""


def format_value(v) -> str:
    """A figure as the docs show it: integers as they are, other numbers to 4 significant digits."""
    if isinstance(v, bool):
        return str(int(v))
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "-"
        if v == int(v) and abs(v) < 1e15:
            return str(int(v))
        return f"{v:.4g}"
    return str(v)


def load_results(results_dir: Path = RESULTS_DIR) -> list[dict]:
    """Every stored result, sorted by benchmark name."""
    docs = []
    for f in sorted(results_dir.glob("*.json")):
        doc = json.loads(f.read_text())
        for key in ("benchmark", "commit", "machine", "load_avg", "figures"):
            if key not in doc:
                raise SystemExit(f"{f}: not a benchmark result (no {key!r}); written by benchmarks/_results.py?")
        docs.append(doc)
    return docs


def _where(doc: dict) -> str:
    m = doc["machine"]
    blas = "; ".join(m.get("blas") or ["unknown"])
    core = doc.get("openblas_coretype", m.get("openblas_coretype")) or "the CPU's own choice"
    numpy = m.get("packages", {}).get("numpy") or m.get("numpy", "?")
    load = doc["load_avg"]
    argv = " ".join(doc.get("argv") or []) or "(defaults)"
    return (f"Measured {doc.get('utc', '?')} at commit `{doc['commit']}`{' with local changes' if doc.get('dirty') else ''}"
            f" on {m.get('cpu', '?')} ({m.get('cores', '?')} cores), Python {m.get('python', '?')}, numpy "
            f"{numpy}, BLAS {blas}, OpenBLAS kernels: {core}; load average "
            f"{load['start'][0]:.1f} at the start, {load['end'][0]:.1f} at the end. Arguments: `{argv}`.")


def render(docs: list[dict]) -> str:
    out = [HEADER]
    out.append("| benchmark | commit | load average (start) | arguments |\n|---|---|---|---|")
    for d in docs:
        out.append(f"| [{d['benchmark']}](#{d['benchmark']}) | `{d['commit']}` | {d['load_avg']['start'][0]:.1f} | "
                   f"`{' '.join(d.get('argv') or []) or '(defaults)'}` |")
    out.append("")
    for d in docs:
        out.append(f"## {d['benchmark']}\n")
        out.append(_where(d) + "\n")
        for title, table in (d.get("tables") or {}).items():
            out.append(f"**{title}**\n")
            out.append(table.rstrip("\n") + "\n")
        if d["figures"]:
            out.append("| figure | value |\n|---|---|")
            for k, v in d["figures"].items():
                out.append(f"| {k.replace('|', '/')} | {format_value(v)} |")
            out.append("")
    return "\n".join(out).rstrip("\n") + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/results.md differs from the rendering")
    args = ap.parse_args(argv)
    text = render(load_results())
    if args.check:
        if not RESULTS_MD.exists() or RESULTS_MD.read_text() != text:
            print(f"{RESULTS_MD.relative_to(ROOT)} is out of date: run python tools/write_results.py", file=sys.stderr)
            return 1
        return 0
    RESULTS_MD.parent.mkdir(parents=True, exist_ok=True)
    RESULTS_MD.write_text(text)
    print(f"wrote {RESULTS_MD.relative_to(ROOT)} ({len(text.splitlines())} lines)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
