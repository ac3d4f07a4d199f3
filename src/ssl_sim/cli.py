"""``ssl-rescue``: run rescue scenarios headlessly, watch them in rerun, sweep them over seeds.

    ssl-rescue list
    ssl-rescue record paper_lab --duration 10 --out rec.wav     # then: ssl-locate rec.wav
    ssl-rescue run paper_lab --seed 3 --rerun save:out/run.rrd --out out/run
    ssl-rescue run scenarios/light_rubble_three.toml --rerun spawn
    ssl-rescue sweep paper_lab light_rubble_three --seeds 0:20 --out out/sweep
    ssl-rescue sweep dense_pump --seeds 0:100 --cluster tcp://scheduler:8786
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from robot.interrupt import deferred_sigint

# The scenario, runner and viewer modules are imported inside the commands: they take 1-2 s to import, and
# a Ctrl-C meanwhile must already find the handler of main() (see robot.interrupt).


def _run(args: argparse.Namespace) -> int:
    from ssl_sim.runner import check_output_dir, format_summary, run_scenario
    from ssl_sim.scenario import load_scenario
    from ssl_sim.viz import parse_rerun_target

    sc = load_scenario(args.scenario)
    seed = args.seed if args.seed is not None else sc.seed
    out = Path(args.out) if args.out else Path("out") / "runs" / f"{sc.name}_seed{seed}"
    # Fail now, not after the whole simulation.
    check_output_dir(out, "--out")
    if args.rerun:
        mode, arg = parse_rerun_target(args.rerun)
        if mode == "save":
            check_output_dir(Path(arg).parent, "--rerun save:")
    result = run_scenario(sc, seed=args.seed, time_limit_s=args.time_limit, rerun=args.rerun, out_dir=out,
                          progress=not args.quiet)
    print(format_summary(result))
    print(f"wrote {out / 'results.json'}" + (f" and {result['rerun_file']}" if result.get("rerun_file") else ""))
    if args.json:
        print(json.dumps({k: result[k] for k in ("scenario", "seed", "n_found", "n_victims", "sim_time_s",
                                                  "path_length_m", "collisions", "spl")}))
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from ssl_sim.runner import check_output_dir
    from ssl_sim.sweep import interval_table, markdown_table, parse_seeds, run_sweep, summarize, write_tables

    seeds = parse_seeds(args.seeds)
    check_output_dir(args.out, "--out")  # now, not after the whole sweep
    rows = run_sweep(args.scenarios, seeds, cluster=args.cluster, workers=args.workers,
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
    return 0


def _list(args: argparse.Namespace) -> int:
    from ssl_sim.scenario import load_scenario, scenario_names

    for name in scenario_names():
        sc = load_scenario(name)
        print(f"{name:<22} {sc.description}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from ssl_sim.scenario import scenario_names

    p = argparse.ArgumentParser(prog="ssl-rescue", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="run one scenario headlessly and write results.json")
    r.add_argument("scenario", nargs="?", default="paper_lab",
                   help=f"a shipped scenario ({', '.join(scenario_names())}) or a .toml file (default paper_lab)")
    r.add_argument("--seed", type=int, default=None, help="run seed (default: the scenario's)")
    r.add_argument("--time-limit", type=float, default=None, help="simulated seconds (default: the scenario's)")
    r.add_argument("--rerun", default=None, metavar="save:PATH|spawn|connect[:ADDR]",
                   help="log to rerun: an .rrd file (headless), a spawned viewer or a running one")
    r.add_argument("--out", default=None, help="output directory (default out/runs/NAME_seedN)")
    r.add_argument("--json", action="store_true", help="also print a one-line JSON summary")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=_run)

    s = sub.add_parser("sweep", help="run scenarios x seeds in parallel (local processes or a Dask cluster)")
    s.add_argument("scenarios", nargs="+", help="shipped scenario names or .toml files")
    s.add_argument("--seeds", default="0:10", help="START:STOP[:STEP] (stop exclusive), a comma list or one seed")
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
    return p


def main(argv: list[str] | None = None) -> int:
    try:
        # Ctrl-C is raised at check points only, never inside an import (robot.interrupt): here at the end of
        # parsing (which imports the scenarios), in ``run`` at every simulated tick. ``sweep`` and ``record`` have
        # no check points and keep Python's immediate KeyboardInterrupt (a sweep's workers get the Ctrl-C too).
        with deferred_sigint():
            args = build_parser().parse_args(argv)
            logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
            if args.func is _run:
                return _run(args)
        return args.func(args)
    except (ValueError, FileNotFoundError) as exc:  # ScenarioError is a ValueError
        print(f"ssl-rescue: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("ssl-rescue: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
