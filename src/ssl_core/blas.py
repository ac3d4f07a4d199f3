"""One BLAS thread for the engine's hot paths.

The engine's matrices are small (8 channels, a few hundred frequency bins), so OpenBLAS's default thread pool
only burns CPU waking and spinning its threads: measured 2.3-21x the single-thread CPU time for the localizer
(``benchmarks/bench_hearing.py``, "pin off") and 2x for one health analysis. The limit is taken around each call,
not for the whole process, so a program that embeds the engine keeps its own BLAS threads elsewhere.
threadpoolctl when installed; without it, a no-op (numpy and scipy stay the only hard needs).
"""
from __future__ import annotations

import contextlib

__all__ = ["one_blas_thread", "disable"]

_CONTROLLER = None   # None: not looked up yet; False: threadpoolctl missing or disabled


def one_blas_thread():
    """A context in which BLAS runs on one thread. The controller is built at the first call, after numpy has
    loaded its BLAS (a controller built earlier would see no library to limit)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        try:
            from threadpoolctl import ThreadpoolController
            _CONTROLLER = ThreadpoolController()
        except ImportError:
            _CONTROLLER = False
    return _CONTROLLER.limit(limits=1, user_api="blas") if _CONTROLLER else contextlib.nullcontext()


def disable() -> None:
    """Leave BLAS's thread count alone from now on (to measure what the default thread pool costs)."""
    global _CONTROLLER
    _CONTROLLER = False
