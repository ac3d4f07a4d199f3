"""Benchmark: how long each command-line program takes to answer ``--help`` (its start-up cost before any work).

Each program runs ``--help`` in a fresh interpreter ``--repeat`` times; the figure is the child's CPU time
(user + system, from ``resource.getrusage(RUSAGE_CHILDREN)``), best of the repeats, with the wall time beside
it (wall depends on the machine's load, which is recorded). The programs import their numerical stack (scipy,
the simulator) only once the arguments are parsed.

Run: ``.venv/bin/python benchmarks/bench_cli_startup.py [--repeat 5]``
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from _results import write_result

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = {"ssl-locate": "ssl_core.cli", "ssl-robot": "robot.cli", "ssl-rescue": "ssl_sim.cli"}


def _one(module: str) -> tuple[float, float]:
    """(CPU s, wall s) of ``python -m module --help``."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", module, "--help"], env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per program (default: %(default)s)")
    args = ap.parse_args(argv)
    if args.repeat < 1:
        raise SystemExit(f"--repeat: expected an integer >= 1, got {args.repeat}")
    figures, rows = {}, ["| program | --help CPU s (best) | wall s (best) |", "|---|---|---|"]
    for prog, module in PROGRAMS.items():
        runs = [_one(module) for _ in range(args.repeat)]
        cpu, wall = min(r[0] for r in runs), min(r[1] for r in runs)
        key = prog.replace("-", "_")
        figures[f"{key}_help_cpu_s"] = round(cpu, 3)
        figures[f"{key}_help_wall_s"] = round(wall, 3)
        rows.append(f"| {prog} | {cpu:.2f} | {wall:.2f} |")
        print(f"{prog} --help: {cpu:.2f} s CPU, {wall:.2f} s wall (best of {args.repeat})")
    write_result("cli_startup", figures, {"--help start-up": "\n".join(rows)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
