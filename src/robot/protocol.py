"""Binary serial protocol between the host (Raspberry Pi) and the drive MCU (Atmega2560).

The specification is docs/protocol.md; firmware/src/protocol.h is the C side.
Every frame is::

    0xA5 | LEN | TYPE | SEQ | PAYLOAD (LEN bytes) | CRC16 (2 bytes, little-endian)

The CRC is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final
xor; check value ``crc16(b"123456789") == 0x29B1``) over LEN, TYPE, SEQ and the
payload. All multi-byte payload fields are little-endian. Physical quantities are
fixed point: mm/s, mrad/s, mrad (robot/body frame, +x forward, +y left, CCW positive).

:class:`FrameParser` is a streaming parser: feed it bytes in any chunking and it
returns the complete, CRC-valid frames; on a bad length or CRC it drops only the
start byte and rescans the bytes it already holds, so a valid frame that follows
(or hides inside) garbage is still found.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field, fields
from enum import IntEnum, IntFlag
from typing import ClassVar

SOF = 0xA5
HEADER_LEN = 4             # SOF, LEN, TYPE, SEQ
CRC_LEN = 2
MAX_PAYLOAD = 64           # largest LEN any receiver accepts (the MCU accepts at most MCU_MAX_PAYLOAD)
MCU_MAX_PAYLOAD = 16       # the MCU's commands are short: it rejects larger LEN at once (limits resync stalls)
PROTOCOL_VERSION = 3       # 3: TELEMETRY carries ranges_cm, PONG range_sensors; 2: gyro_z, sensors, bumpers
PWM_TOP = 400              # firmware duty counts for 100 % (reported in PONG too)
ENCODER_WINDOW_S = 0.050   # telemetry ``encoder_rate`` = counts in the last 50 ms window
COMMAND_TIMEOUT_S = 0.200  # the MCU starts ramping the motors down this long after the last motion command ...
STOP_DEADLINE_S = 0.300    # ... and every duty is zero by this long after it (firmware: 290-291 ms), at any duty
# TELEMETRY gyro_z scale: MPU-6050 at FS_SEL 1 (+-500 deg/s), 65.5 LSB per deg/s (datasheet, table 6.1)
GYRO_COUNTS_PER_RAD_S = 65.5 * 180.0 / math.pi


class ProtocolError(ValueError):
    """A CRC-valid frame whose type or payload does not match the specification."""


def crc16_ccitt_false(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (continue a running CRC by passing ``crc``)."""
    for b in bytes(data):
        # byte-wise form of the 0x1021 polynomial (same algebra as firmware/src/crc16.h)
        crc = ((crc >> 8) | (crc << 8)) & 0xFFFF
        crc ^= b
        crc ^= (crc & 0xFF) >> 4
        crc ^= (crc << 12) & 0xFFFF
        crc ^= (crc & 0xFF) << 5
    return crc


class MsgType(IntEnum):
    # host -> MCU
    PING = 0x01
    SET_TWIST = 0x02
    SET_HEADING = 0x03
    STOP = 0x04
    GET_TELEMETRY = 0x05
    CLEAR_FAULTS = 0x06
    # MCU -> host
    ACK = 0x81
    NAK = 0x82
    PONG = 0x83
    TELEMETRY = 0x84


class NakReason(IntEnum):
    BAD_LENGTH = 1     # payload length wrong for the message type
    UNKNOWN_TYPE = 2   # TYPE not a host->MCU command
    BAD_VALUE = 3      # a field outside its documented range


class Fault(IntFlag):
    """Fault flags reported in TELEMETRY (see docs/protocol.md for which are latched)."""

    NONE = 0
    CMD_TIMEOUT = 1 << 0      # command watchdog ramped the motors down (cleared by next motion cmd or STOP)
    SPEED_LIMITED = 1 << 1    # current setpoint scaled down to the wheel-speed limit
    WDT_RESET = 1 << 2        # latched: last MCU reset came from the hardware watchdog
    BROWNOUT_RESET = 1 << 3   # latched: last MCU reset was a brown-out
    RX_OVERFLOW = 1 << 4      # latched: the receive ring buffer overflowed
    STALL = 1 << 5            # a wheel driven at >= 25 % duty shows no encoder edge for 500 ms
    ENCODER_ERROR = 1 << 6    # latched: impossible quadrature transition (missed edge)


class Sensor(IntFlag):
    """TELEMETRY ``sensors`` bits."""

    NONE = 0
    GYRO_OK = 1 << 0          # a gyro answered WHO_AM_I and ``gyro_z`` is valid
    RANGES_OK = 1 << 1        # range sensors are fitted and ``ranges_cm`` holds a complete window


BUMPERS_LIVE = 0x0F           # TELEMETRY ``bumpers``: bits 0-3 pressed now (debounced), PC0..PC3
BUMPERS_PRESSED_SHIFT = 4     # bits 4-7: pressed at any time since the previous TELEMETRY
# TELEMETRY ``ranges_cm``: one slot per analog input ADC0..ADC8 (PONG ``range_sensors`` says how many are fitted),
# the distance in cm from the sensor along its ray (RANGE_MIN_CM..RANGE_MAX_CM), or RANGE_NO_RETURN
RANGE_SLOTS = 9
RANGE_NO_RETURN = 0           # nothing within RANGE_MAX_CM
RANGE_MIN_CM = 10             # Sharp GP2Y0A21YK0F: 10 cm ... (closer readings are clamped to it by the firmware)
RANGE_MAX_CM = 80             # ... to 80 cm


FAULT_NAMES: dict[Fault, str] = {
    Fault.CMD_TIMEOUT: "cmd_timeout",
    Fault.SPEED_LIMITED: "speed_limited",
    Fault.WDT_RESET: "wdt_reset",
    Fault.BROWNOUT_RESET: "brownout_reset",
    Fault.RX_OVERFLOW: "rx_overflow",
    Fault.STALL: "stall",
    Fault.ENCODER_ERROR: "encoder_error",
}

ACK_SPEED_LIMITED = 0x01   # ACK flags bit: the command was scaled to the wheel-speed limit

_INT_RANGES = {"b": (-128, 127), "B": (0, 255), "h": (-32768, 32767), "H": (0, 65535),
               "i": (-2**31, 2**31 - 1), "I": (0, 2**32 - 1)}


@dataclass(frozen=True)
class Message:
    """Base of all messages: ``FORMAT`` is the struct format of the payload, one code per value.

    Tuple-valued fields take as many codes as they have elements (``ARITY``)."""

    TYPE: ClassVar[MsgType]
    FORMAT: ClassVar[str] = "<"
    ARITY: ClassVar[dict[str, int]] = {}

    def __post_init__(self) -> None:
        codes = iter(self.FORMAT[1:])
        for f in fields(self):
            v = getattr(self, f.name)
            n = self.ARITY.get(f.name, 1)
            values = tuple(v) if n > 1 else (v,)
            if len(values) != n:
                raise ValueError(f"{type(self).__name__}.{f.name} must hold {n} values, got {len(values)}")
            for x in values:
                c = next(codes)
                lo, hi = _INT_RANGES[c]
                if isinstance(x, bool) or not isinstance(x, int) or not lo <= x <= hi:
                    raise ValueError(f"{type(self).__name__}.{f.name} must be integers in [{lo}, {hi}], got {v!r}")

    def pack(self) -> bytes:
        flat: list[int] = []
        for f in fields(self):
            v = getattr(self, f.name)
            flat.extend(v if self.ARITY.get(f.name, 1) > 1 else (v,))
        return struct.pack(self.FORMAT, *flat)

    @classmethod
    def unpack(cls, payload: bytes) -> Message:
        size = struct.calcsize(cls.FORMAT)
        if len(payload) != size:
            raise ProtocolError(f"{cls.TYPE.name} payload must be {size} bytes, got {len(payload)}")
        flat = list(struct.unpack(cls.FORMAT, payload))
        kwargs = {}
        for f in fields(cls):
            n = cls.ARITY.get(f.name, 1)
            kwargs[f.name] = tuple(flat[:n]) if n > 1 else flat[0]
            del flat[:n]
        return cls(**kwargs)


@dataclass(frozen=True)
class Ping(Message):
    TYPE: ClassVar[MsgType] = MsgType.PING
    FORMAT: ClassVar[str] = "<I"
    nonce: int = 0


@dataclass(frozen=True)
class SetTwist(Message):
    """Body twist in the robot frame: mm/s, mm/s, mrad/s."""

    TYPE: ClassVar[MsgType] = MsgType.SET_TWIST
    FORMAT: ClassVar[str] = "<hhh"
    vx_mm_s: int = 0
    vy_mm_s: int = 0
    omega_mrad_s: int = 0


TWIST_SCALE = 1000   # SetTwist units per SI unit: mm/s per m/s, mrad/s per rad/s


def twist_as_sent(vx: float, vy: float, omega: float) -> tuple[float, float, float]:
    """The body twist (m/s, m/s, rad/s) at the resolution ``SetTwist`` carries it: 1 mm/s, 1 mrad/s."""
    return (round(vx * TWIST_SCALE) / TWIST_SCALE, round(vy * TWIST_SCALE) / TWIST_SCALE,
            round(omega * TWIST_SCALE) / TWIST_SCALE)


AZIMUTH_LIMIT_MRAD = 3142   # |azimuth| <= pi, in mrad (the MCU NAKs BAD_VALUE outside)


@dataclass(frozen=True)
class SetHeading(Message):
    """Translate along ``azimuth`` (mrad, CCW from +x, robot frame) at ``speed`` mm/s, turning at omega mrad/s."""

    TYPE: ClassVar[MsgType] = MsgType.SET_HEADING
    FORMAT: ClassVar[str] = "<hHh"
    azimuth_mrad: int = 0
    speed_mm_s: int = 0
    omega_mrad_s: int = 0


@dataclass(frozen=True)
class Stop(Message):
    TYPE: ClassVar[MsgType] = MsgType.STOP


@dataclass(frozen=True)
class GetTelemetry(Message):
    TYPE: ClassVar[MsgType] = MsgType.GET_TELEMETRY


@dataclass(frozen=True)
class ClearFaults(Message):
    """Clear the latched fault flags in ``mask`` (a :class:`Fault` bit set)."""

    TYPE: ClassVar[MsgType] = MsgType.CLEAR_FAULTS
    FORMAT: ClassVar[str] = "<H"
    mask: int = 0xFFFF


@dataclass(frozen=True)
class Ack(Message):
    TYPE: ClassVar[MsgType] = MsgType.ACK
    FORMAT: ClassVar[str] = "<BB"
    of_type: int = 0
    flags: int = 0          # ACK_SPEED_LIMITED


@dataclass(frozen=True)
class Nak(Message):
    TYPE: ClassVar[MsgType] = MsgType.NAK
    FORMAT: ClassVar[str] = "<BB"
    of_type: int = 0
    reason: int = 0         # NakReason


@dataclass(frozen=True)
class Pong(Message):
    TYPE: ClassVar[MsgType] = MsgType.PONG
    FORMAT: ClassVar[str] = "<IBHIHB"
    nonce: int = 0
    protocol_version: int = PROTOCOL_VERSION
    firmware_version: int = 0      # major << 8 | minor
    uptime_ms: int = 0
    pwm_top: int = PWM_TOP
    range_sensors: int = 0         # range sensors fitted, on ADC0..ADC(n-1) (firmware config.h RANGE_SENSORS)


@dataclass(frozen=True)
class Telemetry(Message):
    """Drive state. ``encoder_counts`` cumulative (x4 quadrature), ``encoder_rate`` counts in the last
    ``ENCODER_WINDOW_S``, ``duty`` applied signed duty in counts of ``PWM_TOP``; counters wrap at 2**16."""

    TYPE: ClassVar[MsgType] = MsgType.TELEMETRY
    FORMAT: ClassVar[str] = "<I" + "iii" + "hhh" + "hhh" + "H" + "H" * 10 + "hBB" + "B" * RANGE_SLOTS
    ARITY: ClassVar[dict[str, int]] = {"encoder_counts": 3, "encoder_rate": 3, "duty": 3, "ranges_cm": RANGE_SLOTS}
    uptime_ms: int = 0
    encoder_counts: tuple[int, int, int] = (0, 0, 0)
    encoder_rate: tuple[int, int, int] = (0, 0, 0)
    duty: tuple[int, int, int] = (0, 0, 0)
    faults: int = 0
    rx_frames: int = 0          # valid frames received
    crc_errors: int = 0         # candidate frames with a bad CRC
    length_errors: int = 0      # start bytes followed by LEN > MCU_MAX_PAYLOAD
    timeouts: int = 0           # incomplete frames abandoned after the inter-byte timeout
    dropped_bytes: int = 0      # bytes skipped while hunting for a start byte
    naks: int = 0               # NAK replies sent
    rx_overflows: int = 0       # bytes lost because the receive ring buffer was full
    tx_dropped: int = 0         # replies dropped because the transmit ring was full (request flood)
    max_parse_cycles: int = 0   # worst CPU cycles of one parser call (<= 1 frame, rescans and ISRs incl.)
    max_cmd_cycles: int = 0     # worst CPU cycles to execute one command (IK, PWM update, reply)
    gyro_z: int = 0             # mean gyro Z rate over the last 50 ms, counts (GYRO_COUNTS_PER_RAD_S), bias included
    sensors: int = 0            # Sensor bits
    bumpers: int = 0            # bits 0-3 pressed now, bits 4-7 pressed since the previous TELEMETRY
    ranges_cm: tuple[int, ...] = (RANGE_NO_RETURN,) * RANGE_SLOTS   # per ADC input: cm, or RANGE_NO_RETURN

    @property
    def fault_flags(self) -> Fault:
        return Fault(self.faults & sum(FAULT_NAMES))

    @property
    def gyro_ok(self) -> bool:
        return bool(self.sensors & Sensor.GYRO_OK)

    @property
    def ranges_ok(self) -> bool:
        return bool(self.sensors & Sensor.RANGES_OK)

    @property
    def ranges_m(self) -> tuple[float, ...]:
        """``ranges_cm`` in metres per slot, ``math.inf`` for RANGE_NO_RETURN (valid only if ``ranges_ok``)."""
        return tuple(math.inf if c == RANGE_NO_RETURN else c / 100.0 for c in self.ranges_cm)

    @property
    def bumpers_pressed(self) -> int:
        """Bit mask of the switches pressed now or at any time since the previous TELEMETRY."""
        return (self.bumpers | self.bumpers >> BUMPERS_PRESSED_SHIFT) & BUMPERS_LIVE


MESSAGES: dict[int, type[Message]] = {
    cls.TYPE: cls for cls in (Ping, SetTwist, SetHeading, Stop, GetTelemetry, ClearFaults,
                              Ack, Nak, Pong, Telemetry)
}
assert all(struct.calcsize(c.FORMAT) <= MAX_PAYLOAD for c in MESSAGES.values())
assert all(struct.calcsize(c.FORMAT) <= MCU_MAX_PAYLOAD for t, c in MESSAGES.items() if t < 0x80)


@dataclass(frozen=True)
class Frame:
    """One CRC-valid frame as received: raw type, sequence number and payload."""

    msg_type: int
    seq: int
    payload: bytes = b""

    def decode(self) -> Message:
        cls = MESSAGES.get(self.msg_type)
        if cls is None:
            raise ProtocolError(f"unknown message type 0x{self.msg_type:02X}")
        return cls.unpack(self.payload)

    def to_bytes(self) -> bytes:
        return build_frame(self.msg_type, self.seq, self.payload)


def build_frame(msg_type: int, seq: int, payload: bytes = b"") -> bytes:
    """Raw frame bytes (no checks on type; ``seq`` 0..255, payload <= MAX_PAYLOAD bytes)."""
    if not 0 <= msg_type <= 255:
        raise ValueError(f"msg_type must be 0..255, got {msg_type}")
    if not 0 <= seq <= 255:
        raise ValueError(f"seq must be 0..255, got {seq}")
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload must be <= {MAX_PAYLOAD} bytes, got {len(payload)}")
    body = bytes((len(payload), msg_type, seq)) + bytes(payload)
    return bytes((SOF,)) + body + struct.pack("<H", crc16_ccitt_false(body))


def encode(msg: Message, seq: int) -> bytes:
    """Frame bytes carrying ``msg`` with sequence number ``seq``."""
    return build_frame(msg.TYPE, seq, msg.pack())


@dataclass
class FrameParser:
    """Streaming frame parser with resynchronisation.

    ``feed(data)`` returns the frames completed by ``data``. A start byte followed by
    LEN > ``max_payload`` or by a frame with a bad CRC is dropped alone (counted) and the
    bytes after it are rescanned. ``drop_partial()`` abandons an incomplete frame (call
    it after an inter-byte timeout) and returns any frame found in the bytes it held."""

    max_payload: int = MAX_PAYLOAD
    crc_errors: int = 0
    length_errors: int = 0
    timeouts: int = 0
    dropped_bytes: int = 0
    frames: int = 0
    _buf: bytearray = field(default_factory=bytearray, repr=False)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        self._buf += data
        return self._scan()

    @property
    def pending(self) -> int:
        """Bytes held for an incomplete frame."""
        return len(self._buf)

    def drop_partial(self) -> list[Frame]:
        out: list[Frame] = []
        while self._buf:
            self.timeouts += 1
            del self._buf[0]
            out += self._scan()
        return out

    def _scan(self) -> list[Frame]:
        buf = self._buf
        out: list[Frame] = []
        while buf:
            i = buf.find(SOF)
            if i < 0:
                self.dropped_bytes += len(buf)
                buf.clear()
                break
            if i:
                self.dropped_bytes += i
                del buf[:i]
            if len(buf) < 2:
                break
            n = buf[1]
            if n > self.max_payload:
                self.length_errors += 1
                del buf[0]
                continue
            total = HEADER_LEN + n + CRC_LEN
            if len(buf) < total:
                break
            crc = buf[HEADER_LEN + n] | (buf[HEADER_LEN + n + 1] << 8)
            if crc16_ccitt_false(buf[1:HEADER_LEN + n]) != crc:
                self.crc_errors += 1
                del buf[0]
                continue
            out.append(Frame(buf[2], buf[3], bytes(buf[HEADER_LEN:HEADER_LEN + n])))
            self.frames += 1
            del buf[:total]
        return out
