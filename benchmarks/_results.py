"""Where a benchmark's figures go: ``benchmarks/results/<name>.json``, with the machine they were measured on.

Every benchmark calls :func:`write_result` once with its headline figures (flat ``{key: number}``, units in the
key: ``"loop_x_realtime"``, ``"step_ms_cpu"``) and optionally Markdown tables. Documented figures are read from
these files (``tools/write_results.py`` renders ``docs/results.md``), never copied by hand, so a figure that no
longer holds shows up as a changed file. Schema (one JSON object)::

    {"benchmark": str, "argv": [...], "commit": str, "dirty": bool, "utc": ISO-8601,
     "openblas_coretype": str, "machine": {"cpu": str, "cores": int, "python": str, "packages": {name: version},
     "blas": [...]},
     "load_avg": [1 min, 5 min, 15 min] at the start and at the end,
     "figures": {key: number}, "tables": {title: markdown}}
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any, Mapping

sys.path.append(str(Path(__file__).resolve().parents[1] / "src"))   # a checkout run without PYTHONPATH
from ssl_sim.provenance import provenance as _provenance  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS_DIR = ROOT / "benchmarks" / "results"
_LOAD_AT_IMPORT = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3


def provenance() -> dict[str, Any]:
    """Commit (and whether the tree had uncommitted changes), time, BLAS kernel and machine of a measurement
    (``ssl_sim.provenance``, the same record results.json and sweeps carry, for this checkout)."""
    return _provenance(ROOT)


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
