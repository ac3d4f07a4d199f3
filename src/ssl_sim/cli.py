"""``ssl-rescue``: run rescue scenarios headlessly, watch them in rerun, sweep them over seeds.

    ssl-rescue list
    ssl-rescue record paper_lab --duration 10 --out rec.wav     # then: ssl-locate rec.wav
    ssl-rescue run paper_lab --seed 3 --rerun save:out/run.rrd --out out/run
    ssl-rescue run scenarios/light_rubble_three.toml --rerun spawn
    ssl-rescue sweep paper_lab light_rubble_three --seeds 0:20 --out out/sweep
    ssl-rescue sweep dense_pump --seeds 0:100 --cluster tcp://scheduler:8786
    ssl-rescue suite list test                                   # the generated test split
    ssl-rescue suite show test 17 --out out/suite                # its scenario file: ssl-rescue run PATH
    ssl-rescue sweep --suite test --out out/test                 # the whole test split, each with its own seed
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from robot.interrupt import deferred_sigint
from ssl_core.broken_pipe import quiet_on_broken_pipe
from ssl_core.version import version

# The scenario, runner and viewer modules are imported inside the commands: they take 1-2 s to import, and
# a Ctrl-C meanwhile must already find the handler of main() (see robot.interrupt).


def _checked_models() -> None:
    """The robot's model files loaded and run on silence before anything is simulated or written; a bad one is
    refused like a bad option (exit code 2, the message names the file)."""
    from robot.hearing import VAD_RATE
    from robot.vad import ModelError, check_model

    try:
        check_model(VAD_RATE)
    except ModelError as exc:
        raise ValueError(str(exc)) from None


def _run(args: argparse.Namespace) -> int:
    from contextlib import ExitStack

    from ssl_sim.runner import format_summary, output_dir, run_scenario
    from ssl_sim.scenario import load_scenario, parse_setting
    from ssl_sim.viz import parse_rerun_target

    try:
        settings = dict(map(parse_setting, args.set))
    except ValueError as exc:
        raise ValueError(f"--set: {exc}") from None
    sc = load_scenario(args.scenario, settings)
    for option, name, value in (("--seed", "seed", args.seed), ("--time-limit", "time_limit_s", args.time_limit)):
        try:
            sc.with_overrides(**{name: value})
        except ValueError as exc:
            raise ValueError(str(exc).replace(name, option, 1)) from None
    _checked_models()
    seed = args.seed if args.seed is not None else sc.seed
    out = Path(args.out) if args.out else Path("out") / "runs" / f"{sc.name}_seed{seed}"
    with ExitStack() as made:   # outputs checked now, not after the whole simulation; removed if it is refused
        made.enter_context(output_dir(out, "--out"))
        if args.rerun:
            mode, arg = parse_rerun_target(args.rerun)
            if mode == "save":
                made.enter_context(output_dir(Path(arg).parent, "--rerun save:"))
        result = run_scenario(sc, seed=args.seed, time_limit_s=args.time_limit, rerun=args.rerun, out_dir=out,
                              progress=not args.quiet)
    say = sys.stderr if args.json else sys.stdout  # with --json, stdout carries the JSON line alone
    print(format_summary(result), file=say)
    print(f"wrote {out / 'results.json'}" + (f" and {result['rerun_file']}" if result.get("rerun_file") else ""),
          file=say)
    if result.get("failure"):
        print(f"ssl-rescue: error: the run failed ({result['end_reason']}): {result['failure']['error']}",
              file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({k: result[k] for k in ("scenario", "seed", "n_found", "n_victims", "sim_time_s",
                                                  "path_length_m", "collisions", "spl")}))
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from ssl_sim.runner import output_dir
    from ssl_sim.sweep import interval_table, markdown_table, parse_seeds, run_sweep, summarize, write_tables

    if args.suite is not None:
        from ssl_sim.suite import scenarios

        if args.scenarios:
            raise ValueError(f"sweep: give scenarios or --suite, not both (got {args.scenarios} and "
                             f"--suite {args.suite})")
        seeds = parse_seeds(args.seeds) if args.seeds is not None else None  # None: each its own seed
    else:
        if not args.scenarios:
            raise ValueError("sweep: expected scenario names or .toml files, or --suite train|test")
        if args.count is not None:
            raise ValueError("sweep: --count only goes with --suite")
        seeds = parse_seeds(args.seeds if args.seeds is not None else "0:10")
    _checked_models()
    with output_dir(args.out, "--out"):  # checked now, not after the whole sweep; removed again if it is refused
        todo = scenarios(args.suite, args.count) if args.suite is not None else args.scenarios
        rows = run_sweep(todo, seeds, cluster=args.cluster, workers=args.workers,
                         time_limit_s=args.time_limit, progress=not args.quiet)
        tables = summarize(rows)
        paths = write_tables(rows, tables, args.out)
    print(interval_table(tables["families"]))
    print(markdown_table(tables["scenarios"]))
    print(markdown_table(tables["victims"]))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def _record(args: argparse.Namespace) -> int:
    from ssl_sim.record import parse_pose, record_scenario
    from ssl_sim.scenario import load_scenario

    pose = parse_pose(args.pose) if args.pose is not None else None
    truth = record_scenario(load_scenario(args.scenario), args.out, seed=args.seed, duration_s=args.duration,
                            pose=pose)
    out = Path(args.out)
    if truth["interrupted"]:
        print(f"ssl-rescue: interrupted: recorded {truth['duration_s']:.2f} of {args.duration:g} s",
              file=sys.stderr)
    print(f"wrote {out} ({truth['n_channels']} channels, {truth['duration_s']:.2f} s at {truth['fs']} Hz, int16) "
          f"and {out.with_suffix('.json')} (truth every {truth['frame_s']} s, array frame)")
    for s in truth["sources"]:
        print(f"  {s['name']:<16} {s['kind']:<10} azimuth {s['azimuth_deg'][0]:7.1f} deg  elevation "
              f"{s['elevation_deg'][0]:6.1f} deg  {s['distance_m'][0]:5.2f} m  sounding {100 * s['sounding_fraction']:.0f} %")
    rt = truth["rt60_s"]
    k = rt["octave_hz"].index(1000.0)
    print(f"room RT60 at 1 kHz: {rt['simulated'][k]:.2f} s simulated (the scene's materials alone: "
          f"{rt['scene_materials'][k]:.2f} s)")
    print(f"try: ssl-locate {out} --array cube8 --sources {max(1, len(truth['sources']))}")
    return 130 if truth["interrupted"] else 0


def _suite_list(args: argparse.Namespace) -> int:
    from ssl_sim.suite import generate, indices, summary_row

    print(f"{'index':>5}  {'name':<26}{'room m':>9}  {'vict':>4}  {'sounds':<30}{'buried':>6}  {'intf':>4}  "
          f"{'interferer kinds':<20}{'RT60 s':>7}{'noise dB':>9}{'limit s':>8}")
    for i in indices(args.split, args.count):
        r = summary_row(generate(args.split, i))
        print(f"{i:>5}  {r['name']:<26}{r['room_m']:>9}  {r['victims']:>4}  {r['victim_sounds']:<30}"
              f"{r['buried_max']:>6.2f}  {r['interferers']:>4}  {r['interferer_kinds']:<20}{r['rt60_s']:>7.2f}"
              f"{r['noise_db_spl']:>9.1f}{r['time_limit_s']:>8.0f}")
    return 0


def _suite_show(args: argparse.Namespace) -> int:
    from ssl_sim.suite import generate, summary_row, write_scenario

    path = write_scenario(args.split, args.index, args.out)
    r = summary_row(generate(args.split, args.index))
    print(path.read_text())
    print(f"# {r['family']}, {r['room_m']} m, {r['victims']} victim(s), {r['interferers']} interferer(s)")
    print(f"wrote {path} and {Path(args.out) / 'scenes' / (r['name'] + '.toml')}; rerun: ssl-rescue run {path}")
    return 0


def _list(args: argparse.Namespace) -> int:
    from ssl_sim.scenario import load_scenario, scenario_names

    for name in scenario_names():
        sc = load_scenario(name)
        print(f"{name:<22} {sc.description}")
    return 0


def _shipped_scenarios() -> list[str]:
    # the directory listing, not ssl_sim.scenario.scenario_names(): that module imports the simulator (seconds),
    # and --help should answer at once
    from ssl_sim.resources import SCENARIOS_DIR

    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ssl-rescue", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="run one scenario headlessly and write results.json")
    r.add_argument("scenario", nargs="?", default="paper_lab",
                   help=f"a shipped scenario ({', '.join(_shipped_scenarios())}) or a .toml file (default paper_lab)")
    r.add_argument("--seed", type=int, default=None, help="run seed (default: the scenario's)")
    r.add_argument("--time-limit", type=float, default=None, help="simulated seconds (default: the scenario's)")
    r.add_argument("--rerun", default=None, metavar="save:PATH|spawn|connect[:ADDR]",
                   help="log to rerun: an .rrd file (headless), a spawned viewer or a running one")
    r.add_argument("--set", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="replace a field of the scenario's config tables, as if the file said it (e.g. "
                        "behaviour.p_find=0.6, localizer.n_sources=2); repeatable; results.json records the config")
    r.add_argument("--out", default=None, help="output directory (default out/runs/NAME_seedN)")
    r.add_argument("--json", action="store_true",
                   help="print a one-line JSON summary on stdout (the human-readable summary goes to stderr)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=_run)

    s = sub.add_parser("sweep", help="run scenarios x seeds in parallel (local processes or a Dask cluster)")
    s.add_argument("scenarios", nargs="*", help="shipped scenario names or .toml files")
    s.add_argument("--suite", choices=("train", "test"), default=None,
                   help="run a generated suite split instead (each scenario once with its own seed)")
    s.add_argument("--count", type=int, default=None,
                   help="with --suite: its first N scenarios (default: all 64 of test, 64 of train)")
    s.add_argument("--seeds", default=None,
                   help="START:STOP[:STEP] (stop exclusive), a comma list or one seed (default 0:10; "
                        "with --suite: each scenario's own seed)")
    s.add_argument("--cluster", default=None, metavar="tcp://HOST:PORT",
                   help="Dask scheduler address (needs the 'cluster' extra); default: local processes")
    s.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    s.add_argument("--time-limit", type=float, default=None, help="override every scenario's time limit (s)")
    s.add_argument("--out", default="out/sweep", help="directory for runs.csv, families.csv, scenarios.csv, "
                   "victims.csv, summary.md, summary.json and sweep.png")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_sweep)

    rec = sub.add_parser("record", help="record the 8-channel WAV at the microphones plus a truth JSON")
    rec.add_argument("scenario", help="a shipped scenario or a .toml file")
    rec.add_argument("--seed", type=int, default=None, help="run seed (default: the scenario's)")
    rec.add_argument("--duration", type=float, default=10.0, help="seconds to record (default 10)")
    rec.add_argument("--pose", default=None, metavar="X,Y,YAW",
                     help="robot pose (world m, m, rad; default: the scenario's start)")
    rec.add_argument("--out", required=True, help="WAV file to write; the truth goes to the same name with .json")
    rec.set_defaults(func=_record)

    ls = sub.add_parser("list", help="list the shipped scenarios")
    ls.set_defaults(func=_list)

    su = sub.add_parser("suite", help="generated scenario suites (train / held-out test split)")
    su_sub = su.add_subparsers(dest="suite_command", required=True)
    sl = su_sub.add_parser("list", help="list a split's scenarios (family, room, victims, interferers, RT60, noise)")
    sl.add_argument("split", nargs="?", default="test", choices=("train", "test"), help="default test")
    sl.add_argument("--count", type=int, default=None, help="the first N (default: all 64 of test, 64 of train)")
    sl.set_defaults(func=_suite_list)
    ss = su_sub.add_parser("show", help="write one scenario's TOML (and its scene) so that it can be rerun")
    ss.add_argument("split", choices=("train", "test"))
    ss.add_argument("index", type=int)
    ss.add_argument("--out", default="out/suite", help="directory (default out/suite); scene under OUT/scenes/")
    ss.set_defaults(func=_suite_show)
    return p


@quiet_on_broken_pipe
def main(argv: list[str] | None = None) -> int:
    try:
        # Ctrl-C is raised at check points only, never inside an import (robot.interrupt): here at the end of
        # parsing (which imports the scenarios), in ``run`` at every simulated tick, in ``record`` at every audio
        # block (the recording so far is kept). ``sweep`` has no check points and keeps Python's immediate
        # KeyboardInterrupt (a sweep's workers get the Ctrl-C too).
        with deferred_sigint():
            args = build_parser().parse_args(argv)
            logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
            if args.func in (_run, _record):
                return args.func(args)
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:  # ScenarioError is a ValueError
        print(f"ssl-rescue: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("ssl-rescue: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
