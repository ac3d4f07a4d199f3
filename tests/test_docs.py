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


def test_every_figure_the_readme_quotes_is_in_the_results():
    text = _prose((ROOT / "README.md").read_text())
    figures = {d["benchmark"]: {write_results.format_value(v) for v in d["figures"].values()}
               for d in write_results.load_results()}
    links = LINK.findall(text)
    assert links, "the README links no measured figure (convention: [value](docs/results.md#benchmark))"
    for value, bench in links:
        assert bench in figures, f"README links results.md#{bench}: no such benchmark result"
        assert value in figures[bench], f"README quotes {value} from {bench}, which holds {sorted(figures[bench])}"


def test_the_readme_quotes_no_unlinked_measurement():
    text = LINK.sub("", _prose((ROOT / "README.md").read_text()))
    stray = [m.group(0) for m in MEASURED.finditer(text)]
    assert not stray, f"figures in the README that do not come from docs/results.md: {stray}"


def test_every_scenario_field_is_documented():
    text = (ROOT / "docs" / "scenario.md").read_text()
    missing = [f"[{section}] {name}" for section, name in gen_scenario_reference.all_fields()
               if f"`{name}`" not in text.split(f"## [{section or 'top level'}]", 1)[-1].split("\n## ", 1)[0]]
    assert not missing, f"undocumented scenario fields (run python tools/gen_scenario_reference.py): {missing}"
    assert text == gen_scenario_reference.render(), "docs/scenario.md is out of date: run tools/gen_scenario_reference.py"


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
