"""The rescue behaviour on a fake HAL: an ideal drive in a tiny geometric world with scripted sources."""
import math
from dataclasses import dataclass

import numpy as np
import pytest

from robot.hal import AudioBlock, AudioSource, DriveStatus, ManualClock
from robot.odometry import Odometry
from robot.replay import DryRunDrive
from robot.rescue import RescueBehaviour, RescueConfig, RescueEvent, RescueState
from ssl_core.geometry import cube8
from sound_dataset import recordings

FS = 16000
ROBOT_RADIUS = 0.2  # m, bumper ring


@dataclass
class Source:
    position: tuple[float, float, float]  # world, m (z: mouth height)
    level_db: float                       # beam level at 1 m


@dataclass
class Det:  # what ssl_core's Detection carries (array frame)
    azimuth: float
    elevation: float
    power: float
    level_db: float


@dataclass
class Result:
    detections: list


class World:
    """Ground truth: the dry-run drive's ideal odometry *is* the true pose; discs are obstacles."""

    def __init__(self, sources, obstacles=(), start=(0.0, 0.0, 0.0), seed=0, array_height=0.30):
        self.clock = ManualClock()
        self.sources = list(sources)
        self.obstacles = list(obstacles)  # (x, y, radius)
        self.array_height = array_height
        self.rng = np.random.default_rng(seed)
        self.drive = WorldDrive(self, start)

    def pose(self):
        return self.drive.true_pose()

    def touching(self, pose):
        things = [(o[0], o[1], o[2]) for o in self.obstacles] + [(s.position[0], s.position[1], 0.05)
                                                                  for s in self.sources]
        return any(math.hypot(pose[0] - x, pose[1] - y) < r + ROBOT_RADIUS for x, y, r in things)


class WorldDrive(DryRunDrive):
    def __init__(self, world, start):
        super().__init__(world.clock)
        self.world = world
        self.truth = Odometry(self.params, start)
        self.stalled = False
        self.faults = ()
        self.stop_calls = 0

    def true_pose(self):
        return self.truth.update(DryRunDrive.odometry(self))

    def stop(self):
        self.stop_calls += 1
        super().stop()

    def status(self):
        return DriveStatus(bumper=self.world.touching(self.true_pose()), stalled=self.stalled, faults=self.faults)


class FakeAudio(AudioSource):
    """Silence of the right shape; reading takes the block's duration on the clock, like a capture."""

    def __init__(self, clock, n_channels=8, blocks=None):
        self.clock, self._n, self.blocks, self.flushes, self.reads = clock, n_channels, blocks, 0, 0

    sample_rate = FS

    @property
    def n_channels(self):
        return self._n

    def read(self, n):
        self.reads += 1
        t = self.clock.now()
        self.clock.sleep(n / FS)
        x = np.zeros((self._n, n), np.int16) if self.blocks is None else self.blocks(n)
        return AudioBlock(x, FS, t)

    def flush(self):
        self.flushes += 1


class FakeLocalizer:
    """Detections of every source from the true pose (array frame), 1 deg jitter, loudest first."""

    def __init__(self, world):
        self.world = world
        self.calls = 0

    def locate(self, samples):
        self.calls += 1
        x, y, yaw = self.world.pose()
        dets = []
        for s in self.world.sources:
            dx, dy, dz = s.position[0] - x, s.position[1] - y, s.position[2] - self.world.array_height
            d3 = math.sqrt(dx * dx + dy * dy + dz * dz)
            az = math.atan2(dy, dx) - yaw + math.radians(self.world.rng.normal(0, 1.0))
            el = math.atan2(dz, math.hypot(dx, dy)) + math.radians(self.world.rng.normal(0, 1.0))
            az = (az + math.pi) % (2 * math.pi) - math.pi
            dets.append(Det(az, el, 0.5, s.level_db - 20 * math.log10(max(d3, 0.05))))
        return Result(sorted(dets, key=lambda d: -d.level_db))


def make(world, config=RescueConfig(), **kw):
    audio = kw.pop("audio", None) or FakeAudio(world.clock)
    loc = kw.pop("localizer", None) or FakeLocalizer(world)
    start = world.drive.truth.pose
    return RescueBehaviour(audio, world.drive, world.clock, loc, config, start_pose=start, **kw)


def decisions(events):
    return [e.decision for e in events]


def test_turns_toward_the_loudest_source():
    w = World([Source((2.0, 2.0, 0.1), 60.0), Source((0.0, -3.0, 0.1), 70.0)])
    b = make(w)
    ev = b.step()
    assert decisions(ev) == ["heard", "target", "turn", "drive"]
    target = ev[1]
    assert math.degrees(target.data["azimuth"]) == pytest.approx(-90, abs=4)
    first_motion = next(c for c in w.drive.commands if any(c.twist))
    assert first_motion.twist[2] < 0  # turns clockwise (right), toward -90 deg
    x, y, yaw = w.pose()
    assert math.degrees(yaw) == pytest.approx(-90, abs=5)
    assert y == pytest.approx(-b.config.step_m, abs=0.05) and abs(x) < 0.06  # one step toward it
    np.testing.assert_allclose(b.pose, w.pose(), atol=1e-9)  # behaviour's odometry tracks the (ideal) drive
    assert w.drive.commands[-1].twist == (0.0, 0.0, 0.0)  # stopped at the end of the step
    assert all(isinstance(e, RescueEvent) and e.reason for e in ev)


def test_finds_victims_loudest_first_and_moves_on():
    victims = [Source((2.5, 1.0, 0.1), 62.0), Source((-1.5, 2.0, 0.1), 68.0)]
    w = World(victims, seed=3)
    b = make(w, RescueConfig(max_victims=2))
    ev = b.run(max_time=200.0)
    assert b.done and ev[-1].decision == "all_found"
    found = [e for e in ev if e.decision == "victim_found"]
    assert len(found) == 2
    # loudest first, then the other one; estimated positions near the truth
    for e, v in zip(found, (victims[1], victims[0]), strict=True):
        assert math.dist(e.data["position"], v.position[:2]) < 0.3
        assert "elevation" in e.reason or "bumped" in e.reason
    # after the first find, the first victim's detections were ignored as already found
    after = ev[ev.index(found[0]) + 1:]
    assert any("found victim #1" in s for e in after if e.decision == "heard" for s in e.data["ignored"])
    assert all(e.data["azimuth"] != 0 for e in after if e.decision == "target")
    assert w.drive.commands[-1].twist == (0.0, 0.0, 0.0)


def test_backs_off_and_sidesteps_on_a_bump_then_reaches_the_victim():
    # A pillar right on the line to the victim.
    w = World([Source((3.0, 0.0, 0.1), 65.0)], obstacles=[(1.0, 0.0, 0.15)], seed=1)
    b = make(w, RescueConfig(max_victims=1))
    ev = b.run(max_time=200.0)
    rec = [e for e in ev if e.decision == "recover"]
    assert rec and "bumper pressed while driving (not at a victim)" in rec[0].reason
    assert rec[0].data["bumper"]
    # the commands right after the bump: back off (vx < 0), then a sidestep (vy != 0, vx ~ 0)
    t_bump = rec[0].time
    after = [c.twist for c in w.drive.commands if c.time >= t_bump and any(c.twist)]
    assert after[0][0] < 0 and abs(after[0][1]) < 1e-9
    side = next(t for t in after if abs(t[1]) > 1e-3)
    assert abs(side[0]) < 0.05
    # ... and it went around the pillar and found the victim
    assert b.done and ev[-1].decision == "all_found"
    assert math.dist(b.victims[0].position, (3.0, 0.0)) < 0.3
    # it never drove through the pillar
    assert not any("found" in e.decision and e.data.get("position") and math.dist(e.data["position"], (1, 0)) < 0.3
                   for e in ev)


def test_bump_at_the_victim_counts_as_found():
    w = World([Source((0.9, 0.0, 0.1), 65.0)], seed=2)
    # An elevation threshold that is never reached, so only the bump can end the approach.
    cfg = RescueConfig(found_elevation_deg=80.0, corroborated_elevation_deg=80.0, approach_stop_m=0.0,
                       max_victims=1)
    b = make(w, cfg)
    ev = b.run(max_time=60.0)
    found = [e for e in ev if e.decision == "victim_found"]
    assert len(found) == 1 and "bumped into it" in found[0].reason
    assert not any(e.decision == "recover" and "not at a victim" in e.reason for e in ev)


def test_level_rise_with_moderate_elevation_is_found():
    w = World([Source((3.0, 0.0, 0.1), 65.0)], seed=4)
    cfg = RescueConfig(found_elevation_deg=60.0, corroborated_elevation_deg=15.0, level_rise_db=9.0, max_victims=1)
    b = make(w, cfg)
    b.run(max_time=100.0)
    assert len(b.victims) == 1 and "level rose" in b.victims[0].criterion
    # found once both held: elevation <= -15 deg means the mouth within 0.2/tan(15) = 0.75 m
    assert math.dist(w.pose()[:2], (3.0, 0.0)) < 0.8


def test_wheel_stall_triggers_recovery():
    w = World([Source((3.0, 0.0, 0.1), 65.0)])
    b = make(w)
    b.step()  # one step toward it
    w.drive.stalled = True
    ev = b.step()
    assert ev[0].decision == "recover" and "wheels stalled" in ev[0].reason
    w.drive.stalled = False


def test_own_stall_detection_when_the_wheels_do_not_turn():
    w = World([Source((3.0, 0.0, 0.1), 65.0)])

    class Stuck(WorldDrive):
        def odometry(self):  # encoders frozen: commands are accepted but nothing turns
            o = super().odometry()
            return type(o)(o.timestamp, np.zeros(3), np.zeros(3))

    w.drive = Stuck(w, (0.0, 0.0, 0.0))
    b = make(w)
    ev = b.step()
    assert any(e.decision == "recover" and "wheels stalled while driving" in e.reason for e in ev)


def test_drive_is_stopped_on_any_exception():
    w = World([Source((3.0, 0.0, 0.1), 65.0)])
    b = make(w)
    calls = {"n": 0}
    orig = w.drive.odometry

    def failing():
        calls["n"] += 1
        if calls["n"] == 6:  # in the middle of the drive step
            raise RuntimeError("encoder link lost")
        return orig()

    w.drive.odometry = failing
    with pytest.raises(RuntimeError, match="encoder link lost"):
        b.step()
    assert any(any(c.twist) for c in w.drive.commands)  # it was moving ...
    assert w.drive.commands[-1].twist == (0.0, 0.0, 0.0)  # ... and was stopped
    assert b.events[-1].decision == "error"

    # Ctrl-C while driving (raised from the clock's sleep) stops the robot too.
    w2 = World([Source((0.0, 3.0, 0.1), 65.0)])
    b2 = make(w2)
    n = {"sleeps": 0}
    sleep = w2.clock.sleep

    def interrupted(dt):
        n["sleeps"] += 1
        if n["sleeps"] == 10:
            raise KeyboardInterrupt
        sleep(dt)

    w2.clock.sleep = interrupted
    with pytest.raises(KeyboardInterrupt):
        b2.run(max_time=60.0)
    assert any(any(c.twist) for c in w2.drive.commands)
    assert w2.drive.commands[-1].twist == (0.0, 0.0, 0.0)


def test_listens_standing_still_with_fresh_audio():
    w = World([Source((0.0, 3.0, 0.1), 65.0)])
    audio = FakeAudio(w.clock)
    b = make(w, audio=audio)
    b.step()
    b.step()
    assert audio.flushes == audio.reads == 2
    # every read happened while the last command was a stop
    # (the fake localizer runs right after the read, when the robot must be still)
    assert b.state in (RescueState.APPROACH, RescueState.LISTEN)


def test_silence_leads_to_exploration_and_audio_end_finishes():
    w = World([])
    b = make(w, RescueConfig(explore_after_silent=2, explore_step_m=0.4))
    ev = b.step() + b.step()
    assert decisions(ev) == ["no_source", "no_source", "explore"]
    assert w.pose()[0] == pytest.approx(0.4, abs=0.02)

    class Ending(FakeAudio):
        def read(self, n):
            raise EOFError("rec.wav: end reached")

    b2 = make(World([]), audio=Ending(ManualClock()))
    ev = b2.step()
    assert b2.done and ev[-1].decision == "audio_ended"
    assert b2.step() == []


def test_fatal_fault_ends_the_mission_and_others_are_logged():
    w = World([Source((3.0, 0.0, 0.1), 65.0)])
    b = make(w)
    w.drive.faults = ("brownout_reset",)
    ev = b.step()
    assert ev[0].decision == "drive_fault" and "brownout_reset" in ev[0].reason
    assert not b.done
    w.drive.faults = ("brownout_reset", "encoder_error")
    ev = b.step()
    assert b.done and ev[-1].decision == "fault" and "encoder_error" in ev[-1].reason


def test_keeps_its_target_unless_another_is_clearly_louder():
    # Two sources 1 dB apart at +-60 deg: once committed, the behaviour does not dither.
    w = World([Source((1.5, 2.6, 0.1), 66.0), Source((1.5, -2.6, 0.1), 65.0)], seed=5)
    b = make(w)
    b.step()
    b.step()
    targets = [e for e in b.events if e.decision == "target"]
    assert "keep current target" in targets[1].reason or "still" in targets[1].reason
    bearings = [e.data["azimuth"] + 0 for e in targets]
    assert abs(bearings[1]) < math.radians(15)  # still straight ahead after turning toward the first


# --- voice preference on real signals ---------------------------------------------

def _voice(n, seed, f0=130.0):
    """Voiced speech model: jittered glottal pulses, -12 dB/oct source, 3 formants, lip radiation."""
    from scipy import signal
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    f0_t = f0 * (1 + 0.1 * np.sin(2 * np.pi * 0.5 * t) + 0.01 * rng.standard_normal(n))
    pulses = np.diff(np.floor(np.cumsum(f0_t) / FS), prepend=0.0)
    g = signal.lfilter([1.0], [1, -2 * 0.97, 0.97 ** 2], pulses)
    y = np.zeros(n)
    for fc, bw, gain in ((650, 80, 1.0), (1400, 100, 0.5), (2600, 150, 0.25)):
        r = np.exp(-np.pi * bw / FS)
        y += gain * signal.lfilter([1 - r], [1, -2 * r * np.cos(2 * np.pi * fc / FS), r * r], g)
    y = np.diff(y, prepend=0.0) * (0.3 + np.clip(np.sin(2 * np.pi * 3 * t), 0, None))
    return y / np.std(y)


def _plane(direction, s):
    f = np.fft.rfftfreq(s.size, 1 / FS)
    d = -(cube8().positions @ direction) / 343.0
    return np.fft.irfft(np.fft.rfft(s)[None] * np.exp(-2j * np.pi * f[None] * d[:, None]), s.size)


def _unit(az):
    return np.array([math.cos(az), math.sin(az), 0.0])


@pytest.mark.parametrize("prefer_voice", [True, False])
def test_prefers_a_voice_over_louder_noise(prefer_voice):
    az_voice, az_noise = math.radians(70), math.radians(-100)
    rng = np.random.default_rng(9)

    def blocks(n):
        return 0.05 * (_plane(_unit(az_voice), _voice(n, 1)) + 1.4 * _plane(_unit(az_noise), rng.standard_normal(n)))

    class TwoSources:
        geometry = cube8()

        def locate(self, samples):
            return Result([Det(az_noise, 0.0, 0.6, -20.0), Det(az_voice, 0.0, 0.5, -23.0)])

    w = World([])
    b = make(w, RescueConfig(prefer_voice=prefer_voice), audio=FakeAudio(w.clock, blocks=blocks),
             localizer=TwoSources())
    ev = b.step()
    heard = ev[0].data["candidates"]
    voice = {round(math.degrees(c["azimuth"])): c["voice"] for c in heard}
    assert voice[70] > 0.3 > voice[-100]
    target = next(e for e in ev if e.decision == "target")
    if prefer_voice:
        assert target.data["azimuth"] == pytest.approx(az_voice)
        assert "skipped 1 louder non-voice" in target.reason
    else:
        assert target.data["azimuth"] == pytest.approx(az_noise)


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match="RescueConfig.listen_s"):
        RescueConfig(listen_s=0)
    with pytest.raises(ValueError, match="source_height_m"):
        RescueConfig(source_height_m=0.5)
    with pytest.raises(ValueError, match="max_victims"):
        RescueConfig(max_victims=0)
    w = World([])
    with pytest.raises(ValueError, match="geometry: 8 microphones but the audio source has 4"):
        make(w, audio=FakeAudio(w.clock, n_channels=4), geometry=cube8())


def test_listening_takes_the_block_duration_even_if_the_source_does_not():
    w = World([])

    class Instant(FakeAudio):
        def read(self, n):
            return AudioBlock(np.zeros((8, n), np.int16), FS, self.clock.now())

    b = make(w, RescueConfig(settle_s=0.0, listen_s=0.5), audio=Instant(w.clock))
    t0 = w.clock.now()
    b.step()
    assert w.clock.now() - t0 == pytest.approx(0.5)


# --- robot.voice -------------------------------------------------------------------

def test_voice_likeness_separates_voice_from_noise_hum_and_high_tones():
    from robot.voice import voice_likeness
    rng = np.random.default_rng(0)
    t = np.arange(FS) / FS
    for f0, seed in ((90, 1), (130, 2), (220, 3)):
        assert voice_likeness(_voice(FS, seed, f0), FS).score > 0.6
    assert voice_likeness(rng.standard_normal(FS), FS).score < 0.1                       # white noise
    assert voice_likeness(np.cumsum(rng.standard_normal(FS)), FS).score < 0.1            # rumble
    assert voice_likeness(np.sin(2 * np.pi * 100 * t), FS).score < 0.1                   # mains/motor hum
    assert voice_likeness(np.sin(2 * np.pi * 2000 * t), FS).score < 0.1                 # beeper above the pitch band
    assert voice_likeness(np.zeros(FS), FS).score == 0.0


def test_beam_toward_a_plane_wave_recovers_it_and_attenuates_other_directions():
    from ssl_core.beamform import beam_signal as beamform
    rng = np.random.default_rng(1)
    s = rng.standard_normal(FS)
    u = np.array([math.cos(0.4) * math.cos(-0.3), math.sin(0.4) * math.cos(-0.3), math.sin(-0.3)])
    x = _plane(u, s)
    err = beamform(x, cube8().positions, u, FS) - s
    assert np.sqrt(np.mean(err**2)) < 0.01  # exact but for the Nyquist bin, where a fractional delay is lossy
    off = beamform(x, cube8().positions, -u, FS)
    assert np.mean(off**2) < 0.5 * np.mean(s**2)  # broadband noise from the opposite side loses > 3 dB


# --- end to end with the real SRP-PHAT localizer on audio rendered at the robot's pose -------------

class RenderedAudio(FakeAudio):
    """Point sources heard by the cube array at its current world pose: exact delays and 1/r."""

    def __init__(self, world, signals, noise=1e-4, seed=0):
        super().__init__(world.clock)
        self.world, self.signals, self.noise = world, signals, noise
        self.rng = np.random.default_rng(seed)

    def read(self, n):
        t0 = self.clock.now()
        x, y, yaw = self.world.pose()
        c, s = math.cos(yaw), math.sin(yaw)
        mics = cube8().positions @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + [x, y, self.world.array_height]
        pad = 2048
        m = n + 2 * pad
        i0 = (int(round(t0 * FS)) + pad) % (len(self.signals[0]) - m)
        f = np.fft.rfftfreq(m, 1 / FS)
        out = np.zeros((8, m))
        for src, sig in zip(self.world.sources, self.signals, strict=True):
            r = np.linalg.norm(mics - np.array(src.position), axis=1)
            spec = np.fft.rfft(sig[i0:i0 + m])[None] * np.exp(-2j * np.pi * f[None] * (r / 343.0)[:, None])
            out += np.fft.irfft(spec, m) / r[:, None]
        self.clock.sleep(n / FS)
        return AudioBlock(out[:, pad:pad + n] + self.noise * self.rng.standard_normal((8, n)), FS, t0)


def _recording(name):
    return next(r for r in recordings("test") if r.name == name)


@pytest.mark.parametrize("noise_gain", [0.0, 0.5])
def test_end_to_end_two_voices_with_the_real_localizer(noise_gain):
    from ssl_core.localizer import Localizer, LocalizerConfig
    voices = [Source((2.5, 1.5, 0.1), 0.0), Source((-1.5, 2.0, 0.1), 0.0)]
    noise = [Source((1.0, -2.0, 0.3), 0.0)] if noise_gain else []
    w = World(voices + noise)
    n = 30 * FS
    rng = np.random.default_rng(0)
    sigs = [0.01 * _voice(n, 1, 120), 0.008 * _voice(n, 2, 200)] + [0.01 * noise_gain * rng.standard_normal(n)] * bool(
        noise_gain)
    if not noise_gain:  # real recorded speech (data/sounds test part: a man, a woman), looped; the first 6 dB
        # louder (the model voices' 0.01/0.008 are within 0.5 dB at the robot: too close for pausing speech)
        sigs = [np.resize(r.samples, n) * g * np.sqrt(np.mean(sigs[0] ** 2) / np.mean(r.samples**2))
                for r, g in ((_recording("it_carlo"), 1.0), (_recording("fr_june"), 0.5))]
        # (with the white noise the localizer reports only the noise for real, pausing speech: issue 11's
        # detection; the synthetic continuous voices keep that case about the behaviour)
    loc = Localizer(cube8(), LocalizerConfig(fs=FS, n_sources=3, rel_threshold=0.15))
    b = make(w, RescueConfig(max_victims=len(sigs)), audio=RenderedAudio(w, sigs), localizer=loc)
    ev = b.run(max_time=300.0)
    assert ev[-1].decision == "all_found", [str(e) for e in ev if e.decision != "no_source"]
    found = [v.position for v in b.victims]
    for v in voices:  # every voice found, its position estimated within 15 cm
        assert min(math.dist(p, v.position[:2]) for p in found) < 0.15
    if not noise_gain:
        # the louder (nearer) voice first, and both were recognised as voices
        assert math.dist(found[0], voices[0].position[:2]) < 0.15
        assert all(v.voice >= b.config.voice_threshold for v in b.victims)
    else:
        # Broadband noise dominates SRP-PHAT even 6 dB below the voices: it is the only source reported
        # at first, so it is approached (and "found") first - then the voices.
        assert math.dist(found[0], noise[0].position[:2]) < 0.3 and b.victims[0].voice < b.config.voice_threshold
