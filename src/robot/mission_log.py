"""A mission recorded for replay: the audio the behaviour read and every answer its drive and clock gave.

``ssl-robot --record DIR`` writes

- ``DIR/audio.wav``: the microphone blocks the behaviour read, in order, one channel per microphone (16-bit PCM
  when the source gives int16, else 32-bit float: exact for any ADC of up to 24 bits); written block by block
  (the header's sizes are kept current, so a mission that ends abruptly still leaves a readable file);
- ``DIR/hal.jsonl``: one JSON object per line, in call order: every ``clock.now()`` the behaviour asked and what
  it got (``{"now": t}``), every clock sleep (``{"sleep": s}``), audio read (``{"read": n, "ts": t}``: samples
  and the block's timestamp), audio flush / resync, drive command (``{"twist": [vx, vy, omega]}``,
  ``{"stop": true}``) and drive reading (``{"odometry": {...}}``, ``{"status": {...}}``);
- ``DIR/mission.json``: what was recorded (rate, channels, array, the options of the run).

``ssl-robot --dry-run --replay DIR`` feeds the behaviour the same audio, readings and times in the same order:
the same behaviour with the same options takes the same decisions, on a robot's mission as on a simulated one.
When it asks for something other than what the mission did next (other options or code), the replay stops with
:class:`MissionDiverged` naming the first difference.
"""
from __future__ import annotations

import json
import struct
from dataclasses import asdict
from pathlib import Path

import numpy as np

from robot.hal import AudioBlock, AudioSource, Clock, DriveBase, DriveStatus, EndOfAudio, WheelOdometry

AUDIO_FILE, LOG_FILE, META_FILE = "audio.wav", "hal.jsonl", "mission.json"
FORMAT = "ssl-robot mission"


class MissionDiverged(RuntimeError):
    """The replayed behaviour asked for something the recorded mission did not do at that point."""


class _StreamingWav:
    """A WAV file written block by block: 16-bit PCM or 32-bit IEEE float, the header patched after each block."""

    def __init__(self, path: Path, sample_rate: int, n_channels: int, float_samples: bool) -> None:
        self._f = open(path, "wb")
        self._float = float_samples
        width = 4 if float_samples else 2
        self._frame = width * n_channels
        fmt_tag = 3 if float_samples else 1
        self._f.write(b"RIFF" + struct.pack("<I", 36) + b"WAVE")
        self._f.write(b"fmt " + struct.pack("<IHHIIHH", 16, fmt_tag, n_channels, sample_rate,
                                            sample_rate * self._frame, self._frame, 8 * width))
        self._f.write(b"data" + struct.pack("<I", 0))
        self._data_bytes = 0

    def write(self, samples: np.ndarray) -> None:
        """``samples`` (channels, n)."""
        if self._float:
            x = np.asarray(samples, np.float32) if samples.dtype != np.int16 else samples / np.float32(32768.0)
        else:
            x = samples if samples.dtype == np.int16 else np.clip(np.round(np.asarray(samples) * 32768.0),
                                                                      -32768, 32767)
        raw = np.ascontiguousarray(np.asarray(x, "<f4" if self._float else "<i2").T).tobytes()
        self._f.write(raw)
        self._data_bytes += len(raw)
        end = self._f.tell()
        self._f.seek(4)
        self._f.write(struct.pack("<I", 36 + self._data_bytes))
        self._f.seek(40)
        self._f.write(struct.pack("<I", self._data_bytes))
        self._f.seek(end)

    def close(self) -> None:
        self._f.close()


class MissionRecorder:
    """Writes a mission to ``directory`` (created; it must not hold a recording already). Wrap the audio source,
    the drive and the behaviour's clock with :meth:`audio`, :meth:`drive` and :meth:`clock`; :meth:`close` at
    the end."""

    def __init__(self, directory: str | Path, meta: dict | None = None) -> None:
        self.directory = Path(directory)
        if self.directory.exists() and not self.directory.is_dir():
            raise ValueError(f"--record {self.directory}: exists and is not a directory")
        if any((self.directory / f).exists() for f in (AUDIO_FILE, LOG_FILE, META_FILE)):
            raise ValueError(f"--record {self.directory}: holds a recorded mission already; choose a new directory")
        self.directory.mkdir(parents=True, exist_ok=True)
        self._log = open(self.directory / LOG_FILE, "w", encoding="utf-8")
        self._meta = {"format": FORMAT, "version": 1, "audio": AUDIO_FILE, "log": LOG_FILE, **(meta or {})}
        self._wav: _StreamingWav | None = None

    def entry(self, **item) -> None:
        self._log.write(json.dumps(item, default=_jsonable) + "\n")

    def audio(self, source: AudioSource) -> AudioSource:
        return _RecordedAudio(source, self)

    def drive(self, drive: DriveBase) -> DriveBase:
        return _RecordedDrive(drive, self)

    def clock(self, clock: Clock) -> Clock:
        return _RecordedClock(clock, self)

    def _block(self, block: AudioBlock) -> None:
        if self._wav is None:
            samples = block.samples
            self._meta.update(sample_rate=int(block.sample_rate), n_channels=int(samples.shape[0]),
                              sample_format="int16" if samples.dtype == np.int16 else "float32")
            self._wav = _StreamingWav(self.directory / AUDIO_FILE, int(block.sample_rate), int(samples.shape[0]),
                                      samples.dtype != np.int16)
            self._write_meta()
        self._wav.write(block.samples)

    def _write_meta(self) -> None:
        (self.directory / META_FILE).write_text(json.dumps(self._meta, indent=1))

    def close(self) -> None:
        if self._wav is not None:
            self._wav.close()
        self._log.close()
        self._write_meta()


def _jsonable(o):
    try:
        return o.tolist()  # numpy scalars and arrays
    except AttributeError:
        raise TypeError(f"{type(o).__name__} is not JSON serialisable") from None


class _RecordedAudio(AudioSource):
    def __init__(self, source: AudioSource, rec: MissionRecorder) -> None:
        self._src, self._rec = source, rec

    @property
    def sample_rate(self) -> int:
        return self._src.sample_rate

    @property
    def n_channels(self) -> int:
        return self._src.n_channels

    def read(self, n_samples: int) -> AudioBlock:
        try:
            block = self._src.read(n_samples)
        except EndOfAudio as exc:  # a finite source ended: the replay ends there too, with the same message
            self._rec.entry(eof=int(n_samples), message=str(exc))
            raise
        self._rec.entry(read=int(block.samples.shape[1]), ts=float(block.timestamp))
        self._rec._block(block)
        return block

    def flush(self) -> None:
        self._rec.entry(flush=True)
        self._src.flush()

    def resync(self) -> None:
        self._rec.entry(resync=True)
        self._src.resync()

    def close(self) -> None:
        self._src.close()


def _status_dict(s: DriveStatus) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(s).items()}


class _RecordedDrive(DriveBase):
    def __init__(self, drive: DriveBase, rec: MissionRecorder) -> None:
        self._drive, self._rec = drive, rec

    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        self._rec.entry(twist=[float(vx), float(vy), float(omega)])
        self._drive.set_twist(vx, vy, omega)

    def stop(self) -> None:
        self._rec.entry(stop=True)
        self._drive.stop()

    def odometry(self) -> WheelOdometry:
        o = self._drive.odometry()
        self._rec.entry(odometry={"ts": float(o.timestamp), "angles": np.asarray(o.wheel_angles, float).tolist(),
                                  "speeds": np.asarray(o.wheel_speeds, float).tolist()})
        return o

    def status(self) -> DriveStatus:
        s = self._drive.status()
        self._rec.entry(status=_status_dict(s))
        return s

    def close(self) -> None:
        self._drive.close()


class _RecordedClock(Clock):
    def __init__(self, clock: Clock, rec: MissionRecorder) -> None:
        self._clock, self._rec = clock, rec

    def now(self) -> float:
        t = self._clock.now()
        self._rec.entry(now=float(t))
        return t

    def sleep(self, seconds: float) -> None:
        self._rec.entry(sleep=float(seconds))
        self._clock.sleep(seconds)


def is_mission(path: str | Path) -> bool:
    """Whether ``path`` is a directory written by :class:`MissionRecorder`."""
    return Path(path).is_dir()


class MissionReplay:
    """A recorded mission played back: :meth:`audio`, :meth:`drive` and :meth:`clock` answer the behaviour from
    the recording, in the order the mission asked (``MissionDiverged`` on the first difference)."""

    def __init__(self, directory: str | Path, expected_channels: int | None = None) -> None:
        from robot.replay import WavFileSource

        self.directory = Path(directory)
        meta_path = self.directory / META_FILE
        if not meta_path.is_file():
            raise FileNotFoundError(f"--replay {self.directory}: no {META_FILE}: not a mission recorded with --record")
        try:
            self.meta = json.loads(meta_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"--replay {meta_path}: not a JSON file ({exc})") from None
        if self.meta.get("format") != FORMAT:
            raise ValueError(f"--replay {meta_path}: format {self.meta.get('format')!r}, expected {FORMAT!r}")
        try:
            self._entries = [json.loads(line) for line in (self.directory / LOG_FILE).read_text().splitlines()]
        except FileNotFoundError:
            raise FileNotFoundError(f"--replay {self.directory}: {LOG_FILE} missing") from None
        except json.JSONDecodeError as exc:
            raise ValueError(f"--replay {self.directory / LOG_FILE}: line {exc.lineno}: not JSON") from None
        self._next = 0
        self._wav = WavFileSource(self.directory / AUDIO_FILE, expected_channels=expected_channels)

    def take(self, kind: str) -> dict:
        """The next entry, which must be of ``kind``."""
        if self._next >= len(self._entries):
            raise MissionDiverged(f"replay of {self.directory}: the behaviour asked for {kind} after the recorded "
                                  f"mission ended ({len(self._entries)} entries)")
        e = self._entries[self._next]
        if kind not in e:
            raise MissionDiverged(f"replay of {self.directory}: entry {self._next + 1}: the behaviour asked for "
                                  f"{kind}, the mission had {e}; replay with the options it was recorded with")
        self._next += 1
        return e

    @property
    def finished(self) -> bool:
        return self._next >= len(self._entries)

    def audio(self) -> AudioSource:
        return _ReplayedAudio(self)

    def drive(self) -> DriveBase:
        return _ReplayedDrive(self)

    def clock(self) -> Clock:
        return _ReplayedClock(self)


class _ReplayedAudio(AudioSource):
    def __init__(self, m: MissionReplay) -> None:
        self._m = m

    @property
    def sample_rate(self) -> int:
        return self._m._wav.sample_rate

    @property
    def n_channels(self) -> int:
        return self._m._wav.n_channels

    def read(self, n_samples: int) -> AudioBlock:
        if not self._m.finished and "eof" in self._m._entries[self._m._next]:
            e = self._m.take("eof")
            raise EndOfAudio(e.get("message") or f"replay of {self._m.directory}: the recorded audio ended here")
        e = self._m.take("read")
        if e["read"] != n_samples:
            raise MissionDiverged(f"replay of {self._m.directory}: the behaviour read {n_samples} samples, the "
                                  f"mission {e['read']}")
        block = self._m._wav.read(n_samples)
        return AudioBlock(block.samples, block.sample_rate, float(e["ts"]))

    def flush(self) -> None:
        self._m.take("flush")

    def resync(self) -> None:
        self._m.take("resync")

    def close(self) -> None:
        self._m._wav.close()


class _ReplayedDrive(DriveBase):
    def __init__(self, m: MissionReplay) -> None:
        self._m = m

    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        e = self._m.take("twist")
        if e["twist"] != [float(vx), float(vy), float(omega)]:
            raise MissionDiverged(f"replay of {self._m.directory}: the behaviour commanded the twist "
                                  f"{[vx, vy, omega]}, the mission {e['twist']}")

    def stop(self) -> None:
        self._m.take("stop")

    def odometry(self) -> WheelOdometry:
        o = self._m.take("odometry")["odometry"]
        return WheelOdometry(o["ts"], np.asarray(o["angles"], float), np.asarray(o["speeds"], float))

    def status(self) -> DriveStatus:
        s = dict(self._m.take("status")["status"])
        s["faults"] = tuple(s.get("faults") or ())
        if s.get("ranges") is not None:
            s["ranges"] = tuple(s["ranges"])
        return DriveStatus(**s)

    def close(self) -> None:
        pass


class _ReplayedClock(Clock):
    def __init__(self, m: MissionReplay) -> None:
        self._m = m

    def now(self) -> float:
        return float(self._m.take("now")["now"])

    def sleep(self, seconds: float) -> None:
        self._m.take("sleep")
