"""``ssl-robot``: run the rescue behaviour on the real robot or on a recording.

Real robot:    ssl-robot --serial /dev/ttyUSB0 --audio 2,3 [--channel-map A0,A1,A2,A3,B0,B1,B2,B3]
Mics only:     ssl-robot --dry-run --audio 2,3            (live audio, motors untouched)
Replay:        ssl-robot --dry-run --replay REC.wav       (8-channel WAV, simulated ideal drive)
Record:        ssl-robot ... --record DIR                 (the mission's audio, drive and clock, for --replay DIR)
Replay a mission: ssl-robot --dry-run --replay DIR        (the same audio, drive readings and times)
Devices:       ssl-robot --list-audio
Motor noise:   ssl-robot calibrate-ego-noise --serial /dev/ttyUSB0 --audio 2,3 [--out FILE]

Every decision is printed as it is taken (``--json``: one JSON object per line on stdout, every other message
on stderr). A WAV at another rate than the behaviour's 16 kHz is resampled as it is read (at least 12 kHz:
the localizer's band reaches 6 kHz). Ctrl-C stops the robot.
"""
from __future__ import annotations

import argparse
import importlib
import json
import logging
import math
import sys
from typing import TYPE_CHECKING

from robot.hal import Clock, ManualClock, WallClock
from robot.interrupt import check_interrupt, deferred_sigint
from ssl_core.broken_pipe import quiet_on_broken_pipe

# The behaviour's modules import scipy.signal (seconds): they are imported once the arguments are parsed, so that
# --help and usage errors answer at once.
if TYPE_CHECKING:
    from robot.rescue import RescueEvent
from ssl_core.version import version

PROG = "ssl-robot"
#: Rate the behaviour hears at (robot.vad.SAMPLE_RATE); a replayed WAV at another rate is resampled to it.
BEHAVIOUR_RATE_HZ = 16000
#: Lowest WAV rate replayed: the localizer's analysis band reaches 6 kHz (as ssl-locate requires).
MIN_REPLAY_RATE_HZ = 12000


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    drive = p.add_mutually_exclusive_group()
    drive.add_argument("--serial", metavar="PORT", help="drive MCU serial port (e.g. /dev/ttyUSB0) or pyserial URL")
    drive.add_argument("--dry-run", action="store_true", help="do not move: log commands, integrate ideal odometry")
    audio = p.add_mutually_exclusive_group()
    audio.add_argument("--audio", metavar="DEV_A,DEV_B",
                       help="the two 4-channel USB microphone devices (index or unique name part; see --list-audio)")
    audio.add_argument("--replay", metavar="REC.wav|DIR",
                       help="multichannel recording instead of live audio, or a mission recorded with --record")
    p.add_argument("--record", metavar="DIR", default=None,
                   help="record the mission for --replay DIR: its audio (DIR/audio.wav), drive and clock "
                        "(DIR/hal.jsonl), options (DIR/mission.json)")
    p.add_argument("--list-audio", action="store_true", help="list audio input devices and exit")
    p.add_argument("--channel-map", default="A0,A1,A2,A3,B0,B1,B2,B3",
                   help="device channel of each array mic in order, A/B = first/second device (default: %(default)s)")
    p.add_argument("--calibrate", type=float, default=2.0, metavar="S",
                   help="seconds of audio at start to measure the offset between the two devices "
                        "(clap or talk near the robot; 0 = skip) (default: %(default)s)")
    p.add_argument("--fs", type=int, default=16000, help="sample rate of live capture (Hz) (default: %(default)s)")
    p.add_argument("--array", default="cube8", help="array preset or .toml/.json geometry (default: %(default)s)")
    p.add_argument("--sources", type=int, default=3, help="sources localized per listen (default: %(default)s)")
    p.add_argument("--ego-noise", metavar="FILE.npz", default=None,
                   help="the drive's noise template (written by ssl-robot calibrate-ego-noise): the localizer "
                        "suppresses the motors while the wheels turn, so the behaviour can hear while driving "
                        "(--set listen_while_driving=true)")
    p.add_argument("--rel-threshold", type=float, default=0.15,
                   help="report sources down to this fraction of the strongest's SRP power, so that a weaker "
                        "voice can be preferred over a louder noise (default: %(default)s)")
    p.add_argument("--max-time", type=float, default=600.0, help="mission time limit (s) (default: %(default)s)")
    p.add_argument("--max-victims", type=int, default=None, help="stop after this many victims")
    p.add_argument("--realtime", action="store_true", help="with --replay: pace the replay in real time")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a RescueConfig field, e.g. --set listen_s=2.0, or a field of one of the "
                        "behaviour's other configs, e.g. --set travel.loaded_speed=5.0 (sections: "
                        + ", ".join(sorted(_SECTIONS)) + ") (repeatable)")
    p.add_argument("--json", action="store_true", help="print events as JSON lines")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging on stderr")
    return p


# ``--set SECTION.FIELD=VALUE`` reaches these configs of the behaviour (a plain FIELD: ``RescueConfig``); e.g. the
# odometry's loaded-wheel threshold must be measured on the robot's open-loop drive (``TravelConfig``), and the
# area to search is the room's floor relative to the start pose (``--set coverage.area=-1,-3,6,3``).
_SECTIONS = {"motion": "robot.motion:MotionConfig", "sound_map": "robot.sound_map:SoundMapConfig",
             "planner": "robot.planner:PlannerConfig", "occupancy": "robot.occupancy:OccupancyConfig",
             "gyro": "robot.odometry:GyroFusionConfig", "travel": "robot.odometry:TravelConfig",
             "coverage": "robot.coverage:CoverageConfig", "mount": "robot.mount:ArrayMount",
             "pursuit": "robot.pursuit:PursuitConfig", "options": "robot.options:OptionsConfig",
             "recovery": "robot.recovery:RecoveryConfig"}


def section_config(section: str) -> type:
    """The config class behind ``--set SECTION.FIELD=VALUE`` (imported when first needed)."""
    module, _, name = _SECTIONS[section].partition(":")
    return getattr(importlib.import_module(module), name)


def _rescue_config(args) -> tuple[RescueConfig, dict]:
    """``--set`` values -> (``RescueConfig``, keyword configs of ``RescueBehaviour`` by section)."""
    from robot.config_values import field_values, in_section
    from robot.rescue import RescueConfig

    values: dict[str, dict[str, str]] = {}
    for item in args.set:
        name, sep, text = item.partition("=")
        if not sep:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE or SECTION.FIELD=VALUE, e.g. --set listen_s=2.0")
        section, dot, field = name.strip().rpartition(".")
        if dot and section not in _SECTIONS:
            raise ValueError(f"--set {item!r}: unknown section {section!r}; expected one of {sorted(_SECTIONS)}")
        values.setdefault(section, {})[field] = text
    plain = values.pop("", {})
    try:
        changes = field_values(RescueConfig, plain, "--set", text=True, sep=" ")
        config = RescueConfig(**{"max_victims": args.max_victims, **changes})
    except (ValueError, TypeError) as exc:
        msg = in_section(str(exc), RescueConfig, "")   # "RescueConfig.listen_s: ..." -> "listen_s: ..."
        raise ValueError(msg if msg.startswith("--set") else f"--set {msg}") from None
    sections = {}
    for sec, vals in values.items():
        cls = section_config(sec)
        try:
            sections[sec] = cls(**field_values(cls, vals, f"--set {sec}", text=True))
        except (ValueError, TypeError) as exc:   # "SoundMapConfig.seed=-1: ..." -> "--set sound_map.seed=-1: ..."
            msg = in_section(str(exc), cls, sec)
            raise ValueError(msg if msg.startswith("--set") else f"--set {msg}") from None
    return config, sections


def _ego_noise(args, geometry, fs: int, mount):
    """The localizer's ego-noise suppression from ``--ego-noise`` (None without it)."""
    if args.ego_noise is None:
        return None
    from robot.ego_calibration import MotorMount, array_geometry_check
    from robot.mount import ArrayMount
    from ssl_core.ego_noise import EgoNoiseSuppressor, EgoNoiseTemplate

    try:
        template = EgoNoiseTemplate.load(args.ego_noise)
        array_geometry_check(geometry, template)
    except ValueError as exc:
        raise ValueError(f"--ego-noise: {exc}") from None
    if template.fs != fs:
        raise ValueError(f"--ego-noise: {args.ego_noise} was recorded at {template.fs} Hz, the audio delivers {fs} Hz")
    motors = MotorMount(array=mount if mount is not None else ArrayMount())
    return EgoNoiseSuppressor(geometry, motors.suppression_config(), template)


def _check_options(args) -> None:
    """Numbers the parser accepts but a mission cannot use; the error names the option."""
    if not (math.isfinite(args.max_time) and args.max_time > 0):
        raise ValueError(f"--max-time: expected a duration > 0 s, got {args.max_time}")
    if args.sources < 1:
        raise ValueError(f"--sources: expected an integer >= 1, got {args.sources}")
    if not (math.isfinite(args.rel_threshold) and 0 <= args.rel_threshold <= 1):
        raise ValueError(f"--rel-threshold: expected a fraction in [0, 1], got {args.rel_threshold}")
    if not (math.isfinite(args.calibrate) and args.calibrate >= 0):
        raise ValueError(f"--calibrate: expected seconds >= 0, got {args.calibrate}")
    if args.fs <= 0:
        raise ValueError(f"--fs: expected a sample rate > 0 Hz, got {args.fs}")
    if args.max_victims is not None and args.max_victims < 1:
        raise ValueError(f"--max-victims: expected an integer >= 1, got {args.max_victims}")


def _check_models() -> None:
    """Every model file the behaviour uses, loaded and run on silence before the drive or the audio opens: a bad
    one stops the program at once (exit code 2, the message names the file), not at the first listen."""
    from robot.hearing import VAD_RATE
    from robot.vad import ModelError, check_model

    try:
        check_model(VAD_RATE)
    except ModelError as exc:
        raise ValueError(str(exc)) from None


def _open_drive(args, clock: Clock):
    if args.dry_run:
        from robot.replay import DryRunDrive
        return DryRunDrive(clock)
    try:
        from robot.hardware.serial_drive import SerialDrive
    except ImportError as exc:
        raise RuntimeError(f"the serial drive backend is not available ({exc}); pyserial is needed") from exc
    return SerialDrive(args.serial)


def _open_audio(args, clock: Clock, geometry, out):
    if args.replay:
        from robot.replay import WavFileSource
        return WavFileSource(args.replay, expected_channels=geometry.n_mics, clock=clock,
                             resample_to=BEHAVIOUR_RATE_HZ, min_rate=MIN_REPLAY_RATE_HZ)
    from robot.hardware.audio import ArrayCapture, MergeConfig, parse_channel_map
    devices = [d.strip() for d in args.audio.split(",")]
    if len(devices) != 2 or not all(devices):
        raise ValueError(f"--audio {args.audio!r}: expected two devices separated by a comma, e.g. 2,3")
    cmap = parse_channel_map(args.channel_map)
    if len(cmap) != geometry.n_mics:
        raise ValueError(f"--channel-map: {len(cmap)} entries, array '{geometry.name}' has {geometry.n_mics} mics")
    cap = ArrayCapture(devices, args.fs, MergeConfig(channel_map=cmap), positions=geometry.positions, clock=clock)
    if args.calibrate > 0:
        print(f"{PROG}: measuring the offset between the two audio devices for {args.calibrate:g} s: "
              "clap or talk near the robot", file=out, flush=True)
        try:
            est = cap.calibrate(seconds=args.calibrate)
        except ValueError as exc:
            est = None
            print(f"{PROG}: offset calibration needs more audio ({exc}); continuing with offset 0, "
                  "tracking will correct it", file=out)
        if est is not None:
            state = "applied" if est.confident else "NOT applied (not confident: make a louder sound)"
            print(f"{PROG}: device offset: {est} - {state}", file=out, flush=True)
    return cap


def _monitored(args, audio, geometry, localizer, out):
    """``audio`` watched by the microphone health monitor: faults printed, faulty channels not localized."""
    from robot.hardware.audio import parse_channel_map
    from robot.monitored_audio import MonitoredAudio
    from ssl_core.health import HealthConfig, MicHealth

    cmap = parse_channel_map(args.channel_map)
    devices = [d for d, _ in cmap] if len(cmap) == geometry.n_mics else None

    def report(time: float, new, cleared) -> None:
        for state, faults in (("fault", new), ("cleared", cleared)):
            for f in faults:
                if args.json:
                    print(json.dumps({"time": round(time, 3), "microphone": state, "kind": f.kind,
                                      "channels": list(f.channels), "detail": f.detail}), file=out, flush=True)
                else:
                    print(f"{PROG}: microphone {state} at {time:.1f} s: {f}", file=out, flush=True)

    monitor = MicHealth(geometry, HealthConfig(fs=audio.sample_rate), devices=devices)
    return MonitoredAudio(audio, monitor, localizer, on_change=report)


class _MissionClock(WallClock):
    """Wall time from the start of the program (s), so printed event times read as mission time."""

    def __init__(self) -> None:
        self._t0 = super().now()

    def now(self) -> float:
        return super().now() - self._t0

    def sleep(self, seconds: float) -> None:
        check_interrupt()   # every wait of the motion primitives is a safe place to stop (robot.interrupt)
        super().sleep(seconds)


def _stop(drive) -> str:
    """Stop the drive and say what happened (the behaviour tried already; this reports the truth)."""
    try:
        drive.stop()
    except Exception as exc:
        return f"stopping the robot FAILED: {type(exc).__name__}: {exc}; switch the motors off"
    return "robot stopped"


def _print_event(e: RescueEvent, as_json: bool, out) -> None:
    if as_json:
        data = {k: v for k, v in e.data.to_dict().items() if k != "candidates"}
        print(json.dumps({"time": round(e.time, 3), "state": e.state.value, "decision": e.decision,
                          "reason": e.reason, "data": data}, default=_jsonable), file=out, flush=True)
    else:
        print(e, file=out, flush=True)


def _jsonable(o):
    try:
        return o.tolist()
    except AttributeError:
        return str(o)


@quiet_on_broken_pipe
def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["calibrate-ego-noise"]:  # the drive's noise template (robot.ego_calibration)
        from robot.ego_calibration import main as calibrate_main
        return calibrate_main(argv[1:], out)
    args = _parser().parse_args(argv)
    # with --json, stdout carries the JSON lines alone: every other message goes to stderr
    say = sys.stderr if args.json else out
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")

    def fail(msg: str) -> int:
        print(f"{PROG}: error: {msg}", file=sys.stderr)
        return 2

    if args.list_audio:
        from robot.hardware.audio import list_input_devices
        try:
            lines = list_input_devices()
        except ImportError as exc:
            return fail(str(exc))
        print("\n".join(lines) or "no audio input devices", file=out)
        return 0
    if not (args.serial or args.dry_run):
        return fail("choose the drive: --serial PORT (real robot) or --dry-run (no motors)")
    if not (args.audio or args.replay):
        return fail("choose the audio: --audio DEV_A,DEV_B (live array) or --replay REC.wav")
    if args.replay and args.serial:
        return fail("--replay moves nothing real: use it with --dry-run")
    if args.realtime and not args.replay:
        return fail("--realtime only applies to --replay")
    from robot.mission_log import MissionReplay, MissionRecorder, is_mission
    mission = bool(args.replay) and is_mission(args.replay)
    if mission and args.realtime:
        return fail("--realtime: a recorded mission replays with its own times")

    from robot.rescue import RescueBehaviour
    from ssl_core.geometry import get_array
    from ssl_core.localizer import Localizer, LocalizerConfig

    try:
        _check_options(args)
        config, sections = _rescue_config(args)
        _check_models()
    except ValueError as exc:
        return fail(str(exc))
    drive = audio = recorder = None
    try:
        geometry = get_array(args.array)
        if mission:
            replay = MissionReplay(args.replay, expected_channels=geometry.n_mics)
            clock, drive, audio = replay.clock(), replay.drive(), replay.audio()
        else:
            clock = ManualClock() if args.replay and not args.realtime else _MissionClock()
            drive = _open_drive(args, clock)
            audio = _open_audio(args, clock, geometry, say)
        if args.record:
            recorder = MissionRecorder(args.record, meta={"array": geometry.name, "argv": list(
                sys.argv[1:] if argv is None else argv)})
            clock, drive, audio = recorder.clock(clock), recorder.drive(drive), recorder.audio(audio)
        localizer = Localizer(geometry, LocalizerConfig(fs=audio.sample_rate, n_sources=args.sources,
                                                        rel_threshold=args.rel_threshold),
                              ego_noise=_ego_noise(args, geometry, audio.sample_rate, sections.get("mount")))
        audio = _monitored(args, audio, geometry, localizer, out)
    except (ValueError, FileNotFoundError, ImportError, OSError, RuntimeError) as exc:
        for dev in (drive, audio, recorder):
            if dev is not None:
                dev.close()
        return fail(str(exc))

    src = args.replay or f"audio devices {args.audio}"
    drv = "dry run (no motors)" if args.dry_run else f"drive on {args.serial}"
    print(f"{PROG}: rescue on {src}, {drv}, array {geometry.name}, up to {args.max_time:g} s"
          + (f", recording to {args.record}" if args.record else ""), file=say, flush=True)
    try:
        behaviour = RescueBehaviour(audio, drive, clock, localizer, config, **sections)
    except ValueError as exc:   # a value the configs accept that the parts together cannot use (e.g. a grid)
        for dev in (drive, audio):
            dev.close()
        return fail(str(exc))
    code = 0
    reader_gone = False
    try:
        with deferred_sigint():
            t_end = clock.now() + args.max_time
            while not behaviour.done and clock.now() < t_end:
                for e in behaviour.step():
                    _print_event(e, args.json, out)
                check_interrupt()
        if not behaviour.done:
            print(f"{PROG}: mission time of {args.max_time:g} s used up", file=say)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted, {_stop(drive)}", file=say)
        code = 130
    except BrokenPipeError:  # the reader of stdout went away: stop the robot, then end quietly
        _stop(drive)
        reader_gone = True
    except Exception as exc:
        print(f"{PROG}: error: {type(exc).__name__}: {exc} ({_stop(drive)})", file=sys.stderr)
        code = 1
    finally:
        for dev in (drive, audio, recorder):
            try:
                if dev is not None:
                    dev.close()
            except Exception as exc:
                print(f"{PROG}: closing {type(dev).__name__} failed: {exc}", file=sys.stderr)
    if reader_gone:
        raise BrokenPipeError
    if args.record:
        print(f"{PROG}: mission recorded in {args.record} (replay: {PROG} --dry-run --replay {args.record})",
              file=say)
    if not args.json:
        print(f"{PROG}: {len(behaviour.victims)} victim(s) found", file=out)
        for i, v in enumerate(behaviour.victims, 1):
            print(f"  #{i} at x={v.position[0]:+.2f} m y={v.position[1]:+.2f} m (odometry frame), t={v.time:.1f} s: "
                  f"{v.criterion}", file=out)
    return code


if __name__ == "__main__":
    sys.exit(main())
