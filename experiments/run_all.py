"""Run every experiment of the paper (and the extra sweeps) and assemble ``experiments/REPORT.md``.

``python -m experiments.run_all`` (used by ``make experiments``) runs the full versions and writes
CSVs, PNGs and per-experiment markdown into ``experiments/results/`` and the report into
``experiments/REPORT.md``; ``--quick`` runs the coarse versions (as the tests do) into the scratch folder
``experiments/out/quick/`` (git-ignored), never over the committed full results.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

from experiments import exp1_distance, exp2_angles, exp3_three_sources, exp4_conditions
from experiments.common import LOCALIZER_NOTE, QUICK_RESULTS, RESULTS, Lab, Outcome

EXPERIMENTS = (exp1_distance, exp2_angles, exp3_three_sources, exp4_conditions)
REPORT = Path(__file__).resolve().parent / "REPORT.md"


def source_state(repo: Path = Path(__file__).resolve().parent) -> str:
    """``abc1234`` for a clean work tree, ``abc1234 + uncommitted changes (dirty)`` otherwise, or ``unknown``."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], capture_output=True, text=True, cwd=repo, timeout=10,
                              check=True).stdout.strip()

    try:
        head = git("rev-parse", "--short", "HEAD")
        dirty = git("status", "--porcelain")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{head} + uncommitted changes (dirty)" if dirty else head


def output_paths(quick: bool, out: Path | None = None, report: Path | None = None) -> tuple[Path, Path]:
    """Where a run writes: full runs default to the committed ``experiments/results`` + ``REPORT.md``, quick
    runs to the scratch ``experiments/out/quick`` (never the committed ones: refused with a ValueError)."""
    out = out or (QUICK_RESULTS if quick else RESULTS)
    report = report or (REPORT if out == RESULTS else out / "REPORT.md")
    if quick and (out.resolve() == RESULTS.resolve() or report.resolve() == REPORT.resolve()):
        raise ValueError(f"--quick must not overwrite the committed full results ({RESULTS}, {REPORT}); "
                         f"leave --out/--report out (scratch folder {QUICK_RESULTS}) or choose another place")
    return out, report


def summary_table(outcomes: dict[str, Outcome]) -> str:
    rows = ["| experiment | paper | ours |", "|---|---|---|"]
    if "exp1_distance" in outcomes:
        pd = outcomes["exp1_distance"].summary["per_distance"]
        pick = {round(p["d"], 2): p for p in pd}
        pts = [d for d in (0.5, 1.5, 3.0) if d in pick]
        ours = "; ".join(f"{int(d * 100)} cm: {pick[d]['mse_az']:.1f} / {pick[d]['mse_el']:.1f}" for d in pts)
        rows.append(f"| Fig. 11 error vs distance (MSE az / el, deg²) | grows gradually with distance (plot only) | {ours} |")
    if "exp2_angles" in outcomes:
        s = outcomes["exp2_angles"].summary
        paper = sum(exp2_angles.paper_angular_errors()) / len(exp2_angles.TABLE1)
        rows.append(f"| Table 1 / Figs. 13-16 at 150 cm (mean abs error) | ~1 deg az and el (text); Table 1 mean angular "
                    f"error {paper:.1f} deg | {s['mean_abs_az']:.2f} deg az, {s['mean_abs_el']:.2f} deg el; Table 1 mean "
                    f"angular error {s['table1_mean_ang_err']:.1f} deg |")
    if "exp3_three_sources" in outcomes:
        s = outcomes["exp3_three_sources"].summary
        m, p = s["map"], s["pooled"]
        pe = exp3_three_sources.paper_angular_errors()
        rows.append(f"| Fig. 12 three sources at 200 cm | all 3 found (one trial), angular errors "
                    f"{', '.join(f'{e:.1f}' for e in pe)} deg | summed-map peaks: "
                    f"{m['found_within_10']}/{m['n']} source-trials within 10 deg (median {m['median_ang_err']:.1f} deg); "
                    f"pooled per-window peaks: {p['found_within_10']}/{p['n']} (median {p['median_ang_err']:.1f} deg) |")
    return "\n".join(rows)


#: Experiments run on their own (not by run_all): results file -> what it is.
OTHERS = {
    "policy_baselines.md": "policy baselines on SSLRescue-v0 (random vs map-planning policy: success, SPL, "
                           "path length, collisions; `python -m experiments.policy_baselines`)",
    "listen_while_driving.md": "what listening while driving costs in accuracy, with and without the motors' "
                               "ego-noise (`python -m experiments.listen_while_driving`)",
}


def _others(out_dir: Path, report: Path) -> str:
    rel = os.path.relpath(out_dir, report.parent)
    items = [f"- [{name}]({rel}/{name}): {what}" for name, what in OTHERS.items() if (out_dir / name).exists()]
    return "\n".join(items) or "(none run yet)"


def run_all(quick: bool = False, out_dir: Path | None = None, report: Path | None = None,
            only: tuple[str, ...] | None = None) -> dict[str, Outcome]:
    """Run the experiments and write the report; paths default as in :func:`output_paths`."""
    out_dir, report = output_paths(quick, out_dir, report)
    state = source_state()  # before this run's own outputs change the tree
    out_dir.mkdir(parents=True, exist_ok=True)
    outcomes: dict[str, Outcome] = {}
    for mod in EXPERIMENTS:
        name = mod.__name__.rsplit(".", 1)[-1]
        if only and name not in only:
            # Not rerun: reuse its last outputs so the report stays complete.
            md, js = out_dir / f"{name}.md", out_dir / f"{name}.json"
            if md.exists() and js.exists():
                meta = json.loads(js.read_text())
                outcomes[name] = Outcome(name, md.read_text(), meta.get("files", []), meta.get("seconds", 0.0),
                                         meta.get("summary", {}))
            continue
        print(f"== {name} ({'quick' if quick else 'full'})", flush=True)
        o = mod.run(quick=quick, out_dir=out_dir)
        (out_dir / f"{name}.md").write_text(o.markdown)
        (out_dir / f"{name}.json").write_text(json.dumps(
            {"files": o.files, "seconds": o.seconds, "quick": quick, "summary": o.summary}, indent=1, default=float))
        outcomes[name] = o
        print(f"   {o.seconds:.1f} s", flush=True)
    rel = os.path.relpath(out_dir, report.parent)
    body = "\n\n".join(re.sub(r"\]\((exp[^)]+\.png)\)", rf"]({rel}/\1)", o.markdown) for o in outcomes.values())
    lab = Lab()
    total = sum(o.seconds for o in outcomes.values())
    text = f"""# Experiments: the paper's results reproduced in simulation

Generated by `python -m experiments.run_all{' --quick' if quick else ''}` at commit `{state}`
({'QUICK mode: few trials, coarse sweeps - not the reported figures' if quick else 'full run'};
experiments took {total:.0f} s on one core). Paper: *Search Disaster Victims using Sound Source Localization*
(section "Experimental result"). Data: `{rel}/*.csv`; per-experiment tables: `{rel}/*.md`.

## What is simulated

- **Room** (our assumption, the paper does not describe its lab): {lab.room_size[0]:g} x {lab.room_size[1]:g} x
  {lab.room_size[2]:g} m shoebox, all surfaces with the uniform absorption that gives an Eyring RT60 of
  {lab.rt60_s:g} s; early reflections by the image-source model (order {lab.ism_order}, pyroomacoustics engine),
  late reverberation as a diffuse tail with the same decay (`ssl_sim.acoustics.rir`).
- **Noise**: diffuse background noise (HVAC-like spectrum) of {lab.noise_db_spl:g} dB SPL at the array, with
  diffuse-field coherence between microphones; microphone self-noise 32 dB SPL; 16-bit ADC at -26 dBFS/Pa.
- **Array**: the paper's cube (15 cm, 8 microphones, two per vertical face), capsules off their nominal positions
  by {lab.build_error_m * 1e3:g} mm rms per axis (one fixed as-built array; the localizer knows only the nominal
  geometry), 0.5 dB rms gain mismatch; raised on a stand at the height each experiment needs (stated below).
- **Source**: the paper's 62.5 dB SPL (at 1 m), playing procedurally synthesised calls for help (different voices per
  seed), omnidirectional point source.
- **Localizer**: {LOCALIZER_NOTE}.
- **Trials**: each point is repeated with different seeds (voice, noise, sensor gains); we report spread, not
  one run.

## Paper vs ours at a glance

{summary_table(outcomes)}

{body}

## Other experiments

{_others(out_dir, report)}

## Caveats

- The paper gives numbers only for Table 1 and the three-source positions; Fig. 11 and the box plots are
  compared by trend.
- Simulated errors come from reverberation, noise, the as-built capsule offsets and the 0.5 deg grid; a real
  array adds capsule phase mismatch, a loudspeaker that is not a point, and people in the room.
"""
    report.write_text(text)
    print(f"wrote {report}")
    return outcomes


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="few trials / coarse sweeps")
    ap.add_argument("--out", type=Path, default=None,
                    help="results directory (default experiments/results; with --quick experiments/out/quick)")
    ap.add_argument("--report", type=Path, default=None,
                    help="report path (default experiments/REPORT.md; elsewhere OUT/REPORT.md)")
    ap.add_argument("--only", nargs="*", help="run only these experiments (e.g. exp1_distance)")
    a = ap.parse_args(argv)
    try:
        out, report = output_paths(a.quick, a.out, a.report)
    except ValueError as exc:
        ap.error(str(exc))
    run_all(a.quick, out, report, tuple(a.only) if a.only else None)


if __name__ == "__main__":
    main(sys.argv[1:])
