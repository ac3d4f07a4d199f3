"""``SerialDrive``: the omni-drive base behind a serial link to the Atmega2560 firmware (firmware/).

Speaks the framed protocol of docs/protocol.md (``robot.protocol``) over pyserial
(``serial.serial_for_url``, so device paths, ptys and ``loop://`` all work). Every
command waits for its reply; a missing reply is resent with the same sequence number
(commands are absolute setpoints, so a repeat is harmless) up to ``retries`` times,
then a :class:`DriveLinkError` naming the port is raised. Garbage on the line is
skipped by the resynchronising :class:`robot.protocol.FrameParser`.

The firmware ramps the motors to zero when no motion command arrives for
``COMMAND_TIMEOUT_S`` (200 ms; all duties are zero by ``STOP_DEADLINE_S``, 300 ms). A
background keepalive resends the current non-zero command every ``keepalive`` seconds,
but only while the application itself refreshed it within ``command_deadline`` (a
control loop that calls ``set_twist`` every few tens of ms): a control loop that hangs
or dies stops the robot (the keepalive sends STOP at the deadline; if the whole host
hangs, the firmware's watchdog stops it). The port is opened exclusively (POSIX
``flock``), so a second program cannot fight over the motors.

Replies are matched on type *and* sequence number: an ACK/NAK must name the command's
type, so a late reply to another command that reused the sequence number is skipped.

``status`` reports the bumper switches (pressed now or since the last status), the
gyro's yaw rate in rad/s with its zero-rate bias removed (the bias is learned from the
TELEMETRY read while the robot stands still: all duties zero, no encoder counts), and the
infrared range sensors' distances in metres (``robot.ranging``; the PONG says how many the
firmware reads, which must be ``config.range_layout.n``).
"""
from __future__ import annotations

import errno
import logging
import math
import os
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import serial

from robot import protocol as P
from robot.hal import DriveBase, DriveStatus, WheelOdometry
from robot.kinematics import OmniDriveParams
from robot.ranging import RangeLayout

try:                     # termios.error is what pyserial leaks when a pty/USB device vanishes
    from termios import error as _TermiosError
except ImportError:      # pragma: no cover - non-POSIX host
    class _TermiosError(Exception):
        pass

_LINK_ERRORS = (serial.SerialException, OSError, _TermiosError)

log = logging.getLogger(__name__)

COUNTS_PER_REV = 1200   # x4 quadrature counts per wheel revolution (e.g. 300-line encoder at the wheel)


class DriveLinkError(RuntimeError):
    """The serial link to the drive MCU is missing, vanished, or the MCU stopped answering."""


class DriveProtocolError(DriveLinkError):
    """The MCU answers, but speaks another protocol version (flash the firmware of this checkout)."""


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
    command_deadline: float = 0.5       # s: the keepalive repeats a command only this long after the application
                                        # last set it, then stops the robot (the rescue loop refreshes every 0.05 s)
    gyro_bias_gain: float = 0.1         # EMA gain of the gyro bias estimate per stationary TELEMETRY read
    connect_timeout: float | None = 3.0 # s to wait for the first PONG (an Arduino Mega resets on open); None = skip
    params: OmniDriveParams = field(default_factory=OmniDriveParams)
    # the range sensors on the board, sensor i on analog input ADCi; None: none expected (a board that reports
    # some is refused, as is one reporting a count other than range_layout.n; a board without any is fine)
    range_layout: RangeLayout | None = field(default_factory=RangeLayout)

    def __post_init__(self) -> None:
        if not self.reply_timeout > 0:
            raise ValueError(f"reply_timeout must be > 0 s, got {self.reply_timeout}")
        if self.retries < 0:
            raise ValueError(f"retries must be >= 0, got {self.retries}")
        if self.counts_per_rev <= 0:
            raise ValueError(f"counts_per_rev must be > 0, got {self.counts_per_rev}")
        if self.keepalive is not None and not 0 < self.keepalive < P.COMMAND_TIMEOUT_S:
            raise ValueError(f"keepalive must be in (0, {P.COMMAND_TIMEOUT_S}) s or None, got {self.keepalive}")
        if not self.command_deadline > (self.keepalive or 0.0):
            raise ValueError(f"command_deadline must be > keepalive ({self.keepalive} s), got {self.command_deadline}")
        if not 0 < self.gyro_bias_gain <= 1:
            raise ValueError(f"gyro_bias_gain must be in (0, 1], got {self.gyro_bias_gain}")
        if self.range_layout is not None and not isinstance(self.range_layout, RangeLayout):
            raise ValueError(f"range_layout must be a robot.ranging.RangeLayout or None, got {self.range_layout!r}")
        if self.range_layout is not None and self.range_layout.n > P.RANGE_SLOTS:
            raise ValueError(f"range_layout must have at most {P.RANGE_SLOTS} sensors (the firmware's analog "
                             f"inputs ADC0..ADC8), got {self.range_layout.n}")


@dataclass
class LinkStats:
    """Host-side link counters."""

    commands: int = 0
    retries: int = 0
    stale_replies: int = 0      # CRC-valid replies whose seq or type did not match the outstanding command
    bad_replies: int = 0        # CRC-valid frames that did not decode
    keepalives: int = 0
    deadline_stops: int = 0     # STOPs sent because the application stopped refreshing its command


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
        self.speed_limited = False              # the last motion command was scaled to the wheel-speed limit
        self._seq = 0
        self._lock = threading.RLock()
        self._active: P.Message | None = None   # non-zero motion command kept alive
        self._last_motion = 0.0                 # when the kept-alive command was last sent (monotonic s)
        self._last_set = 0.0                    # when the application last set it (monotonic s)
        self.gyro_bias: float | None = None     # rad/s, learned while standing still
        self._bumped = 0                        # bumper bits seen pressed since the last status()
        self._bg_error: DriveLinkError | None = None
        self._closed = threading.Event()
        try:
            # exclusive: an advisory flock on POSIX; a second SerialDrive (any process) is refused
            self._ser = serial.serial_for_url(port, baudrate=self.config.baudrate, timeout=0.01, write_timeout=1.0,
                                              exclusive=True if os.name == "posix" else None)
        except (serial.SerialException, OSError, ValueError) as e:
            if getattr(e, "errno", None) in (errno.EWOULDBLOCK, errno.EAGAIN):     # pyserial's failed flock
                raise DriveLinkError(f"drive serial port {port!r} is in use by another program (another SerialDrive "
                                     f"or ssl-robot?): only one may command the motors") from e
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
        """Body twist (m/s, m/s, rad/s, robot frame); the MCU scales it to the wheel-speed limit.

        Held while the application sets it again within ``config.command_deadline`` s."""
        msg = P.SetTwist(_fixed(vx, P.TWIST_SCALE, "vx (m/s)"), _fixed(vy, P.TWIST_SCALE, "vy (m/s)"),
                         _fixed(omega, P.TWIST_SCALE, "omega (rad/s)"))
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
        """Faults, stall, bumpers (pressed now or since the last TELEMETRY), the yaw rate (rad/s, CCW
        positive about the robot's +z; gyro bias removed once learned; None without a working gyro) and the
        ranges (m per sensor of ``config.range_layout``, ``inf`` = nothing within 0.8 m; the firmware's 50 ms
        window mean; None on a board without range sensors or before its first complete window)."""
        t = self.telemetry()
        f = t.fault_flags
        names = tuple(n for bit, n in P.FAULT_NAMES.items()
                      if f & bit and bit not in (P.Fault.SPEED_LIMITED, P.Fault.STALL))
        yaw_rate = t.gyro_z / P.GYRO_COUNTS_PER_RAD_S - (self.gyro_bias or 0.0) if t.gyro_ok else None
        bumped, self._bumped = self._bumped, 0
        ranges = None
        if t.ranges_ok:
            if self.board is None:          # not pinged yet (connect_timeout None): the PONG says how many
                self.ping()
            n = self.board.range_sensors
            ranges = t.ranges_m[:n] if n else None
        return DriveStatus(bumper=bool(bumped), stalled=bool(f & P.Fault.STALL), faults=names, yaw_rate=yaw_rate,
                           ranges=ranges)

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
        if pong.protocol_version != P.PROTOCOL_VERSION:
            raise DriveProtocolError(f"drive on {self.port!r} speaks protocol version {pong.protocol_version}, this "
                                     f"host speaks {P.PROTOCOL_VERSION}: flash firmware/ (make -C firmware flash)")
        self._check_ranges(pong.range_sensors)
        self.board = pong
        return rtt

    def _check_ranges(self, n: int) -> None:
        """The firmware reads ``n`` range sensors: ``config.range_layout`` must describe that many."""
        layout = self.config.range_layout
        if n > P.RANGE_SLOTS:
            raise DriveProtocolError(f"drive on {self.port!r} reports range_sensors={n}, the protocol has "
                                     f"{P.RANGE_SLOTS} slots")
        if n and (layout is None or layout.n != n):
            want = "none (range_layout=None)" if layout is None else f"{layout.n} (range_layout.n)"
            raise DriveProtocolError(f"drive on {self.port!r} reads {n} range sensors, SerialDriveConfig."
                                     f"range_layout expects {want}: give range_layout a RangeLayout of {n} "
                                     f"sensors, or build the firmware with RANGE_SENSORS matching it")

    def telemetry(self) -> P.Telemetry:
        t = self._transact(P.GetTelemetry(), P.MsgType.TELEMETRY)
        self._bumped |= t.bumpers_pressed         # kept for status(): odometry() reads TELEMETRY too
        if t.gyro_ok and not any(t.duty) and not any(t.encoder_rate):
            # standing still (nothing driven, no encoder count in the last 50 ms): the gyro reads its bias
            rate = t.gyro_z / P.GYRO_COUNTS_PER_RAD_S
            b = self.gyro_bias
            self.gyro_bias = rate if b is None else b + self.config.gyro_bias_gain * (rate - b)
        return t

    def clear_faults(self, mask: int = 0xFFFF) -> None:
        self._transact(P.ClearFaults(mask), P.MsgType.ACK)

    # ----------------------------------------------------------------- internals
    def _connect(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.ping()
                return
            except (DriveCommandError, DriveProtocolError):
                raise
            except DriveLinkError as e:
                if self._ser is None or not self._ser.is_open or time.monotonic() >= deadline:
                    raise DriveLinkError(f"no drive answering on {self.port!r} within {timeout} s: {e}") from e

    def _motion(self, msg: P.Message, moving: bool) -> None:
        with self._lock:
            ack = self._transact(msg, P.MsgType.ACK)
            self.speed_limited = bool(ack.flags & P.ACK_SPEED_LIMITED)
            self._last_motion = self._last_set = time.monotonic()
            self._active = msg if moving else None

    def _keepalive_loop(self) -> None:
        period = self.config.keepalive
        while not self._closed.wait(period / 4):
            with self._lock:
                if self._active is None or self._closed.is_set():
                    continue
                now = time.monotonic()
                try:
                    if now - self._last_set > self.config.command_deadline:
                        # the application stopped refreshing its command: it hangs or forgot; never drive on
                        log.warning("drive on %r: %s not refreshed for %.2f s (deadline %.2f s): stopping",
                                    self.port, self._active.TYPE.name, now - self._last_set,
                                    self.config.command_deadline)
                        self._active = None
                        self.stats.deadline_stops += 1
                        self._transact(P.Stop(), P.MsgType.ACK)
                    elif now - self._last_motion >= period:
                        # only motion commands feed the MCU's command watchdog (telemetry polls do not)
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
                reply = self._await_reply(msg.TYPE, seq, expect, time.monotonic() + self.config.reply_timeout)
                if reply is None:
                    continue
                if isinstance(reply, P.Nak):
                    try:
                        reason: P.NakReason | int = P.NakReason(reply.reason)
                    except ValueError:
                        reason = reply.reason
                    raise DriveCommandError(f"drive on {self.port!r} rejected {msg.TYPE.name} "
                                            f"(seq {seq}): {getattr(reason, 'name', reason)}", reason)
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

    def _await_reply(self, cmd_type: int, seq: int, expect: P.MsgType, deadline: float) -> P.Message | None:
        """The reply to command ``cmd_type`` sent with ``seq``: a frame with that seq that is ``expect``
        (an ACK must name ``cmd_type``) or a NAK naming ``cmd_type``; None at the deadline. Anything else
        (a late reply to an earlier command that had the same seq) is counted as stale and skipped."""
        while True:
            now = time.monotonic()
            if now >= deadline:
                # give up an incomplete candidate only now, and rescan the bytes it held: a gap mid-reply
                # on a loaded host or USB link is no reason to lose the reply (it once cost a resend)
                return self._reply_in(self.parser.drop_partial(), cmd_type, seq, expect)
            try:
                self._ser.timeout = min(0.01, deadline - now)
                chunk = self._ser.read(max(1, self._ser.in_waiting))
            except (*_LINK_ERRORS, TypeError) as e:
                # pyserial raises TypeError/OSError from a port whose device disappeared mid-read
                raise DriveLinkError(f"drive serial port {self.port!r} failed on read: {e}") from e
            if chunk and (reply := self._reply_in(self.parser.feed(chunk), cmd_type, seq, expect)) is not None:
                return reply

    def _reply_in(self, frames: list[P.Frame], cmd_type: int, seq: int, expect: P.MsgType) -> P.Message | None:
        for fr in frames:
            if fr.msg_type < 0x80:
                continue                     # a command (our own echo on loop://): not a reply
            try:
                msg = fr.decode()
            except P.ProtocolError:
                self.stats.bad_replies += 1
                continue
            if fr.seq != seq or not _answers(msg, cmd_type, expect):
                self.stats.stale_replies += 1
                continue
            return msg
        return None


def _answers(reply: P.Message, cmd_type: int, expect: P.MsgType) -> bool:
    if isinstance(reply, (P.Ack, P.Nak)):
        return reply.of_type == cmd_type and (reply.TYPE == expect or isinstance(reply, P.Nak))
    return reply.TYPE == expect
