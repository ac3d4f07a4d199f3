"""The found model's committed parameters are what its fitting script gives on its committed train-split data."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from robot.found import CUES, FoundModel, default_model_path

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("fit_found_model", ROOT / "tools" / "fit_found_model.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("driving", [False, True], ids=["standing", "driving"])
def test_refitting_the_committed_data_reproduces_the_committed_model(driving):
    tool = _tool()
    committed = json.loads(default_model_path(driving).read_text())
    assert "tools/fit_found_model.py" in committed["provenance"]["fitted_by"]
    assert committed["provenance"]["data"].endswith("assessments_driving.csv.gz" if driving else "assessments.csv.gz")
    refit = tool.fit(write=False, driving=driving)
    assert refit["bias"] == pytest.approx(committed["bias"], abs=1e-3)
    for name, w in committed["weights"].items():
        assert refit["weights"][name] == pytest.approx(w, abs=1e-3), name
    for key in ("confirm_probability", "victims_per_m2", "assessments", "positives"):
        assert refit["provenance"][key] == pytest.approx(committed["provenance"][key], rel=1e-3), key


def test_the_fit_recovers_known_weights_from_synthetic_labels():
    """Labels drawn from a known logistic model (seeded): the fit returns its weights within their noise."""
    tool = _tool()
    rng = np.random.default_rng(7)
    X = rng.normal(size=(20000, 3))
    w_true, b_true = np.array([1.5, -2.0, 0.0]), -0.5
    y = (rng.random(20000) < 1 / (1 + np.exp(-(b_true + X @ w_true)))).astype(float)
    b, w = tool.fit_logistic(X, y, l2=0.0)
    assert b == pytest.approx(b_true, abs=0.08)
    np.testing.assert_allclose(w, w_true, atol=0.08)


def test_the_committed_model_names_every_cue_and_loads():
    for driving in (False, True):
        m = FoundModel.load(driving=driving)
        assert set(m.weights) == {c.name for c in CUES}
