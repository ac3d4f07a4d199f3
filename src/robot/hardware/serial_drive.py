"""``SerialDrive``: the omni-drive base behind a serial link to the Atmega2560 firmware (firmware/).

Speaks the framed protocol of docs/protocol.md (``robot.protocol``) over pyserial
(``serial.serial_for_url``, so device paths, ptys and ``loop://`` all work). Every
command waits for its reply; a missing reply is resent with the same sequence number
(commands are absolute setpoints, so a repeat is harmless) up to ``retries`` times,
then a :class:`DriveLinkError` naming the port is raised. Garbage on the line is
skipped by the resynchronising :class:`robot.protocol.FrameParser`.

The firmware ramps the motors to zero when no motion command arrives for
``COMMAND_TIMEOUT_S`` (300 ms). ``set_twist`` promises a twist "held until changed or
stopped", so a background keepalive resends the current non-zero command every
``keepalive`` seconds; if the host process dies the firmware stops the robot.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import serial

from robot import protocol as P
from robot.hal import DriveBase, DriveStatus, WheelOdometry
from robot.kinematics import OmniDriveParams

try:                     # termios.error is what pyserial leaks when a pty/USB device vanishes
    from termios import error as _TermiosError
except ImportError:      # pragma: no cover - non-POSIX host
    class _TermiosError(Exception):
        pass

_LINK_ERRORS = (serial.SerialException, OSError, _TermiosError)

COUNTS_PER_REV = 1200   # x4 quadrature counts per wheel revolution (e.g. 300-line encoder at the wheel)


class DriveLinkError(RuntimeError):
    """The serial link to the drive MCU is missing, vanished, or the MCU stopped answering."""


class DriveCommandError(DriveLinkError):
    """The MCU answered a command with a NAK."""

    def __init__(self, message: str, reason: P.NakReason | int) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class SerialDriveConfig:
    """Link and drive settings (SI units)."""

    baudrate: int = 115200
    reply_timeout: float = 0.1          # s to wait for the reply to one attempt
    retries: int = 3                    # resends (same seq) after the first attempt
    counts_per_rev: int = COUNTS_PER_REV
    keepalive: float | None = 0.1       # s between resends of a non-zero motion command; None = off
    connect_timeout: float | None = 3.0 # s to wait for the first PONG (an Arduino Mega resets on open); None = skip
    params: OmniDriveParams = field(default_factory=OmniDriveParams)

    def __post_init__(self) -> None:
        if not self.reply_timeout > 0:
            raise ValueError(f"reply_timeout must be > 0 s, got {self.reply_timeout}")
        if self.retries < 0:
            raise ValueError(f"retries must be >= 0, got {self.retries}")
        if self.counts_per_rev <= 0:
            raise ValueError(f"counts_per_rev must be > 0, got {self.counts_per_rev}")
        if self.keepalive is not None and not 0 < self.keepalive < P.COMMAND_TIMEOUT_S:
            raise ValueError(f"keepalive must be in (0, {P.COMMAND_TIMEOUT_S}) s or None, got {self.keepalive}")


@dataclass
class LinkStats:
    """Host-side link counters."""

    commands: int = 0
    retries: int = 0
    stale_replies: int = 0      # CRC-valid replies whose seq did not match the outstanding command
    bad_replies: int = 0        # CRC-valid frames that did not decode
    keepalives: int = 0


def _fixed(value: float, scale: float, name: str, lo: int = -32768, hi: int = 32767) -> int:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    q = int(round(value * scale))
    if not lo <= q <= hi:
        raise ValueError(f"{name} must be within [{lo / scale}, {hi / scale}], got {value}")
    return q


class SerialDrive(DriveBase):
    """Drive base over a serial port (``port``: a device path such as /dev/ttyACM0, a pty, or a pyserial URL)."""

    def __init__(self, port: str, config: SerialDriveConfig | None = None) -> None:
        self.port = port
        self.config = config or SerialDriveConfig()
        self.stats = LinkStats()
        self.parser = P.FrameParser()
        self.board: P.Pong | None = None        # last PONG (firmware version, PWM top)
        self._seq = 0
        self._lock = threading.RLock()
        self._active: P.Message | None = None   # non-zero motion command kept alive
        self._last_motion = 0.0                 # when the kept-alive command was last sent (monotonic s)
        self._bg_error: DriveLinkError | None = None
        self._closed = threading.Event()
        try:
            self._ser = serial.serial_for_url(port, baudrate=self.config.baudrate, timeout=0.01,
                                              write_timeout=1.0)
        except (serial.SerialException, OSError, ValueError) as e:
            raise DriveLinkError(f"drive serial port {port!r} cannot be opened: {e}") from e
        try:
            if self.config.connect_timeout is not None:
                self._connect(self.config.connect_timeout)
        except BaseException:
            self._ser.close()
            raise
        self._thread: threading.Thread | None = None
        if self.config.keepalive is not None:
            self._thread = threading.Thread(target=self._keepalive_loop, name=f"SerialDrive({port})",
                                            daemon=True)
            self._thread.start()

    # ----------------------------------------------------------------- DriveBase
    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        """Body twist (m/s, m/s, rad/s, robot frame); the MCU scales it to the wheel-speed limit."""
        msg = P.SetTwist(_fixed(vx, 1000, "vx (m/s)"), _fixed(vy, 1000, "vy (m/s)"),
                         _fixed(omega, 1000, "omega (rad/s)"))
        self._motion(msg, moving=any((msg.vx_mm_s, msg.vy_mm_s, msg.omega_mrad_s)))

    def set_heading(self, azimuth: float, speed: float, omega: float = 0.0) -> None:
        """Translate along ``azimuth`` (rad, CCW from +x, robot frame) at ``speed`` m/s (what the paper sends)."""
        if not math.isfinite(azimuth):
            raise ValueError(f"azimuth must be finite (rad), got {azimuth}")
        az = math.remainder(azimuth, 2 * math.pi)   # (-pi, pi]
        msg = P.SetHeading(_fixed(az, 1000, "azimuth (rad)", -P.AZIMUTH_LIMIT_MRAD, P.AZIMUTH_LIMIT_MRAD),
                           _fixed(speed, 1000, "speed (m/s)", 0, 65535),
                           _fixed(omega, 1000, "omega (rad/s)"))
        self._motion(msg, moving=bool(msg.speed_mm_s or msg.omega_mrad_s))

    def stop(self) -> None:
        with self._lock:
            self._active = None
            self._transact(P.Stop(), P.MsgType.ACK)

    def odometry(self) -> WheelOdometry:
        t = self.telemetry()
        k = 2 * math.pi / self.config.counts_per_rev
        return WheelOdometry(timestamp=time.monotonic(),
                             wheel_angles=np.asarray(t.encoder_counts, dtype=float) * k,
                             wheel_speeds=np.asarray(t.encoder_rate, dtype=float) * (k / P.ENCODER_WINDOW_S))

    def status(self) -> DriveStatus:
        f = self.telemetry().fault_flags
        names = tuple(n for bit, n in P.FAULT_NAMES.items()
                      if f & bit and bit not in (P.Fault.SPEED_LIMITED, P.Fault.STALL))
        return DriveStatus(bumper=False, stalled=bool(f & P.Fault.STALL), faults=names)

    def close(self) -> None:
        if self._closed.is_set():
            return
        self._closed.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        try:
            if self._bg_error is None:
                self.stop()
        except DriveLinkError:
            pass   # closing a dead link: nothing left to stop
        finally:
            self._ser.close()

    # ----------------------------------------------------------------- extras
    def ping(self, nonce: int | None = None) -> float:
        """Round trip time (s) of a PING; the PONG is kept in ``self.board``."""
        nonce = (time.monotonic_ns() & 0xFFFFFFFF) if nonce is None else nonce
        t0 = time.perf_counter()
        pong = self._transact(P.Ping(nonce), P.MsgType.PONG)
        rtt = time.perf_counter() - t0
        if pong.nonce != nonce:
            raise DriveLinkError(f"drive on {self.port!r} echoed nonce {pong.nonce}, expected {nonce}")
        self.board = pong
        return rtt

    def telemetry(self) -> P.Telemetry:
        return self._transact(P.GetTelemetry(), P.MsgType.TELEMETRY)

    def clear_faults(self, mask: int = 0xFFFF) -> None:
        self._transact(P.ClearFaults(mask), P.MsgType.ACK)

    # ----------------------------------------------------------------- internals
    def _connect(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.ping()
                return
            except DriveCommandError:
                raise
            except DriveLinkError as e:
                if self._ser is None or not self._ser.is_open or time.monotonic() >= deadline:
                    raise DriveLinkError(f"no drive answering on {self.port!r} within {timeout} s: {e}") from e

    def _motion(self, msg: P.Message, moving: bool) -> None:
        with self._lock:
            self._transact(msg, P.MsgType.ACK)
            self._last_motion = time.monotonic()
            self._active = msg if moving else None

    def _keepalive_loop(self) -> None:
        period = self.config.keepalive
        while not self._closed.wait(period / 4):
            with self._lock:
                if self._active is None or self._closed.is_set():
                    continue
                # only motion commands feed the MCU's command watchdog (telemetry polls do not)
                if time.monotonic() - self._last_motion < period:
                    continue
                try:
                    self._transact(self._active, P.MsgType.ACK)
                    self._last_motion = time.monotonic()
                    self.stats.keepalives += 1
                except DriveLinkError as e:
                    self._bg_error = e
                    self._active = None
                    return

    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) & 0xFF
        return self._seq

    def _transact(self, msg: P.Message, expect: P.MsgType) -> P.Message:
        with self._lock:
            if self._bg_error is not None:
                raise self._bg_error
            if not self._ser.is_open:
                raise DriveLinkError(f"drive serial port {self.port!r} is closed")
            seq = self._next_seq()
            data = P.encode(msg, seq)
            self.stats.commands += 1
            attempts = self.config.retries + 1
            for attempt in range(attempts):
                if attempt:
                    self.stats.retries += 1
                self._write(data)
                reply = self._await_reply(seq, time.monotonic() + self.config.reply_timeout)
                if reply is None:
                    continue
                if isinstance(reply, P.Nak):
                    try:
                        reason: P.NakReason | int = P.NakReason(reply.reason)
                    except ValueError:
                        reason = reply.reason
                    raise DriveCommandError(f"drive on {self.port!r} rejected {msg.TYPE.name} "
                                            f"(seq {seq}): {getattr(reason, 'name', reason)}", reason)
                if reply.TYPE != expect or (isinstance(reply, P.Ack) and reply.of_type != msg.TYPE):
                    raise DriveLinkError(f"drive on {self.port!r} answered {msg.TYPE.name} (seq {seq}) "
                                         f"with {reply.TYPE.name}, expected {expect.name}")
                return reply
            raise DriveLinkError(f"no reply from the drive on {self.port!r} to {msg.TYPE.name} (seq {seq}) "
                                 f"after {attempts} attempts of {self.config.reply_timeout} s")

    def _write(self, data: bytes) -> None:
        try:
            self._ser.reset_input_buffer()   # replies to abandoned attempts are useless now
            self._ser.write(data)
            self._ser.flush()
        except _LINK_ERRORS as e:
            raise DriveLinkError(f"drive serial port {self.port!r} failed on write: {e}") from e

    def _await_reply(self, seq: int, deadline: float) -> P.Message | None:
        while True:
            now = time.monotonic()
            if now >= deadline:
                return None
            try:
                self._ser.timeout = min(0.01, deadline - now)
                chunk = self._ser.read(max(1, self._ser.in_waiting))
            except (*_LINK_ERRORS, TypeError) as e:
                # pyserial raises TypeError/OSError from a port whose device disappeared mid-read
                raise DriveLinkError(f"drive serial port {self.port!r} failed on read: {e}") from e
            # a pause mid-frame is an inter-byte timeout: give up the partial frame and rescan it
            frames = self.parser.feed(chunk) if chunk else self.parser.drop_partial()
            for fr in frames:
                if fr.msg_type < 0x80:
                    continue                     # a command (our own echo on loop://): not a reply
                try:
                    msg = fr.decode()
                except P.ProtocolError:
                    self.stats.bad_replies += 1
                    continue
                if fr.seq != seq:
                    self.stats.stale_replies += 1
                    continue
                return msg
