"""Serial protocol (robot.protocol) and the pyserial drive backend (robot.hardware.serial_drive).

The drive is exercised against a fake MCU thread on a pseudo-terminal pair, and over
pyserial's ``loop://`` (which only echoes, so every attempt must time out)."""
from __future__ import annotations

import math
import os
import select
import struct
import threading
import time
import tty
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from robot import protocol as P
from robot.hardware.serial_drive import (
    DriveCommandError,
    DriveLinkError,
    DriveProtocolError,
    SerialDrive,
    SerialDriveConfig,
)
from robot.ranging import RangeLayout

SETTINGS = settings(derandomize=True, max_examples=150, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------- framing
def test_crc_check_value_and_known_frame():
    assert P.crc16_ccitt_false(b"123456789") == 0x29B1          # CRC-16/CCITT-FALSE catalogue check
    assert P.crc16_ccitt_false(b"") == 0xFFFF
    # STOP, seq 7: A5 00 04 07 + CRC over (00 04 07), little-endian
    frame = P.encode(P.Stop(), 7)
    crc = P.crc16_ccitt_false(b"\x00\x04\x07")
    assert frame == bytes([0xA5, 0, 4, 7]) + struct.pack("<H", crc)


def test_crc_matches_bitwise_reference():
    def bitwise(data):
        crc = 0xFFFF
        for b in data:
            crc ^= b << 8
            for _ in range(8):
                crc = ((crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
        return crc
    rng = np.random.default_rng(1)
    for n in (1, 2, 7, 64):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert P.crc16_ccitt_false(data) == bitwise(data)


EXAMPLES = [
    P.Ping(0xDEADBEEF), P.SetTwist(-500, 250, 1571), P.SetHeading(-3142, 300, -100), P.Stop(),
    P.GetTelemetry(), P.ClearFaults(int(P.Fault.WDT_RESET)), P.Ack(P.MsgType.SET_TWIST, P.ACK_SPEED_LIMITED),
    P.Nak(0x42, P.NakReason.UNKNOWN_TYPE), P.Pong(7, 1, 0x0102, 123456, 400, 9),
    P.Telemetry(99, (-2**31, 0, 2**31 - 1), (-5, 0, 5), (-400, 0, 400), 0x41, *range(1, 11), -7, 3, 0x21,
                (0, 10, 80, 255, 33, 0, 47, 12, 61)),
]


def test_every_message_type_has_an_example():
    assert {type(m) for m in EXAMPLES} == set(P.MESSAGES.values())


@pytest.mark.parametrize("msg", EXAMPLES, ids=lambda m: type(m).__name__)
def test_round_trip_every_message_type(msg):
    data = P.encode(msg, 200)
    frames = P.FrameParser().feed(data)
    assert len(frames) == 1 and frames[0].seq == 200 and frames[0].msg_type == msg.TYPE
    assert frames[0].decode() == msg
    assert frames[0].to_bytes() == data


def _message_strategy():
    def for_class(cls):
        codes = cls.FORMAT[1:]
        vals = [st.integers(*P._INT_RANGES[c]) for c in codes]
        def build(xs):
            kw, i = {}, 0
            from dataclasses import fields
            for f in fields(cls):
                n = cls.ARITY.get(f.name, 1)
                kw[f.name] = tuple(xs[i:i + n]) if n > 1 else xs[i]
                i += n
            return cls(**kw)
        return st.tuples(*vals).map(build) if vals else st.just(cls())
    return st.one_of([for_class(c) for c in P.MESSAGES.values()])


messages = _message_strategy()
framed = st.tuples(messages, st.integers(0, 255)).map(lambda ms: P.encode(ms[0], ms[1]))


@SETTINGS
@given(msg=messages, seq=st.integers(0, 255))
def test_round_trip_random_field_values(msg, seq):
    (fr,) = P.FrameParser().feed(P.encode(msg, seq))
    assert (fr.seq, fr.decode()) == (seq, msg)


def test_bad_field_values_raise_naming_the_field():
    with pytest.raises(ValueError, match="vx_mm_s"):
        P.SetTwist(40000, 0, 0)
    with pytest.raises(ValueError, match="encoder_counts"):
        P.Telemetry(encoder_counts=(1, 2))
    with pytest.raises(P.ProtocolError, match="SET_TWIST payload must be 6 bytes"):
        P.Frame(P.MsgType.SET_TWIST, 1, b"\x00").decode()
    with pytest.raises(P.ProtocolError, match="unknown message type 0x7F"):
        P.Frame(0x7F, 1, b"").decode()


def _feed_chunked(data: bytes, cuts: list[int]) -> tuple[list[P.Frame], P.FrameParser]:
    parser = P.FrameParser()
    out, prev = [], 0
    for c in sorted({min(c, len(data)) for c in cuts}) + [len(data)]:
        out += parser.feed(data[prev:c])
        prev = c
    out += parser.drop_partial()
    return out, parser


@SETTINGS
@given(data=st.binary(max_size=400), cuts=st.lists(st.integers(0, 400), max_size=8))
def test_random_bytes_never_crash_and_only_yield_frames_present(data, cuts):
    frames, parser = _feed_chunked(data, cuts)
    whole, _ = _feed_chunked(data, [])
    assert frames == whole                               # chunking does not matter
    for fr in frames:                                     # anything yielded is CRC-valid and really in the stream
        raw = fr.to_bytes()
        assert raw in data
    assert parser.pending == 0


@SETTINGS
@given(items=st.lists(st.one_of(framed.map(lambda b: ("frame", b)),
                                st.binary(min_size=1, max_size=30).map(lambda b: ("garbage", b))),
                      max_size=12),
       cuts=st.lists(st.integers(0, 600), max_size=6), allow_sof=st.booleans())
def test_frames_survive_interleaved_garbage(items, cuts, allow_sof):
    if not allow_sof:
        items = [(k, b if k == "frame" else b.replace(bytes([P.SOF]), b"\x00")) for k, b in items]
    stream = b"".join(b for _, b in items)
    sent = [b for k, b in items if k == "frame"]
    got = [fr.to_bytes() for fr in _feed_chunked(stream, cuts)[0]]
    if not allow_sof:
        assert got == sent
    else:
        it = iter(got)                                    # every sent frame comes out, in order
        assert all(any(g == s for g in it) for s in sent)
        assert all(g in stream for g in got)


@SETTINGS
@given(frames=st.lists(framed, min_size=1, max_size=6), data=st.data())
def test_corrupted_frame_is_rejected_and_the_rest_recovered(frames, data):
    k = data.draw(st.integers(0, len(frames) - 1))
    pos = data.draw(st.integers(0, len(frames[k]) - 1))
    flip = data.draw(st.integers(1, 255))
    bad = bytearray(frames[k])
    bad[pos] ^= flip
    stream = b"".join(frames[:k]) + bytes(bad) + b"".join(frames[k + 1:])
    got, parser = _feed_chunked(stream, [])
    assert [f.to_bytes() for f in got] == frames[:k] + frames[k + 1:]


@SETTINGS
@given(frames=st.lists(framed, min_size=2, max_size=6), data=st.data())
def test_truncated_frame_is_rejected_and_the_rest_recovered(frames, data):
    k = data.draw(st.integers(0, len(frames) - 2))
    cut = data.draw(st.integers(1, len(frames[k]) - 1))
    stream = b"".join(frames[:k]) + frames[k][:cut] + b"".join(frames[k + 1:])
    got = [f.to_bytes() for f in _feed_chunked(stream, [])[0]]
    assert got == frames[:k] + frames[k + 1:]


@SETTINGS
@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 600), max_size=8),
       sof_density=st.floats(0, 0.5), max_payload=st.sampled_from([P.MCU_MAX_PAYLOAD, P.MAX_PAYLOAD]))
def test_fuzz_parser_accounts_for_every_byte(data, cuts, sof_density, max_payload):
    """Fuzz (hypothesis, bounded: <= 150 derandomized examples of <= 600 bytes): every input byte ends up
    in exactly one place: a frame, a skipped byte, or a start byte rejected for length, CRC or timeout."""
    rng = np.random.default_rng(len(data))
    raw = np.frombuffer(data, dtype=np.uint8).copy()
    raw[rng.random(raw.size) < sof_density] = P.SOF        # start bytes everywhere: the resync paths
    parser = P.FrameParser(max_payload=max_payload)
    frames, prev = [], 0
    for c in sorted({min(c, raw.size) for c in cuts}) + [raw.size]:
        frames += parser.feed(raw[prev:c].tobytes())
        prev = c
    frames += parser.drop_partial()
    used = sum(P.HEADER_LEN + len(f.payload) + P.CRC_LEN for f in frames)
    rejected = parser.length_errors + parser.crc_errors + parser.timeouts
    assert used + parser.dropped_bytes + rejected == raw.size and parser.pending == 0
    assert parser.frames == len(frames)
    for f in frames:
        assert len(f.payload) <= max_payload
        try:
            f.decode()                                     # a valid message, or a ProtocolError naming why
        except P.ProtocolError as e:
            assert "payload must be" in str(e) or "unknown message type" in str(e)


def test_parser_counts_resync_events():
    good = P.encode(P.Ping(1), 1)
    bad_crc = bytearray(P.encode(P.Ping(2), 2))
    bad_crc[-1] ^= 0xFF
    p = P.FrameParser(max_payload=P.MCU_MAX_PAYLOAD)
    frames = p.feed(b"\x01\x02\x03" + bytes([P.SOF, 200]) + bytes(bad_crc) + good)
    assert [f.to_bytes() for f in frames] == [good]
    assert p.dropped_bytes >= 3 and p.length_errors == 1 and p.crc_errors == 1


# --------------------------------------------------------------------------- fake MCU over a pty
class FakeMCU(threading.Thread):
    """Answers the protocol like the firmware does, with fault injection for the link tests."""

    def __init__(self, master_fd: int):
        super().__init__(daemon=True)
        self.fd = master_fd
        self.parser = P.FrameParser(max_payload=P.MCU_MAX_PAYLOAD)
        self.received: list[tuple[int, P.Message]] = []
        self.drop_next = 0              # ignore this many frames (lost replies)
        self.garbage = b""              # sent before every reply
        self.stale_first = False        # send a reply with a wrong seq before the right one
        self.foreign_nak_first = False  # send a NAK for another message type with the same seq first
        self.version = P.PROTOCOL_VERSION
        self.range_sensors = 0          # PONG: range sensors fitted
        self.arrived: list[float] = []  # monotonic arrival time of each received frame
        self.telemetry = P.Telemetry()
        self.running = True
        self.start()

    def run(self):
        while self.running:
            try:
                r, _, _ = select.select([self.fd], [], [], 0.02)
                if not r:
                    continue
                data = os.read(self.fd, 256)
            except OSError:
                return
            for fr in self.parser.feed(data):
                self.handle(fr)

    def reply(self, msg, seq):
        out = self.garbage
        if self.stale_first:
            out += P.encode(msg, (seq + 1) & 0xFF)
        if self.foreign_nak_first:
            out += P.encode(P.Nak(P.MsgType.SET_HEADING, P.NakReason.BAD_VALUE), seq)
        os.write(self.fd, out + P.encode(msg, seq))

    def handle(self, fr: P.Frame):
        try:
            msg = fr.decode()
        except P.ProtocolError:
            return self.reply(P.Nak(fr.msg_type, P.NakReason.BAD_LENGTH), fr.seq)
        self.received.append((fr.seq, msg))
        self.arrived.append(time.monotonic())
        if self.drop_next:
            self.drop_next -= 1
            return None
        if isinstance(msg, P.Ping):
            return self.reply(P.Pong(msg.nonce, self.version, 0x0200, 5, 400, self.range_sensors), fr.seq)
        if isinstance(msg, P.GetTelemetry):
            return self.reply(self.telemetry, fr.seq)
        if isinstance(msg, P.SetHeading) and abs(msg.azimuth_mrad) > P.AZIMUTH_LIMIT_MRAD:
            return self.reply(P.Nak(msg.TYPE, P.NakReason.BAD_VALUE), fr.seq)
        return self.reply(P.Ack(msg.TYPE, 0), fr.seq)


@pytest.fixture
def fake():
    master, slave = os.openpty()
    tty.setraw(slave)
    dev = FakeMCU(master)
    dev.path = os.ttyname(slave)
    yield dev
    dev.running = False
    dev.join(1)
    for fd in (master, slave):
        try:
            os.close(fd)
        except OSError:
            pass


FAST = SerialDriveConfig(reply_timeout=0.05, retries=3, keepalive=None, connect_timeout=1.0)
# for tests that count resends or replies: the fake MCU is a Python thread, slow to answer on a loaded machine
STEADY = SerialDriveConfig(reply_timeout=2.0, retries=0, keepalive=None, connect_timeout=3.0)


def test_drive_commands_and_replies_over_pty(fake):
    with SerialDrive(fake.path, FAST) as drive:
        assert drive.board is not None and drive.board.firmware_version == 0x0200
        assert drive.ping() < 0.05
        drive.set_twist(0.2, -0.1, 0.5)
        drive.set_heading(math.radians(-4.0), 0.3)           # the paper's azimuth command
        drive.set_heading(3 * math.pi / 2, 0.1)              # wrapped to -pi/2
        cpr = drive.config.counts_per_rev
        fake.telemetry = P.Telemetry(encoder_counts=(cpr, -cpr // 2, 0), encoder_rate=(60, 0, -30),
                                     faults=int(P.Fault.STALL | P.Fault.CMD_TIMEOUT | P.Fault.SPEED_LIMITED))
        odo = drive.odometry()
        np.testing.assert_allclose(odo.wheel_angles, [2 * np.pi, -np.pi, 0.0])
        np.testing.assert_allclose(odo.wheel_speeds, np.array([60, 0, -30]) / cpr * 2 * np.pi / 0.05)
        st_ = drive.status()
        assert st_.stalled and st_.faults == ("cmd_timeout",) and not st_.ok
    msgs = [m for _, m in fake.received]
    assert P.SetTwist(200, -100, 500) in msgs
    assert P.SetHeading(-70, 300, 0) in msgs and P.SetHeading(-1571, 100, 0) in msgs
    assert isinstance(msgs[-1], P.Stop)                       # close() stops the base
    seqs = [s for s, _ in fake.received]
    assert len(set(seqs)) == len(seqs)                        # a fresh seq per command


def test_missing_reply_is_resent_with_same_seq(fake):
    cfg = SerialDriveConfig(reply_timeout=0.3, retries=3, keepalive=None, connect_timeout=1.0)
    with SerialDrive(fake.path, cfg) as drive:
        n0 = len(fake.received)
        fake.drop_next = 2
        drive.set_twist(0.1, 0, 0)
        tries = fake.received[n0:]
        assert len(tries) == 3 and len({s for s, _ in tries}) == 1
        assert drive.stats.retries == 2
        fake.drop_next = 10
        with pytest.raises(DriveLinkError, match=f"no reply from the drive on '{fake.path}'.*4 attempts"):
            drive.stop()
        fake.drop_next = 0


def test_garbage_and_stale_replies_are_skipped(fake):
    with SerialDrive(fake.path, STEADY) as drive:
        fake.garbage = bytes([0x00, P.SOF, 0x03, 0x81, P.SOF, 0xFF, 0x12, P.SOF])
        fake.stale_first = True
        for _ in range(5):
            drive.set_twist(0.0, 0.1, 0.0)
            drive.ping()
        assert drive.stats.stale_replies == 10 and drive.stats.retries == 0
        assert drive.parser.crc_errors + drive.parser.length_errors + drive.parser.timeouts > 0


def test_nak_raises_command_error(fake):
    with SerialDrive(fake.path, FAST) as drive:
        # bypass the client-side range check to see the MCU's answer
        with pytest.raises(DriveCommandError, match="rejected SET_HEADING.*BAD_VALUE") as ei:
            drive._transact(P.SetHeading(4000, 100, 0), P.MsgType.ACK)
        assert ei.value.reason == P.NakReason.BAD_VALUE
        with pytest.raises(ValueError, match="speed"):
            drive.set_heading(0.0, -0.1)
        with pytest.raises(ValueError, match="vx"):
            drive.set_twist(float("nan"), 0, 0)


def test_keepalive_resends_motion_until_stop(fake):
    cfg = SerialDriveConfig(reply_timeout=0.05, keepalive=0.05, connect_timeout=1.0)
    with SerialDrive(fake.path, cfg) as drive:
        drive.set_twist(0.1, 0.0, 0.0)
        for _ in range(14):                                   # telemetry polls do not replace keepalives
            drive.telemetry()
            time.sleep(0.025)
        n_twists = sum(isinstance(m, P.SetTwist) for _, m in fake.received)
        assert n_twists >= 4                                  # refreshed well inside the 300 ms watchdog
        drive.stop()
        n = len(fake.received)
        time.sleep(0.2)
        assert len(fake.received) == n                        # nothing kept alive after stop
        assert drive.stats.keepalives >= 3


def test_missing_port_names_the_port():
    with pytest.raises(DriveLinkError, match="/dev/does-not-exist-ttyACM9"):
        SerialDrive("/dev/does-not-exist-ttyACM9", FAST)


def test_vanished_port_raises_link_error(fake):
    drive = SerialDrive(fake.path, FAST)
    fake.running = False
    fake.join(1)
    os.close(fake.fd)                                        # the device goes away (USB unplugged)
    with pytest.raises(DriveLinkError, match=fake.path):
        for _ in range(3):
            drive.set_twist(0.1, 0, 0)
    drive.close()                                             # closing a dead link does not raise


def test_loop_url_echo_is_not_a_reply():
    cfg = SerialDriveConfig(reply_timeout=0.02, retries=2, keepalive=None, connect_timeout=None)
    drive = SerialDrive("loop://", cfg)
    with pytest.raises(DriveLinkError, match="loop://.*SET_TWIST.*3 attempts"):
        drive.set_twist(0.1, 0.0, 0.0)
    assert drive.stats.retries == 2
    drive._ser.close()


def test_nak_for_another_message_with_the_same_seq_is_not_ours(fake):
    """replies are matched on type and seq; a NAK naming another command is skipped."""
    with SerialDrive(fake.path, STEADY) as drive:
        fake.foreign_nak_first = True
        for _ in range(5):
            drive.set_twist(0.1, 0.0, 0.0)             # the NAK names SET_HEADING: not this command's reply
            drive.ping()
            drive.stop()
        assert drive.stats.stale_replies == 15 and drive.stats.retries == 0
        with pytest.raises(DriveCommandError, match="rejected SET_HEADING"):
            drive.set_heading(0.0, 0.1)                # ... but it is the reply to a SET_HEADING
        fake.foreign_nak_first = False


def test_keepalive_stops_at_the_command_deadline(fake):
    """the keepalive repeats a command only while the application refreshes it."""
    cfg = SerialDriveConfig(reply_timeout=0.05, keepalive=0.05, command_deadline=0.3, connect_timeout=1.0)
    with SerialDrive(fake.path, cfg) as drive:
        for _ in range(8):                             # a live control loop: 0.4 s, longer than the deadline
            drive.set_twist(0.1, 0.0, 0.0)
            time.sleep(0.05)
        t_last = time.monotonic()
        drive.set_twist(0.2, 0.0, 0.0)
        time.sleep(0.6)                                # ... then it hangs
        msgs = [m for _, m in fake.received]
        i_stop = next(i for i, m in enumerate(msgs) if isinstance(m, P.Stop))
        assert isinstance(msgs[i_stop - 1], P.SetTwist) and msgs[i_stop - 1].vx_mm_s == 200
        assert sum(isinstance(m, P.SetTwist) and m.vx_mm_s == 200 for m in msgs) >= 4    # kept alive meanwhile
        assert 0.3 <= fake.arrived[i_stop] - t_last <= 0.3 + 0.25      # slack: thread wake-ups on a loaded host
        assert not any(isinstance(m, P.SetTwist) for m in msgs[i_stop:])
        assert drive.stats.deadline_stops == 1


def test_second_serial_drive_on_a_port_is_refused(fake):
    with SerialDrive(fake.path, FAST) as first:
        with pytest.raises(DriveLinkError, match=f"'{fake.path}' is in use by another program"):
            SerialDrive(fake.path, FAST)
        first.ping()
    SerialDrive(fake.path, FAST).close()               # free again once closed


def test_firmware_of_another_protocol_version_is_refused(fake):
    fake.version = P.PROTOCOL_VERSION - 1
    with pytest.raises(DriveProtocolError, match=f"protocol version {P.PROTOCOL_VERSION - 1}.*flash"):
        SerialDrive(fake.path, FAST)


def test_status_reports_bumpers_and_yaw_rate(fake):
    with SerialDrive(fake.path, FAST) as drive:
        assert drive.status().yaw_rate is None                          # no gyro on this board
        bias, rate = 40, 1000                                           # counts
        fake.telemetry = P.Telemetry(gyro_z=bias, sensors=int(P.Sensor.GYRO_OK))
        assert drive.status().yaw_rate == 0.0                           # standing still: that is the bias
        fake.telemetry = P.Telemetry(duty=(100, 100, 100), gyro_z=bias + rate, sensors=int(P.Sensor.GYRO_OK))
        assert drive.status().yaw_rate == pytest.approx(rate / P.GYRO_COUNTS_PER_RAD_S)
        fake.telemetry = P.Telemetry(bumpers=0x20)                      # released now, pressed since the last read
        drive.odometry()                                                # a read by odometry() ...
        fake.telemetry = P.Telemetry()
        assert drive.status().bumper                                    # ... does not lose it
        assert not drive.status().bumper


def test_payload_sizes_of_protocol_version_3():
    """Version 3: TELEMETRY grew by one u8 per range sensor slot (54 -> 63 bytes), PONG by range_sensors."""
    assert P.PROTOCOL_VERSION == 3
    assert struct.calcsize(P.Telemetry.FORMAT) == 54 + P.RANGE_SLOTS == 63 <= P.MAX_PAYLOAD
    assert struct.calcsize(P.Pong.FORMAT) == 14
    t = P.Telemetry(ranges_cm=(0, 10, 80, 33, 0, 0, 0, 0, 0), sensors=int(P.Sensor.RANGES_OK))
    assert t.pack()[54:] == bytes([0, 10, 80, 33, 0, 0, 0, 0, 0])      # after bumpers, slot order = ADC order
    assert t.ranges_ok and not t.gyro_ok
    assert t.ranges_m == (math.inf, 0.10, 0.80, 0.33, math.inf, math.inf, math.inf, math.inf, math.inf)
    with pytest.raises(ValueError, match="ranges_cm"):
        P.Telemetry(ranges_cm=(10,) * 8)
    with pytest.raises(ValueError, match="ranges_cm"):
        P.Telemetry(ranges_cm=(10,) * 8 + (300,))


def test_status_reports_ranges_of_the_layout(fake):
    fake.range_sensors = 9
    with SerialDrive(fake.path, FAST) as drive:
        assert drive.board.range_sensors == 9
        assert drive.status().ranges is None                              # no complete window yet
        fake.telemetry = P.Telemetry(ranges_cm=(10, 0, 25, 80, 0, 41, 0, 12, 33), sensors=int(P.Sensor.RANGES_OK))
        r = drive.status().ranges
        assert r == (0.10, math.inf, 0.25, 0.80, math.inf, 0.41, math.inf, 0.12, 0.33)
        RangeLayout().check(r)                                            # what the HAL promises


def test_board_without_range_sensors_reports_none(fake):
    fake.telemetry = P.Telemetry(sensors=int(P.Sensor.GYRO_OK))
    with SerialDrive(fake.path, FAST) as drive:                           # PONG range_sensors 0
        assert drive.status().ranges is None
    with SerialDrive(fake.path, replace(FAST, range_layout=None)) as drive:
        assert drive.status().ranges is None


def test_range_sensor_count_mismatch_is_refused_naming_the_field(fake):
    fake.range_sensors = 9
    four = RangeLayout(azimuths_rad=(0.0, math.pi / 2, math.pi, -math.pi / 2))
    with pytest.raises(DriveProtocolError, match=r"reads 9 range sensors.*range_layout expects 4"):
        SerialDrive(fake.path, replace(FAST, range_layout=four))
    with pytest.raises(DriveProtocolError, match=r"range_layout expects none"):
        SerialDrive(fake.path, replace(FAST, range_layout=None))
    with pytest.raises(ValueError, match="range_layout must have at most 9"):
        SerialDriveConfig(range_layout=RangeLayout(azimuths_rad=tuple(k * 0.5 for k in range(10))))
    with pytest.raises(ValueError, match="range_layout must be a robot.ranging.RangeLayout"):
        SerialDriveConfig(range_layout=8)
