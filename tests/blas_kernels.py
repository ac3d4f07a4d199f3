"""``benchmarks/_blas_kernel.py`` for the tests (which OpenBLAS kernels this CPU runs, the pinned default), loaded by
path; it imports nothing that loads numpy, so tests/conftest.py can use it before numpy chooses its kernels."""
from __future__ import annotations

import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location(
    "_blas_kernel", Path(__file__).resolve().parents[1] / "benchmarks" / "_blas_kernel.py")
kernels = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(kernels)
