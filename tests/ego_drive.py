"""A simulated drive for the ego-noise tests: the robot drives through the paper's lab with its motors
audible while the streaming localizer and tracker listen; truth from the simulator's geometry."""
from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from robot.ego_calibration import MotorMount
from ssl_core.ego_noise import EgoNoiseSuppressor, EgoNoiseTemplate
from ssl_core.geometry import cube8
from ssl_core.localizer import Localizer
from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE, Tracker
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig as SimEgoNoise
from ssl_sim.backends import array_frame_directions, make_sim_hal
from ssl_sim.calibration import ego_noise_template
from ssl_sim.scenario import load_scenario

BLOCK = 2048  # one localizer window (8 hops of 256 samples at 16 kHz)


def calibration_template() -> EgoNoiseTemplate:
    """``robot.ego_calibration`` run on the simulated robot in the empty lab, nobody calling (cached)."""
    return ego_noise_template(SimEgoNoise(), 16000)


def suppressor(template: EgoNoiseTemplate | None, **kw) -> EgoNoiseSuppressor | None:
    return None if template is None else EgoNoiseSuppressor(cube8(), MotorMount().suppression_config(**kw), template)


def drive(sup: EgoNoiseSuppressor | None, twists, seconds_each: float, start=(3.0, 3.6, 0.0), with_caller=True,
          seed: int = 1, on_window=None):
    """Drive ``twists`` (vx, vy, omega) for ``seconds_each`` each after 0.5 s at the first, streaming the audio
    through the localizer (tracking gate) and a tracker compensated with the array's true motion between
    windows. ``on_window(time, tracks, caller_direction_array_frame)`` is called per window (direction None
    without a caller). Returns the list of confirmed track ids ever seen."""
    sc = load_scenario("paper_lab")
    world = sc.world(seed)
    world = replace(world, robot_start=start)
    sources = sc.sources(world, seed) if with_caller else []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hal = make_sim_hal(world, sources=sources, acoustic_config=sc.acoustic_config(seed))
    loc = Localizer(cube8(), replace(sc.localizer, min_significance=TRACKING_MIN_SIGNIFICANCE), ego_noise=sup)
    tracker = Tracker()
    caller = np.asarray(world.victims[0].position, float)[None]
    ids: set[int] = set()
    try:
        hal.drive.set_twist(*twists[0])
        hal.audio.read(8000)  # accelerate
        prev = hal.robot.array_pose()
        for tw in twists:
            hal.drive.set_twist(*tw)
            for _ in range(int(round(seconds_each * 16000 / BLOCK))):
                w = hal.drive.odometry().wheel_speeds
                block = hal.audio.read(BLOCK)
                origin, rot = hal.audio.last_array_poses[-1]
                for r in loc.process(block.samples, block.sample_rate, wheel_speeds=w):
                    tracks = tracker.update(r.detections, r.time, rotation=rot.T @ prev[1],
                                            translation=rot.T @ (origin - prev[0]))
                    prev = (origin, rot)
                    ids.update(t.id for t in tracks)
                    if on_window is not None:
                        u = None
                        if with_caller:
                            az, el, _ = array_frame_directions(origin, rot, caller)
                            u = np.array([np.cos(el[0]) * np.cos(az[0]), np.cos(el[0]) * np.sin(az[0]), np.sin(el[0])])
                        on_window(r.time, tracks, u)
    finally:
        hal.close()
    return sorted(ids)


def caller_track_errors(sup: EgoNoiseSuppressor | None, speed: float = 0.2, seconds: float = 6.0, seed: int = 1):
    """Sideways drive at ``speed`` past the caller (1.5-1.7 m ahead): per 1 s, the azimuth error (deg) of the
    strongest confirmed track (highest SRP power of its last detection) at the second's last window; inf
    when there is no confirmed track."""
    per_window: list[tuple[float, float]] = []

    def on_window(t, tracks, u):
        if not tracks:
            per_window.append((t, np.inf))
            return
        best = max(tracks, key=lambda x: x.power)
        err = abs((np.degrees(best.azimuth - np.arctan2(u[1], u[0])) + 180) % 360 - 180)
        per_window.append((t, err))

    drive(sup, [(0.0, -speed, 0.0)], seconds, seed=seed, on_window=on_window)
    t0 = per_window[0][0]
    seconds_end = {}
    for t, e in per_window:
        seconds_end[int((t - t0) // 1.0)] = e
    return np.array([seconds_end[k] for k in sorted(seconds_end)])
