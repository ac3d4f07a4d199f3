"""The documentation holds no figure that the benchmarks did not write, and no field of a scenario goes undocumented.

Convention: the README quotes a measured figure only as a link into the results file, ``[20.9](docs/results.md#srp)``,
whose anchor names the benchmark; the number must be one of that benchmark's figures as ``tools/write_results.py``
renders them. Prose outside such links may not carry a number with a unit of a measurement (x real time, ms,
steps per second, %). ``docs/results.md`` itself must equal what the script renders from ``benchmarks/results/``.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import gen_scenario_reference  # noqa: E402
import write_results  # noqa: E402

LINK = re.compile(r"\[([^\]]*)\]\(docs/results\.md#([A-Za-z0-9_-]+)\)")
MEASURED = re.compile(r"\d[\d.,]*\s*(?:x faster|x real time|times faster|ms\b|steps? per|steps/s|%)")


def _prose(text: str) -> str:
    """The README without fenced code blocks (commands and code, not claims)."""
    return re.sub(r"```.*?```", "", text, flags=re.S)


def test_results_md_is_rendered_from_the_benchmark_outputs():
    docs = write_results.load_results()
    assert docs, "benchmarks/results/ holds no result"
    assert (ROOT / "docs" / "results.md").read_text() == write_results.render(docs), \
        "docs/results.md differs from the benchmarks' outputs: run python tools/write_results.py"


def _figures() -> dict[str, set[str]]:
    return {d["benchmark"]: {write_results.format_value(v) for v in d["figures"].values()}
            for d in write_results.load_results()}


def link_problems(text: str, figures: dict[str, set[str]]) -> list[str]:
    """Linked figures that are not a figure of the benchmark their link names."""
    out = []
    for value, bench in LINK.findall(_prose(text)):
        if bench not in figures:
            out.append(f"results.md#{bench}: no such benchmark result")
        elif value not in figures[bench]:
            out.append(f"{value} is not a figure of {bench}")
    return out


def unlinked_measurements(text: str) -> list[str]:
    return [m.group(0) for m in MEASURED.finditer(LINK.sub("", _prose(text)))]


def test_every_figure_the_readme_quotes_is_in_the_results():
    text = (ROOT / "README.md").read_text()
    assert LINK.findall(_prose(text)), "the README links no measured figure (convention: [value](docs/results.md#name))"
    assert not link_problems(text, _figures())


def test_the_readme_quotes_no_unlinked_measurement():
    stray = unlinked_measurements((ROOT / "README.md").read_text())
    assert not stray, f"figures in the README that do not come from docs/results.md: {stray}"


def test_the_checks_catch_a_stale_or_unlinked_figure():
    figures = {"srp": {"17.41"}}
    assert link_problems("costs [17.41](docs/results.md#srp) ms", figures) == []
    assert link_problems("costs [9.9](docs/results.md#srp) ms", figures) == ["9.9 is not a figure of srp"]
    assert link_problems("[1](docs/results.md#nothing)", figures) == ["results.md#nothing: no such benchmark result"]
    assert unlinked_measurements("it runs 27.0x faster than real time at 9.9 ms per second, 110 steps per CPU second")
    assert unlinked_measurements("```\nmake bench  # 27x faster\n```\na 15 cm cube, 8 microphones, 1.5-degree grid") == []


def test_every_scenario_field_is_documented():
    """Every key a scenario may hold has a meaning in the code (render() refuses a field without one) and a row
    in docs/scenario.md."""
    gen_scenario_reference.render()
    text = (ROOT / "docs" / "scenario.md").read_text()
    missing = [f"[{section}] {name}" for section, name in gen_scenario_reference.all_fields()
               if f"`{name}`" not in text.split(f"## [{section or 'top level'}]", 1)[-1].split("\n## ", 1)[0]]
    assert not missing, f"undocumented scenario fields (run python tools/gen_scenario_reference.py): {missing}"


HISTORY = re.compile(r"\bsessions? \d|\bsession-\d|\bissues? #?\d|\bcommit [0-9a-f]{7}|\bat [0-9a-f]{7,}\b", re.I)


def test_docs_and_code_comments_tell_no_development_history():
    """Design rationale is physics and measurement; which session or issue a change came from is not (the
    provenance lines of docs/results.md name the commit a figure was measured at, on purpose)."""
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").rglob("*.md")]
    files += [p for d in ("src", "benchmarks", "tools", "experiments", "examples", "scripts") for p in (ROOT / d).rglob("*")
              if p.suffix in (".py", ".toml", ".sh") and "egg-info" not in str(p)]
    files += [p for p in (ROOT / "firmware").rglob("*") if p.suffix in (".c", ".h", ".md")]
    found = []
    for f in files:
        if f.name == "results.md":
            continue
        for n, line in enumerate(f.read_text().splitlines(), 1):
            if HISTORY.search(line):
                found.append(f"{f.relative_to(ROOT)}:{n}: {line.strip()[:100]}")
    assert not found, "history talk:\n" + "\n".join(found)


def test_the_scenario_reference_refuses_an_undocumented_field(tmp_path, monkeypatch):
    (tmp_path / "fake_stage_config.py").write_text(
        "from dataclasses import dataclass\n\n\n@dataclass(frozen=True)\nclass FakeConfig:\n"
        "    documented_m: float = 1.0    # how far, measured from the robot\n"
        "    undocumented_s: float = 2.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import fake_stage_config
    monkeypatch.setitem(gen_scenario_reference.STAGES, "fake", (fake_stage_config.FakeConfig, None))
    notes = gen_scenario_reference._comments(fake_stage_config.FakeConfig)
    assert gen_scenario_reference.meaning(fake_stage_config.FakeConfig, "documented_m", notes) == \
        "how far, measured from the robot"
    with pytest.raises(SystemExit, match=r"\[fake\] undocumented_s"):
        gen_scenario_reference.render()
