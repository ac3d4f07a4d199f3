"""Benchmark: ``ssl-rescue record`` peak memory against the recording's length (the WAV streams to disk).

Records ``paper_lab`` for each duration in a child process (one process per duration, so each peak is its own)
and reports the child's peak resident memory (``ru_maxrss``) and CPU time, then one JSON line
(``benchmarks/results/record_memory.json``). The simulator's own caches (noise and signal chunks, LRU-bounded)
fill during the first ~35 s of audio; after that the peak does not grow with the duration.
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _results import write_result  # noqa: E402

_CHILD = ("import resource, sys; from ssl_sim.cli import main; rc = main(sys.argv[1:]); "
          "u = resource.getrusage(resource.RUSAGE_SELF); "
          "print('RSS', u.ru_maxrss / 1024, u.ru_utime + u.ru_stime, file=sys.stderr); sys.exit(rc)")


def peak(seconds: float, out: Path) -> tuple[float, float]:
    """(peak RSS MB, CPU s) of one ``ssl-rescue record paper_lab --duration seconds``."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    res = subprocess.run([sys.executable, "-c", _CHILD, "record", "paper_lab", "--duration", f"{seconds:g}",
                          "--out", str(out)], capture_output=True, text=True, env=env)
    if res.returncode != 0:
        raise SystemExit(f"ssl-rescue record failed ({res.returncode}): {res.stderr}")
    line = next(ln for ln in res.stderr.splitlines() if ln.startswith("RSS "))
    mb, cpu = map(float, line.split()[1:])
    return mb, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", default="10,60,180", help="recording lengths, comma-separated (s)")
    args = ap.parse_args()
    durations = [float(v) for v in args.seconds.split(",")]
    figures, rows = {}, ["| recorded s | peak RSS MB | CPU s |", "|---:|---:|---:|"]
    with tempfile.TemporaryDirectory() as tmp:
        for s in durations:
            mb, cpu = peak(s, Path(tmp) / f"rec_{s:g}.wav")
            print(f"record {s:g} s: peak RSS {mb:.0f} MB, CPU {cpu:.1f} s", flush=True)
            figures[f"peak_rss_mb_{s:g}s"] = round(mb, 1)
            figures[f"cpu_s_{s:g}s"] = round(cpu, 2)
            rows.append(f"| {s:g} | {mb:.0f} | {cpu:.1f} |")
    write_result("record_memory", figures, {"ssl-rescue record paper_lab: peak memory": "\n".join(rows)})


if __name__ == "__main__":
    main()
