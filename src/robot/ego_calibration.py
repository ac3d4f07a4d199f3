"""The drive's own noise at the array: where the motors are, and a calibration run that records its spectrum.

``MotorMount``: the three gear motors' centres in the ARRAY frame (m), from the robot's mechanical layout
(wheel angles of ``robot.kinematics``, the motors' radial offset and axle height, the array's height on
its mast). The defaults are the paper robot's (the same numbers the simulator's MuJoCo model is built from);
a different chassis sets its own. :func:`calibrate_ego_noise` turns the robot in place through a series of
wheel speeds with no one talking and records, at each, the channel-mean power spectral density at the
array (``ssl_core.ego_noise.EgoNoiseTemplate``, the file ``ssl-robot calibrate-ego-noise`` writes).
Turning in place runs all three wheels at the same speed and needs no more floor than the robot's
footprint.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robot.hal import AudioSource, Clock, DriveBase, as_float_audio
from robot.kinematics import OmniDriveParams
from robot.mount import ArrayMount
from ssl_core.ego_noise import EgoNoiseConfig, EgoNoiseTemplate
from ssl_core.geometry import ArrayGeometry

#: Calibrated wheel speeds (rad/s): geometric steps over the drive's range, 0.75-19 rad/s (the robot's
#: 0.04-0.95 m/s rim speed on 5 cm wheels); successive speeds 1.25x apart, so the nearest template is
#: within 12 % in speed (its tone within 12 % in frequency before the template is stretched).
DEFAULT_SPEEDS = tuple(float(v) for v in np.round(0.75 * 1.25 ** np.arange(15), 3))


@dataclass(frozen=True)
class MotorMount:
    """Motor positions relative to the array (m, robot frame = array frame: the cube is mounted level and
    aligned with the chassis). ``motor_radius_m``: motor centres from the robot's vertical axis;
    ``motor_height_m``: their axle height above the floor (the wheel radius); ``array``: the cube's mounting
    (its centre 0.27 m above the floor on the built robot)."""

    drive: OmniDriveParams = field(default_factory=OmniDriveParams)
    motor_radius_m: float = 0.0679
    motor_height_m: float = 0.05
    array: ArrayMount = ArrayMount(height_m=0.27)

    def __post_init__(self) -> None:
        for name in ("motor_radius_m", "motor_height_m"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"MotorMount.{name}: expected a finite length >= 0 m, got {v!r}")
        if not self.motor_height_m < self.array.height_m:
            raise ValueError(f"MotorMount.motor_height_m: expected below the array (height_m = "
                             f"{self.array.height_m} m)")

    def motor_positions(self) -> np.ndarray:
        """(3, 3) motor centres in the array frame (m), wheel order of ``robot.kinematics``."""
        th = np.asarray(self.drive.wheel_angles, float)
        r = self.motor_radius_m
        return np.stack([r * np.cos(th), r * np.sin(th), np.full(3, self.motor_height_m - self.array.height_m)],
                        axis=1)

    def suppression_config(self, **kw) -> EgoNoiseConfig:
        """``ssl_core.ego_noise.EgoNoiseConfig`` for these motors (floor images included); ``kw`` overrides."""
        return EgoNoiseConfig(motor_positions=tuple(map(tuple, self.motor_positions())),
                              floor_below_m=self.array.height_m, **kw)


def calibrate_ego_noise(drive: DriveBase, audio: AudioSource, clock: Clock, speeds=DEFAULT_SPEEDS,
                    record_s: float = 2.0, settle_s: float = 0.5,
                    drive_params: OmniDriveParams = OmniDriveParams(), progress=None) -> EgoNoiseTemplate:
    """Turn in place at each wheel speed of ``speeds`` (rad/s; alternating direction so the robot ends
    near its start heading), let the motors settle ``settle_s``, record ``record_s`` of audio and the
    wheels' measured speed; stop. Returns the template at the measured mean |wheel speed| of each step.
    Nobody may talk meanwhile (what is recorded is taken as the drive's noise). ``progress(i, n, speed)``:
    optional callback per step."""
    speeds = [float(s) for s in speeds]
    if not speeds or any(not (0 < s <= drive_params.max_wheel_speed) for s in speeds):
        raise ValueError(f"speeds: expected wheel speeds in (0, {drive_params.max_wheel_speed}] rad/s, "
                         f"got {speeds}")
    if not record_s > 0 or not settle_s >= 0:
        raise ValueError(f"record_s: expected > 0 s and settle_s >= 0 s, got {record_s}, {settle_s}")
    fs = audio.sample_rate
    n = int(round(record_s * fs))
    # wheel speed = base_radius * omega / wheel_radius for a turn in place (robot.kinematics)
    k = drive_params.wheel_radius / drive_params.base_radius
    recs, measured = [], []
    try:
        for i, s in enumerate(speeds):
            if progress is not None:
                progress(i, len(speeds), s)
            omega = (1 if i % 2 == 0 else -1) * s * k
            drive.set_twist(0.0, 0.0, omega)
            ticks = max(1, int(np.ceil(settle_s / 0.1)))
            for _ in range(ticks):  # refresh the command (hardware watchdogs) while settling
                drive.set_twist(0.0, 0.0, omega)
                clock.sleep(settle_s / ticks)
            audio.flush()
            chunks, w = [], []
            got = 0
            while got < n:  # read in 0.25 s pieces, refreshing the command and sampling the encoders
                drive.set_twist(0.0, 0.0, omega)
                b = audio.read(min(n - got, fs // 4))
                chunks.append(as_float_audio(b.samples))
                got += chunks[-1].shape[1]
                w.append(np.abs(np.asarray(drive.odometry().wheel_speeds, float)))
            recs.append(np.concatenate(chunks, axis=1))
            measured.append(float(np.mean(w)))
    finally:
        drive.stop()
    if len(set(np.round(measured, 6))) != len(measured):
        raise RuntimeError(f"calibrate_ego_noise: the wheels did not reach distinct speeds (measured {measured} "
                           "rad/s): is the drive stalled or lifted?")
    return EgoNoiseTemplate.from_recordings(measured, recs, fs)


def array_geometry_check(geometry: ArrayGeometry, template: EgoNoiseTemplate) -> None:
    """Refuse a template recorded with another microphone count than ``geometry``'s."""
    if template.channels != geometry.n_mics:
        raise ValueError(f"ego-noise template: recorded with {template.channels} microphones, "
                         f"the array has {geometry.n_mics}")


def main(argv: list[str] | None = None, out=None) -> int:
    """``ssl-robot calibrate-ego-noise --serial PORT --audio DEV_A,DEV_B [--out FILE]``: turn in place through
    the wheel-speed range with nobody talking and write the template file (``ssl_core.ego_noise``)."""
    import argparse
    import sys

    from robot import cli

    out = out or sys.stdout
    p = argparse.ArgumentParser(prog=f"{cli.PROG} calibrate-ego-noise", description=main.__doc__)
    p.add_argument("--serial", metavar="PORT", required=True, help="drive MCU serial port or pyserial URL")
    p.add_argument("--audio", metavar="DEV_A,DEV_B", required=True, help="the two 4-channel USB microphone devices")
    p.add_argument("--channel-map", default="A0,A1,A2,A3,B0,B1,B2,B3", help="as for ssl-robot (default: %(default)s)")
    p.add_argument("--fs", type=int, default=16000, help="sample rate (Hz) (default: %(default)s)")
    p.add_argument("--array", default="cube8", help="array preset or geometry file (default: %(default)s)")
    p.add_argument("--record-s", type=float, default=2.0, help="seconds recorded per speed (default: %(default)s)")
    p.add_argument("--out", default="ego_noise_template.npz", help="template file to write (default: %(default)s)")
    args = p.parse_args(argv)
    args.dry_run, args.replay, args.calibrate = False, None, 2.0
    if not (np.isfinite(args.record_s) and args.record_s > 0.1):
        print(f"{p.prog}: error: --record-s: expected > 0.1 s, got {args.record_s}", file=sys.stderr)
        return 2
    from ssl_core.geometry import get_array

    drive = audio = None
    try:
        geometry = get_array(args.array)
        clock = cli._MissionClock()
        drive = cli._open_drive(args, clock)
        audio = cli._open_audio(args, clock, geometry, out)
        print(f"{p.prog}: keep quiet: the robot turns in place through {len(DEFAULT_SPEEDS)} wheel speeds "
              f"({DEFAULT_SPEEDS[0]:g}-{DEFAULT_SPEEDS[-1]:g} rad/s), about "
              f"{len(DEFAULT_SPEEDS) * (args.record_s + 0.5):.0f} s", file=out, flush=True)
        template = calibrate_ego_noise(drive, audio, clock, record_s=args.record_s,
                                       progress=lambda i, n, s: print(f"  {i + 1}/{n}: {s:g} rad/s", file=out,
                                                                      flush=True))
        array_geometry_check(geometry, template)
        template.save(args.out)
    except (ValueError, FileNotFoundError, ImportError, OSError, RuntimeError) as exc:
        print(f"{p.prog}: error: {exc}", file=sys.stderr)
        return 1
    finally:
        for dev in (drive, audio):
            if dev is not None:
                dev.close()
    for s, lv in zip(template.speeds_rad_s, template.level_dbfs):
        print(f"  {s:6.2f} rad/s: {lv:6.1f} dB re full scale (300-6000 Hz)", file=out)
    print(f"{p.prog}: wrote {args.out}", file=out)
    return 0
