"""The .rrd a run writes, read back with rerun's own reader (rerun 0.41: ``rerun.chunk.RrdReader``),
holds the world, the robot over time, the detections, the true directions and the SRP maps."""
from __future__ import annotations

import numpy as np
import pytest

rr = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from ssl_sim.runner import RescueRun  # noqa: E402
from ssl_sim.scenario import load_scenario  # noqa: E402
from ssl_sim.viz import NullLogger, RerunLogger, parse_rerun_target  # noqa: E402

SEED = 0


def _component(chunks, entity: str, component: str) -> tuple[np.ndarray, list]:
    """(sim_time in s, values) of one component of one entity, in time order; static rows get time nan."""
    times, values = [], []
    for ch in chunks:
        if ch.entity_path != entity:
            continue
        rb = ch.to_record_batch()
        if component not in rb.schema.names:
            continue
        vals = rb.column(component).to_pylist()
        if "sim_time" in rb.schema.names:
            t = [v / 1e9 for v in rb.column("sim_time").cast("int64").to_pylist()]
        else:
            t = [np.nan] * len(vals)
        times += t
        values += vals
    order = np.argsort(times, kind="stable")
    return np.asarray(times)[order], [values[k] for k in order]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp("rrd") / "run.rrd"
    sc = load_scenario("light_rubble_three").with_overrides(time_limit_s=26.0)   # long enough for a first approach target
    run = RescueRun(sc, seed=SEED, logger=RerunLogger(f"save:{path}"))
    result = run.run()
    chunks = RrdReader(path).stream().to_chunks()
    return run, result, chunks


def test_recording_holds_the_static_world(recorded):
    run, _, chunks = recorded
    entities = {ch.entity_path for ch in chunks}
    for e in ("/world/room", "/world/rubble", "/world/victims", "/world/robot", "/world/robot/body", "/world/mics",
              "/world/trail", "/world/robot/array/srp_map", "/world/robot/array/detections",
              "/world/robot/array/truth", "/world/target", "/plots/angular_error_deg", "/plots/wheel_speed/0",
              "/log/behaviour"):
        assert e in entities, e
    _, victims = _component(chunks, "/world/victims", "Points3D:positions")
    np.testing.assert_allclose(victims[0], [v.position for v in run.world.victims], atol=1e-6)
    _, labels = _component(chunks, "/world/victims", "Points3D:labels")
    assert labels[0] == ["beside_slab", "behind_pillar", "far_corner"]
    _, centers = _component(chunks, "/world/rubble", "Boxes3D:centers")
    assert len(centers[0]) == len(run.world.obstacles)
    np.testing.assert_allclose(centers[0], [b.center for b in run.world.obstacles], atol=1e-5)


def test_robot_pose_over_time_matches_the_physics(recorded):
    run, result, chunks = recorded
    t, trans = _component(chunks, "/world/robot", "Transform3D:translation")
    traj = np.array(run.trajectory)
    assert len(t) == len(traj) and np.all(np.diff(t) >= 0)
    np.testing.assert_allclose(t, traj[:, 0], atol=1e-6)
    np.testing.assert_allclose(np.array([p[0] for p in trans]), traj[:, 1:4], atol=1e-5)
    assert t[-1] == pytest.approx(result["sim_time_s"], abs=0.01)
    # The robot moved: its logged positions span more than the path's last step.
    assert np.ptp(np.array([p[0] for p in trans])[:, :2], axis=0).max() > 0.2
    _, mics = _component(chunks, "/world/mics", "Points3D:positions")
    assert all(len(m) == 8 for m in mics)


def test_detections_truth_and_srp_maps_at_every_listen(recorded):
    run, result, chunks = recorded
    listen_times = [rec["time_s"] for rec in result["listens"]]
    assert len(listen_times) >= 2
    t_map, maps = _component(chunks, "/world/robot/array/srp_map", "Points3D:positions")
    n_coarse = run.localizer.coarse_grid.n_points
    with_sound = [rec for rec in result["listens"] if rec["active_frames"] > 0]
    assert len(maps) == len(with_sound) and all(len(m) == n_coarse for m in maps)
    # The map is drawn on a sphere around the array centre (array frame).
    r = np.linalg.norm(np.array(maps[0]), axis=1)
    np.testing.assert_allclose(r, r[0], rtol=1e-5)
    t_det, dets = _component(chunks, "/world/robot/array/detections", "Arrows3D:vectors")
    logged = [rec for rec in result["listens"] if rec["detections"]]
    np.testing.assert_allclose(t_det, [rec["time_s"] for rec in logged], atol=1e-3)
    for vecs, rec in zip(dets, logged):
        assert len(vecs) == len(rec["detections"])
        az = np.degrees(np.arctan2(vecs[0][1], vecs[0][0]))
        assert az == pytest.approx(rec["detections"][0]["azimuth_deg"], abs=0.1)
    t_truth, truth = _component(chunks, "/world/robot/array/truth", "Arrows3D:vectors")
    assert len(truth) == len(listen_times) and all(len(v) == 3 for v in truth)
    az_true = np.degrees(np.arctan2(truth[0][0][1], truth[0][0][0]))
    assert az_true == pytest.approx(result["listens"][0]["sources"][0]["azimuth_deg"], abs=0.1)
    t_err, errs = _component(chunks, "/plots/angular_error_deg", "Scalars:scalars")
    assert len(errs) == len(logged)
    np.testing.assert_allclose([e[0] for e in errs], [rec["detections"][0]["error_deg"] for rec in logged], atol=0.01)
    _, texts = _component(chunks, "/log/behaviour", "TextLog:text")
    assert any("target" in x[0] for x in texts)


def test_logger_targets_and_null_logger():
    assert parse_rerun_target("save:out/x.rrd") == ("save", "out/x.rrd")
    assert parse_rerun_target("spawn") == ("spawn", None)
    assert parse_rerun_target("connect:127.0.0.1:9876") == ("connect", "rerun+http://127.0.0.1:9876/proxy")
    with pytest.raises(ValueError, match="--rerun: expected"):
        parse_rerun_target("file.rrd")
    null = NullLogger()
    assert not null.enabled
    null.listen(0.0, np.zeros(3), np.eye(3), [], [])  # no-ops
    null.close()


def test_coverage_shows_the_floor_around_the_listens(recorded):
    """The listening coverage drawn is floor within the hearing radius of a pose the robot listened from
    (odometry = world frame here, within odometry drift), inside the room."""
    run, result, chunks = recorded
    _, cov = _component(chunks, "/world/coverage", "Points3D:positions")
    assert cov, "no coverage logged"
    pts = np.array(cov[-1])[:, :2]
    poses = np.array([rec["pose"][:2] for rec in result["listens"]])
    d = np.min(np.hypot(pts[:, None, 0] - poses[None, :, 0], pts[:, None, 1] - poses[None, :, 1]), axis=1)
    r = run.behaviour.coverage.config.hearing_radius_m
    assert np.all(d <= r + 0.2)                               # 0.1 m cells and a little drift
    assert len(pts) >= 0.5 * np.pi * r * r / 0.01             # at least half a disc of 0.1 m cells
    room = np.asarray(run.world.room.size[:2])
    assert np.all((pts >= -0.05) & (pts <= room + 0.05))


def test_range_rays_end_on_the_obstacles_they_saw(recorded):
    """The range readings are drawn as rays from the sensor ring; a red ray (a return) ends on a surface of the
    room or its rubble (MuJoCo truth, within odometry drift and the readings' 2 % noise), a grey one at 0.8 m."""
    run, result, chunks = recorded
    _, strips = _component(chunks, "/world/ranges", "LineStrips3D:strips")
    _, colors = _component(chunks, "/world/ranges", "LineStrips3D:colors")
    assert strips, "no range rays logged"
    rays = np.concatenate([np.array(s, float) for s in strips])          # (k, 2, 3): start, end
    red = np.concatenate([[(c >> 24) & 0xFF for c in cs] for cs in colors]) > 200
    assert rays.shape[1:] == (2, 3) and len(rays) % 9 == 0 and red.any() and not red.all()
    length = np.linalg.norm(rays[:, 1] - rays[:, 0], axis=1)
    assert np.allclose(length[~red], 0.8)
    w = run.world
    for end in rays[red, 1, :2]:
        gaps = [min(end[0], end[1], w.room.size[0] - end[0], w.room.size[1] - end[1])]
        for box in w.obstacles:
            if box.climbable:
                continue
            c, s = np.cos(box.yaw), np.sin(box.yaw)
            d = end - np.asarray(box.center[:2])
            local = np.abs([c * d[0] + s * d[1], -s * d[0] + c * d[1]]) - np.asarray(box.size[:2]) / 2
            gaps.append(float(np.hypot(*np.maximum(local, 0.0))))
        assert min(gaps) < 0.08, (end, min(gaps))
    print(f"{len(rays) // 9} readings drawn, {int(red.sum())} returns")
