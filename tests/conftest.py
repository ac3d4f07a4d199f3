import os
import sys
from pathlib import Path

# test helpers (signals.py) importable from every test module
sys.path.insert(0, str(Path(__file__).parent))


def _pin_blas_kernel() -> None:
    """Pin OpenBLAS's kernels for this process and the processes it starts, as benchmarks/bench_rescue.py does.

    OpenBLAS picks kernels by CPU (SkylakeX on AVX-512 parts, Haswell on AVX2 ones); their last-bit rounding
    differences grow through the thresholds of the closed loop (SRP peak tests, bearing gates) into other decisions,
    so a closed-loop test would pass on one machine and fail on another. OpenBLAS reads OPENBLAS_CORETYPE when
    numpy loads it, so this runs before any test module imports numpy. A value the caller set (also '', the CPU's
    own choice) is kept."""
    if "OPENBLAS_CORETYPE" in os.environ:
        return
    from blas_kernels import kernels
    kernel = kernels.default_kernel()
    if kernel:
        if "numpy" in sys.modules:  # a plugin loaded numpy first: its kernels are chosen already
            raise RuntimeError("tests/conftest.py: numpy was imported before OPENBLAS_CORETYPE could be pinned; "
                               f"set OPENBLAS_CORETYPE={kernel} in the environment")
        os.environ["OPENBLAS_CORETYPE"] = kernel


_pin_blas_kernel()
