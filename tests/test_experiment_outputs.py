"""``experiments.run_all --quick`` never overwrites the committed full results, and the report's
"generated at commit" line and every result's provenance tell the truth about the source tree."""
from __future__ import annotations

import subprocess

import pytest

from experiments import run_all as ra
from experiments.common import QUICK_RESULTS, RESULTS
from ssl_sim.provenance import git_commit


def test_quick_runs_go_to_the_scratch_folder_and_full_runs_to_the_committed_one(tmp_path):
    assert ra.output_paths(quick=True) == (QUICK_RESULTS, QUICK_RESULTS / "REPORT.md")
    assert ra.output_paths(quick=False) == (RESULTS, ra.REPORT)
    assert ra.output_paths(quick=True, out=tmp_path) == (tmp_path, tmp_path / "REPORT.md")
    assert "experiments/out/" in (RESULTS.parents[1] / ".gitignore").read_text()  # scratch is not committed
    for kw in ({"out": RESULTS}, {"report": ra.REPORT}, {"out": RESULTS / ".." / "results"}):
        with pytest.raises(ValueError, match="must not overwrite the committed full results"):
            ra.output_paths(quick=True, **kw)
    with pytest.raises(SystemExit) as exc:
        ra.main(["--quick", "--out", str(RESULTS)])
    assert exc.value.code == 2


def _git(repo, *args):
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@example.org", *args], cwd=repo,
                          check=True, capture_output=True, text=True).stdout.strip()


def test_source_state_says_dirty_when_the_tree_is(tmp_path):
    _git(tmp_path, "init", "-q")
    (tmp_path / "a.py").write_text("x = 1\n")
    _git(tmp_path, "add", "a.py")
    _git(tmp_path, "commit", "-qm", "one")
    head = _git(tmp_path, "rev-parse", "--short", "HEAD")
    assert ra.source_state(tmp_path) == head
    (tmp_path / "a.py").write_text("x = 2\n")
    assert ra.source_state(tmp_path) == f"{head} + uncommitted changes (dirty)"
    assert ra.source_state(tmp_path / "no_such_dir") == "unknown"


def test_the_report_states_the_source_state(tmp_path):
    ra.run_all(quick=True, out_dir=tmp_path, only=("none_of_them",))  # no experiment: just the report
    text = (tmp_path / "REPORT.md").read_text()
    assert f"at commit `{ra.source_state()}`" in text and "QUICK mode" in text


def test_provenance_is_dirty_for_code_not_for_results_or_prose(tmp_path):
    """A benchmark run after another (make bench) is not dirty because of the first one's result file; a changed
    source file, model or scenario makes it dirty."""
    for rel in ("src/m.py", "benchmarks/results/a.json", "experiments/results/b.csv", "docs/c.md", "README.md",
                "scenarios/s.toml"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("1\n")
    _git(tmp_path, "init", "-q")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-qm", "one")
    head = _git(tmp_path, "rev-parse", "--short=12", "HEAD")

    def state() -> tuple[str, bool]:
        git_commit.cache_clear()
        return git_commit(tmp_path)

    assert state() == (head, False)
    for rel in ("benchmarks/results/a.json", "experiments/results/b.csv", "docs/c.md", "README.md"):
        (tmp_path / rel).write_text("2\n")
    assert state() == (head, False)
    for rel in ("src/m.py", "scenarios/s.toml"):
        (tmp_path / rel).write_text("2\n")
        assert state() == (head, True)
        _git(tmp_path, "checkout", "-q", "--", rel)
    assert state() == (head, False)
