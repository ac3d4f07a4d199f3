"""Hearing while driving (robot.drive_hearing): windows cut from the audio read at every control tick, heard at
the pose of their middle; on the simulated robot the caller's direction and the motors' silence are checked
against the simulator's geometry."""
import math
import warnings
from dataclasses import replace

import numpy as np
import pytest

from robot.drive_hearing import DriveHearing
from robot.hal import AudioBlock, ManualClock
from robot.listening import Listener
from robot.motion import Motion, MotionConfig
from robot.odometry import Odometry
from ssl_core.geometry import cube8
from ssl_core.localizer import Localizer
from ssl_sim.acoustics import AcousticConfig, AmbientNoise, SoundSource
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig
from ssl_sim.backends import make_sim_hal
from ssl_sim.calibration import ego_noise_suppressor
from ssl_sim.scenario import load_scenario
from ssl_sim.acoustics.voices import continuous_voice
from ssl_sim.world import Room, World

FS = 16000


class _FileAudio:
    """A source whose reads do not let time pass (a file): sample k carries the value k on every channel."""

    sample_rate, n_channels = FS, 8

    def __init__(self) -> None:
        self.position = 0

    def read(self, n: int) -> AudioBlock:
        x = np.repeat(np.arange(self.position, self.position + n, dtype=float)[None], 8, axis=0)
        block = AudioBlock(x, FS, self.position / FS)
        self.position += n
        return block

    def flush(self) -> None:
        pass


class _Ear:
    """What DriveHearing needs of a Listener, recording what it is asked to hear."""

    def __init__(self) -> None:
        self.audio = _FileAudio()
        self.heard: list[dict] = []

    def wheel_speeds(self):
        return np.array([1.0, -2.0, 3.0])

    def hear(self, block, min_power, *, time, pose, wheel_speeds):
        self.heard.append(dict(block=block, time=time, pose=pose, wheels=wheel_speeds))
        return len(self.heard)


def test_every_window_is_heard_whole_at_the_pose_of_its_middle():
    clock, ear, windows = ManualClock(), _Ear(), []
    speed = 0.2   # m/s along +x, turning 0.1 rad/s: the truth the poses are checked against

    def pose():
        return np.array([speed * clock.now(), 0.0, 0.1 * clock.now()])

    hearing = DriveHearing(ear, clock, pose, window_s=1.0, min_power=0.0,
                           on_window=lambda listen, traj: windows.append(traj) is None and len(windows) < 2)
    hearing.start()
    going = [hearing.pace(0.05) for _ in range(50)]       # 2.5 s of control ticks
    assert len(ear.heard) == 2 and hearing.windows == 2
    assert going.index(False) == 39 and hearing.stopped     # the handler ended the move at the second window
    for k, h in enumerate(ear.heard):
        x = h["block"].samples
        assert x.shape == (8, FS)                           # a whole window ...
        np.testing.assert_array_equal(x[0], np.arange(k * FS, (k + 1) * FS))   # ... nothing dropped or repeated
        assert h["time"] == pytest.approx(k + 1.0)          # the clock at the window's end
        middle = k + 0.5
        np.testing.assert_allclose(h["pose"], (speed * middle, 0.0, 0.1 * middle), atol=1e-9)
        np.testing.assert_allclose(h["wheels"], (1.0, -2.0, 3.0))
        assert windows[k][0, 0] == pytest.approx(k) and windows[k][-1, 0] == pytest.approx(k + 1.0)


def test_a_bad_window_is_named():
    with pytest.raises(ValueError, match="window_s"):
        DriveHearing(_Ear(), ManualClock(), lambda: np.zeros(3), window_s=0.0, min_power=0.0,
                     on_window=lambda *a: True)


@pytest.fixture(scope="module")
def suppressor():
    return ego_noise_suppressor(EgoNoiseConfig(), FS, 0.27)


def test_driving_past_a_talker_hears_her_from_each_window_middle_and_keeps_her_track(suppressor):
    world = World(room=Room(size=(5.0, 4.0, 2.5)), robot_start=(1.5, 2.0, 0.0), name="drive_hearing")
    talker = np.array([3.5, 2.0, 0.4])
    src = SoundSource(tuple(talker), continuous_voice("female", seed=3, fs=FS), 70.0, name="talker")
    cfg = AcousticConfig(seed=1, rt60_s=0.3, max_rir_s=0.5, ambient=AmbientNoise(30.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hal = make_sim_hal(world, sources=[src], acoustic_config=cfg, ego_noise=EgoNoiseConfig())
    try:
        hal.robot.step(0.2)
        p = hal.robot.pose()
        odometry = Odometry(start_pose=(p.x, p.y, p.yaw))
        motion = Motion(hal.drive, hal.clock, odometry, MotionConfig())
        localizer = Localizer(cube8(), ego_noise=suppressor)
        listener = Listener(hal.audio, hal.clock, localizer, cube8(), speech=lambda *a: 0.0, drive=hal.drive)
        heard = []

        def on_window(listen, trajectory):
            heard.append((listen, trajectory))
            return len(heard) < 3

        hearing = DriveHearing(listener, hal.clock, lambda: odometry.pose, 1.0, 0.0, on_window)
        hearing.start()
        made = motion.translate(math.pi / 2, 2.0, pace=hearing.pace)   # sideways, the talker 2 m ahead
    finally:
        hal.close()
    assert len(heard) == 3
    assert 0.4 < made < 1.0                       # ended at the third window, well short of the 2 m asked
    ids = set()
    for listen, trajectory in heard:
        mid = 0.5 * (trajectory[0, 0] + trajectory[-1, 0])
        x = np.interp(mid, trajectory[:, 0], trajectory[:, 1])
        y = np.interp(mid, trajectory[:, 0], trajectory[:, 2])
        yaw = np.interp(mid, trajectory[:, 0], trajectory[:, 3])
        truth = math.atan2(talker[1] - y, talker[0] - x) - yaw
        best = listen.evidence[0]
        assert abs(math.degrees(math.remainder(best.azimuth - truth, 2 * math.pi))) <= 5.0
        ids.add(best.track_id)
    assert len(ids) == 1 and None not in ids      # one track through the drive (translation compensated)


def test_the_motors_residue_makes_no_peak_on_the_rim_of_their_mask(suppressor):
    """Driving through the light rubble among its callers, from standing in eight directions: no detection just
    outside the directions masked around the motors (a search that masks before it looks for maxima finds the
    motors' lobes where the mask ends: 4 of these 16 windows had a detection 0-1 deg outside it)."""
    sc = load_scenario("light_rubble_three")
    world = sc.world(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hal = make_sim_hal(world, sources=sc.sources(world, 0), acoustic_config=sc.acoustic_config(0),
                           ego_noise=EgoNoiseConfig())
    loc = Localizer(cube8(), sc.localizer, ego_noise=suppressor)
    motors = suppressor._sources / np.linalg.norm(suppressor._sources, axis=1, keepdims=True)
    off = []
    try:
        for heading in np.arange(8) * math.pi / 4:
            hal.drive.stop()
            hal.audio.read(4000)
            hal.drive.set_twist(0.25 * math.cos(heading), 0.25 * math.sin(heading), 0.0)
            for _ in range(2):   # 1 s windows of 50 ms reads, the wheels' mean speed over each
                w, x = [], []
                for _ in range(20):
                    w.append(hal.drive.odometry().wheel_speeds)
                    x.append(hal.audio.read(800).samples)
                res = loc.locate(np.concatenate(x, axis=1), wheel_speeds=np.mean(w, axis=0))
                off += [float(np.degrees(np.arccos(np.clip(motors @ np.asarray(d.direction), -1, 1))).min())
                        for d in res.detections]
    finally:
        hal.close()
    exclude = suppressor.config.exclude_deg
    assert off and not [a for a in off if exclude <= a <= exclude + 5.0], off


def test_a_rescue_run_that_hears_while_driving_uses_its_own_found_model_and_hears_the_callers():
    from ssl_sim.runner import RescueRun

    sc = load_scenario("light_rubble_three").with_overrides(time_limit_s=25.0)
    sc = replace(sc, behaviour=replace(sc.behaviour, listen_while_driving=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = RescueRun(sc, seed=0)
        r = run.run()
    b = run.behaviour
    assert b.drive_hearing is not None and b.localizer.ego_noise is not None
    assert b.finder.model.provenance["data"].endswith("assessments_driving.csv.gz")
    driving = [e for e in b.events if e.reason.startswith("while driving")]
    assert b.drive_hearing.windows >= 3 and len(driving) == b.drive_hearing.windows
    # every localizer result is scored against the truth at its window's middle (the runner's listens): the
    # callers' detections heard while driving are as accurate as those heard standing
    assert len(r["listens"]) >= b.drive_hearing.windows + 3
    moving_times = {round(e.time, 2) for e in driving}
    # the runner's own flag (the array moved over the window, from the simulator's poses) marks the same windows
    assert {round(rec["time_s"], 2) for rec in r["listens"] if rec["moving"]} == moving_times
    errors = {True: [], False: []}
    for rec in r["listens"]:
        errors[round(rec["time_s"], 2) in moving_times] += [d["error_deg"] for d in rec["detections"]
                                                             if d.get("source_kind") == "victim"]
    assert errors[True] and errors[False]
    assert np.median(errors[True]) <= max(10.0, np.median(errors[False]) + 3.0), errors
