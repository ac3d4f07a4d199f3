"""Where victims are lost: the furthest link of the rescue chain each victim reached, over train-split runs.

For every victim of every run the chain is followed until its first broken link (a found victim is found,
whatever the links say):

1. ``silent``: never sounding above the ambient noise at the array: her direct level at the array (level at 1 m,
   spherical spreading to the listening pose, the covering's broadband loss ``15 * buried`` dB) never exceeds
   the diffuse noise level during a listen in which she was calling;
2. ``undetected``: sounding, but no listen's detection matched to her (the runner matches each detection to the
   nearest calling source) lies within ``NEAR_DEG`` of her true azimuth (the map is built from horizontal
   bearings; the cube's elevation is the worse coordinate, floor reflections); the cause says whether her direct
   level stayed below the sounding interferers' (power sum of their direct levels) at every listen;
3. ``unmapped``: detected, but no sound-map source ever lay within ``MAP_NEAR_M`` of her (horizontal);
4. ``not_targeted``: mapped, but no ``target`` decision chose a source of hers (classified interferer, low
   P(victim), rejected, or only never chosen);
5. ``not_approached``: targeted, but the base never came within 1.5 m of her (recoveries while pursuing her,
   time up while pursuing her, or pursuit abandoned);
6. ``not_declared``: approached within 1.5 m but never declared (no declaration of hers);
7. ``declared_off``: declared (a report nearest her within ``DECLARED_NEAR_M``, or a declared map source of
   hers) but the report lay more than 0.5 m from her or the base more than 1.5 m away;
8. ``found``.

Per run also: the false finds and their cause (a re-declared found victim, a machine, a report near an unfound
victim but too far off, a mirror image outside the room, a ghost inside it), robot time per activity (listening,
driving toward a target, exploring, recovering) and the end reason.

Evidence read from each ``results.json`` (``ssl_sim.runner``): ``listens`` (detections matched to the true
source directions, the true pose, the true distance and calling activity of every source), ``declarations``
(judged), ``events``, ``config.noise``. Runs made by this tool add the typed events (``event_log``), the sound
map after every listen (``map_log``), the true sources with their levels (``sources_truth``), the room size and
each victim's closest approach over the whole true trajectory (``victim_closest_m``; otherwise only the listening
poses and declarations count). Without ``map_log`` a source of hers is one the events place within
``MAP_NEAR_M`` of her (targets, rejections, declarations), which misses sources never targeted.

Run (train split only; the test split is refused):

    nice -n 10 python tools/failure_breakdown.py --count 16 --out /tmp/runs --json /tmp/breakdown.json
    python tools/failure_breakdown.py --runs /tmp/runs --json /tmp/breakdown.json   # re-classify, no simulation
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import math
import multiprocessing as mp
import os
import re
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from ssl_sim.scoring import FIND_BASE_RADIUS_M, FIND_REPORT_RADIUS_M
from ssl_sim.stats import LEVEL, N_BOOT, Interval

NEAR_DEG = 10.0          # a detection this close to her true azimuth heard her (2 bearing sigmas of the map)
MAP_NEAR_M = 1.0         # a map source this close to her (horizontal) is hers
DECLARED_NEAR_M = 1.5    # a report nearest her and this close names her (beyond: a false find elsewhere)
COVER_LOSS_DB = 15.0     # broadband loss of a fully covered source (ssl_sim.acoustics.sources.SoundSource)
MACHINE_NEAR_M = 1.0     # a false report this close to an interferer is the machine

STAGES = ("silent", "undetected", "unmapped", "not_targeted", "not_approached", "not_declared", "declared_off",
          "found")
STAGE_TEXT = {"silent": "never above the noise at the array", "undetected": "sounding, never detected within 10 deg",
              "unmapped": "detected, never a map source within 1 m", "not_targeted": "mapped, never targeted",
              "not_approached": "targeted, never approached within 1.5 m",
              "not_declared": "approached within 1.5 m, never declared",
              "declared_off": "declared, report > 0.5 m off or base > 1.5 m", "found": "found"}
LINKS = ("sounding", "detected", "mapped", "targeted", "approached", "declared")
ACTIVITIES = ("listening", "driving", "exploring", "recovering", "other")
_TARGET = re.compile(r"#(\d+) at \(([-\d.]+), ([-\d.]+)\) m")
_SOURCE = re.compile(r"source #(\d+)")
_POS = re.compile(r"at \(([-\d.]+), ([-\d.]+)\)")
_EVENT = re.compile(r"^\[\s*([-\d.]+) s\]\s+(\S+)\s+(\S+)\s+(.*)$")


def _map_row(s) -> dict[str, Any]:
    """One sound-map source (``robot.sound_map.MapSource``) as a JSON row (m, world frame)."""
    return {"id": int(s.id), "x": round(float(s.position[0]), 3), "y": round(float(s.position[1]), 3),
            "z": round(float(s.position[2]), 3), "sigma_m": round(float(s.horizontal_sigma_m), 3),
            "p_victim": round(float(s.victim_probability), 3), "cls": str(s.cls.value),
            "state": str(s.state.value), "n_listens": int(s.n_listens)}


def _jsonable(v):
    """An event's data as JSON values (typed payloads as their dicts, numpy to lists and numbers, enums and the
    rest as text)."""
    if hasattr(v, "to_dict"):
        return _jsonable(v.to_dict())
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, float):
        return round(v, 4) if math.isfinite(v) else None
    if isinstance(v, (int, str, bool)) or v is None:
        return v
    return str(v)


def run_one(index: int, out_dir: str, time_limit_s: float | None = None, oracle: str = "") -> str:
    """Run train scenario ``index`` to its time limit; write ``out_dir/train_NNN/results.json`` with the run's
    typed events (``event_log``) and the sound map after every listen (``map_log``) added. ``oracle``: an ablation
    of the robot's hearing by name (``ssl_sim.runner.ORACLES``)."""
    os.nice(10)
    from ssl_sim import suite
    from ssl_sim.runner import ORACLES, RescueRun, write_results
    sc = suite.generate("train", index)
    if time_limit_s is not None:
        sc = sc.with_overrides(time_limit_s=time_limit_s)

    class _Run(RescueRun):
        """The runner, also recording typed events and the sound map after every listen."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.event_log: list[dict] = []
            self.map_log: list[dict] = []

        def _handle_events(self, events):
            super()._handle_events(events)
            for ev in events:
                self.event_log.append({"time_s": round(ev.time, 3), "state": ev.state.value,
                                       "decision": ev.decision.value, "reason": ev.reason,
                                       "data": _jsonable(ev.data)})
            if any(ev.decision.value in ("heard", "no_source") for ev in events):
                self.map_log.append({"time_s": round(self.robot.time, 3),
                                     "sources": [_map_row(s) for s in self.behaviour.map.sources]})

        def _results(self, end_reason, loop_s):
            res = super()._results(end_reason, loop_s)
            res["event_log"], res["map_log"] = self.event_log, self.map_log
            res["suite"] = {"split": "train", "index": index, "family": suite.family_of(sc.name)}
            res["room_size"] = [float(v) for v in self.world.room.size[:2]]
            # closest true approach of the base to each victim over the whole trajectory (between listens too)
            traj = np.array([row[1:3] for row in self.trajectory])
            res["victim_closest_m"] = [round(float(np.min(np.hypot(*(traj - np.asarray(s.position[:2])).T))), 3)
                                       for s in self.sources[: self.n_victims]]
            res["sources_truth"] = [{"name": s.name, "kind": s.kind, "position": [float(v) for v in s.position],
                                     "level_db_spl": float(s.level_db_spl), "buried": float(s.buried)}
                                    for s in self.sources]
            return res

    run = _Run(sc, **ORACLES[oracle]) if oracle else _Run(sc)
    try:
        res = run.run()
    except Exception as exc:   # the simulator refused a state (a microphone driven inside an obstacle): keep
        # the run up to there, classified like any other, with its end reason saying why it stopped
        res = run._results("simulator_error", 0.0)
        res["failure"] = {"part": "simulator", "error": f"{type(exc).__name__}: {exc}"}
    out = Path(out_dir) / sc.name
    write_results(res, out)
    return str(out / "results.json")


def run_many(indices: list[int], out_dir: str, workers: int = 2, oracle: str = "") -> list[str]:
    """Run train scenarios ``indices`` in a pool of ``workers`` processes (each at nice 10); their results paths."""
    ctx = mp.get_context("spawn")
    paths = []
    with cf.ProcessPoolExecutor(workers, mp_context=ctx) as ex:
        futs = {ex.submit(run_one, i, out_dir, None, oracle): i for i in indices}
        for f in cf.as_completed(futs):
            paths.append(f.result())
            print(f"done train {futs[f]}: {paths[-1]}", flush=True)
    return paths




# ----------------------------------------------------------------------------- reading a run
def _events(run: dict) -> list[dict]:
    """The run's events as {time_s, state, decision, reason, data}: typed when recorded, else parsed from text."""
    if run.get("event_log"):
        return run["event_log"]
    out = []
    for e in run.get("events", []):
        m = _EVENT.match(e)
        if m is None:
            continue
        t, state, decision, reason = float(m.group(1)), m.group(2), m.group(3), m.group(4)
        data: dict[str, Any] = {}
        if decision == "target" and (mt := _TARGET.search(reason)):
            data = {"source": int(mt.group(1)), "position": [float(mt.group(2)), float(mt.group(3))]}
        elif decision in ("rejected", "victim_found") and (ms := _SOURCE.search(reason)):
            data = {"source": int(ms.group(1))}
            if (mp_ := _POS.search(reason)) is not None:
                data["position"] = [float(mp_.group(1)), float(mp_.group(2))]
        out.append({"time_s": t, "state": state, "decision": decision, "reason": reason, "data": data})
    return out


def _truth_sources(run: dict) -> list[dict]:
    """True sources with position, level and covering; from ``sources_truth`` or the victims (no interferers)."""
    if run.get("sources_truth"):
        return run["sources_truth"]
    return [{"name": v["name"], "kind": "victim", "position": v["position"], "level_db_spl": v["level_db_spl"],
             "buried": v.get("buried", 0.0)} for v in run["victims"]]


def _hdist(a, b) -> float:
    return float(math.hypot(a[0] - b[0], a[1] - b[1]))


def direct_snr_db(level_1m_db: float, buried: float, distance_m: float, noise_db: float) -> float:
    """Her direct-path level at the array over the diffuse noise (dB): spherical spreading from 1 m and the
    covering's broadband loss; distances below 0.1 m are clipped (the array is never inside a source)."""
    return level_1m_db - 20.0 * math.log10(max(distance_m, 0.1)) - COVER_LOSS_DB * buried - noise_db


def _direct_sir_db(run: dict, name: str) -> list[float]:
    """Per listen in which she called and an interferer sounded: her direct level at the array over the power sum
    of the sounding interferers' direct levels (dB; same spreading and covering model). Empty without the
    interferers' levels (``sources_truth``)."""
    truth = {s["name"]: s for s in run.get("sources_truth", [])}
    if name not in truth:
        return []
    out = []
    for rec in run.get("listens", []):
        by = {s["name"]: s for s in rec["sources"]}
        me = by.get(name)
        if me is None or not me.get("active"):
            continue
        others = [direct_snr_db(truth[n]["level_db_spl"], truth[n]["buried"], s["distance_m"], 0.0)
                  for n, s in by.items() if n in truth and truth[n]["kind"] != "victim" and s.get("active")]
        if others:
            mine = direct_snr_db(truth[name]["level_db_spl"], truth[name]["buried"], me["distance_m"], 0.0)
            out.append(mine - 10.0 * math.log10(sum(10 ** (o / 10.0) for o in others)))
    return out


def _noise_db(run: dict) -> float:
    noise = (run.get("config") or {}).get("noise")
    return -math.inf if not noise else float(noise["level_db_spl"])


def _her_sources(run: dict, events: list[dict], xy) -> tuple[set[int], list[dict]]:
    """Map source ids that lay within MAP_NEAR_M of ``xy`` and those map rows (from ``map_log``, else the events)."""
    ids, rows = set(), []
    if run.get("map_log"):
        for snap in run["map_log"]:
            for s in snap["sources"]:
                if _hdist((s["x"], s["y"]), xy) <= MAP_NEAR_M:
                    ids.add(s["id"])
                    rows.append({**s, "time_s": snap["time_s"]})
        return ids, rows
    for e in events:
        pos = e["data"].get("position")
        if e["decision"] in ("target", "rejected", "victim_found") and pos is not None and "source" in e["data"] \
                and _hdist(pos, xy) <= MAP_NEAR_M:
            ids.add(int(e["data"]["source"]))
            rows.append({"id": int(e["data"]["source"]), "x": pos[0], "y": pos[1], "time_s": e["time_s"],
                         "p_victim": e["data"].get("victim_probability"), "cls": None})
    return ids, rows


def _base_positions(run: dict) -> list[tuple[float, list[float]]]:
    """True base positions known at times: every listen's pose and every declaration's base."""
    pts = [(rec["time_s"], rec["pose"][:2]) for rec in run.get("listens", [])]
    pts += [(d["time_s"], d["robot_position"]) for d in run.get("declarations", [])]
    return sorted(pts, key=lambda p: p[0])


def _reason_key(reason: str) -> str:
    """An event's reason without its numbers and source ids: what the behaviour said, to count."""
    key = re.sub(r"^source #\d+: ", "", reason)      # a rejection: what follows is why
    key = re.sub(r"#\d+", "#", key)
    key = re.sub(r"[-+]?\d+(\.\d+)?", "N", key)
    return key.split(":")[0][:90]


def classify_victim(run: dict, k: int, events: list[dict] | None = None) -> dict[str, Any]:
    """The furthest link victim ``k`` of ``run`` reached (``stage``, one of STAGES) with the evidence of each link."""
    events = _events(run) if events is None else events
    v = run["victims"][k]
    name, xy = v["name"], v["position"][:2]
    noise = _noise_db(run)
    out: dict[str, Any] = {"name": name, "scenario": run["scenario"]}
    # 1. sounding above the noise at the array in a listen while calling
    snrs = [direct_snr_db(v["level_db_spl"], v.get("buried", 0.0), s["distance_m"], noise)
            for rec in run.get("listens", []) for s in rec["sources"] if s["name"] == name and s.get("active")]
    out["best_direct_snr_db"] = round(max(snrs), 1) if snrs else None
    sirs = _direct_sir_db(run, name)
    out["best_direct_sir_db"] = round(max(sirs), 1) if sirs else None
    out["listens_calling"] = len(snrs)
    # the steepest true bearing down to her from any listening pose (array frame): what an elevation cue can see
    els = [s["elevation_deg"] for rec in run.get("listens", []) for s in rec["sources"]
           if s["name"] == name and s.get("elevation_deg") is not None]
    out["steepest_true_deg"] = round(-min(els), 1) if els else None
    sounding = bool(snrs) and max(snrs) > 0.0
    # 2. detected within NEAR_DEG
    errs = [abs(d["azimuth_error_deg"]) for rec in run.get("listens", []) for d in rec["detections"]
            if d.get("source") == name and d.get("azimuth_error_deg") is not None]
    hits = [e for e in errs if e <= NEAR_DEG]
    out["detections_near"] = len(hits)
    out["best_error_deg"] = round(min(errs), 1) if errs else None
    detected = bool(hits)
    if sounding and not detected:
        out["undetected_cause"] = ("no interferer calling" if not sirs else "below an interferer at every listen"
                                   if max(sirs) < 0.0 else "above every interferer at some listen")
    # 3. a map source of hers
    ids, rows = _her_sources(run, events, xy)
    out["map_sources"] = sorted(ids)
    ps = [r["p_victim"] for r in rows if r.get("p_victim") is not None]
    out["max_p_victim"] = round(max(ps), 3) if ps else None
    classes = Counter(r["cls"] for r in rows if r.get("cls"))
    out["map_classes"] = dict(classes)
    map_err = [_hdist((r["x"], r["y"]), xy) for r in rows]
    out["best_map_error_m"] = round(min(map_err), 2) if map_err else None
    mapped = bool(ids)
    # 4. targeted
    targets = [e for e in events if e["decision"] == "target"
               and (int(e["data"].get("source", -1)) in ids
                    or (e["data"].get("position") is not None and _hdist(e["data"]["position"], xy) <= MAP_NEAR_M))]
    out["targets"] = len(targets)
    targeted = bool(targets)
    if mapped and not targeted:
        rejected = any(e["decision"] == "rejected" and int(e["data"].get("source", -1)) in ids for e in events)
        out["not_targeted_cause"] = ("rejected" if rejected else "classified victim, never chosen"
                                     if classes.get("victim") else "classified interferer"
                                     if classes.get("interferer") else "unclassified, never chosen")
    # 5. approached within 1.5 m
    bases = _base_positions(run)
    dists = [_hdist(p, xy) for _, p in bases]
    if run.get("victim_closest_m"):         # the whole true trajectory, when the run recorded it
        dists.append(float(run["victim_closest_m"][k]))
    out["closest_base_m"] = round(min(dists), 2) if dists else None
    approached = bool(dists) and min(dists) <= FIND_BASE_RADIUS_M
    if targeted and not approached:
        first = targets[0]["time_s"]
        last_target = [e for e in events if e["decision"] == "target"][-1]
        later = [e for e in events if e["time_s"] >= first]
        recovers = sum(1 for e in later if e["decision"] in ("recover", "obstacle"))
        out["recoveries_after_first_target"] = recovers
        out["not_approached_cause"] = ("time up while pursuing her" if last_target in targets
                                       and run.get("end_reason") == "time_up" else "pursuit abandoned")
    # 6./7. declared
    decl = [d for d in run.get("declarations", []) if d.get("victim") == name and d.get("estimate_error_m") is not None
            and d["estimate_error_m"] <= DECLARED_NEAR_M]
    decl_ids = {int(e["data"]["source"]) for e in events if e["decision"] == "victim_found" and "source" in e["data"]}
    declared = bool(decl) or bool(decl_ids & ids)
    out["declarations"] = [{"kind": d["kind"], "estimate_error_m": d["estimate_error_m"],
                            "robot_distance_m": d["robot_distance_m"], "criterion": d.get("criterion")}
                           for d in decl]
    if approached and not declared:
        near = [(t, p) for t, p in bases if _hdist(p, xy) <= FIND_BASE_RADIUS_M]
        # None: only the trajectory between listens came that close (``victim_closest_m``)
        out["time_first_within_1_5_m_s"] = near[0][0] if near else None
        near_recs = [rec for rec in run.get("listens", []) if _hdist(rec["pose"][:2], xy) <= FIND_BASE_RADIUS_M]
        calling = [rec for rec in near_recs if any(s["name"] == name and s.get("active") for s in rec["sources"])]
        heard = [rec for rec in calling if any(d.get("source") == name and d.get("azimuth_error_deg") is not None
                                               and abs(d["azimuth_error_deg"]) <= NEAR_DEG for d in rec["detections"])]
        out["listens_within_1_5_m"] = len(near_recs)
        out["near_listens_calling"] = len(calling)
        out["near_listens_calling_heard"] = len(heard)
        said = Counter(_reason_key(e["reason"]) for e in events if e["decision"] in ("no_target", "rejected")
                       and int(e["data"].get("source", -1)) in ids)
        out["her_source_events"] = dict(said)
        close = out["best_map_error_m"] is not None and out["best_map_error_m"] <= FIND_REPORT_RADIUS_M
        out["not_declared_cause"] = ("never classified victim" if not classes.get("victim")
                                     else "map estimate never within 0.5 m" if not close
                                     else "classified victim, estimate within 0.5 m, no find criterion met")
    if declared and not v["found"]:
        off = [d for d in decl if d["estimate_error_m"] > FIND_REPORT_RADIUS_M]
        far = [d for d in decl if d["robot_distance_m"] is not None and d["robot_distance_m"] > FIND_BASE_RADIUS_M]
        out["declared_off_cause"] = ("report off and base too far" if off and far else "report off" if off
                                     else "base too far" if far else "declared source of hers, report elsewhere")
    flags = {"sounding": sounding, "detected": detected, "mapped": mapped, "targeted": targeted,
             "approached": approached, "declared": declared}
    out["links"] = flags
    if v["found"]:
        out["stage"] = "found"
    else:
        chain = list(flags.values())
        out["stage"] = STAGES[chain.index(False)] if False in chain else "declared_off"
    return out


def false_find_causes(run: dict) -> list[dict[str, Any]]:
    """Each false find with its cause: ``re-declared found victim``, ``machine``, ``victim, report off``,
    ``mirror outside the room`` or ``ghost inside the room`` (echo, rays of two sources crossing)."""
    truth = _truth_sources(run)
    victims = {v["name"]: v for v in run["victims"]}
    machines = [s for s in truth if s["kind"] != "victim"]
    room = run.get("room_size")
    found_at: dict[str, float] = {d["victim"]: d["time_s"] for d in run.get("declarations", [])
                                  if d["kind"] == "find"}
    out = []
    for d in run.get("declarations", []):
        if d["kind"] != "false_find":
            continue
        rep = d["estimate"]
        dv = {n: _hdist(rep, v["position"]) for n, v in victims.items()}
        refound = [n for n, dd in dv.items() if dd <= MAP_NEAR_M and found_at.get(n, math.inf) < d["time_s"]]
        dm = [_hdist(rep, s["position"]) for s in machines]
        if refound:
            cause = "re-declared found victim"
        elif dm and min(dm) <= MACHINE_NEAR_M:
            cause = "machine"
        elif dv and min(dv.values()) <= DECLARED_NEAR_M:
            cause = "victim, report off"
        elif room is not None and not (0.0 <= rep[0] <= room[0] and 0.0 <= rep[1] <= room[1]):
            cause = "mirror outside the room"
        else:
            cause = "ghost inside the room"
        out.append({"time_s": d["time_s"], "estimate": rep, "cause": cause,
                    "nearest_victim_m": round(min(dv.values()), 2) if dv else None,
                    "nearest_machine_m": round(min(dm), 2) if dm else None})
    return out


_MOTION = {"drive": "driving", "target": "driving", "explore": "exploring", "recover": "recovering",
           "obstacle": "recovering"}


def time_split(run: dict, events: list[dict] | None = None) -> dict[str, float]:
    """Robot seconds per activity: each listen (settle + listen, ending at its ``heard``/``no_source`` event) is
    listening; the time between listens goes to the last motion decision before it (drive/target: driving,
    explore, recover/obstacle: recovering; none since the last listen: other, e.g. turning, declaring)."""
    events = _events(run) if events is None else events
    beh = (run.get("config") or {}).get("behaviour") or {}
    listen_s = float(beh.get("listen_s", 1.0)) + float(beh.get("settle_s", 0.3))
    out = dict.fromkeys(ACTIVITIES, 0.0)
    t_prev, current = 0.0, "other"
    for e in events:
        t = e["time_s"]
        if e["decision"] in ("heard", "no_source"):
            listen = min(listen_s, max(t - t_prev, 0.0))
            out["listening"] += listen
            out[current] += max(t - t_prev - listen, 0.0)
            t_prev, current = t, "other"
        elif e["decision"] in _MOTION:
            out[current] += max(t - t_prev, 0.0)
            t_prev, current = t, _MOTION[e["decision"]]
    end = float(run.get("sim_time_s") or t_prev)
    out[current] += max(end - t_prev, 0.0)
    return {k: round(v, 2) for k, v in out.items()}


def _family(run: dict) -> str:
    if run.get("suite"):
        return run["suite"]["family"]
    from ssl_sim.suite import family_of
    try:
        return family_of(run["scenario"])
    except (ValueError, KeyError):
        return run["scenario"]


def classify_run(run: dict) -> dict[str, Any]:
    """Every victim's stage, the false finds with causes, time per activity and the end reason of one run."""
    name = str(run.get("scenario", ""))
    if name.startswith("test_") or (run.get("suite") or {}).get("split") == "test":
        raise ValueError(f"scenario: {name!r} is a test-split scenario; the breakdown reads train runs only")
    events = _events(run)
    return {"scenario": name, "family": _family(run), "n_victims": run["n_victims"], "n_found": run["n_found"],
            "end_reason": run.get("end_reason"), "sim_time_s": run.get("sim_time_s"), "failure": run.get("failure"),
            "victims": [classify_victim(run, k, events) for k in range(len(run["victims"]))],
            "false_finds": false_find_causes(run), "time_s": time_split(run, events)}


# ----------------------------------------------------------------------------- tables
def share_interval(counts: np.ndarray, totals: np.ndarray, seed: int = 0) -> Interval:
    """Share sum(counts) / sum(totals) with its percentile bootstrap interval over runs (victims of one run
    share the scene, so runs, not victims, are resampled; ``ssl_sim.stats`` resamples independent values)."""
    counts, totals = np.asarray(counts, float), np.asarray(totals, float)
    if not totals.sum():
        return Interval(math.nan, math.nan, math.nan, 0)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(totals), size=(N_BOOT, len(totals)))
    tot = totals[idx].sum(axis=1)
    shares = counts[idx].sum(axis=1) / np.where(tot > 0, tot, np.nan)
    a = (1 - LEVEL) / 2
    lo, hi = np.nanquantile(shares, [a, 1 - a])
    return Interval(float(counts.sum() / totals.sum()), float(lo), float(hi), len(totals))


def summarize_runs(rows: list[dict]) -> dict[str, Any]:
    """Stage table (count, share, interval), per family, false-find causes, time split and end reasons."""
    totals = np.array([r["n_victims"] for r in rows])
    stages = []
    for st in STAGES:
        c = np.array([sum(v["stage"] == st for v in r["victims"]) for r in rows])
        iv = share_interval(c, totals)
        stages.append({"stage": st, "what": STAGE_TEXT[st], "count": int(c.sum()), **iv.as_dict("share")})
    links = {}
    for link in LINKS:
        c = np.array([sum(bool(v["links"][link]) for v in r["victims"]) for r in rows])
        links[link] = {"count": int(c.sum()), **share_interval(c, totals).as_dict("share")}
    fams: dict[str, Counter] = defaultdict(Counter)
    for r in rows:
        fams[r["family"]]["victims"] += r["n_victims"]
        fams[r["family"]]["runs"] += 1
        for v in r["victims"]:
            fams[r["family"]][v["stage"]] += 1
    causes = Counter(f["cause"] for r in rows for f in r["false_finds"])
    sub = defaultdict(Counter)
    for r in rows:
        for v in r["victims"]:
            key = f"{v['stage']}_cause"
            if key in v:
                sub[v["stage"]][v[key]] += 1
    said, near = Counter(), Counter()
    for r in rows:
        for v in r["victims"]:
            if v["stage"] == "not_declared":
                said.update(v.get("her_source_events", {}))
                steep = v.get("steepest_true_deg")
                near.update({"victims": 1, "steepest_below_20_deg": int(steep is not None and steep < 20.0),
                             "steepest_below_30_deg": int(steep is not None and steep < 30.0)})
                near.update({"listens": v["listens_within_1_5_m"], "calling": v["near_listens_calling"],
                             "calling_heard": v["near_listens_calling_heard"]})
    time_tot = {a: float(sum(r["time_s"][a] for r in rows)) for a in ACTIVITIES}
    all_t = sum(time_tot.values()) or 1.0
    return {"n_runs": len(rows), "n_victims": int(totals.sum()), "stages": stages, "links": links,
            "families": {f: dict(c) for f, c in sorted(fams.items())},
            "stage_causes": {k: dict(c) for k, c in sub.items()},
            "not_declared_events": dict(said.most_common()),
            "not_declared_near_listens": dict(near),
            "false_finds": {"total": int(sum(causes.values())), "per_run": round(sum(causes.values()) / len(rows), 3),
                            "causes": dict(causes)},
            "time_share": {a: round(t / all_t, 3) for a, t in time_tot.items()},
            "end_reasons": dict(Counter(r["end_reason"] for r in rows)),
            "failures": {r["scenario"]: r["failure"] for r in rows if r.get("failure")}}


def format_runs(rows: list[dict]) -> str:
    """One line per run: finds, false finds with causes, robot seconds per activity, end reason."""
    lines = [f"{'run':<28}{'found':>6}  {'false finds':<30}" + "".join(f"{a[:9]:>10}" for a in ACTIVITIES)
             + "  end"]
    for r in rows:
        ff = ", ".join(f["cause"] for f in r["false_finds"]) or "-"
        lines.append(f"{r['scenario']:<28}{r['n_found']:>3}/{r['n_victims']:<2}  {ff[:30]:<30}"
                     + "".join(f"{r['time_s'][a]:>10.1f}" for a in ACTIVITIES) + f"  {r['end_reason']}")
    return "\n".join(lines)


def format_tables(summary: dict) -> str:
    lines = [f"{summary['n_victims']} victims in {summary['n_runs']} runs", "",
             f"{'stage reached (first broken link)':<48} {'count':>5}  share [95 % interval, runs resampled]"]
    for s in summary["stages"]:
        iv = f"{s['share']:.2f} [{s['share_lo']:.2f}, {s['share_hi']:.2f}]" if s["share"] is not None else "-"
        lines.append(f"{s['stage'] + ': ' + s['what']:<48} {s['count']:>5}  {iv}")
    lines += ["", "each link held, whatever the links before it (count, share [95 % interval]):",
              "  " + ", ".join(f"{k} {v['count']} {v['share']:.2f} [{v['share_lo']:.2f}, {v['share_hi']:.2f}]"
                               for k, v in summary["links"].items())]
    lines += ["", "per family (victims per stage):",
              f"{'family':<18}{'runs':>5}{'vict':>5}" + "".join(f"{st[:12]:>13}" for st in STAGES)]
    for f, c in summary["families"].items():
        lines.append(f"{f:<18}{c['runs']:>5}{c['victims']:>5}" + "".join(f"{c.get(st, 0):>13}" for st in STAGES))
    lines += ["", "causes within stages: " + json.dumps(summary["stage_causes"]),
              "what the behaviour said about the sources of approached, undeclared victims: "
              + json.dumps(summary["not_declared_events"]),
              "those victims, their steepest true bearing from a listening pose, and their listens within 1.5 m "
              "(all, she calling, she calling and detected within 10 deg): "
              + json.dumps(summary["not_declared_near_listens"]),
              f"false finds: {summary['false_finds']['total']} ({summary['false_finds']['per_run']} per run) "
              + json.dumps(summary["false_finds"]["causes"]),
              "robot time share: " + ", ".join(f"{a} {t:.2f}" for a, t in summary["time_share"].items()),
              "end reasons: " + json.dumps(summary["end_reasons"])]
    lines += [f"run failed: {name}: {f}" for name, f in summary["failures"].items()]
    return "\n".join(lines)


def load_runs(directory: str | Path) -> list[dict]:
    files = sorted(Path(directory).rglob("results.json"))
    if not files:
        raise FileNotFoundError(f"--runs: no results.json below {directory}")
    return [json.loads(f.read_text()) for f in files]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", help="classify the results.json files below this directory (no simulation)")
    ap.add_argument("--count", type=int, default=16, help="train scenarios to run (indices start..start+count-1)")
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--out", default="out/failure_breakdown", help="where the runs' results.json go")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="write the per-victim classification and the tables here")
    from ssl_sim.runner import ORACLES
    ap.add_argument("--oracle", choices=tuple(ORACLES), default="",
                    help="an ablation of the robot's hearing (ssl_sim.runner.ORACLES): SRP-PHAT's detections of no "
                         "sounding source dropped, the truth's directions, and with 'hearing' also its voice evidence")
    a = ap.parse_args(argv)
    if a.runs is None:
        if a.count < 1 or a.start < 0:
            ap.error(f"--count must be >= 1 and --start >= 0, got {a.count} and {a.start}")
        run_many(list(range(a.start, a.start + a.count)), a.out, a.workers, a.oracle)
    try:
        rows = [classify_run(r) for r in load_runs(a.runs or a.out)]
    except (FileNotFoundError, ValueError) as exc:
        ap.error(str(exc))
    summary = summarize_runs(rows)
    print(format_runs(rows) + "\n")
    print(format_tables(summary))
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({"summary": summary, "runs": rows}, indent=1))
    print(json.dumps({"n_runs": summary["n_runs"], "n_victims": summary["n_victims"],
                      **{s["stage"]: s["count"] for s in summary["stages"]}}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
