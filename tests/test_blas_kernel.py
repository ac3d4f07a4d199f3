"""The test process runs OpenBLAS's pinned kernels (benchmarks/_blas_kernel.py), so closed-loop tests take the same
decisions on every x86 machine; a kernel the caller chose is kept."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from blas_kernels import kernels as _blas

TESTS = Path(__file__).resolve().parent

# what a process that loaded tests/conftest.py then numpy runs: OpenBLAS's own report of its kernels
_PROBE = ("import sys; sys.path.insert(0, sys.argv[1]); import conftest, numpy; "
          "from threadpoolctl import threadpool_info; "
          "print([i['architecture'] for i in threadpool_info() if i['internal_api'] == 'openblas'][0])")


def _kernel_in_child(env: dict) -> str:
    pytest.importorskip("threadpoolctl")
    p = subprocess.run([sys.executable, "-c", _PROBE, str(TESTS)], env=env, capture_output=True, text=True,
                       timeout=60, cwd=str(TESTS.parent))
    assert p.returncode == 0, p.stderr
    return p.stdout.strip()


def test_the_test_process_pins_the_benchmarks_kernel():
    kernel = _blas.default_kernel()
    if not kernel:
        pytest.skip("not an x86-64 CPU with AVX2 and FMA: nothing to pin")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    assert _kernel_in_child(env).lower() == kernel.lower()
    assert os.environ.get("OPENBLAS_CORETYPE") is not None  # and so every subprocess a test starts inherits it


def test_a_kernel_the_caller_set_is_kept():
    if not _blas.NEEDS["Sandybridge"] <= _blas.cpu_flags():
        pytest.skip("this CPU cannot run the Sandybridge kernels")
    env = dict(os.environ, OPENBLAS_CORETYPE="Sandybridge")
    assert _kernel_in_child(env).lower() == "sandybridge"
