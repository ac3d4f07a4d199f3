"""One BLAS thread for hot paths of small matrices.

Their matrices are small, so OpenBLAS's default thread pool only burns CPU: measured 2.3x-21x in the
localizer (issue 11), and in ``robot.hearing`` (listening all the time, 4 tracks) 19-27 ms of CPU per second
of audio instead of 8 (the LSTM cell's matrix products of Silero VAD). threadpoolctl when installed.
"""
from __future__ import annotations

import contextlib

_CONTROLLER = None   # threadpoolctl's controller, made at first use (after numpy has loaded its BLAS); False: off


def one_blas_thread():
    """Context manager: BLAS limited to one thread inside (a no-op without threadpoolctl)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        try:
            from threadpoolctl import ThreadpoolController
            _CONTROLLER = ThreadpoolController()
        except ImportError:  # pure-Python optional speed-up; numpy/scipy stay the only hard needs
            _CONTROLLER = False
    return _CONTROLLER.limit(limits=1, user_api="blas") if _CONTROLLER else contextlib.nullcontext()
