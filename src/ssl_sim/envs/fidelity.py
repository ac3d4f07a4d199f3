"""Fast versus full acoustic fidelity: localization errors of the environment's observation on
the same robot poses.

For each scene (the environment's own episode builds, one per seed, so the same world, voices,
noise and sensor in both modes) robot poses are drawn on free floor at 0.5-3.5 m from the
victim, the array is placed there as on the MuJoCo robot (``ArrayMount`` at
``RobotModelConfig.array_height``), one listen window is rendered per pose by each mode's
``AcousticSimulator``, and the environment's localizer reports the strongest detection. Its
errors against the true direction of the victim (array frame) are compared pose by pose.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ssl_core.grid import angular_distance
from ssl_sim.acoustics import ArrayMount, RobotPose
from ssl_sim.envs.config import EnvConfig
from ssl_sim.envs.rescue_env import FS, SSLRescueEnv
from ssl_sim.physics.robot_model import RobotModelConfig


@dataclass(frozen=True)
class PoseErrors:
    """Per pose: azimuth error and 3-D angular error (deg) of the strongest detection, NaN if none."""

    seed: int
    pose: tuple[float, float, float]
    distance_m: float
    az_err_deg: dict[str, float]
    ang_err_deg: dict[str, float]


def _wrap_deg(a: float) -> float:
    return float((a + 180.0) % 360.0 - 180.0)


def compare_fidelities(config: EnvConfig, seeds, poses_per_scene: int = 8, dist_range=(0.5, 3.5),
                       listen_s: float | None = None) -> list[PoseErrors]:
    """Errors of the strongest detection in ``fast`` and ``full`` fidelity on the same poses.

    ``config``: the environment configuration (generator/scene settings; one victim expected,
    the first victim is the truth otherwise); ``seeds``: ``env.reset`` seeds (one scene each)."""
    envs = {f: SSLRescueEnv(config.with_overrides(fidelity=f)) for f in ("fast", "full")}
    mount = ArrayMount(height_m=RobotModelConfig().array_height)
    n = int(round((listen_s or config.listen_s) * FS))
    out = []
    try:
        for seed in seeds:
            for e in envs.values():
                e.reset(seed=int(seed))
            ep = envs["full"]._ep
            world = ep.world
            victim = np.asarray(world.victims[0].position, float)
            free, centres = ep.geodesic.free, ep.geodesic.centres
            cells = centres[free]
            d = np.hypot(*(cells - victim[:2]).T)
            ok = np.flatnonzero((d >= dist_range[0]) & (d <= dist_range[1]))
            rng = np.random.default_rng([int(seed), 0xF1DE])
            pick = rng.choice(ok, size=min(poses_per_scene, ok.size), replace=False)
            for j, i in enumerate(pick):
                pose = RobotPose(float(cells[i, 0]), float(cells[i, 1]), yaw=float(rng.uniform(-np.pi, np.pi)))
                mics = mount.mic_positions_world(pose)
                truth = (victim - mics.mean(axis=0)) @ pose.rotation  # world -> array frame
                truth /= np.linalg.norm(truth)
                az_true = np.degrees(np.arctan2(truth[1], truth[0]))
                t0 = 1.0 + 1.7 * j  # s: a different part of the voices per pose
                az_err, ang_err = {}, {}
                for f, e in envs.items():
                    x = e._ep.acoustics.listen(mics, n / FS, t0)
                    res = e.localizer.locate(x)
                    if res.detections:
                        det = res.detections[0]
                        az_err[f] = abs(_wrap_deg(det.azimuth_deg - az_true))
                        ang_err[f] = float(np.degrees(angular_distance(det.direction, truth)))
                    else:
                        az_err[f] = ang_err[f] = float("nan")
                out.append(PoseErrors(int(seed), (pose.x, pose.y, pose.yaw), float(d[i]), az_err, ang_err))
    finally:
        for e in envs.values():
            e.close()
    return out


def fidelity_summary(rows: list[PoseErrors]) -> dict:
    """Mean/median errors per mode over poses where both modes detected, per-pose differences,
    detection rates (errors in degrees)."""
    both = [r for r in rows if np.isfinite(r.az_err_deg["fast"]) and np.isfinite(r.az_err_deg["full"])]
    out: dict = {"poses": len(rows), "both_detected": len(both)}
    for f in ("fast", "full"):
        out[f"detection_rate_{f}"] = float(np.mean([np.isfinite(r.az_err_deg[f]) for r in rows])) if rows else 0.0
    for kind in ("az", "ang"):
        e = {f: np.array([getattr(r, f"{kind}_err_deg")[f] for r in both]) for f in ("fast", "full")}
        for f in ("fast", "full"):
            out[f"{kind}_mean_{f}"] = float(e[f].mean()) if both else float("nan")
            out[f"{kind}_median_{f}"] = float(np.median(e[f])) if both else float("nan")
        diff = np.abs(e["fast"] - e["full"])
        out[f"{kind}_mean_diff"] = abs(out[f"{kind}_mean_fast"] - out[f"{kind}_mean_full"])
        out[f"{kind}_median_diff"] = abs(out[f"{kind}_median_fast"] - out[f"{kind}_median_full"])
        out[f"{kind}_per_pose_absdiff_median"] = float(np.median(diff)) if both else float("nan")
        out[f"{kind}_per_pose_absdiff_p90"] = float(np.percentile(diff, 90)) if both else float("nan")
        out[f"{kind}_per_pose_within_1deg"] = float(np.mean(diff <= 1.0)) if both else float("nan")
    return out
