"""The occupancy grid and listening coverage as a window over a map that grows: what the window shows after it
moved must equal one large grid that saw the same marks (the straightforward full map); the planner's kept graph
and search must equal a fresh computation; a drive 30 m from the start runs with flat memory; configs that ask
for more memory than the budget are refused with the estimate."""
import math
import tracemalloc

import numpy as np
import pytest
from scipy import sparse
from scipy.sparse.csgraph import dijkstra

from robot.coverage import CoverageConfig, ListeningCoverage
from robot.occupancy import MapMemoryError, OccupancyConfig, OccupancyGrid
from robot.planner import Planner, grid_graph
from robot.rescue import Decision
from test_rescue import Source, World, always_speech, make

RES = 0.1


def _marks(rng, n=80, span=30.0):
    """A scripted drive along x with a wall beside it: footprints, rays, contacts and listens at known points."""
    out = []
    x = 0.0
    for k in range(n):
        x1 = x + span / n
        y = 0.8 * math.sin(k / 5.0)
        out.append(("path", (x, y), (x1, y)))
        starts = np.array([[x1, y]] * 5)
        ang = np.linspace(-0.6, 0.6, 5) + math.pi / 2
        ends = starts + 1.5 * np.stack([np.cos(ang), np.sin(ang)], 1)
        hit = rng.random(5) < 0.5
        out.append(("rays", starts, ends, hit))
        if k % 7 == 3:
            out.append(("contact", (x1, y, 0.0), math.pi / 2))
        out.append(("listen", (x1, y)))
        x = x1
    return out


def _apply(grid, cov, m):
    if m[0] == "path":
        grid.mark_path(m[1], m[2])
    elif m[0] == "rays":
        grid.mark_rays(m[1], m[2], m[3])
    elif m[0] == "contact":
        c = grid.mark_contact(m[1], m[2])
        cov.shadow(c, m[2], grid.config.contact_width_m)
    else:
        cov.listened(m[1])


def _world_values(grid, cov, xy):
    ij = np.floor((xy - grid.origin) / grid.resolution).astype(int)
    ok = ((ij >= 0) & (ij < grid.n)).all(1)
    i, j = ij[ok, 0], ij[ok, 1]
    return ok, grid.log_odds[i, j], grid.range_log_odds[i, j], grid.visited[i, j], cov.unheard[i, j]


def test_moved_window_equals_one_large_grid_that_saw_the_same_marks():
    area = (-2.0, -3.0, 40.0, 3.0)
    small = OccupancyGrid(OccupancyConfig(size_m=8.0, resolution_m=RES, edge_margin_m=2.0), origin=(0.0, 0.0))
    cov = ListeningCoverage(small.origin, small.n, RES, CoverageConfig(area=area))
    # the full map: one grid holding the whole drive, its cells those of the window's map (the same corner)
    big = OccupancyGrid(OccupancyConfig(size_m=88.0, resolution_m=RES, memory_budget_mb=1000.0), corner=small.anchor)
    big_cov = ListeningCoverage(big.origin, big.n, RES, CoverageConfig(area=area))
    moves = 0
    for m in _marks(np.random.default_rng(0)):
        if m[0] == "path":
            if small.follow(m[2]):
                cov.move_to(small.offset)
                moves += 1
        _apply(small, cov, m)
        _apply(big, big_cov, m)
    assert moves >= 5 and small.store.blocks
    # every point of the drive's neighbourhood, now in the window or back from the store
    xs, ys = np.meshgrid(np.arange(-1.0, 31.0, 0.05), np.arange(-2.9, 2.9, 0.05), indexing="ij")
    pts = np.stack([xs.ravel(), ys.ravel()], 1)
    for target in (None, (0.0, 0.0), (15.0, 0.0), (30.0, 0.0)):
        if target is not None:
            small.move_to(small.window_offset_for(target))
            cov.move_to(small.offset)
        ok, *got = _world_values(small, cov, pts)
        ok_big, *want = _world_values(big, big_cov, pts[ok])
        assert ok.sum() > 1000 and ok_big.all()
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a, b)


def test_kept_graph_and_search_equal_a_fresh_computation():
    """The planner keeps its graph and Dijkstra search while the free cells stay; each answer must equal a
    fresh build and search on the grid as it is (cells change between the calls, the window moves)."""
    grid = OccupancyGrid(OccupancyConfig(size_m=8.0, resolution_m=RES), origin=(0.0, 0.0))
    planner = Planner()
    rng = np.random.default_rng(1)
    rebuilt = 0
    for k, m in enumerate(_marks(rng, n=40, span=12.0)):
        if m[0] == "path" and grid.follow(m[2]):
            rebuilt += 1
        if m[0] != "listen":
            _apply(grid, ListeningCoverage(grid.origin, grid.n, RES), m)
        start = m[2] if m[0] == "path" else grid.centre(grid.cell(m[1][0])) if m[0] == "rays" else None
        if start is None:
            continue
        dist, pred, idx, s = planner.distances(grid, start)
        free = ~grid.blocked
        c = grid.cell(start)
        free[c] = True
        g, idx_ref = grid_graph(free, grid.resolution)
        d_ref, p_ref = dijkstra(g, directed=False, indices=int(idx_ref[c]), return_predecessors=True)
        np.testing.assert_array_equal(idx, idx_ref)
        np.testing.assert_array_equal(dist, d_ref)
        np.testing.assert_array_equal(pred, p_ref)
        goal = np.asarray(start) + (2.0, 1.0)
        plan = planner.plan(grid, start, goal)
        assert plan is None or np.isfinite(plan.length)
    assert rebuilt >= 1


def test_grid_graph_is_the_sparse_matrix_of_its_edges():
    """The directly built CSR graph equals, array for array, the matrix scipy makes of the edges listed one by
    one (every free cell to each free king or knight neighbour after it), so a search on it is the same."""
    rng = np.random.default_rng(3)
    for trial in range(6):
        free = rng.random((23, 31)) > rng.uniform(0.0, 0.6)
        idx = -np.ones(free.shape, int)
        idx[free] = np.arange(free.sum())
        rows, cols, w = [], [], []
        for i, j in zip(*np.nonzero(free)):
            for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2)):
                a, b = i + di, j + dj
                if 0 <= a < free.shape[0] and 0 <= b < free.shape[1] and free[a, b]:
                    rows.append(idx[i, j])
                    cols.append(idx[a, b])
                    w.append(RES * math.hypot(di, dj))
        n = int(free.sum())
        want = sparse.coo_matrix((w, (rows, cols)), shape=(n, n)).tocsr()
        got, got_idx = grid_graph(free, RES)
        np.testing.assert_array_equal(got_idx, idx)
        for name in ("indptr", "indices", "data"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
            assert getattr(got, name).dtype == getattr(want, name).dtype
        d1, p1 = dijkstra(got, directed=False, indices=0, return_predecessors=True)
        d2, p2 = dijkstra(want, directed=False, indices=0, return_predecessors=True)
        np.testing.assert_array_equal(d1, d2)
        np.testing.assert_array_equal(p1, p2)


def test_drive_30_m_from_the_start_with_flat_memory():
    """The behaviour's map calls of a 30 m drive along a corridor (window moves, plans, exploration goals): no
    error, and the memory held after each cycle grows only by the store's blocks."""
    cfg = OccupancyConfig()  # 20 m window: the old fixed grid ended the mission 10 m from the start
    grid = OccupancyGrid(cfg, origin=(0.0, 0.0))
    cov = ListeningCoverage(grid.origin, grid.n, grid.resolution, memory_budget_mb=grid.coverage_store_mb)
    planner = Planner()
    rng = np.random.default_rng(2)
    tracemalloc.start()
    held = []
    try:
        pose = np.array([0.0, 0.0, 0.0])
        for k in range(60):
            nxt = np.array([pose[0] + 0.5, 0.8 * math.sin(k / 6.0), 0.0])
            if grid.follow(nxt[:2]):
                cov.move_to(grid.offset)
            grid.mark_path(pose[:2], nxt[:2])
            starts = np.repeat(nxt[None, :2], 6, 0)
            ang = np.array([0.5, 1.0, 1.5, -0.5, -1.0, -1.5]) * math.pi / 2
            grid.mark_rays(starts, starts + 2.0 * np.stack([np.cos(ang), np.sin(ang)], 1), rng.random(6) < 0.7)
            cov.listened(nxt[:2])
            pose = nxt
            plan = planner.plan(grid, pose[:2], pose[:2] + (1.5, 0.0), stop_radius=0.3)
            goal, _ = planner.explore_goal(grid, pose, cov)
            assert plan is not None and goal is not None
            held.append(tracemalloc.get_traced_memory()[0] - grid.store.nbytes - cov.store.nbytes)
    finally:
        tracemalloc.stop()
    assert pose[0] >= 30.0 and grid.offset != (0, 0)
    # flat: once the window has moved (cycle 16, 8 m out), what the cycles hold beyond the stores does not grow
    # over the next 20 m and three more moves
    assert held[-1] - held[20] < 0.1e6, [round(h / 1e6, 3) for h in held[::5]]
    assert grid.memory_bytes < cfg.memory_budget_mb * 1e6


def test_behaviour_reaches_a_caller_beyond_its_first_window():
    """A 6 m window (+-3 m around the start) and callers 2.5 and 5 m away: the window follows the robot, both are
    found where they are; a fixed grid ended the mission once the robot left it."""
    callers = [Source((2.5, 0.3, 0.1), 66.0), Source((5.0, -0.3, 0.1), 66.0)]
    w = World(callers, seed=5)
    b = make(w, occupancy=OccupancyConfig(size_m=6.0), speech=always_speech)
    ev = b.run(max_time=120.0)
    assert Decision.ERROR not in [e.decision for e in ev]
    found = [e for e in ev if e.decision is Decision.VICTIM_FOUND]
    assert len(found) == 2
    for c in callers:
        assert min(math.dist(e.data.position, c.position[:2]) for e in found) < 0.5
    assert b.grid.offset != (0, 0) and b.coverage.offset == b.grid.offset


def test_behaviour_ends_the_mission_when_the_map_reaches_its_budget():
    """A budget that holds the 6 m window and less than one stored block: the mission ends as a fault naming the
    budget once the window must move, the drive stopped; no exception."""
    w = World([Source((2.5, 0.3, 0.1), 66.0), Source((5.0, -0.3, 0.1), 66.0)], seed=5)
    window_mb = (6.0 / RES) ** 2 * 600 / 1e6
    b = make(w, occupancy=OccupancyConfig(size_m=6.0, memory_budget_mb=window_mb + 0.05), speech=always_speech)
    ev = b.run(max_time=120.0)
    assert b.done and ev[-1].decision is Decision.FAULT
    assert "memory budget" in ev[-1].reason and "memory_budget_mb" in ev[-1].reason
    assert w.drive.commands[-1].twist == (0.0, 0.0, 0.0)


def test_store_beyond_the_budget_names_the_figures():
    cfg = OccupancyConfig(size_m=4.0, memory_budget_mb=4.0 * 4.0 / RES ** 2 * 600 / 1e6 + 0.07)
    grid = OccupancyGrid(cfg, origin=(0.0, 0.0))
    with pytest.raises(MapMemoryError, match="occupancy: .* over its memory budget .* raise memory_budget_mb"):
        for x in np.arange(0.0, 200.0, 0.5):
            grid.follow((x, 0.0))
            grid.mark_free((x, 0.0))


@pytest.mark.parametrize("kw, text", [({"resolution_m": 0.0001}, "TB"), ({"size_m": 1e6}, "TB"),
                                      ({"resolution_m": 0.01}, "GB")])
def test_configs_beyond_the_memory_budget_are_refused_with_the_estimate(kw, text):
    with pytest.raises(ValueError, match=rf"OccupancyConfig\.resolution_m=.*size_m=.*needs about [0-9.e+]+ {text}.*"
                                         r"memory_budget_mb=256"):
        OccupancyConfig(**kw)


def test_a_raised_budget_accepts_a_fine_window():
    assert OccupancyConfig(resolution_m=0.01, memory_budget_mb=3000.0).resolution_m == 0.01
