"""Watching a rescue run: a logger interface the runner calls, a no-op one and a rerun one.

The runner calls the logger; without rerun (or with :class:`NullLogger`) nothing is logged.
:class:`RerunLogger` writes a rerun recording (``.rrd`` file, headless: the default), spawns a
viewer or streams to a running one (gRPC). Timeline ``sim_time`` = simulated seconds.

Entities (world frame unless said otherwise; all lengths m)::

    world/room               room outline (Boxes3D, wireframe)              static
    world/rubble             obstacles (Boxes3D; climbable debris brownish) static
    world/victims            true victim mouths (Points3D, labelled)        static
    world/interferers        other sound sources (Points3D)                 static
    world/found              victims found so far (true positions, green)   at each find
    world/robot              robot pose (Transform3D: base frame, full 3D attitude)
    world/robot/body         chassis (Cylinders3D, robot frame)             static
    world/robot/array        array frame (Transform3D: cube centre above the base)
    world/robot/array/srp_map     SRP-PHAT coarse map on a sphere around the array (Points3D, coloured)
    world/robot/array/detections  detected directions (Arrows3D, red, length ~ power)
    world/robot/array/truth       true directions of the sources (Arrows3D, green: victims, orange: others)
    world/mics               microphone world positions (Points3D)
    world/trail              the path driven (LineStrips3D)
    world/target             where the behaviour is heading (Arrows3D from the robot, world)
    world/coverage           floor listened to, coloured by P(a caller there still unheard) (Points3D)
    world/learned_obstacles  the behaviour's occupancy grid: cells learned by touch or range rays (Boxes3D)
    world/ranges             the range sensors' last rays as the behaviour placed them (LineStrips3D: red to
                             a return, grey to the sensors' maximum range where nothing was seen)
    plots/angular_error_deg, plots/distance_to_victim_m, plots/wheel_speed/{0,1,2} (Scalars)
    log/behaviour            the behaviour's decisions (TextLog); log/state its state
"""
from __future__ import annotations

import atexit
import logging
import math
import os
import shutil
import socket
import sys
import threading
import uuid
from pathlib import Path
from typing import Any, Sequence
from urllib.parse import urlsplit

import numpy as np

from robot.interrupt import check_interrupt

__all__ = ["RunLogger", "NullLogger", "RerunLogger", "ViewerUnavailable", "make_logger", "parse_rerun_target"]

log = logging.getLogger(__name__)

#: How long a viewer may take to accept the connection, and to take the last data at the end of a run.
#: A local viewer answers in milliseconds; rerun 0.41 itself would wait forever (flush without a timeout).
VIEWER_TIMEOUT_S = 3.0
DEFAULT_VIEWER_ADDR = ("127.0.0.1", 9876)  # rerun's default gRPC port
_RERUN_DISCONNECT_GRACE_S = 5.0  # rerun 0.41 waits this long for a connection when a sink shuts down (measured)
# rerun's gRPC client keeps flushing in a background thread after close() abandoned a stalled viewer and warns
# "Flushing the gRPC stream has taken over 10.0s" from there, after our own last line (e.g. "interrupted").
# close() reports the abandoned viewer itself, so that module logs errors only. rerun reads RUST_LOG once, when
# it is imported; "info" is its own default for everything else. A RUST_LOG the user set is left as it is.
_RERUN_LOG_FILTER = "info,re_grpc_client::write=error"


def _import_rerun():
    """``rerun``, imported with :data:`_RERUN_LOG_FILTER` unless the user set RUST_LOG (the variable is set for
    the import only: a spawned viewer keeps its own default)."""
    if "rerun" in sys.modules or "RUST_LOG" in os.environ:
        import rerun
        return rerun
    os.environ["RUST_LOG"] = _RERUN_LOG_FILTER
    try:
        import rerun
    finally:
        os.environ.pop("RUST_LOG", None)
    return rerun


class ViewerUnavailable(RuntimeError):
    """No rerun viewer can be reached for ``spawn`` / ``connect``."""


class RunLogger:
    """What the runner reports while a rescue runs; every method is a no-op here."""

    enabled = False
    path: Path | None = None  # the .rrd file being written, if any

    def start(self, world, sources: Sequence, robot_config, title: str = "") -> None:
        """The scene: ``world`` (ssl_sim.world.World), ``sources`` (SoundSource list), robot model config."""

    def robot(self, t: float, position: np.ndarray, quat_wxyz: np.ndarray, mics_world: np.ndarray,
              wheel_speeds: np.ndarray) -> None:
        """Robot base pose (world), microphone world positions (n, 3), wheel speeds (rad/s)."""

    def trail(self, t: float, xyz: np.ndarray) -> None:
        """The path so far, (k, 3) world points."""

    def listen(self, t: float, srp_map: np.ndarray, grid_directions: np.ndarray, detections: Sequence[dict],
               truth: Sequence[dict]) -> None:
        """One localization: coarse SRP map on ``grid_directions`` (array frame unit vectors),
        detections and true directions as dicts with ``direction`` (array frame unit vector) and more."""

    def target(self, t: float, origin_world: np.ndarray, direction_world: np.ndarray | None) -> None:
        """Where the behaviour heads (world direction from ``origin_world``), or None for no target."""

    def found(self, t: float, estimated_world: np.ndarray, truth_world: np.ndarray, labels: Sequence[str]) -> None:
        """Victims found so far: where the robot reported them (its map estimate) and where they are, (k, 3) each."""

    def sound_map(self, t: float, sources: Sequence) -> None:
        """The robot's sound map (``robot.sound_map.MapSource`` list, world frame)."""

    def plan(self, t: float, start_world: np.ndarray, waypoints_world: np.ndarray | None) -> None:
        """The planned path (k, 2) from ``start_world`` (x, y), or None."""

    def obstacles(self, t: float, cells_world: np.ndarray, cell_size: float) -> None:
        """Obstacles learned by touch and range rays: centres (k, 2) of occupied grid cells of ``cell_size`` m."""

    def ranges(self, t: float, starts_world: np.ndarray, ends_world: np.ndarray, hit: np.ndarray) -> None:
        """The range sensors' last reading: rays from ``starts_world`` to ``ends_world`` ((k, 3) each) and whether
        each ended on a return (``hit``, (k,)) or at the sensors' maximum range."""

    def coverage(self, t: float, cells_world: np.ndarray, unheard: np.ndarray) -> None:
        """Floor listened to: centres (k, 2) of grid cells and the probability (k,) that a caller there is
        still unheard (``robot.coverage``)."""

    def scalars(self, t: float, values: dict[str, float]) -> None:
        """Time series, e.g. ``{"angular_error_deg": 2.1}``."""

    def event(self, t: float, state: str, text: str, level: str = "INFO") -> None:
        """A behaviour decision."""

    def close(self) -> None:
        """Flush and close sinks."""


class NullLogger(RunLogger):
    """Logs nothing (the runner's default)."""


def parse_rerun_target(target: str) -> tuple[str, str | None]:
    """``save:PATH`` | ``spawn`` | ``connect`` | ``connect:ADDR`` -> (mode, argument).

    ``ADDR``: a full ``rerun+http://host:port/proxy`` URL or ``host:port``."""
    if target == "spawn":
        return "spawn", None
    if target == "connect":
        return "connect", None
    mode, sep, arg = target.partition(":")
    if not sep or not arg or mode not in ("save", "connect"):
        raise ValueError(f"--rerun: expected save:PATH, spawn or connect[:ADDR], got {target!r}")
    if mode == "connect" and "://" not in arg:
        arg = f"rerun+http://{arg}/proxy"
    return mode, arg


def viewer_problem(mode: str, arg: str | None, timeout_s: float = VIEWER_TIMEOUT_S) -> str | None:
    """Why a ``spawn`` / ``connect`` viewer cannot work here, or None. Checked before connecting, since
    rerun's own connection retries in the background and its flush then blocks."""
    if mode == "spawn":
        if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            return "no display to spawn a viewer on (DISPLAY and WAYLAND_DISPLAY are unset)"
        if shutil.which("rerun") is None:
            return "the rerun viewer executable is not on PATH"
        return None
    if mode == "connect":
        url = urlsplit(arg) if arg else None
        host, port = (url.hostname, url.port or DEFAULT_VIEWER_ADDR[1]) if url and url.hostname else DEFAULT_VIEWER_ADDR
        try:
            with socket.create_connection((host, port), timeout=timeout_s) as s:
                # A gRPC server answers the HTTP/2 preface with a SETTINGS frame (RFC 9113, 3.4); a port that
                # accepts but never answers would make rerun's final flush and exit block forever.
                s.sendall(_H2_PREFACE + _H2_EMPTY_SETTINGS)
                head = s.recv(9)
        except OSError as exc:
            return f"no viewer answers at {host}:{port} ({exc.strerror or exc})"
        if len(head) < 9 or head[3] != 0x04:
            return f"{host}:{port} does not answer as a rerun viewer (gRPC) does"
    return None


_H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"
_H2_EMPTY_SETTINGS = bytes([0, 0, 0, 0x04, 0, 0, 0, 0, 0])  # length 0, type SETTINGS, no flags, stream 0


_VICTIM_RGB = (230, 40, 40)
_FOUND_RGB = (40, 200, 60)
_OTHER_RGB = (255, 150, 0)
#: Sound-map classes (the truth markers above use red / orange; the map's estimates lighter tones).
_CLASS_RGB = {"victim": (60, 220, 220), "interferer": (255, 200, 60), "unknown": (170, 170, 170)}


def _colormap(values: np.ndarray) -> np.ndarray:
    """Power (0..max) -> RGB uint8 with matplotlib's viridis (dark blue low .. yellow high)."""
    from matplotlib import colormaps

    v = np.asarray(values, float)
    top = float(v.max()) if v.size and v.max() > 0 else 1.0
    return (colormaps["viridis"](np.clip(v / top, 0, 1))[:, :3] * 255).astype(np.uint8)


class RerunLogger(RunLogger):
    """Logs to a rerun recording stream. ``target``: see :func:`parse_rerun_target`.

    ``srp_radius_m``: radius of the sphere the SRP map is drawn on; ``trail_every``: log the
    trail every this many robot updates (it is re-sent whole, so not every update)."""

    enabled = True

    def __init__(self, target: str = "save:out/run.rrd", application_id: str = "ssl_rescue",
                 recording_name: str | None = None, srp_radius_m: float = 0.45, trail_every: int = 20,
                 timeout_s: float = VIEWER_TIMEOUT_S) -> None:
        """Raises :class:`ViewerUnavailable` when a ``spawn`` / ``connect`` viewer cannot be reached."""
        rr = _import_rerun()

        check_interrupt()  # after the slow import and the viewer probe; nothing to undo yet (see robot.interrupt)
        self.rr = rr
        self.mode, arg = parse_rerun_target(target)
        self.timeout_s = float(timeout_s)
        if (problem := viewer_problem(self.mode, arg, self.timeout_s)) is not None:
            raise ViewerUnavailable(problem)
        check_interrupt()
        self.rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        self.path: Path | None = None
        self._closed = False
        if self.mode != "save":
            # rerun's own exit handler flushes without a timeout: a viewer that stops answering would hang the
            # exit (also after Ctrl-C, before close() ran); ours is bounded.
            rr.unregister_shutdown()
            atexit.register(self.close)
        try:
            if self.mode == "save":
                self.path = Path(arg)
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.rec.save(self.path)
            elif self.mode == "spawn":
                self.rec.spawn()
            else:
                self.rec.connect_grpc(arg)
        except RuntimeError as exc:  # e.g. the viewer executable is missing
            raise ViewerUnavailable(str(exc).strip().splitlines()[0]) from exc
        if recording_name:
            self.rec.send_recording_name(recording_name)
        self.rec.send_blueprint(rescue_blueprint())
        self.srp_radius_m = float(srp_radius_m)
        self.trail_every = int(trail_every)
        self._n_robot = 0

    def _time(self, t: float) -> None:
        self.rec.set_time("sim_time", duration=float(t))

    def start(self, world, sources, robot_config, title: str = "") -> None:
        rr, rec = self.rr, self.rec
        L = np.asarray(world.room.size)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log("world/room", rr.Boxes3D(centers=[L / 2], half_sizes=[L / 2], colors=[(160, 160, 160)],
                                         fill_mode=rr.components.FillMode.MajorWireframe, labels=[world.name]),
                static=True)
        if world.obstacles:
            obs = world.obstacles
            colors = [(150, 120, 90) if b.climbable else (120, 120, 130) for b in obs]
            quats = [rr.Quaternion(xyzw=[0.0, 0.0, math.sin(b.yaw / 2), math.cos(b.yaw / 2)]) for b in obs]
            rec.log("world/rubble", rr.Boxes3D(centers=[b.center for b in obs],
                                               half_sizes=[np.asarray(b.size) / 2 for b in obs], quaternions=quats,
                                               colors=colors, fill_mode=rr.components.FillMode.Solid), static=True)
        victims = [s for s in sources if s.kind == "victim"]
        others = [s for s in sources if s.kind != "victim"]
        if victims:
            rec.log("world/victims", rr.Points3D([s.position for s in victims], radii=0.06, colors=[_VICTIM_RGB],
                                                 labels=[s.name for s in victims]), static=True)
        if others:
            rec.log("world/interferers", rr.Points3D([s.position for s in others], radii=0.08, colors=[_OTHER_RGB],
                                                     labels=[s.name for s in others]), static=True)
        r = robot_config.bumper_radius
        rec.log("world/robot/body", rr.Cylinders3D(lengths=[0.1], radii=[r], centers=[[0, 0, 0.08]],
                                                   colors=[(70, 110, 200)]), static=True)
        rec.log("world/robot/array", rr.Transform3D(translation=[0.0, 0.0, robot_config.array_height]), static=True)
        rec.log("world/robot/array/cube", rr.Boxes3D(half_sizes=[[robot_config.cube_edge / 2] * 3],
                                                     colors=[(200, 200, 220)],
                                                     fill_mode=rr.components.FillMode.MajorWireframe), static=True)
        if title:
            rec.log("log/behaviour", rr.TextLog(title, level=rr.TextLogLevel.INFO), static=True)

    def robot(self, t, position, quat_wxyz, mics_world, wheel_speeds) -> None:
        rr, rec = self.rr, self.rec
        self._time(t)
        w, x, y, z = (float(v) for v in quat_wxyz)
        rec.log("world/robot", rr.Transform3D(translation=np.asarray(position, float),
                                              quaternion=rr.Quaternion(xyzw=[x, y, z, w])))
        rec.log("world/mics", rr.Points3D(np.asarray(mics_world, float), radii=0.008, colors=[(20, 20, 20)]))
        for i, v in enumerate(np.asarray(wheel_speeds, float)):
            rec.log(f"plots/wheel_speed/{i}", rr.Scalars(float(v)))
        self._n_robot += 1

    def trail(self, t, xyz) -> None:
        self._time(t)
        pts = np.asarray(xyz, float)
        if len(pts) >= 2:
            self.rec.log("world/trail", self.rr.LineStrips3D([pts], colors=[(70, 110, 200)], radii=0.01))

    def listen(self, t, srp_map, grid_directions, detections, truth) -> None:
        rr, rec = self.rr, self.rec
        self._time(t)
        srp = np.asarray(srp_map, float)
        dirs = np.asarray(grid_directions, float)
        if srp.size and np.any(srp > 0):
            rec.log("world/robot/array/srp_map", rr.Points3D(self.srp_radius_m * dirs, colors=_colormap(srp),
                                                             radii=0.008))
        else:
            rec.log("world/robot/array/srp_map", rr.Clear(recursive=False))
        if detections:
            vec = [0.4 * max(0.25, min(1.0, float(d.get("power", 1.0)) * 2)) * np.asarray(d["direction"])
                   for d in detections]
            labels = [f"{d['azimuth_deg']:+.0f}/{d['elevation_deg']:+.0f} deg" for d in detections]
            rec.log("world/robot/array/detections", rr.Arrows3D(vectors=vec, colors=[(220, 30, 30)], radii=0.006,
                                                               labels=labels))
        else:
            rec.log("world/robot/array/detections", rr.Clear(recursive=False))
        if truth:
            cols = [_VICTIM_RGB if s.get("kind") == "victim" else _OTHER_RGB for s in truth]
            cols = [c if s.get("active", True) else (150, 150, 150) for c, s in zip(cols, truth)]
            rec.log("world/robot/array/truth", rr.Arrows3D(vectors=[0.5 * np.asarray(s["direction"]) for s in truth],
                                                           colors=cols, radii=0.004,
                                                           labels=[s.get("name", "") for s in truth]))

    def target(self, t, origin_world, direction_world) -> None:
        self._time(t)
        if direction_world is None:
            self.rec.log("world/target", self.rr.Clear(recursive=False))
        else:
            self.rec.log("world/target", self.rr.Arrows3D(origins=[np.asarray(origin_world, float)],
                                                         vectors=[0.8 * np.asarray(direction_world, float)],
                                                         colors=[(255, 0, 255)], radii=0.012, labels=["target"]))

    def found(self, t, estimated_world, truth_world, labels) -> None:
        self._time(t)
        est = np.asarray(estimated_world, float).reshape(-1, 3)
        tru = np.asarray(truth_world, float).reshape(-1, 3)
        self.rec.log("world/found", self.rr.Points3D(est, radii=0.1, colors=[_FOUND_RGB], labels=list(labels)))
        # the estimate's error as a line from the report to the truth
        self.rec.log("world/found_error", self.rr.LineStrips3D([[a, b] for a, b in zip(est, tru)],
                                                               colors=[(200, 0, 0)], radii=0.01))

    def sound_map(self, t, sources) -> None:
        self._time(t)
        if not sources:
            self.rec.log("world/sound_map", self.rr.Clear(recursive=False))
            return
        centers, halves, quats, colors, labels = [], [], [], [], []
        for s in sources:
            # 2-sigma ellipse of the horizontal covariance (a flat ellipsoid; z half-size from its variance)
            w, v = np.linalg.eigh(np.asarray(s.covariance, float)[:2, :2])
            w = np.sqrt(np.maximum(w, 1e-6))
            a = math.atan2(v[1, 1], v[0, 1])       # the long axis
            centers.append(np.asarray(s.position, float))
            halves.append([min(2 * w[1], 5.0), min(2 * w[0], 5.0), min(2 * math.sqrt(max(s.covariance[2][2], 1e-6)), 1.0)])
            quats.append(self.rr.Quaternion(xyzw=[0.0, 0.0, math.sin(a / 2), math.cos(a / 2)]))
            rgb = _CLASS_RGB.get(s.cls.value, (150, 150, 150))
            colors.append(tuple(int(c * 0.5) for c in rgb) if s.state.value in ("found", "rejected") else rgb)
            labels.append(f"#{s.id} {s.cls.value} P={s.victim_probability:.2f} {s.state.value}")
        self.rec.log("world/sound_map", self.rr.Ellipsoids3D(centers=centers, half_sizes=halves, quaternions=quats,
                                                             colors=colors, labels=labels,
                                                             fill_mode=self.rr.components.FillMode.MajorWireframe))

    def plan(self, t, start_world, waypoints_world) -> None:
        self._time(t)
        if waypoints_world is None or not len(waypoints_world):
            self.rec.log("world/plan", self.rr.Clear(recursive=False))
            return
        pts = np.vstack([np.asarray(start_world, float)[:2], np.asarray(waypoints_world, float).reshape(-1, 2)])
        pts = np.column_stack([pts, np.full(len(pts), 0.02)])
        self.rec.log("world/plan", self.rr.LineStrips3D([pts], colors=[(255, 0, 255)], radii=0.015))

    def obstacles(self, t, cells_world, cell_size) -> None:
        self._time(t)
        c = np.asarray(cells_world, float).reshape(-1, 2)
        if not len(c):
            return
        self.rec.log("world/learned_obstacles",
                     self.rr.Boxes3D(centers=np.column_stack([c, np.full(len(c), 0.1)]),
                                     half_sizes=[[cell_size / 2, cell_size / 2, 0.1]] * len(c),
                                     colors=[(230, 120, 40, 160)], fill_mode=self.rr.components.FillMode.Solid))

    def ranges(self, t, starts_world, ends_world, hit) -> None:
        self._time(t)
        a, b = np.asarray(starts_world, float).reshape(-1, 3), np.asarray(ends_world, float).reshape(-1, 3)
        colors = [(230, 40, 40) if h else (150, 150, 150) for h in np.asarray(hit, bool).reshape(-1)]
        self.rec.log("world/ranges", self.rr.LineStrips3D(np.stack([a, b], axis=1), colors=colors, radii=0.004))

    def coverage(self, t, cells_world, unheard) -> None:
        self._time(t)
        c = np.asarray(cells_world, float).reshape(-1, 2)
        if not len(c):
            return
        from matplotlib import colormaps

        # Heard floor dark, still unheard floor light: where the robot has listened, and how well.
        rgb = (colormaps["cividis"](np.clip(np.asarray(unheard, float), 0, 1))[:, :3] * 255).astype(np.uint8)
        self.rec.log("world/coverage", self.rr.Points3D(np.column_stack([c, np.full(len(c), 0.005)]), radii=0.05,
                                                        colors=rgb))

    def scalars(self, t, values: dict[str, float]) -> None:
        self._time(t)
        for k, v in values.items():
            if v is not None and math.isfinite(v):
                self.rec.log(f"plots/{k}", self.rr.Scalars(float(v)))

    def event(self, t, state, text, level="INFO") -> None:
        rr = self.rr
        self._time(t)
        lvl = getattr(rr.TextLogLevel, level, rr.TextLogLevel.INFO)
        self.rec.log("log/behaviour", rr.TextLog(text, level=lvl))
        self.rec.log("log/state", rr.TextLog(state, level=rr.TextLogLevel.DEBUG))

    def close(self) -> None:
        """Flush and disconnect. A file is waited for; a viewer gets ``timeout_s`` for the flush plus rerun's own
        5 s disconnect grace, then is abandoned with a warning (rerun 0.41 would block forever on a viewer that
        stopped answering, also at interpreter exit)."""
        if self._closed:
            return
        if self.mode == "save":
            self.rec.flush()
            self.rec.disconnect()
            self._closed = True
            return
        problems: list[str] = []

        def finish() -> None:
            try:
                self.rec.flush(timeout_sec=self.timeout_s)
            except RuntimeError as exc:  # rerun 0.41 raises on a flush timeout
                problems.append(str(exc))
            self.rec.disconnect()

        worker = threading.Thread(target=finish, name="rerun-close", daemon=True)
        worker.start()
        worker.join(self.timeout_s + _RERUN_DISCONNECT_GRACE_S + 1.0)
        self._closed = True
        if worker.is_alive():
            problems.append("it stopped answering")
        if problems:
            log.warning("rerun viewer did not take the end of the recording (%s); its view is incomplete",
                        "; ".join(problems))

def rescue_blueprint():
    """The viewer layout of a rescue recording: the 3D world and robot (left, large), the SRP map seen
    from the array with detections and truth (top right), the plots (middle right) and the behaviour log
    (bottom right), on the ``sim_time`` timeline."""
    _import_rerun()
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="World and robot"),
            rrb.Vertical(
                rrb.Spatial3DView(origin="world/robot/array", contents=["$origin/**", "- $origin/cube"],
                                  name="SRP map (array frame)"),
                rrb.TimeSeriesView(origin="plots", name="Plots"),
                rrb.TextLogView(origin="log", name="Behaviour log"),
                row_shares=[3, 2, 2],
            ),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline="sim_time"),
        collapse_panels=False,
    )


def make_logger(target: str | None, recording_name: str | None = None, fallback_save: str | Path | None = None,
                **kw: Any) -> RunLogger:
    """A RerunLogger for ``target`` (see :func:`parse_rerun_target`), or a NullLogger for None.

    When a ``spawn`` / ``connect`` viewer cannot be reached the run goes on headless with a warning:
    recorded to ``fallback_save`` (an .rrd path) if given, else not logged."""
    if not target:
        return NullLogger()
    try:
        return RerunLogger(target, recording_name=recording_name, **kw)
    except ViewerUnavailable as exc:
        instead = f"recording to {fallback_save} instead" if fallback_save else "running without a viewer"
        log.warning("rerun %s: %s; %s", target, exc, instead)
        if fallback_save is None:
            return NullLogger()
        return RerunLogger(f"save:{fallback_save}", recording_name=recording_name, **kw)
