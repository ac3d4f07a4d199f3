"""The .rrd a run writes carries the viewer layout (``ssl_sim.viz.rescue_blueprint``): whoever opens it sees the
3D world, the SRP map, the plots and the behaviour log side by side (read back with rerun 0.41's RrdReader)."""
from __future__ import annotations

import pytest

pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from ssl_sim.viz import RerunLogger, rescue_blueprint  # noqa: E402


def test_recording_carries_the_blueprint(tmp_path):
    path = tmp_path / "run.rrd"
    logger = RerunLogger(f"save:{path}", recording_name="layout test")
    logger.event(0.0, "listen", "hello")
    logger.close()
    entries = RrdReader(path).blueprints()
    assert [(e.kind, e.application_id) for e in entries] == [("blueprint", "ssl_rescue")]


def test_blueprint_views_point_at_the_logged_entities():
    bp = rescue_blueprint()
    root = bp.root_container
    views = []

    def walk(c):
        for x in getattr(c, "contents", []):
            if hasattr(x, "contents") and not hasattr(x, "origin"):
                walk(x)
            else:
                views.append(x)

    walk(root)
    origins = {str(v.origin).strip("/") for v in views}
    # the entity roots RerunLogger writes: world/..., world/robot/array/srp_map, plots/..., log/...
    assert origins == {"world", "world/robot/array", "plots", "log"}
