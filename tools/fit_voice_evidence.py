"""How much one listen's voice evidence says, measured on the benchmark's train split.

The sound map (``robot.sound_map``) sums one log-odds term per listen that heard a source: ``VOICE_P`` when the
VAD heard speech in the beam toward the detection (``robot.listening``), ``NON_VOICE_P`` when it did not, at every
beam level. Those terms are likelihood ratios: how much more
often a bearing toward a calling victim has speech in its beam than a bearing toward anything else (a machine, a
reflection, a lobe). This tool measures them.

Each train scenario runs as the benchmark runs it (``ssl_sim.runner.RescueRun``, the robot as it is). Every
candidate of every listen (``HeardPayload``: the beam's speech fraction and level) is labelled from the runner's
truth of that listen: *victim* when a victim sounding in it (``SOUNDING_FRACTION``) lies within ``NEAR_DEG`` of the
bearing's azimuth (array frame; the cube's elevation is the worse coordinate), else *other* (a sounding interferer,
a silent source, a reflection or a lobe: what a map source built from the bearing would not be a victim at).
Printed per beam level and pooled: P(speech | victim), P(speech | other) and the log-odds of a listen with and
without speech that they imply (95 % intervals by resampling scenarios), beside the ones the map uses; the pooled
ones are ``VOICE_P`` and ``NON_VOICE_P`` as probabilities (prior 0.5).

Run (train split; choose on train):

    nice -n 10 python tools/fit_voice_evidence.py --first 0 --count 48 --workers 2 \
        --json experiments/results/voice_evidence/train_0_47_rows.json.gz
    python tools/fit_voice_evidence.py --rows-in experiments/results/voice_evidence/train_0_47_rows.json.gz
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import gzip
import json
import math
import multiprocessing as mp
import os

import numpy as np

NEAR_DEG = 10.0                      # a bearing this close in azimuth to a sounding victim is hers
LEVEL_BINS_DB = (-math.inf, -60.0, -54.0, -51.0, -45.0, math.inf)   # beam level, dB re full-scale sine


def run_one(index: int) -> list[dict]:
    """Train scenario ``index``: one row per candidate heard (speech fraction, beam level, label)."""
    os.nice(10)
    from robot.events import HeardPayload
    from ssl_sim import suite
    from ssl_sim.runner import RescueRun
    run = RescueRun(suite.generate("train", index))
    try:
        run.run()
    except Exception as exc:   # a simulator refusal ends the run; its listens so far still count
        print(f"train {index}: stopped early ({type(exc).__name__}: {exc})", flush=True)
    threshold = run.behaviour.config.voice_threshold
    times = np.array([rec["time_s"] for rec in run.listens])
    rows = []
    for ev in run.events:
        if not isinstance(ev.data, HeardPayload) or not len(times):
            continue
        k = int(np.searchsorted(times, ev.time + 1e-6)) - 1
        if k < 0 or ev.time - times[k] > 1.5:
            continue
        victims = [s for s in run.listens[k]["sources"] if s["kind"] == "victim" and s["active"]]
        for c in ev.data.candidates:
            az = math.degrees(c.azimuth)
            near = [abs((az - s["azimuth_deg"] + 180.0) % 360.0 - 180.0) for s in victims]
            rows.append({"scenario": index, "voice": float(c.voice), "speech": bool(c.voice >= threshold),
                         "level_db": float(c.level_db), "voice_scan": bool(c.voice_scan),
                         "victim": bool(near and min(near) <= NEAR_DEG)})
    return rows


def load(path: str) -> dict:
    """A ``--json`` file (gzipped when its name ends in .gz)."""
    opener = gzip.open if str(path).endswith(".gz") else open
    with opener(path, "rt") as f:
        return json.load(f)


def likelihoods(rows: list[dict]) -> dict:
    """Counts, P(speech | victim), P(speech | other) (add-one smoothed) and the per-listen log-odds of a listen
    with and without speech."""
    v = [r["speech"] for r in rows if r["victim"]]
    o = [r["speech"] for r in rows if not r["victim"]]
    pv, po = (sum(v) + 1) / (len(v) + 2), (sum(o) + 1) / (len(o) + 2)
    return {"victim": len(v), "other": len(o), "p_speech_victim": pv, "p_speech_other": po,
            "log_odds_speech": math.log(pv / po), "log_odds_silent": math.log((1 - pv) / (1 - po))}


def pooled(rows: list[dict], n_boot: int = 1000, seed: int = 0) -> dict:
    """:func:`likelihoods` over every row, with 95 % intervals of both log-odds by resampling scenarios, and the
    per-listen voice probabilities they are (prior 0.5): ``voice_p`` with speech, ``non_voice_p`` without."""
    out = likelihoods(rows)
    by: dict[int, list[dict]] = {}
    for r in rows:
        by.setdefault(r["scenario"], []).append(r)
    keys = sorted(by)
    rng = np.random.default_rng(seed)
    boot = [likelihoods([r for k in rng.choice(keys, len(keys)) for r in by[k]]) for _ in range(n_boot)]
    for name in ("log_odds_speech", "log_odds_silent"):
        out[name + "_ci"] = [float(np.percentile([b[name] for b in boot], q)) for q in (2.5, 97.5)]
    out["voice_p"] = 1.0 / (1.0 + math.exp(-out["log_odds_speech"]))
    out["non_voice_p"] = 1.0 / (1.0 + math.exp(-out["log_odds_silent"]))
    return out


def table(rows: list[dict]) -> list[dict]:
    """:func:`likelihoods` per beam-level bin (dB re full-scale sine)."""
    out = []
    for lo, hi in zip(LEVEL_BINS_DB[:-1], LEVEL_BINS_DB[1:]):
        sel = [r for r in rows if lo <= r["level_db"] < hi]
        if sel:
            out.append({"level_db": f"{lo:g} .. {hi:g}", **likelihoods(sel)})
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--count", type=int, default=48)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rows-in", help="tabulate the rows of an earlier run (--json) instead of running")
    ap.add_argument("--json", help="write the rows and the table here")
    args = ap.parse_args(argv)
    if args.rows_in:
        data = load(args.rows_in)
        rows, args.first, args.count = data["rows"], data["first"], data["count"]
    else:
        idx = list(range(args.first, args.first + args.count))
        with cf.ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as ex:
            rows = [r for rs in ex.map(run_one, idx) for r in rs]
    from robot.listening import NON_VOICE_P, VOICE_P
    tab, pool = table(rows), pooled(rows)
    print(f"{len(rows)} candidates heard, {sum(r['victim'] for r in rows)} toward a sounding victim")
    print("| beam level (dB FS) | victim | other | P(speech / victim) | P(speech / other) | log-odds speech | "
          "log-odds silent |")
    print("|---|---|---|---|---|---|---|")
    for t in [*tab, {**pool, "level_db": "all"}]:
        print(f"| {t['level_db']} | {t['victim']} | {t['other']} | {t['p_speech_victim']:.3f} | "
              f"{t['p_speech_other']:.3f} | {t['log_odds_speech']:+.2f} | {t['log_odds_silent']:+.2f} |")
    (s_lo, s_hi), (n_lo, n_hi) = pool["log_odds_speech_ci"], pool["log_odds_silent_ci"]
    print(f"pooled, 95 % over scenarios: speech {pool['log_odds_speech']:+.2f} [{s_lo:+.2f}, {s_hi:+.2f}] -> VOICE_P "
          f"{pool['voice_p']:.2f}; silent {pool['log_odds_silent']:+.2f} [{n_lo:+.2f}, {n_hi:+.2f}] -> NON_VOICE_P "
          f"{pool['non_voice_p']:.2f}")
    print(f"the map: VOICE_P {VOICE_P} ({math.log(VOICE_P / (1 - VOICE_P)):+.2f}), NON_VOICE_P {NON_VOICE_P} "
          f"({math.log(NON_VOICE_P / (1 - NON_VOICE_P)):+.2f})")
    if args.json:
        data = json.dumps({"first": args.first, "count": args.count, "near_deg": NEAR_DEG, "pooled": pool,
                           "table": tab, "rows": rows})
        if args.json.endswith(".gz"):
            with gzip.GzipFile(args.json, "wb", mtime=0) as f:   # mtime 0: the same rows give the same file
                f.write(data.encode())
        else:
            with open(args.json, "w") as f:
                f.write(data)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
