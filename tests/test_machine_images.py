"""The planner's machine-image rule against the simulator's truth: beside the pump of dense_pump, the voiceless
sources the map builds from standing listens and the planner sets aside as the pump's images are none of the
callers, and the pump itself is mapped as an interferer."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robot.planner import Planner
from robot.sound_map import SourceClass
from ssl_sim.runner import RescueRun
from ssl_sim.scenario import load_scenario

# Standing points around the pump's pocket (world m): the start pocket and the floor north and west of it,
# 0.9-2.0 m from the pump, where the shipped behaviour chased its reflections (issue 13).
POINTS = ((5.7, 1.6), (6.2, 2.3), (5.6, 2.7), (6.3, 3.7), (5.2, 2.9))


@pytest.mark.slow
def test_images_set_aside_beside_the_pump_are_not_callers():
    run = RescueRun(load_scenario("dense_pump"), seed=0)
    beh = run.behaviour
    t = 0.0
    for x, y in POINTS:
        for _ in range(4):
            run.robot.place(x, y, 0.0)
            res = beh.listener.listen(1.0, 0.0, 0.0)
            t = run.clock.now()
            beh.map.update(res.evidence, (x, y, 0.0), t)   # the true pose: the odometry frame is the world's
    truth = {s.name: np.asarray(s.position[:2], float) for s in run.sources}
    pump, callers = truth["water_pump"], [truth["in_void"], truth["mid_room"]]
    sources = beh.map.sources
    planner = Planner()
    machines = [s for s in sources if s.cls is SourceClass.INTERFERER and s.n_inliers >= planner.config.min_listens]
    assert any(m.distance_to(pump) <= 0.5 for m in machines), "the pump is not mapped as an interferer"
    images = [s for s in sources if s.cls is SourceClass.UNKNOWN and planner.machine_image(s, machines)]
    for s in images:
        # not a caller: no caller within a success radius (0.75 m) of the estimate, none along its rays either
        assert min(s.distance_to(c) for c in callers) > 0.75, f"image #{s.id} at {s.position} is a caller"
        for r in s.history:
            o, d = np.asarray(r.origin[:2]), np.asarray(r.direction[:2])
            for c in callers:
                off = math.degrees(abs(math.atan2(d[0] * (c - o)[1] - d[1] * (c - o)[0], d @ (c - o))))
                assert off > 10.0, f"image #{s.id} was heard from {o} toward a caller ({off:.0f} deg off)"
