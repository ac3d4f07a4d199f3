"""Drive firmware figures, measured on the compiled ATmega2560 image in simavr.

* flash / static RAM use (avr-size of firmware/build/drive.elf);
* parser cost: every call of ``link_poll`` is timed cycle-exactly by the simavr harness
  (``--profile``) while byte streams go in over the pty: well-formed commands, garbage,
  bad-CRC frames and an adversarial stream of nested start bytes whose candidates all
  complete on the same byte (the parser's worst case);
* command-to-PWM latency: simulated cycles from the stop bit of a command's last byte
  (UART RXC) to the last motor-output register write, for SET_TWIST, SET_HEADING, STOP;
* IK match: firmware duty vs ``robot.kinematics.twist_to_wheels`` over random twists;
* link loss: simulated time from a motion command's last byte to the start of the watchdog
  ramp and to zero duty on all wheels, from full, half and 10 % duty (requirement: <= 300 ms);
* range sensors: cycles of every ADC interrupt (one conversion read, the next started) and of
  every ``ranges_tick`` call (the tick that converts one sensor's window mean to cm is the
  worst), each from its own short run with all eight inputs driven, and the CPU share.

All times are simulated CPU cycles at 16 MHz. Prints a table and one JSON line.
Run: .venv/bin/python benchmarks/bench_firmware.py
"""
from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from _results import write_result
from robot import protocol as P
from robot.hardware.serial_drive import SerialDrive, SerialDriveConfig
from robot.kinematics import OmniDriveParams, twist_to_wheels

FW = Path(__file__).resolve().parents[1] / "firmware"
ELF = FW / "build" / "drive.elf"
SIM = FW / "sim" / "build" / "simdrive"
F_CPU = 16_000_000
FLASH_BYTES, SRAM_BYTES = 256 * 1024, 8 * 1024


def build() -> None:
    r = subprocess.run(["make", "-C", str(FW), "all", "sim"], capture_output=True, text=True)
    if r.returncode:
        sys.exit(f"firmware build failed:\n{r.stdout}{r.stderr}")


def sizes() -> dict:
    out = subprocess.run(["avr-size", "-A", str(ELF)], capture_output=True, text=True, check=True).stdout
    sec = {f[0]: int(f[1]) for f in (line.split() for line in out.splitlines()) if len(f) >= 2 and f[0].startswith(".")
           and f[1].isdigit()}
    flash = sec.get(".text", 0) + sec.get(".data", 0)
    ram = sec.get(".data", 0) + sec.get(".bss", 0) + sec.get(".noinit", 0)
    return {"flash_bytes": flash, "flash_pct": 100 * flash / FLASH_BYTES,
            "static_ram_bytes": ram, "static_ram_pct": 100 * ram / SRAM_BYTES}


def symbol(name: str) -> int:
    out = subprocess.run(["avr-nm", str(ELF)], capture_output=True, text=True, check=True).stdout
    for line in out.splitlines():
        f = line.split()
        if len(f) == 3 and f[2] == name:
            return int(f[0], 16)
    raise KeyError(name)


class Board:
    def __init__(self, *args: str):
        self.proc = subprocess.Popen([str(SIM), *args, str(ELF)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, text=True)
        self.port = self.proc.stdout.readline().split()[1]
        self.pwm: list[tuple[int, tuple[int, int, int], int]] = []
        self.prof: list[tuple[int, int]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            f = line.split()
            if f[:1] == ["PWM"]:
                c, d0, d1, d2, dirs, rx = (int(x) for x in f[1:7])
                self.pwm.append((c, tuple(d if dirs >> i & 1 else -d for i, d in enumerate((d0, d1, d2))), rx))
            elif f[:1] == ["PROF"]:
                self.prof.append((int(f[1]), int(f[2])))

    def wait_pwm(self, n: int, timeout: float = 2.0):
        deadline = time.monotonic() + timeout
        while len(self.pwm) <= n:
            if time.monotonic() > deadline:
                raise TimeoutError("no PWM change")
            time.sleep(0.001)
        return self.pwm[n]

    def close(self):
        self.proc.terminate()
        self.proc.wait(5)


def parser_cost(drive: SerialDrive, board: Board) -> dict:
    rng = np.random.default_rng(3)
    frames = b"".join(P.encode(m, i) for i, m in enumerate(
        [P.SetTwist(100, 0, 0), P.Ping(7), P.GetTelemetry(), P.SetHeading(-70, 300, 0)] * 10))
    garbage = rng.integers(0, 256, 400, dtype=np.uint8)
    garbage = bytes(garbage[garbage != P.SOF])
    bad = bytearray()
    for i in range(20):
        f = bytearray(P.build_frame(0x02, i, bytes(rng.integers(0, 256, P.MCU_MAX_PAYLOAD, dtype=np.uint8))))
        f[-1] ^= 0xFF
        bad += f
    # nested candidates: A5 L A5 L-2 ... all ending on the same byte -> one byte completes them all
    nested = bytearray()
    for _ in range(10):
        lens = list(range(P.MCU_MAX_PAYLOAD, -1, -2))
        blob = bytearray()
        for k, n in enumerate(lens):
            blob += bytes([P.SOF, n])
        need = max(6 + n + 2 * k for k, n in enumerate(lens))
        blob += bytes(need - len(blob))
        nested += blob
    streams = {"valid frames": frames, "garbage (no SOF)": garbage, "bad-CRC max-length frames": bytes(bad),
               "nested start bytes": bytes(nested)}
    out = {}
    for name, data in streams.items():
        board.prof.clear()
        time.sleep(0.02)
        start = len(board.prof)
        drive._ser.write(data)                     # raw bytes: the bench exercises the MCU parser
        drive._ser.flush()
        time.sleep(len(data) * 11 / 117647 + 0.1)  # line time (+ replies) and settling
        drive._ser.reset_input_buffer()
        calls = [c for _, c in board.prof[start:]]
        out[name] = {"bytes": len(data), "calls": len(calls), "max_cycles_per_call": max(calls),
                     "mean_cycles_per_byte": sum(calls) / len(data)}
    return out


def latency_and_ik(drive: SerialDrive, board: Board, n: int = 60) -> dict:
    rng = np.random.default_rng(11)
    params = OmniDriveParams()
    lat = {"SET_TWIST": [], "SET_HEADING": [], "STOP": []}
    ik_err = []
    for i in range(n):
        if i % 3 == 2:
            az, speed = rng.uniform(-math.pi, math.pi), rng.uniform(0.05, 0.8)
            k = len(board.pwm)
            drive.set_heading(az, speed)
            az_w = round(az * 1000) / 1000
            twist = (round(speed * 1000) / 1000 * math.cos(az_w), round(speed * 1000) / 1000 * math.sin(az_w), 0.0)
            kind = "SET_HEADING"
        else:
            twist = tuple(round(x, 3) for x in rng.uniform([-0.6, -0.6, -3.0], [0.6, 0.6, 3.0]))
            k = len(board.pwm)
            drive.set_twist(*twist)
            kind = "SET_TWIST"
        c, duty, rx = board.wait_pwm(k)
        lat[kind].append(c - rx)
        want = twist_to_wheels(twist, params) / params.max_wheel_speed * P.PWM_TOP
        ik_err.append(float(np.abs(np.array(duty) - want).max()))
        if i % 5 == 4:
            k = len(board.pwm)
            drive.stop()
            c, duty, rx = board.wait_pwm(k)
            assert duty == (0, 0, 0)
            lat["STOP"].append(c - rx)
    res = {k: {"min": int(min(v)), "median": float(np.median(v)), "max": int(max(v))} for k, v in lat.items()}
    res["ik_max_err_counts"] = max(ik_err)
    res["ik_max_err_rad_s"] = max(ik_err) * params.max_wheel_speed / P.PWM_TOP
    res["n_commands"] = n
    return res


def link_loss(drive: SerialDrive, board: Board) -> dict:
    out = {}
    for omega, label in ((8.0, "full"), (4.0, "half"), (0.8, "10 %")):   # 8 rad/s turn: every wheel at 20 rad/s
        n = len(board.pwm)
        drive.set_twist(0.0, 0.0, omega)
        deadline = time.monotonic() + 5.0
        while not (len(board.pwm) > n + 1 and board.pwm[-1][1] == (0, 0, 0)):
            if time.monotonic() > deadline:
                raise TimeoutError("watchdog did not stop the motors")
            time.sleep(0.005)
        ev = board.pwm[n:]
        t_cmd = ev[0][2]
        out[label] = {"duty": ev[0][1][0], "ramp_start_ms": (ev[1][0] - t_cmd) / F_CPU * 1e3,
                      "zero_ms": (ev[-1][0] - t_cmd) / F_CPU * 1e3}
    return out


def range_costs(seconds: float = 0.5) -> dict:
    """Cycles per call of the ADC interrupt and of ranges_tick (cycle-exact, --profile), inputs at 0.3-2.3 V."""
    out = {}
    for name, sym in (("adc_isr", "__vector_29"), ("ranges_tick", "ranges_tick")):
        board = Board("--profile", hex(symbol(sym)))
        try:
            for ch in range(8):
                board.proc.stdin.write(f"ADC {ch} {300 + 250 * ch}\n")
            board.proc.stdin.flush()
            time.sleep(seconds)
        finally:
            board.close()
        prof = board.prof[10:]                       # past start-up
        calls = np.array([c for _, c in prof], float)
        span = (prof[-1][0] - prof[0][0]) / F_CPU
        out[name] = {"calls_per_s": len(prof) / span, "min_cycles": int(calls.min()),
                     "median_cycles": float(np.median(calls)), "max_cycles": int(calls.max()),
                     "cpu_pct": 100 * calls.sum() / (span * F_CPU)}
    return out


def main() -> int:
    missing = [t for t in ("avr-gcc", "avr-size", "avr-nm", "make") if shutil.which(t) is None]
    if missing or not Path("/usr/include/simavr/sim_avr.h").exists():
        sys.exit(f"bench_firmware: needs gcc-avr, avr-libc, simavr, libsimavr-dev (missing: {missing or 'simavr'})")
    build()
    size = sizes()
    board = Board("--profile", hex(symbol("link_poll")))
    try:
        with SerialDrive(board.port, SerialDriveConfig(keepalive=None)) as drive:
            parse = parser_cost(drive, board)
            perf = latency_and_ik(drive, board)
            loss = link_loss(drive, board)
            tel = drive.telemetry()
    finally:
        board.close()
    ranges = range_costs()

    print(f"flash {size['flash_bytes']} B ({size['flash_pct']:.1f} % of 256 KiB), "
          f"static RAM {size['static_ram_bytes']} B ({size['static_ram_pct']:.1f} % of 8 KiB; stack not included)")
    print("parser (link_poll, cycle-exact in simavr, interrupts taken meanwhile included):")
    for name, r in parse.items():
        print(f"  {name:28s} {r['bytes']:5d} B  {r['calls']:5d} calls  worst call {r['max_cycles_per_call']:5d} cyc "
              f"({r['max_cycles_per_call'] / 16:.1f} us)  mean {r['mean_cycles_per_byte']:.0f} cyc/byte")
    byte_time = 11 * F_CPU / 117647
    print(f"  one byte lasts {byte_time:.0f} cycles on the wire (115200 Bd, U2X: 117647 Bd)")
    print(f"  firmware's own telemetry: max_parse_cycles {tel.max_parse_cycles} (one call), max_cmd_cycles "
          f"{tel.max_cmd_cycles}, replies dropped under the 'valid frames' flood: {tel.tx_dropped}")
    print("command -> PWM latency (last byte's RXC to the last output register write), cycles:")
    for k in ("SET_TWIST", "SET_HEADING", "STOP"):
        r = perf[k]
        print(f"  {k:12s} min {r['min']:6d}  median {r['median']:8.0f}  max {r['max']:6d}  (max {r['max'] / 16:.0f} us)")
    print(f"IK match over {perf['n_commands']} random commands: max |duty - python IK| = "
          f"{perf['ik_max_err_counts']:.3f} counts of {P.PWM_TOP} = {perf['ik_max_err_rad_s']:.4f} rad/s")
    print("link loss (no command after the last one), simulated ms after its last byte:")
    for k, r in loss.items():
        print(f"  {k:5s} duty {r['duty']:4d}: ramp starts {r['ramp_start_ms']:6.1f}, all zero {r['zero_ms']:6.1f}")
    print("range sensors (cycles per call, interrupts taken meanwhile included; an interrupt's 8-cycle response "
          "and vector jump not included):")
    for k, r in ranges.items():
        print(f"  {k:12s} {r['calls_per_s']:6.0f} calls/s  min {r['min_cycles']:5d}  median {r['median_cycles']:6.0f}  "
              f"max {r['max_cycles']:5d}  ({r['max_cycles'] / 16:.1f} us)  CPU {r['cpu_pct']:.2f} %")
    print(json.dumps({"bench": "firmware", **size,
                      "parser": parse,
                      "parser_worst_cycles_per_call": max(r["max_cycles_per_call"] for r in parse.values()),
                      "fw_max_parse_cycles": tel.max_parse_cycles, "fw_max_cmd_cycles": tel.max_cmd_cycles,
                      "latency_cycles": {k: perf[k] for k in ("SET_TWIST", "SET_HEADING", "STOP")},
                      "ik_max_err_counts": perf["ik_max_err_counts"], "ik_max_err_rad_s": perf["ik_max_err_rad_s"],
                      "link_loss_ms": loss, "ranges": ranges}))
    figures = {**{k: v for k, v in size.items() if isinstance(v, (int, float))},
               "parser_worst_cycles_per_call": max(r["max_cycles_per_call"] for r in parse.values()),
               **{f"parser_mean_cycles_per_byte {k}": r["mean_cycles_per_byte"] for k, r in parse.items()},
               **{f"latency_median_cycles {k}": perf[k]["median"] for k in ("SET_TWIST", "SET_HEADING", "STOP")},
               "ik_max_err_counts": perf["ik_max_err_counts"],
               **{f"link_loss_all_zero_ms {k}": r["zero_ms"] for k, r in loss.items()},
               **{f"range_cpu_pct {k}": r["cpu_pct"] for k, r in ranges.items()}}
    write_result("firmware", figures)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
