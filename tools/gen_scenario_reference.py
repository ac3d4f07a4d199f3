"""Write ``docs/scenario.md``, the scenario TOML reference, from the code that reads a scenario.

Sections of plain keys come from the loader's own key sets (``ssl_sim.scenario``); the sections that configure a
stage list the fields of that stage's frozen config dataclass with their type, default and the comment written
beside the field in the source. A new field therefore appears here once this script runs, and
``tests/test_docs.py`` fails until it has.

Run: ``python tools/gen_scenario_reference.py``.
"""
from __future__ import annotations

import dataclasses
import inspect
import re
from pathlib import Path

from robot.coverage import CoverageConfig
from robot.options import OptionsConfig
from robot.pursuit import PursuitConfig
from robot.recovery import RecoveryConfig
from robot.motion import MotionConfig
from robot.occupancy import OccupancyConfig
from robot.planner import PlannerConfig
from robot.rescue import RescueConfig
from robot.sound_map import SoundMapConfig
from ssl_core.localizer import LocalizerConfig
from ssl_sim import scenario as S
from ssl_sim.acoustics import AcousticConfig, AmbientNoise
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "scenario.md"

#: Plain keys: what each means (the loader's key sets decide which keys exist; a key without a line here fails).
KEYS = {
    "": {"name": "scenario name (default: the file name)", "description": "one line shown by `ssl-rescue list`",
         "seed": "default run seed (voices, noise, sensor, generated scenes)", "time_limit_s": "simulated seconds",
         "success_radius_m": "older files only: accepted when 0.75 (finds are scored by ssl_sim.scoring, "
                             "docs/design/scoring.md)",
         "scene": "table: where", "robot": "table: the start pose", "victims": "array of tables: who calls",
         "interferers": "array of tables: what else sounds", "noise": "table: diffuse ambient noise",
         "acoustics": "table: the acoustic simulation", "localizer": "table: the localization engine",
         "behaviour": "table: the rescue decisions", "motion": "table: motion primitives",
         "sound_map": "table: the sound map", "planner": "table: the planner", "occupancy": "table: the obstacle grid",
         "coverage": "table: listening coverage", "pursuit": "table: per-source pursuit limits",
         "options": "table: valuing the next move", "recovery": "table: getting free",
         "ego_noise": "table: the drive's own motor noise (on unless `enabled = false`)"},
    "scene": {"name": "a named scene (`empty_lab`, `light_rubble`, `dense_collapsed_room`)",
              "file": "a scene TOML file, relative to the scenario", "generate": "a generator preset name",
              "seed": "the generator's seed (default: the run seed)",
              "use_scene_victims": "add the scene's own victim sites (default: only without [[victims]])"},
    "robot": {"start": "[x, y, yaw]: world m, m, rad (default: the scene's start)"},
    "victims": {"position": "[x, y, z] of the mouth, world m", "scene_victim": "index of a victim site of the scene",
                "sound": "what the victim does (a call, moans, knocks: see ssl_sim.acoustics.voices)",
                "speaker": "a simulated voice's name", "level_db_spl": "level at 1 m (dB SPL)",
                "buried": "0..1: how much debris covers the mouth", "period_s": "time between calls (s)",
                "p_event": "probability of a call per period", "file": "a WAV recording to play instead",
                "name": "a name for the outputs"},
    "interferers": {"kind": "what it is (pump, generator, ...)", "position": "[x, y, z], world m",
                    "level_db_spl": "level at 1 m (dB SPL)", "speaker": "a simulated voice (a non-victim talker)",
                    "file": "a WAV recording to play", "name": "a name for the outputs"},
}
PLAIN_KEYS = {"": S._TOP_KEYS, "scene": {"name", "file", "generate", "seed", "use_scene_victims"},
              "robot": {"start"}, "victims": S._VICTIM_KEYS,
              "interferers": {"kind", "position", "level_db_spl", "speaker", "file", "name"}}
#: Stage sections: TOML table -> config dataclass (and the subset of fields read, if not all).
STAGES = {"noise": (AmbientNoise, None), "acoustics": (AcousticConfig, S.ACOUSTIC_FIELDS),
          "localizer": (LocalizerConfig, None), "behaviour": (RescueConfig, None), "motion": (MotionConfig, None),
          "sound_map": (SoundMapConfig, None), "planner": (PlannerConfig, None),
          "occupancy": (OccupancyConfig, None), "coverage": (CoverageConfig, None),
          "pursuit": (PursuitConfig, None), "options": (OptionsConfig, None), "recovery": (RecoveryConfig, None),
          "ego_noise": (EgoNoiseConfig, None)}


def _comments(cls) -> dict[str, str]:
    """Per field, the comment on its line (with its continuation lines), else the comment block just above it."""
    out: dict[str, str] = {}
    current, above = None, []
    for line in inspect.getsource(cls).splitlines():
        stripped = line.strip()
        m = re.match(r"\s{4}(\w+)\s*:\s*[^#]*?(?:#\s*(.*))?$", line)
        if m and not stripped.startswith("#") and not stripped.startswith(("def ", "@")):
            current = m.group(1)
            out[current] = (m.group(2) or "").strip() or " ".join(above)
            above = []
        elif current and re.match(r"\s+#\s{10,}", line):
            out[current] = (out[current] + " " + stripped.lstrip("#").strip()).strip()
        elif re.match(r"\s{4}#", line):
            current = None
            above.append(stripped.lstrip("#:").strip())
        else:
            current, above = None, []
    return out


def _meaning(comment: str) -> str:
    """The comment's first clause: what the field is (its measured justification belongs to docs/design/)."""
    comment = re.sub(r"\s*\([^()]*\bseeds?\b[^()]*\)", "", comment)  # which runs measured it: docs/design/
    cut = len(comment)
    for sep in (". ", "; ", " Measured", " measured"):
        i = comment.find(sep, 12)  # not within a lead such as "... and"
        if 0 < i < cut:
            cut = i
    i = comment.find(": ", 12)
    if 0 < i < cut and re.search(r"\bseeds?\b", comment[i:cut]):  # the example that measured it
        cut = i
    return comment[:cut].rstrip(" ,:")


def _from_docstring(cls, name: str) -> str:
    """What the class docstring says of ``name``: its ````name````: entry, or the sentence that names it."""
    doc = " ".join((inspect.getdoc(cls) or "").split())
    m = re.search(rf"``{name}``\s*:\s*(.+?)(?=\s``\w+``\s*:|\.\s|$)", doc)
    if m:
        return m.group(1).strip()
    for sentence in re.split(r"(?<=\.)\s", doc):
        if f"``{name}``" in sentence:
            return sentence.replace("``", "`").strip()
    return ""


def _from_comment_naming(cls, name: str) -> str:
    """The sentence of a comment in the class body that names the field (a comment block over a group of fields)."""
    text = " ".join(l.strip().lstrip("#").strip() for l in inspect.getsource(cls).splitlines() if l.strip().startswith("#"))
    for sentence in re.split(r"(?<=\.)\s", text):
        if re.search(rf"\b{name}\b", sentence):
            return _meaning(sentence.replace("``", "`")) or sentence
    return ""


def meaning(cls, name: str, comments: dict[str, str]) -> str:
    """One line on what a config field is: its source comment's first clause, else the class docstring, else a
    comment of the class body that names it."""
    return _meaning(comments.get(name, "")) or _from_docstring(cls, name) or _from_comment_naming(cls, name)


def _default(f) -> str:
    if f.default is not dataclasses.MISSING:
        return repr(f.default)
    if f.default_factory is not dataclasses.MISSING:
        return repr(f.default_factory())
    return "required"


def all_fields() -> list[tuple[str, str]]:
    """(section, field) of every key a scenario may hold; section '' is the top level."""
    out = [(sec, k) for sec, keys in PLAIN_KEYS.items() for k in sorted(keys)]
    for sec, (cls, only) in STAGES.items():
        out += [(sec, f.name) for f in dataclasses.fields(cls) if f.init and (only is None or f.name in only)]
    return out


def _cell(text: str) -> str:
    return text.replace("|", "/").replace("\n", " ")


def render() -> str:
    lines = ["# Scenario TOML reference", "",
             "Generated by `tools/gen_scenario_reference.py` from the code that reads a scenario; do not edit by hand.",
             "A scenario is a TOML file (the shipped ones are in `src/ssl_sim/scenarios/`); `ssl-rescue run FILE.toml`",
             "runs it. Units are SI in the world frame (m, s, rad); every value is checked at load time and an error",
             "names the file and the field. Unknown keys are refused.", ""]
    for sec, keys in PLAIN_KEYS.items():
        title = "top level" if not sec else (f"[[{sec}]]" if sec in ("victims", "interferers") else f"[{sec}]")
        lines += [f"## [{sec}]" if sec else "## [top level]", "", f"Keys of {title}.", "", "| key | meaning |", "|---|---|"]
        for k in sorted(keys):
            if k not in KEYS[sec]:
                raise SystemExit(f"tools/gen_scenario_reference.py: no description of [{sec}] {k}: add one to KEYS")
            lines.append(f"| `{k}` | {_cell(KEYS[sec][k])} |")
        lines.append("")
    for sec, (cls, only) in STAGES.items():
        doc = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
        if doc.startswith(cls.__name__ + "("):  # the dataclass's generated signature, no docstring
            doc = ""
        lines += [f"## [{sec}]", "", f"Fields of `{cls.__module__}.{cls.__name__}`{': ' + doc if doc else '.'}", "",
                  "| field | type | default | meaning (from the source's comment) |", "|---|---|---|---|"]
        notes = _comments(cls)
        for f in dataclasses.fields(cls):
            if not f.init or (only is not None and f.name not in only):
                continue
            typ = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
            text = meaning(cls, f.name, notes)
            if not text:
                raise SystemExit(f"tools/gen_scenario_reference.py: [{sec}] {f.name} ({cls.__name__}) has no comment "
                                 f"in the source and no mention in the class docstring: document it there")
            lines.append(f"| `{f.name}` | `{_cell(str(typ))}` | `{_cell(_default(f))}` | {_cell(text)} |")
        lines.append("")
    retired = [(sec, name, why) for sec, (cls, _) in STAGES.items()
               for name, why in getattr(cls, "RETIRED", {}).items()]
    if retired:
        lines += ["## Retired fields", "",
                  "Fields older scenario files may still set. One no decision read is ignored with a warning; one whose",
                  "value now belongs elsewhere is refused with an error saying where.", "",
                  "| field | on load |", "|---|---|"]
        for sec, name, why in retired:
            what = f"error: {why[6:].strip()}" if why.startswith("MOVED:") else f"ignored with a warning ({why})"
            lines.append(f"| `[{sec}] {name}` | {_cell(what)} |")
        lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"


def main(argv: list[str] | None = None) -> int:
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/scenario.md is out of date")
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        if not OUT.exists() or OUT.read_text() != text:
            print(f"{OUT.relative_to(ROOT)} is out of date: run python tools/gen_scenario_reference.py")
            return 1
        return 0
    OUT.write_text(text)
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
