"""The per-listen voice evidence (``robot.listening.VOICE_P``, ``NON_VOICE_P``) is what its measuring script gives on
its committed train-split rows."""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from robot.listening import NON_VOICE_P, VOICE_P

ROOT = Path(__file__).resolve().parents[1]
ROWS = ROOT / "experiments" / "results" / "voice_evidence" / "train_0_47_rows.json.gz"


def _tool():
    spec = importlib.util.spec_from_file_location("fit_voice_evidence", ROOT / "tools" / "fit_voice_evidence.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_committed_rows_give_the_committed_voice_probabilities():
    tool = _tool()
    data = tool.load(ROWS)
    assert (data["first"], data["count"]) == (0, 48)
    assert {r["scenario"] for r in data["rows"]} <= set(range(48))
    pool = tool.pooled(data["rows"], n_boot=50)
    assert pool["voice_p"] == pytest.approx(VOICE_P, abs=0.005)
    assert pool["non_voice_p"] == pytest.approx(NON_VOICE_P, abs=0.005)


def test_known_speech_rates_give_their_likelihood_ratios():
    """Rows drawn with known speech rates (seeded): the log-odds are log(pv / po) and log((1 - pv) / (1 - po))
    within their sampling noise, and the resampled interval covers them."""
    tool = _tool()
    rng = np.random.default_rng(3)
    pv, po = 0.4, 0.05
    rows = [{"scenario": int(s), "victim": bool(v), "speech": bool(rng.random() < (pv if v else po)),
             "level_db": -50.0}
            for s in range(40) for v in rng.random(200) < 0.15]
    pool = tool.pooled(rows, n_boot=200)
    want_speech, want_silent = math.log(pv / po), math.log((1 - pv) / (1 - po))
    assert pool["log_odds_speech"] == pytest.approx(want_speech, abs=0.2)
    assert pool["log_odds_silent"] == pytest.approx(want_silent, abs=0.1)
    lo, hi = pool["log_odds_speech_ci"]
    assert lo < want_speech < hi
    lo, hi = pool["log_odds_silent_ci"]
    assert lo < want_silent < hi
