"""Acoustic simulation: what the robot's 8-microphone cube hears in a rescue world.

Public API::

    from ssl_sim.acoustics import AcousticSimulator, AcousticConfig, SoundSource, RobotPose, ArrayMount
    sim = AcousticSimulator(world, AcousticConfig(seed=1))          # victims from world.victims
    x = sim.listen_pose(RobotPose(1.0, 1.0, yaw=0.3), 1.0, t0=0.0)  # int16 (8, 16000)

World frame metres; levels in dB SPL re 20 uPa (sources: at 1 m, free field, while sounding).
"""
from .diffraction import barrier_attenuation_db
from .ego_noise import EgoNoise, EgoNoiseConfig
from .materials import (AcousticMaterial, get_material, known_materials, register_material,
                        uniform_material)
from .noise import AmbientNoise, DiffuseNoiseField
from .pose import ArrayMount, RobotPose, point_at, rotation_matrix
from .scene import AcousticScene, ImageSet, Surface
from .sensor import ClippingWarning, Sensor, SensorConfig
from .signals import (EventStream, LoopedSignal, ShapedNoise, SignalStream, TimeKeyedNoise,
                      generator_noise, pump_noise, unit_rms)
from .simulator import AcousticConfig, AcousticSimulator
from .sources import PAPER_LEVEL_DB_SPL, SoundSource, noise_source, victim_source
from .voices import SPEAKERS, Speaker, continuous_voice, synth_knock, synth_moan, synth_phrase, victim_voice

__all__ = [
    "AcousticConfig", "AcousticMaterial", "AcousticScene", "AcousticSimulator", "AmbientNoise", "ArrayMount",
    "ClippingWarning", "DiffuseNoiseField", "EgoNoise", "EgoNoiseConfig", "barrier_attenuation_db", "EventStream", "ImageSet", "LoopedSignal", "PAPER_LEVEL_DB_SPL",
    "RobotPose", "SPEAKERS", "Sensor", "SensorConfig", "ShapedNoise", "SignalStream", "SoundSource", "Speaker",
    "Surface", "TimeKeyedNoise", "continuous_voice", "generator_noise", "get_material", "known_materials",
    "noise_source", "point_at", "pump_noise", "register_material", "rotation_matrix", "synth_knock", "synth_moan",
    "synth_phrase", "uniform_material", "unit_rms", "victim_source", "victim_voice",
]
