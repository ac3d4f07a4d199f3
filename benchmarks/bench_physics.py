"""Speed and fidelity of the MuJoCo robot: simulated seconds per wall-clock second.

Cases (random body twists, new one every second, seeded):
- robot alone on a flat floor, 30 s;
- dense_collapsed_room (named scene), 60 s; target >= 20x real time on one core.
Also measured: twist tracking error on flat ground and wheel-odometry drift over 10 s.

Prints a table and one JSON line. Run: ``.venv/bin/python benchmarks/bench_physics.py``.
"""
from __future__ import annotations

import argparse
import json
import platform
import time

import mujoco
import numpy as np

from _results import add_check_option, finish, require_stored
from robot.kinematics import forward_kinematics, integrate_pose
from ssl_sim.physics import SimRobot, load_scene


def speed(world, seconds: float, seed: int = 0) -> dict:
    robot = SimRobot(world)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    ncon = []
    for _ in range(int(seconds)):
        robot.set_twist(*rng.uniform([-0.35, -0.35, -1.2], [0.35, 0.35, 1.2]))
        for _ in range(10):
            robot.step(0.1)
            ncon.append(robot.data.ncon)
    wall = time.perf_counter() - t0
    timer = robot.data.timer
    per_step = {name: timer[int(t)].duration / max(timer[int(t)].number, 1) * 1e6
                for name, t in (("step", mujoco.mjtTimer.mjTIMER_STEP),
                                ("collision", mujoco.mjtTimer.mjTIMER_POS_COLLISION),
                                ("constraint", mujoco.mjtTimer.mjTIMER_CONSTRAINT))}
    return {"sim_s": seconds, "wall_s": wall, "speed_x": seconds / wall, "mean_contacts": float(np.mean(ncon)),
            "us_per_step": per_step, "nv": robot.model.nv, "ngeom": robot.model.ngeom}


def tracking() -> dict:
    """Worst relative error of the measured mean body twist vs the commanded one (flat floor)."""
    robot = SimRobot()
    worst = 0.0
    for tw in [(0.3, 0, 0), (0, 0.3, 0), (0, 0, 1.2), (0.25, -0.1, 0.6), (-0.15, 0.3, -1.0), (0.5, 0.3, 0.0)]:
        robot.reset()
        robot.set_twist(*tw)
        robot.step(0.5)
        meas = np.mean([robot.body_twist() for _ in range(150) if robot.step(0.01) is None], axis=0)
        v = np.hypot(*tw[:2])
        if v:
            worst = max(worst, np.linalg.norm(meas[:2] - tw[:2]) / v)
        if tw[2]:
            worst = max(worst, abs(meas[2] - tw[2]) / abs(tw[2]))
    return {"worst_rel_error": worst}


def odometry(ramp: bool) -> dict:
    robot = SimRobot()
    plan = [(0.3, 0.0, 0.0), (0.2, 0.15, 0.5), (0.0, -0.3, 0.0), (-0.2, 0.1, -0.8), (0.3, 0.0, 0.4)]
    p0 = robot.pose()
    est, cmd, dt, path = np.array([p0.x, p0.y, p0.yaw]), np.zeros(3), 0.01, 0.0
    prev = robot.wheel_odometry().wheel_angles
    last = np.array([p0.x, p0.y])
    for k in range(1000):
        target = np.array(plan[k // 200])
        cmd = cmd + np.clip(target - cmd, -np.array([1, 1, 3]) * dt, np.array([1, 1, 3]) * dt) if ramp else target
        robot.set_twist(*cmd)
        robot.step(dt)
        ang = robot.wheel_odometry().wheel_angles
        est = integrate_pose(est, forward_kinematics((ang - prev) / dt, robot.params), dt)
        prev = ang
        p = robot.pose()
        path += float(np.hypot(p.x - last[0], p.y - last[1]))
        last = np.array([p.x, p.y])
    p = robot.pose()
    return {"path_m": path, "pos_drift_m": float(np.hypot(est[0] - p.x, est[1] - p.y)),
            "yaw_drift_deg": float(np.degrees(abs(np.angle(np.exp(1j * (est[2] - p.yaw))))))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_check_option(ap)
    args = ap.parse_args()
    require_stored("physics", args.check)
    alone = speed(None, 30.0)
    dense = speed(load_scene("dense_collapsed_room"), 60.0)
    track = tracking()
    odo_ramp, odo_step = odometry(True), odometry(False)
    cpu = platform.processor() or platform.machine()
    print(f"mujoco {mujoco.__version__}, timestep {SimRobot().timestep * 1e3:.1f} ms, {cpu}")
    print(f"{'case':24s} {'speed':>8s} {'us/step':>8s} {'collide':>8s} {'solve':>8s} {'contacts':>9s}")
    for name, r in (("robot alone", alone), ("dense_collapsed_room", dense)):
        u = r["us_per_step"]
        print(f"{name:24s} {r['speed_x']:7.1f}x {u['step']:8.1f} {u['collision']:8.1f} {u['constraint']:8.1f} "
              f"{r['mean_contacts']:9.1f}")
    print(f"twist tracking, worst relative error: {track['worst_rel_error'] * 100:.2f} %")
    for name, o in (("ramped 1 m/s^2", odo_ramp), ("step commands", odo_step)):
        print(f"odometry drift over 10 s ({name}): {o['pos_drift_m'] * 1e3:.1f} mm over {o['path_m']:.2f} m, "
              f"yaw {o['yaw_drift_deg']:.2f} deg")
    figures = {"speed_x_robot_alone": round(alone["speed_x"], 1),
                      "speed_x_dense_rubble": round(dense["speed_x"], 1),
                      "twist_worst_rel_error": round(track["worst_rel_error"], 4),
                      "odo_drift_ramped_m": round(odo_ramp["pos_drift_m"], 4),
                      "odo_drift_step_m": round(odo_step["pos_drift_m"], 4),
                      "odo_yaw_drift_ramped_deg": round(odo_ramp["yaw_drift_deg"], 2),
                      "odo_yaw_drift_step_deg": round(odo_step["yaw_drift_deg"], 2)}
    return finish("physics", figures, check=args.check,
                  better={"speed_x_robot_alone": "higher", "speed_x_dense_rubble": "higher"})


if __name__ == "__main__":
    raise SystemExit(main())
