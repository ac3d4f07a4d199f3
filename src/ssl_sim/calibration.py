"""The simulated robot's ego-noise calibration, as the real robot's is made before a mission.

``ego_noise_suppressor`` runs ``robot.ego_calibration.calibrate_ego_noise`` (``ssl-robot calibrate-ego-noise`` on
hardware) on the simulated robot with the scenario's motor noise, in the empty paper lab with nobody calling, and
builds the localizer's ``ssl_core.ego_noise.EgoNoiseSuppressor`` from that template and the robot's motor mount.
The calibration (21 s of simulated turning through 15 wheel speeds, 2.7 s of CPU) is made once per process for
each motor-noise model and array height: a robot is calibrated once, not in every room it searches.
"""
from __future__ import annotations

import warnings
from dataclasses import replace
from functools import lru_cache

from robot.ego_calibration import MotorMount, calibrate_ego_noise
from robot.mount import ArrayMount
from ssl_core.ego_noise import EgoNoiseSuppressor, EgoNoiseTemplate
from ssl_core.geometry import cube8
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig
from ssl_sim.backends import make_sim_hal
from ssl_sim.scenario import load_scenario

__all__ = ["ego_noise_template", "ego_noise_suppressor"]

CALIBRATION_SCENE = "paper_lab"   # a quiet room with floor to turn in place
CALIBRATION_SEED = 100            # the calibration room's acoustic draw (not any run's)


@lru_cache(maxsize=4)
def ego_noise_template(ego: EgoNoiseConfig, fs: int) -> EgoNoiseTemplate:
    """The template a calibration run of the simulated drive with motor noise ``ego`` records at ``fs`` Hz."""
    sc = load_scenario(CALIBRATION_SCENE)
    acoustic = sc.acoustic_config(CALIBRATION_SEED)
    if acoustic.fs != fs:
        acoustic = replace(acoustic, fs=fs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the empty room's own setup notes
        hal = make_sim_hal(sc.world(0), sources=[], acoustic_config=acoustic, ego_noise=ego)
    try:
        return calibrate_ego_noise(hal.drive, hal.audio, hal.clock, record_s=1.0, settle_s=0.4)
    finally:
        hal.close()


def ego_noise_suppressor(ego: EgoNoiseConfig, fs: int, array_height_m: float) -> EgoNoiseSuppressor:
    """The localizer's suppression of the drive ``ego`` for a cube whose centre is ``array_height_m`` up."""
    mount = MotorMount(array=ArrayMount(height_m=array_height_m))
    return EgoNoiseSuppressor(cube8(), mount.suppression_config(), ego_noise_template(ego, int(fs)))
