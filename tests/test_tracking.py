"""Source tracking against independent truth: hand-made detections from known trajectories, and the
localizer's detections of a simulated talker at a known position."""
from __future__ import annotations

import numpy as np
import pytest

from ssl_core.geometry import cube8
from ssl_core.grid import angular_distance, direction_from_angles
from ssl_core.localizer import Detection, Localizer, LocalizerConfig
from ssl_core.tracking import Tracker, TrackerConfig

WINDOW = 0.128  # s, the localizer's default window (8 frames of 16 ms)
FS = 16000


def det(az_deg: float, el_deg: float = 0.0, power: float = 0.12, level_db: float = -30.0) -> Detection:
    az, el = np.deg2rad(az_deg), np.deg2rad(el_deg)
    return Detection(az, el, direction_from_angles(az, el), power, level_db)


def noisy(rng, az_deg, el_deg, sigma_deg=2.0, power=0.12) -> Detection:
    return det(az_deg + rng.normal(0, sigma_deg) / np.cos(np.deg2rad(el_deg)), el_deg + rng.normal(0, sigma_deg), power)


def err_deg(track, az_deg, el_deg=0.0) -> float:
    truth = direction_from_angles(np.deg2rad(az_deg), np.deg2rad(el_deg))
    return float(np.rad2deg(angular_distance(track.direction, truth)))


def rz(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------------- configuration and input errors
@pytest.mark.parametrize("kwargs, field", [
    ({"p_track": 1.5}, "p_track"),
    ({"confirm_hits": 4, "confirm_windows": 3}, "confirm_windows"),
    ({"measurement_sigma": ((0.1, 2.0), (0.05, 5.0))}, "measurement_sigma"),
    ({"silence_s": 0.0}, "silence_s"),
    ({"active_power": 0.01}, "active_power"),
])
def test_config_errors_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"TrackerConfig.{field}="):
        TrackerConfig(**kwargs)


def test_bad_time_and_rotation_are_named():
    t = Tracker()
    t.update([det(10)], 1.0)
    with pytest.raises(ValueError, match="time="):
        t.update([], 0.5)
    with pytest.raises(ValueError, match="rotation"):
        t.update([], 1.2, rotation=2 * np.eye(3))
    with pytest.raises(ValueError, match=r"detections\[0\].direction"):
        t.update([Detection(0.0, 0.0, np.array([2.0, 0, 0]), 0.1, -30.0)], 1.3)


# ---------------------------------------------------------------------- lifecycle
def test_birth_after_confirm_hits_then_coast_then_death_after_silence():
    cfg = TrackerConfig()
    t = Tracker(cfg)
    outputs = [t.update([det(40.0, 10.0, level_db=-20.0 - k)], k * WINDOW) for k in range(6)]
    assert [len(o) for o in outputs[: cfg.confirm_hits - 1]] == [0] * (cfg.confirm_hits - 1)
    first = outputs[cfg.confirm_hits - 1]
    assert len(first) == 1 and first[0].id == 1 and first[0].first_time == 0.0
    last = outputs[-1][0]
    assert last.n_updates == 6 and last.last_time == 5 * WINDOW and last.level_db == -25.0
    assert err_deg(last, 40.0, 10.0) < 0.5 and abs(last.azimuth_deg - 40.0) < 0.5
    # silence: the track coasts while its activity decays, and dies after silence_s
    k, time, activities = 6, 6 * WINDOW, []
    while time - last.last_time <= cfg.silence_s:
        out = t.update([], time)
        assert [o.id for o in out] == [1]
        activities.append(out[0].activity)
        k, time = k + 1, (k + 1) * WINDOW
    assert t.update([], time) == []
    assert activities[0] < last.activity and activities[-1] < 0.2 and np.all(np.diff(activities) <= 1e-12)
    # the same source again is a new track: ids are never reused
    out = [t.update([det(40.0, 10.0)], time + j * WINDOW) for j in range(1, 4)][-1]
    assert [o.id for o in out] == [2]


def test_pauses_keep_the_track_and_history_records_levels():
    t = Tracker()
    rng = np.random.default_rng(1)
    times = np.arange(60) * WINDOW
    talking = (times % 3.0) < 1.8  # 1.8 s of speech, 1.2 s pause
    ids = set()
    for k, time in enumerate(times):
        out = t.update([noisy(rng, -75.0, 5.0)] if talking[k] else [], time)
        ids |= {o.id for o in out}
        if out and time > 1.0:  # detections err 2.8 deg RMS; a pause lets the velocity estimate drift a little
            assert err_deg(out[0], -75.0, 5.0) < 6.0
    assert ids == {1}
    h = t.history(1)
    assert np.array_equal(h.times, times[talking]) and np.all(h.power == 0.12) and np.all(h.level_db == -30.0)
    with pytest.raises(KeyError, match="track_id=7"):
        t.history(7)


def test_two_alternating_talkers_keep_two_stable_ids():
    rng = np.random.default_rng(2)
    t = Tracker()
    talkers = {0: (0.0, 10.0), 1: (100.0, -5.0)}
    owner: dict[int, int] = {}
    for k in range(int(16 / WINDOW)):
        time = k * WINDOW
        who = int(time // 1.5) % 2  # turns of 1.5 s
        dets = [noisy(rng, *talkers[who])] if rng.random() < 0.85 else []
        out = t.update(dets, time)
        for o in out:  # each id stays on one talker (a coasting track extrapolates its velocity a little)
            nearest = min(talkers, key=lambda w: err_deg(o, *talkers[w]))
            assert owner.setdefault(o.id, nearest) == nearest and err_deg(o, *talkers[nearest]) < 10.0
        if time > 3.0 and (time % 1.5) > 1.0:  # late in a turn: both tracks alive, the talking one active
            act = {owner[o.id]: o.activity for o in out}
            assert set(act) == {0, 1} and act[who] > act[1 - who] and act[1 - who] < 0.3
    assert sorted(owner) == [1, 2]


def test_two_simultaneous_talkers_40_deg_apart_never_swap():
    """Two detections per window (the localizer with n_sources=2), strongest first in random order."""
    rng = np.random.default_rng(7)
    t = Tracker()
    talkers = [(-20.0, 0.0), (20.0, 5.0)]
    owner: dict[int, int] = {}
    for k in range(int(8 / WINDOW)):
        dets = [noisy(rng, *talkers[i]) for i in rng.permutation(2) if rng.random() < 0.9]
        for o in t.update(dets, k * WINDOW):
            nearest = int(np.argmin([err_deg(o, *w) for w in talkers]))
            assert owner.setdefault(o.id, nearest) == nearest and err_deg(o, *talkers[nearest]) < 5.0
    assert sorted(owner) == [1, 2] and sorted(owner.values()) == [0, 1]


def test_talker_moving_30_deg_per_s_is_followed_within_10_deg():
    rng = np.random.default_rng(3)
    t = Tracker()
    errors, ids = [], set()
    for k in range(int(12 / WINDOW)):  # 360 deg of azimuth, through the +-180 seam
        time = k * WINDOW
        az = -150.0 + 30.0 * time
        out = t.update([noisy(rng, az, 15.0, sigma_deg=3.0, power=0.09)] if rng.random() < 0.8 else [], time)
        ids |= {o.id for o in out}
        if time >= 1.0:
            assert len(out) == 1
            errors.append(err_deg(out[0], az, 15.0))
    assert ids == {1} and max(errors) < 10.0, max(errors)
    # the decaying velocity (speed_memory_s) pulls a steady speed estimate low: measured 22 of 30 deg/s
    speed = np.rad2deg(np.linalg.norm(out[0].velocity)) / np.cos(np.deg2rad(15))
    assert 20.0 < speed < 32.0, speed


# ---------------------------------------------------------------------- the array turning in place
def _turn_run(give_rotation: bool, world_az: float = 30.0, turn_deg: float = 90.0):
    """A static source at world azimuth ``world_az``; the robot yaws by ``turn_deg`` (CCW) between
    the windows at 2.0 s and 2.128 s. Returns the outputs per window and the array-frame azimuths."""
    rng = np.random.default_rng(4)
    t = Tracker()
    outs, truth = [], []
    for k in range(int((2.5 + TrackerConfig().silence_s) / WINDOW)):
        time = k * WINDOW
        yaw = turn_deg if time > 2.0 else 0.0
        turned = give_rotation and k > 0 and (k - 1) * WINDOW <= 2.0 < time
        az = world_az - yaw  # the source seen from the turned array
        outs.append(t.update([noisy(rng, az, 0.0)], time, rotation=rz(-np.deg2rad(turn_deg)) if turned else None))
        truth.append(az)
    return outs, truth


def test_turn_in_place_with_rotation_keeps_the_id():
    outs, truth = _turn_run(give_rotation=True)
    ids = {o.id for out in outs for o in out}
    assert ids == {1}
    for out, az in zip(outs[4:], truth[4:]):  # detections err 2.8 deg RMS
        assert len(out) == 1 and err_deg(out[0], az) < 5.0


def test_continuous_turn_with_rotations_keeps_the_id():
    rng = np.random.default_rng(5)
    t = Tracker()
    rate = np.deg2rad(120.0)  # rad/s of yaw, a brisk in-place turn
    for k in range(int(4 / WINDOW)):
        yaw = rate * k * WINDOW
        out = t.update([noisy(rng, 60.0 - np.rad2deg(yaw), 20.0)], k * WINDOW,
                       rotation=rz(-rate * WINDOW) if k else None)
        if k >= 3:
            assert [o.id for o in out] == [1] and err_deg(out[0], 60.0 - np.rad2deg(yaw), 20.0) < 4.0


def test_turn_without_rotation_starts_a_new_track_and_the_old_one_does_not_jump():
    cfg = TrackerConfig()
    outs, truth = _turn_run(give_rotation=False)
    k_turn = int(2.0 / WINDOW) + 1
    for k, out in enumerate(outs[k_turn:], start=k_turn):
        by_id = {o.id: o for o in out}
        if 1 in by_id:  # the old track coasts near where the source was before the turn (no 90 deg jump), then dies
            assert err_deg(by_id[1], truth[0]) < 10.0
            assert k * WINDOW - by_id[1].last_time <= cfg.silence_s
        if k >= k_turn + cfg.confirm_windows:  # the source is tracked again under a new id
            assert 2 in by_id and err_deg(by_id[2], truth[k]) < 4.0
    assert [o.id for o in outs[-1]] == [2]


# ---------------------------------------------------------------------- false detections
@pytest.mark.parametrize("rate, power", [
    (0.1, lambda rng, n: np.full(n, 0.12)),                     # 10x the 1 % target, all strong peaks
    # half the windows, powers as measured for false peaks (the localizer without a floor at SNR 5 dB:
    # 53 % of its peaks are over 20 deg off). At one per window, 1-2 false tracks appear per 10 min.
    (0.5, lambda rng, n: 10 ** rng.normal(np.log10(0.022), 0.2, n)),
])
def test_false_detections_uniform_on_the_sphere_make_no_lasting_track(rate, power):
    """Ten minutes of 128 ms windows with only false detections (Poisson count per window, directions
    uniform on the sphere): no track lasts over 1 s (see the false-alarm design in ssl_core.tracking)."""
    rng = np.random.default_rng(6)
    t = Tracker()
    longest = 0.0
    for k in range(int(600 / WINDOW)):
        n = rng.poisson(rate)
        v = rng.standard_normal((n, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        dets = [Detection(float(np.arctan2(u[1], u[0])), float(np.arcsin(u[2])), u, float(p), -40.0)
                for u, p in zip(v, power(rng, n))]
        for o in t.update(dets, k * WINDOW):
            longest = max(longest, o.last_time - o.first_time)
    assert longest <= 1.0


# ---------------------------------------------------------------------- the localizer's detections of a talker
def _talker_windows(az_deg: float, el_deg: float, snr_db: float, seed: int, duration_s: float = 6.0,
                    calls: bool = False, distance_m: float = 1.5):
    """One talker (near-continuous speech-like calls, or a victim's calls every 2.5 s) ``distance_m``
    away in a 6 x 5 x 3 m room with RT60 0.5 s, white sensor noise at ``snr_db`` re the talker's active
    level at the mics. Returns the localizer's windows, the true direction (array frame) and the dry
    signal."""
    pra = pytest.importorskip("pyroomacoustics")
    from ssl_sim.acoustics.voices import continuous_voice, victim_voice

    g = cube8()
    room_dim = np.array([6.0, 5.0, 3.0])
    e_abs, max_order = pra.inverse_sabine(0.5, room_dim)
    centre = np.array([2.6, 2.2, 1.2])
    u = direction_from_angles(np.deg2rad(az_deg), np.deg2rad(el_deg))
    voice = victim_voice("calls", seed=seed) if calls else continuous_voice("male", seed=seed)
    s = voice.render(0, int(duration_s * FS))
    room = pra.ShoeBox(room_dim, fs=FS, materials=pra.Material(e_abs), max_order=min(max_order, 12))
    room.add_source(centre + distance_m * u, signal=s)
    room.add_microphone_array((centre + g.positions).T)
    room.simulate()
    x = room.mic_array.signals[:, : s.size]
    frames = (x**2).mean(axis=0)[: x.shape[1] // 160 * 160].reshape(-1, 160).mean(axis=1)  # 10 ms
    active_ms = frames[frames >= 1e-3 * frames.max()].mean()
    x = x + np.random.default_rng(100 + seed).standard_normal(x.shape) * np.sqrt(active_ms) / 10 ** (snr_db / 20)
    # No fixed power floor: the localizer's adaptive gate (issue 11, item 1) is not merged yet. Measured
    # with that gate (branch hearing): SNR 5 dB gives 29 of 36 seconds at its default min_significance 7
    # (six of the misses before the first confirmation), 35 of 36 at 5; the tracker's confirmation is the
    # false-alarm control, so a looser per-window gate suits it.
    return Localizer(g, LocalizerConfig(min_power=0.0)).process_all(x), u, s


def _active_seconds(s: np.ndarray) -> np.ndarray:
    """Per 1 s of the dry signal: does the talker sound in at least 30 % of its 10 ms frames (within 30 dB
    of the loudest)?"""
    frames = (s**2)[: s.size // 160 * 160].reshape(-1, 160).mean(axis=1)
    on = frames >= 1e-3 * frames.max()
    return on[: on.size // 100 * 100].reshape(-1, 100).mean(axis=1) >= 0.3


TALKERS = [(30, 10), (-120, -20), (160, 35), (75, -5), (-60, 20), (-170, 0)]


@pytest.mark.parametrize("snr_db, tolerance_deg, required", [(20.0, 5.0, 0.95), (5.0, 10.0, 0.90)])
def test_simulated_talker_is_tracked(snr_db, tolerance_deg, required):
    """The most active track at the end of each second in which the talker speaks points at her."""
    good = total = 0
    for seed, (az, el) in enumerate(TALKERS):
        windows, u, s = _talker_windows(az, el, snr_db, seed)
        t = Tracker()
        at_second: dict[int, float] = {}
        ids = set()
        for w in windows:
            out = t.update(w.detections, w.time)
            ids |= {o.id for o in out}
            best = max(out, key=lambda o: o.activity, default=None)
            at_second[int(np.floor(w.time - 1e-9))] = np.inf if best is None else \
                float(np.rad2deg(angular_distance(best.direction, u)))
        active = _active_seconds(s)
        good += sum(at_second[k] <= tolerance_deg for k in np.flatnonzero(active))
        total += int(active.sum())
        assert len(ids) <= 2, ids  # one talker, at most one spurious track
    assert total >= 30 and good / total >= required, (good, total)


def test_simulated_talker_keeps_its_id_while_the_robot_turns_90_deg():
    """3 s of a talker at azimuth 30 deg, then the robot turns 90 deg CCW in place (the talker is now at
    -60 deg in the array frame) and listens 3 s more; the rotation is given at the first window after it."""
    before, u0, _ = _talker_windows(30.0, 10.0, 20.0, seed=0, duration_s=3.0)
    after, u1, _ = _talker_windows(-60.0, 10.0, 20.0, seed=1, duration_s=3.0)
    t = Tracker()
    for w in before:
        out = t.update(w.detections, w.time)
    assert [o.id for o in out] == [1] and np.rad2deg(angular_distance(out[0].direction, u0)) < 5.0
    offset = before[-1].time
    ids = set()
    for k, w in enumerate(after):
        out = t.update(w.detections, offset + w.time, rotation=rz(-np.pi / 2) if k == 0 else None)
        ids |= {o.id for o in out}
        assert 1 in {o.id for o in out}
        if k == 0:  # the rotation moved the track before association: the new pose's first detection is its own
            track = next(o for o in out if o.id == 1)
            assert np.rad2deg(angular_distance(track.direction, u1)) < 8.0
    assert ids == {1} and np.rad2deg(angular_distance(out[0].direction, u1)) < 5.0


def test_victim_calling_every_few_seconds_keeps_one_id():
    """30 s of a victim's calls (one per 2.5 s period, gaps up to ~4 s) at 2 m, SNR 20 dB: one track,
    on the victim, for the whole run (``silence_s`` outlasts the gaps)."""
    windows, u, _ = _talker_windows(40.0, 10.0, 20.0, seed=0, duration_s=30.0, calls=True, distance_m=2.0)
    t = Tracker()
    errors: dict[int, list[float]] = {}
    for w in windows:
        for o in t.update(w.detections, w.time):
            errors.setdefault(o.id, []).append(float(np.rad2deg(angular_distance(o.direction, u))))
    assert list(errors) == [1] and np.median(errors[1]) < 3.0 and max(errors[1]) < 10.0
