"""Where a result came from: code commit, package versions, BLAS kernel, CPU and time.

Closed-loop runs turn last-bit rounding differences between OpenBLAS kernels into other decisions, so a result is
reproducible only with its commit, its numerical packages and its BLAS kernel; every results.json, sweep summary
and benchmark result carries :func:`provenance`.
"""
from __future__ import annotations

import datetime as _dt
import functools
import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = ["provenance", "machine", "git_commit", "PACKAGES"]

#: The packages whose versions decide a run's numbers.
PACKAGES = ("numpy", "scipy", "mujoco", "pyroomacoustics", "onnxruntime")
_SRC_ROOT = Path(__file__).resolve().parents[2]   # the checkout holding src/ssl_sim (no git: an installed wheel)


def _git(root: Path, *args: str) -> str:
    try:
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, check=True,
                              timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


#: Paths whose uncommitted changes cannot change what is measured: the outputs of benchmarks and experiments, and
#: prose. Without this every benchmark of ``make bench`` after the first was marked dirty by the first one's file.
NOT_MEASURED = ("benchmarks/results/**", "experiments/results/**", "docs/**", "**/*.md")   # git glob pathspecs


@functools.lru_cache(maxsize=4)
def git_commit(root: Path = _SRC_ROOT) -> tuple[str, bool]:
    """(commit hash, uncommitted changes?) of the checkout at ``root`` (its top directory); ("", False) outside git.
    Changes to :data:`NOT_MEASURED` paths do not count: "dirty" says the code, models or scenarios differed."""
    commit = _git(root, "rev-parse", "--short=12", "HEAD")
    excluded = [f":(top,exclude,glob){p}" for p in NOT_MEASURED]
    changed = _git(root, "status", "--porcelain", "--untracked-files=no", "--", ":(top)", *excluded)
    return commit, bool(commit) and bool(changed)


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _version(pkg: str) -> str | None:
    try:
        return metadata.version(pkg)
    except metadata.PackageNotFoundError:
        return None


@functools.lru_cache(maxsize=1)
def machine() -> dict[str, Any]:
    """CPU, core count, Python, the numerical packages' versions and the BLAS libraries numpy runs."""
    info: dict[str, Any] = {"cpu": _cpu_name(), "cores": os.cpu_count(), "python": platform.python_version(),
                            "packages": {p: _version(p) for p in PACKAGES}}
    try:
        from threadpoolctl import threadpool_info
        info["blas"] = [f"{d.get('internal_api')} {d.get('version')} {d.get('architecture')}"
                        for d in threadpool_info() if d.get("user_api") == "blas"]
    except ImportError:
        info["blas"] = []
    return info


def provenance(root: str | Path | None = None) -> dict[str, Any]:
    """Commit (and whether the tree had uncommitted changes), UTC time, the pinned OpenBLAS kernel
    (``OPENBLAS_CORETYPE``, '' = the CPU's own choice) and :func:`machine` of a result. ``root``: the checkout
    whose commit to name (default: the one this package runs from)."""
    commit, dirty = git_commit(Path(root).resolve() if root is not None else _SRC_ROOT)
    return {"commit": commit, "dirty": dirty, "utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE", ""), "machine": machine()}
