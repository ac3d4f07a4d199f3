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
    """Write ``<out_dir or benchmarks/results>/<name>.json`` and print its one-line JSON; returns the path. Replacing
    a result measured with other arguments (a ``--quick`` run over a full one) is said on stderr."""
    doc = {"benchmark": name, "argv": sys.argv[1:], **provenance(),
           "load_avg": {"start": list(_LOAD_AT_IMPORT), "end": list(load_avg())},
           "figures": dict(figures), "tables": dict(tables or {})}
    out = Path(out_dir) if out_dir is not None else RESULTS_DIR
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{name}.json"
    before = json.loads(path.read_text()).get("argv") if path.exists() else None
    path.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    print(json.dumps({"benchmark": name, "figures": doc["figures"], "load_avg": doc["load_avg"]}, default=float))
    if before is not None and before != doc["argv"]:
        # a quick or partial run replaced the stored figure: say so, so that it is not committed by accident
        print(f"note: {path} held a measurement made with arguments {before}; it now holds this run's, made with "
              f"{doc['argv']} (git checkout {path.name} to keep the stored one)", file=sys.stderr)
    return path


#: ``--check`` fails when a figure is this many times worse than the stored one (a shared machine's noise is
#: 10-30 %; a regression worth a person's look is larger).
CHECK_FACTOR = 1.5


def add_check_option(parser) -> None:
    """Add ``--check`` to a speed benchmark's argparse parser."""
    parser.add_argument("--check", action="store_true",
                        help=f"compare with the figures stored in benchmarks/results/ and exit 1 if one is more than "
                             f"{CHECK_FACTOR}x worse (the stored file is left unchanged)")


def _stored_path(name: str, results_dir: str | Path | None) -> Path:
    return (Path(results_dir) if results_dir is not None else RESULTS_DIR) / f"{name}.json"


def stored_for_check(name: str, results_dir: str | Path | None = None) -> tuple[Path, dict | None, str]:
    """The stored result a ``--check`` of this run would compare with: (path, document or None, why not)."""
    path = _stored_path(name, results_dir)
    if not path.exists():
        return path, None, f"--check: no stored result {path}; run the benchmark without --check first"
    stored = json.loads(path.read_text())
    args = [a for a in sys.argv[1:] if a != "--check"]
    if stored.get("argv", []) != args:
        return path, None, (f"--check: {path.name} was measured with arguments {stored.get('argv')}, not {args}: run "
                            f"--check with the stored arguments (or store a figure for these)")
    return path, stored, ""


def stored_argv(name: str, results_dir: str | Path | None = None) -> list[str]:
    """The arguments ``benchmarks/results/<name>.json`` was measured with (a ``--check`` must repeat them)."""
    path = _stored_path(name, results_dir)
    if not path.exists():
        raise FileNotFoundError(f"no stored result {path}; run benchmarks/bench_{name}.py first")
    return [str(a) for a in json.loads(path.read_text()).get("argv", [])]


def require_stored(name: str, check: bool) -> None:
    """With ``check``, exit 2 at once (before measuring) when there is no stored result for these arguments."""
    if check:
        _path, stored, why = stored_for_check(name)
        if stored is None:
            print(why, file=sys.stderr)
            raise SystemExit(2)


def check_result(name: str, figures: Mapping[str, float], better: Mapping[str, str],
                 factor: float = CHECK_FACTOR, results_dir: str | Path | None = None) -> int:
    """Compare ``figures`` with ``<results_dir>/<name>.json``; print one line per figure; return an exit code.

    ``better`` names the figures checked and which way is better: ``"lower"`` for a cost (CPU ms, seconds),
    ``"higher"`` for a rate (x real time, steps per second). 0 = every checked figure within ``factor`` of the
    stored one, 1 = at least one worse by more, 2 = nothing stored to compare with (or a figure missing).
    """
    path, stored, why = stored_for_check(name, results_dir)
    if stored is None:
        print(why, file=sys.stderr)
        return 2
    old = stored.get("figures", {})
    code = 0
    print(f"--check against {path.name} (commit {stored.get('commit', '?')}, load "
          f"{stored.get('load_avg', {}).get('start', ['?'])[0]}; now load {load_avg()[0]:.2f})")
    for key, way in better.items():
        if way not in ("lower", "higher"):
            raise ValueError(f"better[{key!r}]: expected 'lower' or 'higher', got {way!r}")
        if key not in old or key not in figures:
            print(f"  {key}: missing ({'stored' if key not in old else 'measured'} figures lack it)")
            code = max(code, 2)
            continue
        new_v, old_v = float(figures[key]), float(old[key])
        worse = new_v / old_v if way == "lower" else old_v / new_v if new_v > 0 else float("inf")
        ok = worse <= factor
        print(f"  {key}: {new_v:.4g} now, {old_v:.4g} stored ({way} is better): {worse:.2f}x "
              f"{'ok' if ok else f'WORSE than {factor}x'}")
        if not ok:
            code = max(code, 1) if code != 2 else 2
    return code


def finish(name: str, figures: Mapping[str, float], tables: Mapping[str, str] | None = None, *,
           check: bool = False, better: Mapping[str, str] | None = None) -> int:
    """A benchmark's last step: with ``check``, :func:`check_result` (nothing written); else :func:`write_result`.

    Returns the process exit code.
    """
    if check:
        return check_result(name, figures, better or {})
    write_result(name, figures, tables)
    return 0


if __name__ == "__main__":
    # ``python benchmarks/_results.py argv NAME``: the stored arguments, one per line (``make bench-check``)
    if len(sys.argv) != 3 or sys.argv[1] != "argv":
        raise SystemExit("usage: python benchmarks/_results.py argv NAME")
    try:
        print("\n".join(stored_argv(sys.argv[2])))
    except FileNotFoundError as exc:
        raise SystemExit(str(exc)) from None
