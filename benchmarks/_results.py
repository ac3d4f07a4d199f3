"""Where a benchmark's figures go: ``benchmarks/results/<name>.json``, with the machine they were measured on.

Every benchmark calls :func:`write_result` once with its headline figures (flat ``{key: number}``, units in the
key: ``"loop_x_realtime"``, ``"step_ms_cpu"``) and optionally Markdown tables. Documented figures are read from
these files (``tools/write_results.py`` renders ``docs/results.md``), never copied by hand, so a figure that no
longer holds shows up as a changed file. Schema (one JSON object)::

    {"benchmark": str, "argv": [...], "commit": str, "dirty": bool, "utc": ISO-8601,
     "machine": {"cpu": str, "cores": int, "python": str, "numpy": str, "blas": [...], "openblas_coretype": str},
     "load_avg": [1 min, 5 min, 15 min] at the start and at the end,
     "figures": {key: number}, "tables": {title: markdown}}
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any, Mapping

ROOT = Path(__file__).resolve().parents[1]
RESULTS_DIR = ROOT / "benchmarks" / "results"
_LOAD_AT_IMPORT = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict[str, Any]:
    """CPU, core count, Python, numpy and the BLAS libraries numpy runs (threadpoolctl), as measured now."""
    info: dict[str, Any] = {"cpu": _cpu_name(), "cores": os.cpu_count(), "python": platform.python_version(),
                            "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE", "")}
    try:
        import numpy as np
        from threadpoolctl import threadpool_info
        info["numpy"] = np.__version__
        info["blas"] = [f"{d.get('internal_api')} {d.get('version')} {d.get('architecture')}"
                        for d in threadpool_info() if d.get("user_api") == "blas"]
    except ImportError:
        pass
    return info


def provenance() -> dict[str, Any]:
    """Commit (and whether the tree had uncommitted changes), time and machine of a measurement."""
    return {"commit": _git("rev-parse", "--short=12", "HEAD"), "dirty": bool(_git("status", "--porcelain")),
            "utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), "machine": machine()}


def load_avg() -> tuple[float, float, float]:
    """The 1, 5 and 15 minute load averages now (print them beside any speed figure: a busy machine is slower)."""
    return os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3


def write_result(name: str, figures: Mapping[str, float], tables: Mapping[str, str] | None = None,
                 out_dir: str | Path | None = None) -> Path:
    """Write ``<out_dir or benchmarks/results>/<name>.json`` and print its one-line JSON; returns the path."""
    doc = {"benchmark": name, "argv": sys.argv[1:], **provenance(),
           "load_avg": {"start": list(_LOAD_AT_IMPORT), "end": list(load_avg())},
           "figures": dict(figures), "tables": dict(tables or {})}
    out = Path(out_dir) if out_dir is not None else RESULTS_DIR
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.json"
    path.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    print(json.dumps({"benchmark": name, "figures": doc["figures"], "load_avg": doc["load_avg"]}, default=float))
    return path
