"""The engine's hot paths run BLAS on one thread and leave the caller's thread count as it was."""
from __future__ import annotations

import numpy as np
import pytest

threadpoolctl = pytest.importorskip("threadpoolctl")

from ssl_core.blas import one_blas_thread  # noqa: E402
from ssl_core.geometry import cube8  # noqa: E402
from ssl_core.health import HealthConfig, MicHealth  # noqa: E402


def _blas_threads() -> set[int]:
    return {d["num_threads"] for d in threadpoolctl.threadpool_info() if d["user_api"] == "blas"}


@pytest.fixture
def two_blas_threads():
    """BLAS set to two threads by the caller (skipped where the BLAS cannot run two)."""
    np.ones((2, 2)) @ np.ones((2, 2))     # numpy's BLAS loaded
    if not _blas_threads():
        pytest.skip("threadpoolctl finds no BLAS library in this numpy")
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        if _blas_threads() != {2}:
            pytest.skip(f"this BLAS does not run two threads (it reports {_blas_threads()})")
        yield


def test_one_thread_inside_and_the_caller_s_setting_after(two_blas_threads):
    with one_blas_thread():
        assert _blas_threads() == {1}
    assert _blas_threads() == {2}


def test_the_health_analysis_runs_on_one_blas_thread(two_blas_threads, monkeypatch):
    seen = []
    monitor = MicHealth(cube8(), HealthConfig())
    original = monitor._coherence_faults

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        return original(*args, **kwargs)

    monkeypatch.setattr(monitor, "_coherence_faults", spy)
    rng = np.random.default_rng(0)
    talker = rng.standard_normal(16000) * 0.1     # one sound at zero delay on every channel: coherent
    x = np.tile(talker, (8, 1)) + 0.001 * rng.standard_normal((8, 16000))
    monitor.analyse(x)
    assert seen == [{1}]
