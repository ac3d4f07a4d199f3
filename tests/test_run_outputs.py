"""A finished ``ssl-rescue run`` is never lost (issue 14, item 5): output paths are checked before
simulating, results.json is written before the viewer is flushed, and a viewer that is not there
(no display to spawn one on, nothing listening, a peer that never answers) costs a bounded wait and a
warning, not a hang."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("rerun")

from ssl_sim import cli, runner  # noqa: E402
from ssl_sim.viz import VIEWER_TIMEOUT_S, NullLogger, RerunLogger, make_logger  # noqa: E402

SRC = Path(__file__).resolve().parents[1] / "src"
TIME_LIMIT_S = 3.0  # simulated seconds; the runs below take well under a second of CPU each


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]  # closed again on leaving: nothing listens there


def test_unwritable_out_fails_before_simulating(tmp_path, monkeypatch, capsys):
    (tmp_path / "a_file").write_text("x")

    def no_sim(*a, **k):
        raise AssertionError("simulated although --out cannot be written")

    monkeypatch.setattr(runner, "RescueRun", no_sim)
    code = cli.main(["run", "paper_lab", "-q", "--out", str(tmp_path / "a_file" / "run")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and "--out" in err and "a_file" in err
    code = cli.main(["run", "paper_lab", "-q", "--out", str(tmp_path / "ok"),
                     "--rerun", f"save:{tmp_path / 'a_file' / 'run.rrd'}"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--rerun save:" in err
    with pytest.raises(runner.OutputPathError, match="out_dir"):
        runner.run_scenario("paper_lab", out_dir=tmp_path / "a_file" / "x")
    import ssl_sim.sweep as sweep

    monkeypatch.setattr(sweep, "run_sweep", no_sim)
    code = cli.main(["sweep", "paper_lab", "--seeds", "0:2", "-q", "--out", str(tmp_path / "a_file" / "sweep")])
    assert code == 2 and "--out" in capsys.readouterr().err


def test_connect_to_a_closed_port_falls_back_to_a_file_at_once(tmp_path, caplog):
    t0 = time.perf_counter()
    logger = make_logger(f"connect:127.0.0.1:{_closed_port()}", fallback_save=tmp_path / "r.rrd")
    assert time.perf_counter() - t0 < VIEWER_TIMEOUT_S
    assert isinstance(logger, RerunLogger) and logger.mode == "save" and logger.path == tmp_path / "r.rrd"
    assert "no viewer answers" in caplog.text and "r.rrd" in caplog.text
    logger.close()
    assert isinstance(make_logger("connect:127.0.0.1:1"), NullLogger)  # no fallback file: just no logging


def test_spawn_without_a_display_falls_back(tmp_path, monkeypatch, caplog):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is Linux-specific")
    logger = make_logger("spawn", fallback_save=tmp_path / "r.rrd")
    assert logger.mode == "save" and "no display" in caplog.text
    logger.close()


def _cli_run(tmp_path: Path, rerun: str, env_drop=()) -> tuple[subprocess.CompletedProcess, float, Path]:
    env = {k: v for k, v in os.environ.items() if k not in env_drop}
    env["PYTHONPATH"] = str(SRC)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"  # the venv's rerun viewer
    out = tmp_path / "run"
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "ssl_sim.cli", "run", "paper_lab", "-q", "--time-limit",
                        str(TIME_LIMIT_S), "--rerun", rerun, "--out", str(out)],
                       capture_output=True, text=True, env=env, timeout=120)
    return p, time.perf_counter() - t0, out


class _Peer:
    """A TCP peer on localhost that accepts connections and never speaks gRPC; with ``settings`` it answers the
    HTTP/2 preface with a SETTINGS frame (so it looks like a viewer) and then stalls, like a hung viewer."""

    def __init__(self, settings: bool) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.conns: list[socket.socket] = []
        if settings:
            threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                c, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(c)
            c.sendall(bytes([0, 0, 0, 0x04, 0, 0, 0, 0, 0]))

    def close(self) -> None:
        for c in self.conns:
            c.close()
        self.sock.close()


@pytest.mark.slow
@pytest.mark.parametrize("how", ["connect_closed", "spawn_no_display", "connect_silent_peer", "connect_stalled"])
def test_cli_run_finishes_and_writes_results_without_a_viewer(tmp_path, how):
    """The whole CLI in a subprocess (as a user runs it). Wall time is printed, not asserted (the machine
    is shared); the hard subprocess timeout is what catches a hang."""
    peer = _Peer(settings=how == "connect_stalled") if how.startswith("connect_s") else None
    target = ("spawn" if how == "spawn_no_display" else
              f"connect:127.0.0.1:{peer.port if peer else _closed_port()}")
    try:
        p, wall, out = _cli_run(tmp_path, target, env_drop=("DISPLAY", "WAYLAND_DISPLAY"))
    finally:
        if peer is not None:
            peer.close()
    print(f"{how}: {wall:.1f} s wall")
    assert p.returncode == 0, p.stderr
    result = json.loads((out / "results.json").read_text())
    assert result["time_limit_s"] == TIME_LIMIT_S and result["n_listens"] >= 1
    if how != "connect_stalled":
        assert "WARNING" in p.stderr and "instead" in p.stderr
        assert (out / "rescue.rrd").stat().st_size > 0 and result["rerun_file"] == str(out / "rescue.rrd")
    else:  # connected to the "viewer"; abandoned at the end
        assert "did not take the end of the recording" in p.stderr and "rerun_file" not in result


#: When Ctrl-C comes: this many s after ``--out`` appears ("out") or after the run connected to the stalled viewer
#: ("viewer": its second connection; the first is the probe). After ``--out``, rerun is imported (0.6 s on the idle
#: 2-core machine, 1.5-5 s under load), the viewer probed and connected (10-30 ms), the scene built (0.3 s), then
#: the run simulates. Python's own SIGINT handling failed inside the import (robot.interrupt): of 118 signals sent
#: 0-400 ms after ``--out`` appeared, 3 (at 184-208 ms) ended in death by SIGINT instead of exit 130 and 2 (at 140
#: and 350 ms) were swallowed, the run going on to its end. At the viewer connection it was raised inside
#: RerunLogger.__init__ after the logger had registered its exit-time close, so "interrupted" was followed by a 9 s
#: wait and the viewer warning as the last line (4 of 4 runs of this test on the old code).
CTRL_C_AT = (("out", 0.0), ("out", 0.05), ("out", 0.15), ("out", 0.3), ("viewer", 0.0), ("viewer", 1.5))


@pytest.mark.slow
def test_ctrl_c_ends_a_run_with_a_stalled_viewer(tmp_path):
    """Ctrl-C while a run starts or simulates: exit 130 with "interrupted" as the last line, no results.json and
    nothing else left in --out (nor --out itself). The issue's run ignored Ctrl-C while blocked in the viewer flush; once connected to
    the stalled viewer a run now ends within the viewer timeout (3 s flush + rerun's 5 s disconnect grace). The runs
    go at once, each signalled at its own moment: their load is part of the test (the failure was seen at load
    average 4-6)."""
    env = dict(os.environ, PYTHONPATH=str(SRC))
    runs = []
    try:
        for event, delay_s in CTRL_C_AT:
            peer = _Peer(settings=True)
            out, err = tmp_path / f"run_{event}_{delay_s}", tmp_path / f"stderr_{event}_{delay_s}.txt"
            with err.open("w") as err_file:  # a file, not a pipe: nothing blocks on a full pipe meanwhile
                p = subprocess.Popen([sys.executable, "-m", "ssl_sim.cli", "run", "light_rubble_three", "-q",
                                      "--time-limit", "120", "--rerun", f"connect:127.0.0.1:{peer.port}",
                                      "--out", str(out)], env=env, stdout=subprocess.DEVNULL, stderr=err_file,
                                     preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
            runs.append({"at": f"{delay_s} s after {event}", "event": event, "delay_s": delay_s, "out": out,
                         "err": err, "peer": peer, "p": p})
        deadline = time.monotonic() + 120
        waiting = list(runs)
        while waiting and time.monotonic() < deadline:
            now = time.monotonic()
            for r in list(waiting):
                happened = r["out"].exists() if r["event"] == "out" else len(r["peer"].conns) >= 2
                if happened and "event_at" not in r:
                    r["event_at"] = now
                if ("event_at" in r and now >= r["event_at"] + r["delay_s"]) or r["p"].poll() is not None:
                    r["p"].send_signal(signal.SIGINT)
                    r["sent_at"] = time.monotonic()
                    waiting.remove(r)
            time.sleep(0.002)
        assert not waiting, "a run did not reach its moment within 120 s"
        running = list(runs)
        while running and time.monotonic() < deadline + 60:  # this hard timeout is what catches a hang
            for r in list(running):
                if r["p"].poll() is not None:
                    print(f"SIGINT {r['at']}: exit {r['p'].returncode} {time.monotonic() - r['sent_at']:.1f} s later")
                    running.remove(r)
            time.sleep(0.02)
    finally:
        for r in runs:
            r["p"].kill()
            r["p"].wait()
            r["peer"].close()
    for r in runs:
        p, err, out = r["p"], r["err"].read_text(), r["out"]
        assert p.returncode == 130, f"SIGINT {r['at']}: exit {p.returncode}\n{err}"
        assert err.strip().splitlines()[-1] == "ssl-rescue: interrupted" and "Traceback" not in err, err
        # nothing left: no results.json, partial or stray file (the folder the run made is removed with it)
        assert not out.exists() or list(out.iterdir()) == [], list(out.iterdir())


_ABANDON_SCRIPT = r"""
import sys, time
import numpy as np
from ssl_sim.viz import RerunLogger
lg = RerunLogger(f"connect:127.0.0.1:{sys.argv[1]}")
rng = np.random.default_rng(0)
for _ in range(300):  # megabytes the stalled peer never reads: the flush cannot finish
    lg.rec.log("x", lg.rr.Points3D(rng.random((2000, 3))))
lg.close()
print("closed", file=sys.stderr, flush=True)
time.sleep(float(sys.argv[2]))
print("last line", file=sys.stderr, flush=True)
"""


@pytest.mark.slow
def test_an_abandoned_viewer_prints_nothing_after_close(tmp_path):
    """Once close() gave up on a viewer that stopped answering (and said so), nothing more reaches stderr: rerun's
    gRPC client, still flushing in the background, warns 10 s after the flush began - after the program's last
    line ("interrupted") when the process takes that long to end under load. Here the process waits out those
    10 s itself (close() takes the 3 s flush timeout + 5 s disconnect grace + 1 s)."""
    peer = _Peer(settings=True)
    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    env["PYTHONPATH"] = str(SRC)
    try:
        p = subprocess.run([sys.executable, "-c", _ABANDON_SCRIPT, str(peer.port), "4"], env=env,
                           capture_output=True, text=True, timeout=120)
    finally:
        peer.close()
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 0, p.stderr
    assert "did not take the end of the recording" in p.stderr, p.stderr  # our own warning, before close returns
    assert lines[-2:] == ["closed", "last line"], p.stderr
