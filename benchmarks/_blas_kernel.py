"""Which OpenBLAS kernels (``OPENBLAS_CORETYPE``) a closed-loop benchmark may pin on this CPU.

The rescue loop turns last-bit rounding differences between kernels into other decisions (thresholds on SRP
peaks, gates on bearings), so x86 machines reproduce each other's tables only with the same kernels.
"""
from __future__ import annotations

import platform
from pathlib import Path

# instruction-set flags (/proc/cpuinfo) each kernel executes
NEEDS = {"Prescott": {"sse3"}, "Nehalem": {"sse4_2"}, "Sandybridge": {"avx"}, "Haswell": {"avx2", "fma"},
         "Zen": {"avx2", "fma"}, "SkylakeX": {"avx512f", "avx512bw", "avx512dq", "avx512vl", "avx512cd"},
         "Cooperlake": {"avx512f", "avx512bw", "avx512dq", "avx512vl", "avx512cd", "avx512_bf16"}}
DEFAULT = "Haswell"


def cpu_flags() -> set[str]:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def default_kernel() -> str:
    """Haswell on an x86-64 CPU with AVX2 and FMA, else '' (the CPU's own choice: nothing to pin to)."""
    if platform.machine().lower() in ("x86_64", "amd64") and NEEDS[DEFAULT] <= cpu_flags():
        return DEFAULT
    return ""


def check_kernels(kernels: list[str]) -> list[str]:
    """The kernels, each known and executable here ('' = the CPU's own choice); a clear error otherwise."""
    flags = cpu_flags()
    for k in kernels:
        if k and k not in NEEDS:
            raise SystemExit(f"--blas: unknown OpenBLAS kernel {k!r}, expected one of {sorted(NEEDS)} or ''")
        if k and not NEEDS[k] <= flags:
            raise SystemExit(f"--blas: this CPU lacks {sorted(NEEDS[k] - flags)} for the {k} kernels")
    return kernels
