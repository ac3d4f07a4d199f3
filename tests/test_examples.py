"""The documented gym example runs: a seeded random policy steps the environment and reports its return."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_random_policy_example_runs_an_episode():
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "random_policy.py"), "--episodes", "1", "--steps", "3"],
                       capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    (line,) = [l for l in r.stdout.splitlines() if l.startswith("episode 0:")]
    m = re.match(r"episode 0: (\d+) steps, return (-?[\d.]+),", line)
    assert m, line
    steps, total = int(m.group(1)), float(m.group(2))
    assert 1 <= steps <= 3
    # reward per step: progress (1 per m; a 0.5 s step drives well under 1 m) - 0.01 - 0.2 per collision, + 10 a find
    assert -0.25 * steps <= total <= 1.0 * steps + 10.0
