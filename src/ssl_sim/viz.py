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
    plots/angular_error_deg, plots/distance_to_victim_m, plots/wheel_speed/{0,1,2} (Scalars)
    log/behaviour            the behaviour's decisions (TextLog); log/state its state
"""
from __future__ import annotations

import math
import uuid
from pathlib import Path
from typing import Any, Sequence

import numpy as np

__all__ = ["RunLogger", "NullLogger", "RerunLogger", "make_logger", "parse_rerun_target"]


class RunLogger:
    """What the runner reports while a rescue runs; every method is a no-op here."""

    enabled = False

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
        """Obstacles learned by touch: centres (k, 2) of occupied grid cells of ``cell_size`` m."""

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
                 recording_name: str | None = None, srp_radius_m: float = 0.45, trail_every: int = 20) -> None:
        import rerun as rr

        self.rr = rr
        self.mode, arg = parse_rerun_target(target)
        self.rec = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        if self.mode == "save":
            path = Path(arg)
            path.parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(path)
            self.path: Path | None = path
        elif self.mode == "spawn":
            self.rec.spawn()
            self.path = None
        else:
            self.rec.connect_grpc(arg)
            self.path = None
        if recording_name:
            self.rec.send_recording_name(recording_name)
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
        self.rec.flush()
        if self.mode == "save":
            self.rec.disconnect()


def make_logger(target: str | None, recording_name: str | None = None, **kw: Any) -> RunLogger:
    """A RerunLogger for ``target`` (see :func:`parse_rerun_target`), or a NullLogger for None."""
    if not target:
        return NullLogger()
    return RerunLogger(target, recording_name=recording_name, **kw)
