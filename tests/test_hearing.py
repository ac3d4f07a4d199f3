"""robot.hearing: MPDR beams toward tracks, VAD per beam, per-track voice probability; and the
streaming STFT / MPDR of ssl_core.beamform. Truth: plane waves of known direction, and a simulated
reverberant room with real recordings (ssl_sim/sounds test part) at known positions."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from robot.hearing import Hearing, HearingConfig, TrackEvidence, VoiceClass, classify
from signals import plane_wave
from sound_dataset import FS, ROOM_CASES, recordings, room_case
from ssl_core.beamform import MpdrBeamformer, OverlapAdd, StftStream, beam_signal
from ssl_core.geometry import cube8
from ssl_core.grid import angular_distance
from ssl_core.localizer import Localizer, LocalizerConfig
from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE, Track, Tracker

POS = cube8().positions
BLOCK = FS // 10


def _unit(az_deg, el_deg=0.0):
    a, e = np.deg2rad(az_deg), np.deg2rad(el_deg)
    return np.array([np.cos(a) * np.cos(e), np.sin(a) * np.cos(e), np.sin(e)])


def _track(track_id, direction, activity):
    """A track by hand at a known direction (what the Tracker would report; fields it does not use are 0)."""
    return Track(track_id, np.asarray(direction, float), np.zeros(3), activity, 0.0, 0.0, 0.0, 0.0, 0)


def _recording(name):
    return next(r for r in recordings("test") if r.name == name)


def test_stft_overlap_add_gives_the_input_back_one_hop_late():
    x = np.random.default_rng(0).standard_normal((3, FS))
    st, oa = StftStream(3), OverlapAdd()
    y = np.concatenate([oa.synthesise(st.analyse(x[:, i:i + 1237])[1]) for i in range(0, FS, 1237)])
    h = StftStream.HOP
    np.testing.assert_allclose(y[h + 512:], x[1, 512:len(y) - h], atol=1e-12)


def test_decimating_overlap_add_gives_every_other_sample_of_a_band_limited_input():
    # beams below 4 kHz go to Silero at 8 kHz: synthesising only those bins at 8 kHz must give every other
    # sample of the full-rate synthesis of the same bins, and (tones below 4 kHz) every other input sample
    t = np.arange(FS) / FS
    f = np.array([130.0, 710.0, 2450.0, 3400.0])
    x = np.sin(2 * np.pi * f[:, None] * t + np.arange(4)[:, None]).sum(0)[None].repeat(2, axis=0)
    st, full, half = StftStream(2), OverlapAdd(), OverlapAdd(2)
    nb = StftStream.FRAME // 4   # bins below 4 kHz
    y16, y8 = [], []
    for i in range(0, FS, 1237):
        spec = st.analyse(x[:, i:i + 1237])[1]
        spec[:, nb:] = 0
        y16.append(full.synthesise(spec))
        y8.append(half.synthesise(spec[:, :nb]))
    y16, y8 = np.concatenate(y16), np.concatenate(y8)
    np.testing.assert_allclose(y8, y16[::2], atol=1e-12)
    h = StftStream.HOP // 2
    # (the window's leakage of 3.4 kHz above 4 kHz, cut off with those bins: ~1e-4 of the amplitude)
    np.testing.assert_allclose(y8[h + 256:], x[1, 512:2 * (len(y8) - h):2], atol=1e-3)
    with pytest.raises(ValueError, match="spec"):
        half.synthesise(np.zeros((1, nb + 1), complex))


def test_mpdr_passes_the_look_direction_and_cancels_a_louder_plane_wave():
    rng = np.random.default_rng(1)
    s, n = rng.standard_normal(3 * FS), 3 * rng.standard_normal(3 * FS)
    u, v = _unit(30, 10), _unit(-60, -5)
    x = plane_wave(POS, u, s, FS) + plane_wave(POS, v, n, FS)
    st, mp, oa = StftStream(8), MpdrBeamformer(POS, FS), OverlapAdd()
    y = np.concatenate([oa.synthesise(mp.process(st.analyse(x[:, i:i + BLOCK]), u[None])[0])
                        for i in range(0, x.shape[1], BLOCK)])
    h, late = StftStream.HOP, FS  # after 1 s of covariance
    err_mpdr = y[h + late:] - s[late:len(y) - h]
    err_ds = beam_signal(x, POS, u, FS)[late:] - s[late:]
    gain_db = 10 * np.log10(np.mean(err_ds**2) / np.mean(err_mpdr**2))
    assert gain_db > 10, gain_db  # delay-and-sum leaves most of the 9.5 dB louder interferer in


def test_pause_keeps_the_probability_and_classify_uses_the_stated_thresholds():
    talk = _recording("it_carlo").samples[: 4 * FS]
    u = _unit(40)
    x = plane_wave(POS, u, talk, FS) + 1e-4 * np.random.default_rng(2).standard_normal((8, len(talk)))
    h = Hearing(POS)
    track = _track(7, u, 1.0)
    for k in range(0, len(talk), BLOCK):
        ev = h.update(x[:, k:k + BLOCK], [track], (k + BLOCK) / FS)
    assert classify(ev[0]) is VoiceClass.VOICE and ev[0].track_id == 7
    p_before = ev[0].voice_probability
    silent = _track(7, u, 0.1)   # pausing: below min_activity
    for k in range(30):
        ev = h.update(1e-4 * np.random.default_rng(k).standard_normal((8, BLOCK)), [silent], 5 + k / 10)
    assert ev[0].voice_probability == p_before
    assert h.voice_probability(99) == 0.5     # a track never heard is undecided
    mk = lambda p: TrackEvidence(1, u, 0.0, p, -20.0, 1.0)  # noqa: E731
    assert [classify(mk(p)) for p in (0.9, 0.8, 0.5, 0.2, 0.1)] == [
        VoiceClass.VOICE, VoiceClass.VOICE, VoiceClass.UNKNOWN, VoiceClass.NON_VOICE, VoiceClass.NON_VOICE]


def test_between_listening_bursts_the_evidence_is_held():
    """The chain listens 0.5 s in every 1 s: a burst of noise outside the listening time changes nothing."""
    h = Hearing(POS)
    t = _track(3, _unit(0), 1.0)
    rng = np.random.default_rng(4)
    ev = [h.update(1e-2 * rng.standard_normal((8, BLOCK)), [t], (k + 1) / 10)[0] for k in range(20)]
    listened = [k for k in range(20) if (k / 10) % 1.0 < 0.5]
    changes = [k for k in range(1, 20) if ev[k].voice_probability != ev[k - 1].voice_probability]
    assert changes and set(changes) <= set(listened)
    assert ev[-1].voice_probability < 0.2            # steady noise: non-voice within 2 s
    # blocks as long as the listening period are all heard, each frame counting once: 1 s of steady noise
    # = ~30 non-speech frames of 32 ms = -1.5 log-odds (P ~0.19; counted double it would be ~0.05)
    h = Hearing(POS)
    p = h.update(1e-2 * rng.standard_normal((8, FS)), [t], 1.0)[0].voice_probability
    assert 0.15 < p < 0.25, p


def test_a_dropped_track_is_forgotten_and_config_errors_name_the_field():
    h = Hearing(POS)
    t = _track(1, _unit(0), 1.0)
    h.update(np.zeros((8, BLOCK)), [t], 0.1)
    assert h.update(np.zeros((8, BLOCK)), [], 0.2) == [] and h.voice_probability(1) == 0.5
    with pytest.raises(ValueError, match="HearingConfig.fall_per_s"):
        HearingConfig(fall_per_s=0)
    with pytest.raises(ValueError, match="HearingConfig.min_activity"):
        HearingConfig(min_activity=2)
    with pytest.raises(ValueError, match="sample_rate"):
        Hearing(POS, 8000)
    with pytest.raises(ValueError, match="HearingConfig.vad_period_s"):
        HearingConfig(vad_on_s=1.0, vad_period_s=0.5)
    with pytest.raises(ValueError, match="HearingConfig.credit_probability"):
        HearingConfig(credit_probability=0.3)
    with pytest.raises(ValueError, match="HearingConfig.inherit_deg"):
        HearingConfig(inherit_deg=-1)
    with pytest.raises(ValueError, match="HearingConfig.settle_s"):
        HearingConfig(settle_s=-0.5)
    with pytest.raises(ValueError, match="HearingConfig.scan_step_deg"):
        HearingConfig(scan_step_deg=-15)


def test_a_new_track_beside_a_known_one_starts_from_its_evidence():
    """The tracker starts duplicates of one machine at other elevations: a new id within inherit_deg
    (20 deg) of a NON_VOICE track starts NON_VOICE; one far from every track starts undecided."""
    u = _unit(30)
    rng = np.random.default_rng(5)
    noise = plane_wave(POS, u, 0.05 * rng.standard_normal(3 * FS), FS)
    h = Hearing(POS)
    for k in range(20):   # 2 s of a steady source: NON_VOICE
        ev = h.update(noise[:, k * BLOCK:(k + 1) * BLOCK], [_track(1, u, 1.0)], (k + 1) / 10)
    assert classify(ev[0]) is VoiceClass.NON_VOICE
    # a duplicate 12 deg above it and a track 90 deg away, both pausing (their silence lowers nothing)
    tracks = [_track(1, u, 1.0), _track(2, _unit(30, 12), 0.1), _track(3, _unit(120), 0.1)]
    ev = h.update(noise[:, 20 * BLOCK:21 * BLOCK], tracks, 2.1)
    assert classify(ev[1]) is VoiceClass.NON_VOICE and ev[1].voice_probability <= ev[0].voice_probability + 0.05
    assert ev[2].voice_probability == 0.5
    off = Hearing(POS, config=HearingConfig(inherit_deg=0))
    for k in range(21):
        ev = off.update(noise[:, k * BLOCK:(k + 1) * BLOCK], tracks[:1] if k < 20 else tracks, (k + 1) / 10)
    assert ev[1].voice_probability == 0.5


def test_voice_scan_finds_a_talker_beside_a_louder_machine_and_nothing_beside_the_machine_alone():
    """Free field, plane waves of known direction: a real talker at 40 deg and a real machine recording
    (data set test part) at -60 deg, 6 dB louder (RMS over the whole 5 s). The voice scan's detections (no
    tracks given) point at her within 10 deg; with the machine alone it makes none."""
    fs5 = 5 * FS
    talk = np.resize(_recording("it_carlo").samples, fs5)     # looped
    machine = np.resize(_recording("ore_mine").samples, fs5)
    machine = machine * 2 * np.sqrt(np.mean(talk**2) / np.mean(machine**2))
    u_her, u_machine = _unit(40), _unit(-60)
    noise = 1e-4 * np.random.default_rng(6).standard_normal((8, fs5))
    x_machine = plane_wave(POS, u_machine, machine, FS) + noise

    def scan(x):
        h, found = Hearing(POS, config=HearingConfig(scan_step_deg=15)), []
        for k in range(0, fs5, BLOCK):
            h.update(x[:, k:k + BLOCK], [], (k + BLOCK) / FS)
            found += h.voice_detections()
        return found
    found = scan(x_machine + plane_wave(POS, u_her, talk, FS))
    errors = [float(np.rad2deg(angular_distance(d.direction, u_her))) for d in found]
    print("voice scan detections, error from her (deg):", np.round(errors, 1))
    assert len(errors) >= 5 and max(errors) <= 10, errors
    assert scan(x_machine) == []


# --- reverberant room: a talker and a real machine 6 dB louder ------------------------------------
SETTLE_S = 2  # windows before this are not scored: MPDR covariance and noise floors still filling
_room = functools.lru_cache(maxsize=None)(room_case)   # each room simulated once per module


def _room_run(talker, machine, az_t, az_m, seconds=16):
    x, directions, she_talks = _room(talker, machine, az_t, az_m, seconds)
    tracks = [_track(i, d, 1.0) for i, d in enumerate(directions)]
    h = Hearing(POS)
    out = []
    for k in range(seconds * 10):
        ev = h.update(x[:, k * BLOCK:(k + 1) * BLOCK], tracks, (k + 1) / 10)
        if (k + 1) % 10 == 0:
            out.append([classify(e) for e in ev])
    return out, she_talks


@pytest.mark.slow
def test_given_tracks_at_the_true_directions_talker_is_voice_and_louder_machine_is_not():
    """RT60 0.6 s, machine 6 dB louder (active speech level vs machine RMS), 80-180 deg apart, 2 m.
    The hearing alone: tracks are made by hand at the true directions, always active (pauses count
    against the talker). The requirement through the real chain is the test below."""
    voice_ok, machine_ok, report = [], [], []
    for case in ROOM_CASES:
        out, she_talks = _room_run(*case)
        v = [o[0] is VoiceClass.VOICE for o, t in zip(out, she_talks) if t][SETTLE_S:]
        m = [o[1] is VoiceClass.NON_VOICE for o in out][SETTLE_S:]
        voice_ok += v
        machine_ok += m
        report.append((case, round(float(np.mean(v)), 2), round(float(np.mean(m)), 2)))
    print("talker voice / machine non-voice share of 1 s windows:", report)
    assert np.mean(voice_ok) >= 0.9, report
    assert np.mean(machine_ok) >= 0.95, report


# --- the same rooms through the real chain: Localizer -> Tracker -> Hearing -------------------------
TRACK_GATE_DEG = 20.0   # the track nearest a source within this is "its" track


@functools.lru_cache(maxsize=None)
def _chain_run(case, sir_db, seconds=16):
    """Per 1 s window (end of it): the evidence of every confirmed track; plus the true directions and
    whether she talks. Localizer with noise suppression, two sources per window, the interference rescan
    (the second source is searched in bins that depart from the recent spatial covariance and rise above
    their recent power: onsets), the tracking gate; the hearing's voice scan (beams every 15 deg, the one
    carrying the most speech) adds a detection to the tracker's next window."""
    x, directions, she_talks = _room(*case, seconds, sir_db)
    loc = Localizer("cube8", LocalizerConfig(noise_suppression=True, n_sources=2, interference_rescan=True,
                                             min_significance=TRACKING_MIN_SIGNIFICANCE))
    tracker, hearing, tracks, out = Tracker(), Hearing(POS, config=HearingConfig(scan_step_deg=15)), [], []
    for k in range(seconds * 10):
        block = x[:, k * BLOCK:(k + 1) * BLOCK]
        for r in loc.process(block):
            tracks = tracker.update([*r.detections, *hearing.voice_detections()], r.time)
        ev = hearing.update(block, tracks, (k + 1) / 10)
        if (k + 1) % 10 == 0:
            out.append(ev)
    return out, directions, she_talks


def _nearest(evidence, direction, within_deg):
    d = [float(np.rad2deg(angular_distance(e.direction, direction))) for e in evidence]
    i = int(np.argmin(d)) if d else -1
    return evidence[i] if d and d[i] <= within_deg else None


def _chain_scores(sir_db):
    """Per room case: (her talking windows with her track VOICE, windows with the machine's track
    NON_VOICE, her talking windows with a VOICE track within 10 deg of her), windows after SETTLE_S."""
    rows = []
    for case in ROOM_CASES:
        out, (u_her, u_machine), she_talks = _chain_run(case, sir_db)
        scored = [(ev, t) for ev, t in zip(out, she_talks)][SETTLE_S:]
        her = [_nearest(ev, u_her, TRACK_GATE_DEG) for ev, t in scored if t]
        machine = [_nearest(ev, u_machine, TRACK_GATE_DEG) for ev, _ in scored]
        near = [any(classify(e) is VoiceClass.VOICE and np.rad2deg(angular_distance(e.direction, u_her)) <= 10
                    for e in ev) for ev, t in scored if t]
        rows.append(([e is not None and classify(e) is VoiceClass.VOICE for e in her],
                     [e is not None and classify(e) is VoiceClass.NON_VOICE for e in machine], near))
    return rows


# Measured (docs/design/hearing.md), per room in the order of ROOM_CASES. Without the
# interference rescan the talker got no track in most rooms: the SRP-PHAT map of the mixture had a peak
# within 10 deg of her in 2-56 of 124 windows at -6 dB SIR even with four peaks and no gate; pooled, her
# track VOICE 33 %, machine NON_VOICE 81 %. With the rescan (bins weighted by their departure from the
# recent spatial covariance and by their onset; tuned on other rooms, DEV_ROOM_CASES): her track VOICE
# 61 %, the machine's NON_VOICE 77 %; with the hearing's crediting rules 61 / 93 %; with the voice scan
# (MPDR beams every 15 deg on the horizon, VAD on each, the beam with the most VAD probability x denoised
# power becomes a detection) 76 % (79/100/79/100/21) / 93 % (100/64/100/100/100). Then (chosen on
# DEV_ROOM_CASES, docs/design/hearing.md "The voice scan's map"): speech heard in several beams goes to the
# track whose azimuth carries the most of the scan's speech (not the largest excess over the noise floor,
# which let the machine's beam and a ghost own her speech), and the scan detects after 0.5 s of listening
# instead of 2 s: her track VOICE 100/93/100/100/71 % (pooled 93 %, 65 of her 70 windows, 63 needed), the
# machine's NON_VOICE 100/93/100/100/100 % (pooled 99 %, 69 of 70, 67 needed). Seeded simulation,
# deterministic.
@pytest.mark.slow
def test_real_chain_talker_is_voice_and_louder_machine_is_not_in_a_reverberant_room():
    rows = _chain_scores(-6.0)
    report = [(c[:2], round(float(np.mean(v)), 2), round(float(np.mean(m)), 2)) for c, (v, m, _) in zip(ROOM_CASES, rows)]
    print("real chain, SIR -6 dB: her track VOICE / machine's track NON_VOICE share of 1 s windows:", report,
          "pooled", round(float(np.mean(sum((v for v, _, _ in rows), []))), 2),
          round(float(np.mean(sum((m for _, m, _ in rows), []))), 2))
    assert np.mean(sum((v for v, _, _ in rows), [])) >= 0.9, report
    assert np.mean(sum((m for _, m, _ in rows), [])) >= 0.95, report


# Measured: a VOICE track within 10 deg of her in 93/79/100/100/93 % of her windows per room, pooled 93 %
# with the voice scan's owner rule and 0.5 s settle (86/86/100/100/79, 90 %, before them; 77 % before the
# scan: 79/64/93/93/57; 43 % without the interference rescan, 63 % with it before the onset weight, 73 %
# before the hearing's crediting rules; docs/design/hearing.md). Seeded simulation, deterministic: 65 of her 70
# windows (63 before the owner rule, 54 before the scan), the threshold is 49.
@pytest.mark.slow
def test_real_chain_voice_track_within_10_deg_at_0_db_sir():
    rows = _chain_scores(0.0)
    report = [(c[:2], round(float(np.mean(n)), 2)) for c, (_, _, n) in zip(ROOM_CASES, rows)]
    print("real chain, SIR 0 dB: a VOICE track within 10 deg of her, share of her 1 s windows:", report,
          "pooled", round(float(np.mean(sum((n for _, _, n in rows), []))), 2))
    assert np.mean(sum((n for _, _, n in rows), [])) >= 0.7, report


# --- one standing listen (robot.listening): the same chain on 1 s, fresh each listen -------------------------
def test_one_listen_hears_the_talker_beside_a_louder_machine_and_gives_the_machine_no_voice():
    """The five real-recording rooms above (machine 6 dB louder, 2 m, RT60 0.6 s), cut into 1 s listens as the
    rescue behaviour makes them, beams at the true directions: the listener's chain (``speech_fractions``: MPDR,
    noise suppression, gain, speech owned by one beam) hears her where the plain delay-and-sum beam does not,
    and gives the machine's beam no speech (docs/design/behaviour.md, "The sound map")."""
    from robot.hearing import speech_fractions
    from robot.vad import SileroVad, speech_fraction
    from ssl_core.beamform import beam_signal
    vad8, vad16 = SileroVad(sample_rate=8000), SileroVad()
    talker = machine = listens = talking_s = ds_talker = 0
    for case in ROOM_CASES:
        x, directions, she_talks = _room(*case)
        x = x.astype(float) / 32768.0
        for k, talks in enumerate(she_talks[: x.shape[1] // FS]):
            block = x[:, k * FS:(k + 1) * FS]
            f = speech_fractions(block, POS, np.array(directions), vad8)
            listens += 1
            machine += f[1] >= 0.1
            if talks:
                talking_s += 1
                talker += f[0] >= 0.1
                ds = beam_signal(block, POS, directions[0], FS)
                ds_talker += speech_fraction(vad16.probabilities(ds, FS)) >= 0.1
    print("one listen: her beam voice in", talker, "of", talking_s, "talking seconds (delay-and-sum", ds_talker,
          "); the machine's in", machine, "of", listens)
    assert talker >= 0.9 * talking_s, (talker, talking_s)
    assert machine <= 0.05 * listens, (machine, listens)
    assert talker >= ds_talker + 0.5 * talking_s, (talker, ds_talker, talking_s)


def _voice_hits(scan_deg, tmp_path):
    """Over the five rooms in 1 s listens (replayed from WAV files after the settle): (talking listens, those
    with voice evidence within 15 deg of her azimuth, listens with voice evidence within 15 deg of the
    machine's, listens)."""
    from scipy.io import wavfile

    from robot.hal import ManualClock
    from robot.listening import Listener
    from robot.replay import WavFileSource
    loc = Localizer(cube8(), LocalizerConfig(n_sources=3, rel_threshold=0.25, noise_suppression=True))
    talking = hits = machine = listens = 0
    for k, case in enumerate(ROOM_CASES):
        x, directions, she_talks = _room(*case)
        wavfile.write(tmp_path / f"room{k}.wav", FS, x.T)
        audio = WavFileSource(tmp_path / f"room{k}.wav", 8, FS)
        audio.seek(SETTLE_S)
        listener = Listener(audio, ManualClock(), loc, POS, voice_threshold=0.1, voice_scan_deg=scan_deg)
        az = [np.arctan2(d[1], d[0]) for d in directions]
        for talks in she_talks[SETTLE_S: x.shape[1] // FS]:
            voiced = [e.azimuth for e in listener.listen(1.0, 0.0, 0.0).evidence if e.speech_fraction >= 0.1]

            def near(a):
                return any(abs(np.rad2deg(np.angle(np.exp(1j * (v - a))))) <= 15 for v in voiced)
            listens += 1
            machine += near(az[1])
            if talks:
                talking += 1
                hits += near(az[0])
    return talking, hits, machine, listens


def test_listen_voice_scan_hears_the_talker_the_srp_map_misses_beside_a_louder_machine(tmp_path):
    """The five real-recording rooms (machine 6 dB louder, 2 m, RT60 0.6 s) in 1 s listens through the rescue's
    listener (localizer with noise suppression, 3 sources): with the voice scan a voiced detection points at her
    (within 15 deg of azimuth) in more of her talking listens (measured: 31 of 70 against 15), and the machine
    gets no more voiced detections than without it (5 against 6 of 70: her speech leaking into its beam)."""
    plain, scanned = _voice_hits(0.0, tmp_path), _voice_hits(15.0, tmp_path)
    print("talking listens, voiced at her, voiced at the machine, listens: without scan", plain, "with", scanned)
    talking, hits, machine, listens = scanned
    assert hits >= plain[1] + 0.15 * talking, (plain, scanned)
    assert machine <= plain[2], (plain, scanned)
