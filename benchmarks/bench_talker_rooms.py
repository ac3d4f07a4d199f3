"""Benchmark: a talker beside a louder real machine in a reverberant room, through the real chain.

The talker-beside-a-machine rooms (tests/sound_dataset.py: RT60 0.6 s, 7 x 6 x 3.2 m, talker and machine 2 m from the
cube, 60+ deg apart, recorded speech and machinery): ``--rooms test`` the five scored in
tests/test_hearing.py (data set test part), ``--rooms dev`` six tuning rooms (dev part's talkers and
machines, other azimuths, robot position and simulation seed). For each localizer setting:

- per 128 ms window of her talking seconds (after the first 2 s): a detection within 10 deg of her
  (``her det``), per window of all seconds a detection farther than 20 deg from both sources (``ghost``);
- through ``Localizer -> Tracker -> Hearing`` as in tests/test_hearing.py: her track VOICE in her talking
  1 s windows and the machine's NON_VOICE in all windows at SIR -6 dB; a VOICE track within 10 deg of her
  at SIR 0 dB (the 90 / 95 / 70 % requirements).

With ``--hear scan_step_deg=15`` the hearing's voice scan feeds its detections to the tracker (as in
tests/test_hearing.py); its columns: her talking seconds with a scan detection within 10 deg of her, scan
detections more than 20 deg from her, and scan detections with the machine alone (a third run per room).
False alarms: scored seconds with a VOICE track more than 20 deg from her at -6 dB, and with any VOICE track
when the machine is alone.
"From 6 s": her track VOICE in her talking seconds from the 6th on (the steady state).

Prints a table per room and pooled, and one JSON line. ``--quick``: localizer columns only (no VAD);
``--set`` / ``--hear FIELD=VALUE`` override ``LocalizerConfig`` / ``HearingConfig``.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "src"), str(ROOT / "tests")]

import numpy as np  # noqa: E402

from _results import write_result  # noqa: E402
from sound_dataset import DEV_ROBOT_XY, DEV_ROOM_CASES, DEV_SEED, FS, ROOM_CASES, room_case  # noqa: E402
from ssl_core.grid import angular_distance  # noqa: E402
from ssl_core.localizer import Localizer, LocalizerConfig  # noqa: E402
from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE, Tracker  # noqa: E402

SETTLE_S = 2
SECONDS = 16
LATE_S = 6   # the "from 6 s" column: her windows from this second on (steady state, after the voice scan settles)
BLOCK = FS // 10
CACHE = Path("/tmp/bench_talker_rooms")


def room(case, sir_db: float, rooms: str, with_talker: bool = True):
    """(audio, directions, she_talks) of one room, cached on disk (the simulation is deterministic).
    ``sir_db`` = inf: the talker alone (the machine silent); ``with_talker=False``: the machine alone."""
    CACHE.mkdir(exist_ok=True)
    f = CACHE / f"{rooms}_{'_'.join(map(str, case))}_{sir_db:g}{'' if with_talker else '_machine'}.npz"
    if not f.exists():
        kw = dict(split="dev", robot_xy=DEV_ROBOT_XY, seed=DEV_SEED) if rooms == "dev" else {}
        x, dirs, talks = room_case(*case, SECONDS, 0.0 if np.isinf(sir_db) else sir_db, with_talker=with_talker,
                                   with_machine=not np.isinf(sir_db), **kw)
        np.savez(f, x=x, dirs=np.array(dirs), talks=np.array(talks))
    d = np.load(f)
    return d["x"], list(d["dirs"]), [bool(t) for t in d["talks"]]


def chain_config(**overrides) -> LocalizerConfig:
    """The chain's localizer (tests/test_hearing.py) with ``overrides``."""
    base = LocalizerConfig(noise_suppression=True, n_sources=2, interference_rescan=True,
                           min_significance=TRACKING_MIN_SIGNIFICANCE)
    return replace(base, **overrides)


def _deg(u, v) -> float:
    return float(np.rad2deg(angular_distance(u, v)))


def run(case, sir_db, rooms, cfg: LocalizerConfig, hear: bool, with_talker: bool = True, hearing_config=None):
    """Per-window localizer figures and, if ``hear``, per-second chain evidence (``Hearing`` with
    ``hearing_config``, default ``HearingConfig()``)."""
    from robot.hearing import Hearing, HearingConfig, classify, VoiceClass
    x, (u_her, u_m), talks = room(case, sir_db, rooms, with_talker)
    loc, tracker, tracks = Localizer("cube8", cfg), Tracker(), []
    hearing = Hearing(loc.geometry.positions, config=hearing_config or HearingConfig()) if hear else None
    her_det, m_det, ghost, off_her, off_m, per_s = [], [], [], [], [], []
    ghost_track, ghost_track_her = [], []
    scan_log = []   # the hearing's voice-scan detections: (time, direction)
    for k in range(SECONDS * 10):
        block = x[:, k * BLOCK:(k + 1) * BLOCK]
        for r in loc.process(block):
            voiced = hearing.voice_detections() if hear else []
            scan_log += [(r.time, d.direction) for d in voiced]
            tracks = tracker.update([*r.detections, *voiced], r.time)
            sec = int(r.time)
            if sec >= SETTLE_S and sec < SECONDS:
                d_her = [_deg(d.direction, u_her) for d in r.detections]
                d_m = [_deg(d.direction, u_m) for d in r.detections]
                if talks[sec]:
                    her_det.append(any(a <= 10 for a in d_her))
                m_det.append(any(b <= 10 for b in d_m))
                off_her.append(any(a > 20 for a in d_her))
                off_m.append(any(b > 20 for b in d_m))
                ghost.append(any(a > 20 and b > 20 for a, b in zip(d_her, d_m)))
        if (k + 1) % 10 == 0 and (k + 1) // 10 > SETTLE_S:
            ghost_track.append(any(_deg(t.direction, u_her) > 20 and _deg(t.direction, u_m) > 20 for t in tracks))
            ghost_track_her.append(any(_deg(t.direction, u_her) > 20 for t in tracks))
        if hear:
            ev = hearing.update(block, tracks, (k + 1) / 10)
            if (k + 1) % 10 == 0:
                per_s.append(ev)
    out = dict(her_det=her_det, m_det=m_det, ghost=ghost, off_her=off_her, off_m=off_m, ghost_track=ghost_track,
               ghost_track_her=ghost_track_her)
    if hear:
        scored = list(zip(per_s, talks))[SETTLE_S:]

        def nearest(ev, u):
            d = [_deg(e.direction, u) for e in ev]
            i = int(np.argmin(d)) if d else -1
            return ev[i] if d and d[i] <= 20 else None
        her = [nearest(ev, u_her) for ev, t in scored if t]
        mach = [nearest(ev, u_m) for ev, _ in scored]
        out["voice"] = [e is not None and classify(e) is VoiceClass.VOICE for e in her]
        her_late = [nearest(ev, u_her) for ev, t in scored[LATE_S - SETTLE_S:] if t]
        out["voice_late"] = [e is not None and classify(e) is VoiceClass.VOICE for e in her_late]
        out["nonvoice"] = [e is not None and classify(e) is VoiceClass.NON_VOICE for e in mach]
        out["m_track"] = [e is not None for e in mach]
        out["her_track"] = [e is not None for e in her]
        out["near"] = [any(classify(e) is VoiceClass.VOICE and _deg(e.direction, u_her) <= 10 for e in ev)
                       for ev, t in scored if t]
        scan = [(int(t), _deg(u, u_her)) for t, u in scan_log if SETTLE_S <= t < SECONDS]
        out["scan_her"] = [any(s == sec and d <= 10 for s, d in scan)
                           for sec in range(SETTLE_S, SECONDS) if talks[sec]]
        out["scan_off"] = [d > 20 for _, d in scan]
        # false alarms: scored seconds with a VOICE track more than 20 deg from her (with the machine alone:
        # any VOICE track, she is silent)
        out["voice_off"] = [any(classify(e) is VoiceClass.VOICE and (_deg(e.direction, u_her) > 20 or not with_talker)
                                for e in ev) for ev, _ in scored]
    return out


def _row(name: str, r: dict) -> str:
    def pct(k):
        return f"{100 * np.mean(r[k]):.0f}" if len(r[k]) else "-"
    return (f"| {name} | {pct('det6')} / {pct('det0')} | {pct('mdet6')} | {pct('ghost6')} / {pct('ghost0')} | "
            f"{pct('htrack')} | {pct('voice')} | {pct('mtrack')} | {pct('nonvoice')} | {pct('near')} | "
            f"{pct('scan6')} / {pct('scan0')} | {pct('scanoff6')} | {len(r['scanalone'])} | {pct('voicelate')} | "
            f"{pct('voiceoff6')} / {pct('voicealone')} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rooms", choices=("dev", "test"), default="dev")
    ap.add_argument("--quick", action="store_true", help="localizer columns only (no VAD)")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="LocalizerConfig override (Python literal), repeatable")
    ap.add_argument("--hear", action="append", default=[], metavar="FIELD=VALUE",
                    help="HearingConfig override (Python literal), repeatable")
    args = ap.parse_args()
    import ast
    from robot.hearing import HearingConfig
    over = {k: ast.literal_eval(v) for k, v in (s.split("=", 1) for s in args.set)}
    hear_over = {k: ast.literal_eval(v) for k, v in (s.split("=", 1) for s in args.hear)}
    cfg, hcfg = chain_config(**over), HearingConfig(**hear_over)
    cases = DEV_ROOM_CASES if args.rooms == "dev" else ROOM_CASES
    pooled: dict[str, list] = {}
    print(f"rooms={args.rooms} overrides={over} hearing={hear_over}")
    print("| room | her det -6 / 0 dB | machine det -6 | ghost -6 / 0 dB | her track -6 | her VOICE -6 | "
          "machine track -6 | machine NON_VOICE -6 | VOICE within 10 deg, 0 dB | voice scan on her -6 / 0 dB | "
          "scan detections off her -6 | scan detections, machine alone | her VOICE -6, from 6 s | "
          "VOICE track > 20 deg from her -6 / machine alone |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for case in cases:
        a = run(case, -6.0, args.rooms, cfg, not args.quick, hearing_config=hcfg)
        b = run(case, 0.0, args.rooms, cfg, not args.quick, hearing_config=hcfg)
        c = run(case, -6.0, args.rooms, cfg, not args.quick, with_talker=False, hearing_config=hcfg)
        row = {"det6": a["her_det"], "det0": b["her_det"], "mdet6": a["m_det"], "ghost6": a["ghost"],
               "ghost0": b["ghost"], "htrack": a.get("her_track", []), "voice": a.get("voice", []),
               "mtrack": a.get("m_track", []), "nonvoice": a.get("nonvoice", []), "near": b.get("near", []),
               "scan6": a.get("scan_her", []), "scan0": b.get("scan_her", []), "scanoff6": a.get("scan_off", []),
               "scanalone": c.get("scan_off", []), "voicelate": a.get("voice_late", []),
               "voiceoff6": a.get("voice_off", []), "voicealone": c.get("voice_off", [])}
        for k, v in row.items():
            pooled.setdefault(k, []).extend(v)
        print(_row(str(case), row), flush=True)
    print(_row("pooled", pooled))
    print(json.dumps({"bench": "talker_rooms", "rooms": args.rooms, "overrides": over, "hearing": hear_over,
                      **{k: round(float(np.mean(v)), 3) if v else None for k, v in pooled.items() if k != "scanalone"},
                      "scan_detections_machine_alone": len(pooled["scanalone"])}))
    figures = {f"{k}_share": round(float(np.mean(v)), 3) for k, v in pooled.items() if k != "scanalone" and v}
    figures["scan_detections_machine_alone"] = len(pooled["scanalone"])
    suffix = "" if not (over or hear_over or args.quick) else "_variant"
    write_result(f"talker_rooms_{args.rooms}{suffix}", figures)


if __name__ == "__main__":
    main()
