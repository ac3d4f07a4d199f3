"""Detection without a fixed floor, against simulated truth (ssl_sim lab: diffuse noise, reverberation).

- No source (diffuse noise of three spectra plus the sensor's own noise): the significance test
  (ssl_core.localizer docstring) fires in at most 1 % of 128 ms windows.
- A voice beside a steady pump of equal level (0 dB SIR at 1 m, same distance): with noise
  suppression the voice is found within 10 deg in at least 70 % of the seconds in which it talks.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from experiments.common import Lab, Truth, build_sim
from ssl_core.grid import angular_distance
from ssl_core.localizer import Localizer, LocalizerConfig
from ssl_sim.acoustics import AcousticConfig, AcousticSimulator, AmbientNoise
from ssl_sim.world import Room, World

FS = 16000
LAB = Lab()


# The interference rescan (n_sources > 1) only acts after a first detection; with it on, the no-source
# tests must hold unchanged (measured: the same 0 of 279 windows at the default gate, 2 at the tracking gate).
_RESCAN = LocalizerConfig(n_sources=2, interference_rescan=True, noise_suppression=True)


@pytest.mark.parametrize("config", [LocalizerConfig(), _RESCAN], ids=["default", "rescan"])
def test_no_source_gives_at_most_one_percent_false_windows(config):
    loc = Localizer("cube8", config)
    n_windows = n_false = 0
    for k, (spectrum, level) in enumerate((("hvac", 45.0), ("pink", 60.0), ("white", 40.0))):
        sim = AcousticSimulator(World(room=Room(LAB.room_size), name="lab"),
                                AcousticConfig(rt60_s=0.5, seed=10 + k, ambient=AmbientNoise(level, spectrum)), [])
        results = loc.process_all(sim.listen_pose(LAB.pose, 12.0, mount=LAB.mount))
        n_windows += len(results)
        n_false += sum(1 for r in results if r.detections)
    assert n_windows >= 270
    assert n_false <= 0.01 * n_windows, f"{n_false} false detections in {n_windows} windows"


@lru_cache(maxsize=None)
def _voice_beside_pump():
    """8 s: a talker at 30 deg and a pump at -60 deg, both 1.5 m away; RT60 0.5 s. The talker is 62.5 dB SPL
    at 1 m while sounding; the pump's 59.5 dB SPL puts it level with the talker's active seconds (checked)."""
    lab = Lab(duration_s=8.0)
    voice, pump = Truth(30.0, 0.0, 1.5), Truth(-60.0, 0.0, 1.5, level_db_spl=59.5)
    mix = build_sim(lab, [voice], seed=4, pump=pump, p_event=0.7).listen_pose(lab.pose, lab.duration_s, mount=lab.mount)
    alone = build_sim(lab, [voice], seed=4, p_event=0.7, ambient=False).listen_pose(lab.pose, lab.duration_s,
                                                                                   mount=lab.mount)
    pump_alone = build_sim(lab, [], seed=4, pump=pump, ambient=False).listen_pose(lab.pose, lab.duration_s,
                                                                                 mount=lab.mount)
    return mix, alone, pump_alone, voice


def _seconds_found(results, truth: Truth, active: np.ndarray) -> tuple[int, int]:
    """(active seconds in which some window has a detection within 10 deg of ``truth``, active seconds)."""
    found = np.zeros(active.size, bool)
    for r in results:
        s = min(int(r.time), active.size - 1)
        found[s] |= any(np.rad2deg(angular_distance(d.direction, truth.direction)) <= 10 for d in r.detections)
    return int(found[active].sum()), int(active.sum())


def test_voice_beside_an_equal_steady_noise_is_found_with_noise_suppression():
    mix, alone, pump_alone, voice = _voice_beside_pump()
    seconds = mix.shape[1] // FS
    v = alone[:, :seconds * FS].astype(float).reshape(8, seconds, FS)
    p = pump_alone[:, :seconds * FS].astype(float).reshape(8, seconds, FS)
    v_ms, p_ms = (v**2).mean(axis=(0, 2)), (p**2).mean(axis=(0, 2))
    active = v_ms > 0.25 * v_ms.max()  # seconds in which the talker calls (within 6 dB of its loudest)
    assert active.sum() >= 4
    # equal level: the voice's seconds are within 3 dB of the pump at the array (0 dB SIR)
    assert abs(10 * np.log10(v_ms[active].mean() / p_ms.mean())) < 1.0
    found, total = _seconds_found(Localizer("cube8", LocalizerConfig(noise_suppression=True)).process_all(mix),
                                  voice, active)
    assert found >= 0.7 * total, f"voice found in {found} of {total} active seconds"
    without = _seconds_found(Localizer("cube8", LocalizerConfig()).process_all(mix), voice, active)[0]
    print(f"voice found in {found}/{total} active seconds with noise suppression, {without} without")


def test_voice_beside_an_equal_steady_noise_is_tracked_with_noise_suppression():
    """The tracked version: at the end of at least 70 % of the talker's active seconds a confirmed track
    is within 10 deg of it (two sources per window: the pump is a real source and gets its own track)."""
    from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE, Tracker

    mix, alone, _, voice = _voice_beside_pump()
    seconds = mix.shape[1] // FS
    v_ms = (alone[:, :seconds * FS].astype(float).reshape(8, seconds, FS) ** 2).mean(axis=(0, 2))
    active = v_ms > 0.25 * v_ms.max()
    loc = Localizer("cube8", LocalizerConfig(noise_suppression=True, n_sources=2,
                                             min_significance=TRACKING_MIN_SIGNIFICANCE))
    tracker, on_voice = Tracker(), np.zeros(seconds, bool)
    for r in loc.process_all(mix):
        tracks = tracker.update(r.detections, r.time)
        on_voice[min(int(r.time), seconds - 1)] = any(
            np.rad2deg(angular_distance(t.direction, voice.direction)) <= 10 for t in tracks)
    assert on_voice[active].sum() >= 0.7 * active.sum(), (on_voice.astype(int), active.astype(int))


@pytest.mark.parametrize("config", [LocalizerConfig(), _RESCAN], ids=["default", "rescan"])
def test_no_source_gives_no_lasting_track_at_the_tracking_gate(config):
    """Diffuse noise with no source, detections at the looser gate meant for tracking: no confirmed
    track lasts over 1 s (the requirement; the tracker's confirmation is the false-alarm control)."""
    from dataclasses import replace

    from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE, Tracker

    loc = Localizer("cube8", replace(config, min_significance=TRACKING_MIN_SIGNIFICANCE))
    n_detections = 0
    for k, (spectrum, level) in enumerate((("hvac", 45.0), ("pink", 60.0), ("white", 40.0))):
        sim = AcousticSimulator(World(room=Room(LAB.room_size), name="lab"),
                                AcousticConfig(rt60_s=0.5, seed=20 + k, ambient=AmbientNoise(level, spectrum)), [])
        tracker, life = Tracker(), {}
        for r in loc.process_all(sim.listen_pose(LAB.pose, 20.0, mount=LAB.mount)):
            n_detections += len(r.detections)
            for t in tracker.update(r.detections, r.time):
                life.setdefault(t.id, [r.time, r.time])[1] = r.time
        assert all(end - start <= 1.0 for start, end in life.values()), (spectrum, life)
    assert n_detections > 0  # the looser gate does let false peaks through: the tracker is what holds


def test_the_interference_rescan_finds_a_talker_beside_a_machine_and_adds_no_ghosts():
    """Real recordings 2 m away in an RT60 0.6 s room (tests/sound_dataset.py): a talker at 30 deg beside
    a machine at -50 deg of equal level (0 dB SIR), and the machine alone; two sources per window at the
    tracking gate. With the rescan a detection within 10 deg of her comes in at least twice as many of
    her windows (measured 13 -> 79 of 109), and with the machine alone the detections more than 20 deg
    from it (its reflections) do not grow (measured 4 -> 4 of 124)."""
    from sound_dataset import room_case
    from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE

    case = ("it_carlo", "ore_mine", 30, -50)
    mix, (u_her, u_machine), talks = room_case(*case, sir_db=0.0)
    alone = room_case(*case, sir_db=0.0, with_talker=False)[0]
    her, ghosts = {}, {}
    for on in (False, True):
        loc = Localizer("cube8", LocalizerConfig(noise_suppression=True, n_sources=2, interference_rescan=on,
                                                 min_significance=TRACKING_MIN_SIGNIFICANCE))
        her[on] = sum(any(np.rad2deg(angular_distance(d.direction, u_her)) <= 10 for d in r.detections)
                      for r in loc.process_all(mix) if r.time >= 2 and talks[min(int(r.time), len(talks) - 1)])
        ghosts[on] = sum(any(np.rad2deg(angular_distance(d.direction, u_machine)) > 20 for d in r.detections)
                         for r in loc.process_all(alone))
    print("her windows without / with the rescan:", her, "machine-alone ghost windows:", ghosts)
    assert her[True] >= 2 * max(her[False], 5), her
    assert ghosts[True] <= ghosts[False], ghosts
