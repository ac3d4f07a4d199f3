"""A speed benchmark's ``--check`` fails beyond 1.5x of its stored figure, in the right direction, and only
compares measurements made with the same arguments."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import _results  # noqa: E402


@pytest.fixture
def stored(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--seconds", "5"])
    _results.write_result("x", {"cpu_ms": 10.0, "x_realtime": 30.0}, out_dir=tmp_path)
    doc = json.loads((tmp_path / "x.json").read_text())
    assert doc["argv"] == ["--seconds", "5"] and doc["figures"]["cpu_ms"] == 10.0
    assert {"cpu", "cores", "blas"} <= set(doc["machine"]) and len(doc["load_avg"]["start"]) == 3
    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--seconds", "5", "--check"])
    return tmp_path


@pytest.mark.parametrize("cpu_ms, x_realtime, code", [
    (10.0, 30.0, 0),    # unchanged
    (14.9, 20.1, 0),    # within 1.5x either way
    (15.1, 30.0, 1),    # a cost 1.51x higher
    (10.0, 19.9, 1),    # a rate 1.51x lower
    (2.0, 90.0, 0),     # faster is never a failure
])
def test_check_compares_in_the_figures_direction(stored, cpu_ms, x_realtime, code):
    got = _results.check_result("x", {"cpu_ms": cpu_ms, "x_realtime": x_realtime},
                                {"cpu_ms": "lower", "x_realtime": "higher"}, results_dir=stored)
    assert got == code


def test_check_refuses_other_arguments_and_missing_results(stored, monkeypatch):
    better = {"cpu_ms": "lower"}
    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--seconds", "60", "--check"])
    assert _results.check_result("x", {"cpu_ms": 10.0}, better, results_dir=stored) == 2
    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--seconds", "5", "--check"])
    assert _results.check_result("nothing_stored", {"cpu_ms": 10.0}, better, results_dir=stored) == 2
    assert _results.check_result("x", {"other": 1.0}, better, results_dir=stored) == 2
    with pytest.raises(ValueError, match="better"):
        _results.check_result("x", {"cpu_ms": 10.0}, {"cpu_ms": "faster"}, results_dir=stored)


def test_require_stored_stops_before_measuring(stored, monkeypatch):
    monkeypatch.setattr(_results, "RESULTS_DIR", stored)
    _results.require_stored("x", check=True)          # the same arguments: go on
    _results.require_stored("nothing_stored", check=False)   # not a check: nothing to require
    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--seconds", "60", "--check"])
    with pytest.raises(SystemExit) as e:
        _results.require_stored("x", check=True)
    assert e.value.code == 2


def test_stored_arguments_are_what_a_release_check_repeats(stored, monkeypatch):
    """``make bench-check`` reruns each benchmark with the arguments its stored figure was measured with."""
    assert _results.stored_argv("x", results_dir=stored) == ["--seconds", "5"]
    with pytest.raises(FileNotFoundError, match="nothing_stored"):
        _results.stored_argv("nothing_stored", results_dir=stored)
    # the same arguments again, with --check appended as the Makefile does: compared, not refused
    monkeypatch.setattr(sys, "argv", ["bench_x.py", *_results.stored_argv("x", results_dir=stored), "--check"])
    assert _results.check_result("x", {"cpu_ms": 10.0}, {"cpu_ms": "lower"}, results_dir=stored) == 0


def test_replacing_a_figure_measured_with_other_arguments_is_said(stored, monkeypatch, capsys):
    """A quick or partial run overwrites the stored result (the file records its arguments); stderr says which
    measurement it replaced, so that it is not committed by accident. The same arguments again: nothing to say."""
    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--seconds", "5"])
    _results.write_result("x", {"cpu_ms": 11.0}, out_dir=stored)
    assert "held a measurement" not in capsys.readouterr().err
    monkeypatch.setattr(sys, "argv", ["bench_x.py", "--quick"])
    _results.write_result("x", {"cpu_ms": 12.0}, out_dir=stored)
    err = capsys.readouterr().err
    assert "arguments ['--seconds', '5']" in err and "['--quick']" in err
    assert json.loads((stored / "x.json").read_text())["argv"] == ["--quick"]
