"""Rescue sweep: this tree's behaviour beside a baseline version of it (``--baseline``), measured in the same run.

For each code version (this tree's ``src`` and the ``--baseline`` git ref's ``src``, extracted with
``git archive`` into a temporary directory) a worker process runs every scenario x seed as ``ssl-rescue sweep``
does (``ssl_sim.runner.RescueRun``, one process per run, deterministic per seed) and returns one row per run.
Every version is ended and scored by *this* tree's ``ssl_sim/scoring.py`` (loaded by path in the old version's
process too): a find is a report within 0.5 m of an unfound victim with the base within 1.5 m of her, SPL on
the one free-space graph (``docs/design/scoring.md``). Scenario files are always this tree's (the old code runs
the same scenarios; sections it does not know are removed from a temporary copy), or with ``--suite SPLIT`` a
generated suite's (``ssl_sim.suite.write_scenarios``); ``--baseline-scenarios own`` gives the baseline its own
tree's files instead, so a changed robot profile or scenario config is compared too. Prints, per version: every
metric per scene family with its 95 % bootstrap interval over scenarios (``ssl_sim.stats``); per scenario victims
found and reached, runs with all found, mean SPL, false finds per run, runs ending "stuck", position error of
found victims; the paired difference this tree - baseline over the same scenarios ("outside chance" only when its
interval excludes 0); the share of runs whose outcome differs between two BLAS kernels; then one JSON line. Each
run is reported on stderr as it ends.

**Reproducible across x86 machines**: OpenBLAS picks its kernels by CPU (SkylakeX on AVX-512 Intel parts, Haswell
on AMD Zen), and their last-bit rounding differences grow, through thresholds in the closed loop, into other
decisions: light_rubble_three seeds 0-7 at one commit gave 24/24 victims and SPL 0.581 with the SkylakeX kernels,
23/24 and 0.536 with Haswell, 24/24 and 0.553 with Sandybridge. So the runs pin ``OPENBLAS_CORETYPE`` (``--blas``,
default Haswell where the CPU has AVX2 and FMA). Several kernels (``--blas Haswell,SkylakeX,Sandybridge``) repeat every
run under each: the tables then pool them and give the spread of the mean SPL over kernels, the numerical noise
floor of a seed set.

Run (background it, it takes long on a shared machine):
``nice .venv/bin/python benchmarks/bench_rescue.py --seeds 0:8 [--baseline main] [--workers 2] [--blas K1,K2]``
``nice .venv/bin/python benchmarks/bench_rescue.py --suite test --seeds 0 --results-name rescue_suite_test``
``nice .venv/bin/python benchmarks/bench_rescue.py --suite train --first 200 --count 64 --baseline HEAD --set
behaviour.voice_scan_deg=15 --results-name ''`` (one setting against the same code: ``--set`` changes only this
tree's runs)
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import concurrent.futures as cf  # noqa: E402
import json  # noqa: E402
import multiprocessing  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import tomllib  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from _blas_kernel import check_kernels, default_kernel  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ["paper_lab", "light_rubble_three", "dense_pump", "behind_partition", "half_buried_slab"]
OPTIONAL = ["generator_louder"]        # the machine-louder scenario, when present
TIME_LIMITS = {"light_rubble_three": 180.0}   # the target is set with a 180 s limit
NEW_SECTIONS = ("motion", "sound_map", "planner", "occupancy")


# ----------------------------------------------------------------------------- worker side
ORACLE_NAMES = ("no_false_detections", "exact_directions", "localization", "hearing")   # ssl_sim.runner.ORACLES, in the tree run


def _scoring():
    """This tree's ``ssl_sim/scoring.py``, loaded by path: every code version is scored by the same definition
    (an older tree's runner scores by its own rules, which are not the ones compared here)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("_bench_scoring", ROOT / "src" / "ssl_sim" / "scoring.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod      # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _one(path: str, seed: int, time_limit: float | None, oracle: str = "", settings: tuple[str, ...] = ()) -> dict:
    """One run of whatever code version is on the path, driven as ``RescueRun.run`` does, but ended and scored by
    this tree's scoring (the run ends when every victim is *found* by its rules, the behaviour finishes or time is
    up). ``oracle``: an ablation of the robot's hearing by name (``ssl_sim.runner.ORACLES``), '' for none;
    ``settings``: "SECTION.FIELD=VALUE" replacing the scenario's config fields (``ssl_sim.scenario.parse_setting``)."""
    from robot.rescue import Decision
    from ssl_sim.runner import RescueRun
    from ssl_sim.scenario import load_scenario
    scoring = _scoring()
    t0 = time.process_time()
    if settings:   # only then: an older tree (a baseline) has no settings
        from ssl_sim.scenario import parse_setting
        sc = load_scenario(path, dict(map(parse_setting, settings)))
    else:
        sc = load_scenario(path)
    sc = sc.with_overrides(seed=None if seed < 0 else seed, time_limit_s=time_limit)
    if oracle:   # only then: an older tree (a baseline) has no ablations
        from ssl_sim.runner import ORACLES
        run = RescueRun(sc, **ORACLES[oracle])
    else:
        run = RescueRun(sc)
    n = run.n_victims
    victims_xy = [s.position[:2] for s in run.sources[:n]]
    judge = scoring.Judge(victims_xy, sc.time_limit_s)
    finds = []
    end_reason = "time_up"
    try:
        while True:
            if len(judge.found) == n:
                end_reason = "all_found"
                break
            if run.behaviour.done:
                last = run.behaviour.events[-1].decision if run.behaviour.events else "done"
                end_reason = f"behaviour_{getattr(last, 'value', last)}"
                break
            if run.clock.now() >= sc.time_limit_s:
                break
            events = run.behaviour.step()
            run._handle_events(events)
            for ev in events:
                if ev.decision is Decision.VICTIM_FOUND:
                    _, x, y, _, _ = run._pose_at(ev.time)
                    # the reported position: a typed payload, or the plain dict older versions emit
                    pos = ev.data["position"] if isinstance(ev.data, dict) else ev.data.position
                    j = judge.declare(ev.time, pos, (x, y))
                    if j.kind == "find":
                        finds.append((j.victim, (x, y), run._path_at(ev.time)))
    finally:
        run.drive.stop()
    graph = scoring.FreeSpaceGraph(run.world)
    legs = scoring.leg_spls(graph, victims_xy, run.world.robot_start[:2], finds)
    ev = [str(e) for e in run.events]
    last_backoff_ok = not any("backing off blocked" in e for e in ev[-3:])
    found = sorted(judge.found)
    return {"scenario": sc.name, "seed": sc.seed, "blas": os.environ.get("OPENBLAS_CORETYPE", ""),
            "n_found": len(found), "n_victims": n, "n_reached": len(judge.reached), "success": len(found) == n,
            "spl": scoring.run_spl(n, legs), "false_finds": len(judge.false_finds),
            "too_far": sum(j.kind == "too_far" for j in judge.judgements), "end_reason": end_reason,
            "stuck_with_free_backoff": end_reason.endswith("stuck") and last_backoff_ok,
            "sim_time_s": round(run.robot.time, 2), "cpu_s": round(time.process_time() - t0, 2),
            "found_victims": [run.sources[k].name for k in found],
            "find_times_s": [round(judge.found[k].time_s, 2) for k in found],
            "position_errors_m": [round(judge.found[k].report_error_m, 4) for k in found]}


def worker(paths: list[str], seeds: list[int], workers: int, out: str, oracle: str = "",
           settings: tuple[str, ...] = ()) -> None:
    tasks = [(p, s, TIME_LIMITS.get(Path(p).stem), oracle, tuple(settings)) for p in paths for s in seeds]
    ctx = multiprocessing.get_context("spawn")
    rows = []
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        for r in ex.map(_one, *zip(*tasks)):
            rows.append(r)
            # progress on stderr (the tables come at the end of a run that can take half an hour)
            print(f"{Path(out).stem}: {len(rows)}/{len(tasks)} {r['scenario']} seed {r['seed']}: {r['n_found']}/"
                  f"{r['n_victims']} found, {r['false_finds']} false, {r['cpu_s']} CPU s", file=sys.stderr, flush=True)
    Path(out).write_text(json.dumps(rows))


# ----------------------------------------------------------------------------- driver side
def _scenario_paths(tmp: Path, old: bool, only: list[str] | None = None, files: list[Path] | None = None) -> list[str]:
    """Scenario files for one version: the shipped ones (``only``: some of them) or ``files`` (a suite's)."""
    if files is not None:
        sources = list(files)
    else:
        names = SCENARIOS + [n for n in OPTIONAL if (ROOT / "src" / "ssl_sim" / "scenarios" / f"{n}.toml").exists()]
        if only:
            unknown = sorted(set(only) - set(names))
            if unknown:
                raise SystemExit(f"bench_rescue.py: --scenarios: unknown {unknown}, expected some of {names}")
            names = [n for n in names if n in only]
        sources = [ROOT / "src" / "ssl_sim" / "scenarios" / f"{n}.toml" for n in names]
    out = []
    for src in sources:
        n = src.stem
        if not old:
            out.append(str(src))
            continue
        data = tomllib.loads(src.read_text())
        if not any(k in data for k in NEW_SECTIONS):
            out.append(str(src))
            continue
        # The old code rejects sections it does not know: a copy without them, beside the original (scene paths).
        lines, skip = [], False
        for line in src.read_text().splitlines():
            if line.strip().startswith("["):
                skip = line.strip().strip("[]") in NEW_SECTIONS
            if not skip:
                lines.append(line)
        dst = src.with_name(f".{n}.baseline.toml")
        dst.write_text("\n".join(lines) + "\n")
        out.append(str(dst))
    return out


def _own_scenario_paths(base_src: Path, tmp: Path, names: list[str], args) -> list[str]:
    """The baseline tree's own files for the scenarios ``names`` (``--baseline-scenarios own``): its shipped ones,
    or its generator's suite written with its own code (its robot profile, its draws)."""
    if args.suite:
        code = ("import sys; from ssl_sim.suite import write_scenarios; "
                "print('\\n'.join(map(str, write_scenarios(*sys.argv[1:3], None if sys.argv[3] == '-' else "
                "int(sys.argv[3]), int(sys.argv[4])))))")
        out = subprocess.run([sys.executable, "-c", code, args.suite, str(tmp / "baseline_suite"),
                              str(args.count) if args.count is not None else "-", str(args.first)],
                             env=dict(os.environ, PYTHONPATH=str(base_src)), capture_output=True, text=True)
        if out.returncode != 0:
            raise SystemExit(f"bench_rescue.py: --baseline-scenarios own: the baseline cannot write the {args.suite!r} "
                             f"suite:\n{out.stderr.strip()[-2000:]}")
        paths = out.stdout.split()
    else:
        paths = [str(base_src / "ssl_sim" / "scenarios" / f"{n}.toml") for n in names]
    missing = [p for p in paths if not Path(p).exists()]
    if missing or [Path(p).stem for p in paths] != names:
        raise SystemExit(f"bench_rescue.py: --baseline-scenarios own: the baseline's scenarios "
                         f"{[Path(p).stem for p in paths]} are not this tree's {names} (missing: {missing})")
    return paths


def _start_version(src: Path, paths: list[str], seeds: list[int], workers: int, tmp: Path, tag: str, blas: str,
                   oracle: str = "", settings: tuple[str, ...] = ()):
    """Start one code version's runs in a worker process (OpenBLAS kernels ``blas``, '' = the CPU's own choice);
    returns (process, output file)."""
    out = tmp / f"{tag}-{blas or 'cpu'}.json"
    env = dict(os.environ, PYTHONPATH=str(src))
    env.pop("OPENBLAS_CORETYPE", None)
    if blas:
        env["OPENBLAS_CORETYPE"] = blas
    cmd = [sys.executable, __file__, "--worker", str(out), "--workers", str(workers),
           "--seeds", ",".join(map(str, seeds)), "--paths", *paths] + (["--oracle", oracle] if oracle else []) \
        + [f"--set={x}" for x in settings]
    return subprocess.Popen(cmd, env=env, cwd=str(ROOT)), out


def _finish(proc, out: Path) -> list[dict]:
    if proc.wait() != 0:
        raise RuntimeError(f"bench worker failed (exit {proc.returncode})")
    return json.loads(out.read_text())


def _table(rows: list[dict]) -> list[dict]:
    out = []
    for name in dict.fromkeys(r["scenario"] for r in rows):
        rs = [r for r in rows if r["scenario"] == name]
        errs = np.array([e for r in rs for e in r["position_errors_m"]])
        kernels = sorted({r.get("blas", "") for r in rs})
        spl_by_kernel = [float(np.mean([r["spl"] for r in rs if r.get("blas", "") == k])) for k in kernels]
        out.append({"scenario": name, "runs": len(rs), "blas": "+".join(k or "cpu" for k in kernels),
                    "victims_found": f"{sum(r['n_found'] for r in rs)}/{sum(r['n_victims'] for r in rs)}",
                    "victims_reached": f"{sum(r['n_reached'] for r in rs)}/{sum(r['n_victims'] for r in rs)}",
                    "all_found_runs": sum(r["success"] for r in rs),
                    "mean_spl": round(float(np.mean([r["spl"] for r in rs])), 3),
                    "spl_range_over_blas": (f"{min(spl_by_kernel):.3f}-{max(spl_by_kernel):.3f}"
                                            if len(kernels) > 1 else "-"),
                    "false_finds_per_run": round(float(np.mean([r["false_finds"] for r in rs])), 3),
                    "too_far_per_run": round(float(np.mean([r["too_far"] for r in rs])), 3),
                    "stuck_runs": sum(r["end_reason"].endswith("stuck") for r in rs),
                    "stuck_with_free_backoff": sum(r["stuck_with_free_backoff"] for r in rs),
                    "pos_err_median_m": round(float(np.median(errs)), 3) if errs.size else None,
                    "pos_err_p90_m": round(float(np.percentile(errs, 90)), 3) if errs.size else None,
                    "mean_sim_time_s": round(float(np.mean([r["sim_time_s"] for r in rs])), 1),
                    "cpu_s_per_run": round(float(np.mean([r["cpu_s"] for r in rs])), 1)})
    return out


def _interval_rows(summary: list[dict]) -> list[dict]:
    """``ssl_sim.stats.summarize`` rows as "mean [lo, hi]" cells."""
    from ssl_sim import stats
    out = []
    for r in summary:
        row = {"family": r["family"], "scenarios": r["scenarios"]}
        for m, (label, unit) in stats.METRICS.items():
            iv = stats.Interval(*(float("nan") if r[k] is None else r[k] for k in (m, f"{m}_lo", f"{m}_hi")),
                                n=r["scenarios"])
            row[label + (f" ({unit})" if unit else "")] = iv.fmt(1 if unit == "s" else 2 if unit == "m" else 3)
        out.append(row)
    return out


def _paired_rows(comparison: list[dict]) -> list[dict]:
    def f(x):
        return "-" if x is None or x != x else f"{x:.3f}"
    return [{"metric": c["metric"], "pairs": c["pairs"], "this tree": f(c["new"]), "baseline": f(c["old"]),
             "difference [95 %]": f"{f(c['difference'])} [{f(c['difference_lo'])}, {f(c['difference_hi'])}]",
             "outside chance": "yes" if c["outside_chance"] else "no"} for c in comparison]


def _markdown(rows: list[dict]) -> str:
    if not rows:
        return "(no rows)"
    cols = list(rows[0])
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join("-" if r[c] is None else str(r[c]) for c in cols) + " |" for r in rows]
    return "\n".join(lines)


def _family(scenario: str) -> str:
    try:
        from ssl_sim.suite import family_of
        return family_of(scenario)
    except (ImportError, ValueError):
        return scenario


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0:8", help="START:STOP (stop exclusive) or a comma list (with --suite: "
                    "default each scenario's own seed)")
    ap.add_argument("--baseline", default="main", help="git ref of the old behaviour ('' = skip it)")
    ap.add_argument("--baseline-src", default=None,
                    help="or the src directory of a checkout of the old behaviour (with its models/, data/ beside)")
    ap.add_argument("--baseline-scenarios", choices=("this", "own"), default="this",
                    help="which scenario files the baseline runs: this tree's (default: the same worlds and robot "
                         "configs, so only the code differs) or its own tree's shipped files or generated suite "
                         "(also a changed [localizer], [behaviour] or suite profile differs)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenarios", default=None, help="comma list of scenario names (default: all shipped ones)")
    ap.add_argument("--suite", default=None, help="run a generated suite's split (train | test) instead of the "
                    "shipped scenarios (ssl_sim.suite.write_scenarios)")
    ap.add_argument("--count", type=int, default=None, help="with --suite: only its first COUNT scenarios")
    ap.add_argument("--first", type=int, default=0, help="with --suite: start at this index (train: a range apart "
                    "from the one a model was fitted on; test: a part of the fixed split, to run it in parts)")
    ap.add_argument("--results-name", default=None, help="write benchmarks/results/NAME.json (_results.py); '' for "
                    "none (default: rescue, none with --tables-only: re-tabulated rows are not a stored result)")
    ap.add_argument("--tables-only", action="store_true",
                    help="run nothing: only tabulate the rows of --rows-in (e.g. to re-render an earlier run)")
    ap.add_argument("--rows-out", default=None, help="also write every run's row (JSON) here")
    ap.add_argument("--rows-in", nargs="*", default=(), help="rows files of earlier runs to add to the tables")
    ap.add_argument("--blas", default=None,
                    help="comma list of OPENBLAS_CORETYPE kernels to run every run under ('' = the CPU's own "
                         "choice; default $OPENBLAS_CORETYPE, else Haswell where the CPU has AVX2 and FMA)")
    ap.add_argument("--oracle", choices=ORACLE_NAMES, default="",
                    help="an ablation of this tree's runs: 'no_false_detections' drops SRP-PHAT's detections more "
                         "than 10 deg from every sounding source, 'localization' gives the behaviour the true "
                         "directions of the sounding sources instead, 'hearing' also the truth's voice evidence "
                         "(ssl_sim.runner.ORACLES)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE", dest="settings",
                    help="replace a config field of every scenario in this tree's runs only (the baseline runs the "
                         "files as they are), e.g. --set behaviour.voice_scan_deg=15 with --baseline HEAD: one "
                         "setting against the same code; repeatable (ssl_sim.scenario.parse_setting)")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--paths", nargs="*", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    seeds = (list(range(*map(int, args.seeds.split(":")))) if ":" in args.seeds
             else [int(s) for s in args.seeds.split(",")])
    if args.results_name is None:
        args.results_name = "" if args.tables_only else "rescue"
    if args.worker:
        worker(args.paths, seeds, args.workers, args.worker, args.oracle, tuple(args.settings))
        return 0
    # An OPENBLAS_CORETYPE the caller set is kept, not replaced by the default.
    kernels = check_kernels(args.blas.split(",") if args.blas is not None
                            else [os.environ.get("OPENBLAS_CORETYPE") or default_kernel()])
    sys.path.append(str(ROOT / "src"))   # the driver reads this tree's ssl_sim (stats, suite); workers get PYTHONPATH
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        only = args.scenarios.split(",") if args.scenarios else None
        suite_files = None
        if args.suite:
            if args.scenarios:
                raise SystemExit("bench_rescue.py: --suite and --scenarios exclude each other")
            try:
                from ssl_sim.suite import write_scenarios
            except ImportError as exc:
                raise SystemExit(f"bench_rescue.py: --suite needs ssl_sim.suite.write_scenarios, which this tree does "
                                 f"not provide ({exc})") from None
            suite_files = [Path(p) for p in write_scenarios(args.suite, tmp / "suite", args.count, args.first)]
            if "--seeds" not in (argv if argv is not None else sys.argv[1:]):
                seeds = [-1]    # a suite scenario is complete with its seed
        new_paths = _scenario_paths(tmp, old=False, only=only, files=suite_files)
        if args.settings:   # refused now, by name, rather than in every worker
            from ssl_sim.scenario import ScenarioError, load_scenario, parse_setting
            try:
                load_scenario(new_paths[0], dict(map(parse_setting, args.settings)))
            except (ScenarioError, ValueError) as exc:
                raise SystemExit(f"bench_rescue.py: --set: {exc}") from None
        old_paths: list[str] = []
        base_src = None
        if args.baseline or args.baseline_src:
            if args.baseline_src:
                base_src = Path(args.baseline_src).resolve()
            else:
                base = tmp / "baseline"
                base.mkdir()
                # the whole tree: the code finds its scenes and sounds beside src (models/, data/ in older trees)
                arch = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline], check=True,
                                      capture_output=True).stdout
                subprocess.run(["tar", "-x", "-C", str(base)], input=arch, check=True)
                base_src = base / "src"
            if args.baseline_scenarios == "own":
                old_paths = _own_scenario_paths(base_src, tmp, [Path(p).stem for p in new_paths], args)
            else:
                old_paths = _scenario_paths(tmp, old=True, only=only, files=suite_files)
        rows: dict[str, list[dict]] = {"new": []}
        try:
            for blas in ([] if args.tables_only else kernels):
                # Both versions at once (each with ``workers`` processes): the same seeds, scenario files, kernels.
                jobs = {"new": _start_version(ROOT / "src", new_paths, seeds, args.workers, tmp, "new", blas,
                                              args.oracle, tuple(args.settings))}
                if base_src is not None:
                    jobs["old"] = _start_version(base_src, old_paths, seeds, args.workers, tmp, "old", blas)
                for tag, job in jobs.items():
                    rows.setdefault(tag, []).extend(_finish(*job))
        finally:
            for p in old_paths:
                if Path(p).name.startswith("."):
                    Path(p).unlink(missing_ok=True)
        for f in args.rows_in:      # e.g. other seeds run earlier: one table over all of them
            for tag, rs in json.loads(Path(f).read_text()).items():
                rows.setdefault(tag, []).extend(rs)
        if args.rows_out:
            Path(args.rows_out).write_text(json.dumps(rows))
        seeds = sorted({r["seed"] for r in rows["new"]})
    from ssl_sim import stats
    for rs in rows.values():
        for r in rs:   # the family each run is summarized under: a suite scenario's scene family, else its name
            r["family"] = _family(r["scenario"])
    new, old = _table(rows["new"]), (_table(rows["old"]) if "old" in rows else None)
    summary = {tag: stats.summarize(rs) for tag, rs in rows.items()}
    paired = stats.paired_comparison(rows["new"], rows["old"]) if "old" in rows else None
    divergence = {tag: stats.kernel_divergence(rs) for tag, rs in rows.items()}
    what = f"suite {args.suite!r} ({len(suite_files)} scenarios)" if args.suite else \
        f"light_rubble_three limited to {TIME_LIMITS['light_rubble_three']:g} s"
    if args.settings:
        what += f"; this tree's runs with {', '.join(args.settings)}"
    print(f"seeds {seeds}; {what}; OpenBLAS kernels {', '.join(k or 'the CPU default' for k in kernels)}; scored by "
          "this tree's ssl_sim.scoring (find: report within 0.5 m, base within 1.5 m; SPL to within 1.5 m)\n")
    tables = {"this tree, 95 % intervals over scenarios": _markdown(_interval_rows(summary["new"])),
              "this tree, per scenario": _markdown(new)}
    if old:
        base = args.baseline_src or args.baseline
        tables[f"baseline {base}, 95 % intervals over scenarios"] = _markdown(_interval_rows(summary["old"]))
        tables[f"baseline {base}, per scenario"] = _markdown(old)
        tables[f"this tree - baseline {base}, paired over the same scenarios"] = _markdown(_paired_rows(paired))
    for tag, div in divergence.items():
        if div:
            tables[f"{'this tree' if tag == 'new' else 'baseline'}: BLAS kernel divergence"] = _markdown(div)
    for title, text in tables.items():
        print(f"{title}:\n{text}\n")
    if args.results_name:
        from _results import write_result   # here, not at the top: a baseline worker runs an older ssl_sim
        overall = next(r for r in summary["new"] if r["family"] == "all") if len(summary["new"]) > 1 \
            else summary["new"][0]
        figures = {f"{k}": overall[k] for k in overall if k not in ("family",) and overall[k] is not None}
        for c in paired or []:
            figures[f"paired_{c['metric']}_difference"] = c["difference"]
            figures[f"paired_{c['metric']}_difference_lo"] = c["difference_lo"]
            figures[f"paired_{c['metric']}_difference_hi"] = c["difference_hi"]
        write_result(args.results_name, {k: v for k, v in figures.items() if v is not None}, tables)
    print(json.dumps({"bench": "rescue", "seeds": seeds, "suite": args.suite, "settings": args.settings, "blas": kernels, "new": new, "old": old,
                      "summary": summary, "paired": paired, "divergence": divergence,
                      "wall_s": round(time.perf_counter() - t0, 1)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
