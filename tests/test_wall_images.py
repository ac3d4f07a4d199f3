"""AcousticScene.wall_images (the room-wall paths kept above AcousticConfig.obstacle_order) against
pyroomacoustics' full image-source search with obstacle faces: the same wall-only images, same band factors."""
from __future__ import annotations

import numpy as np

from ssl_sim.acoustics import AcousticScene
from ssl_sim.world import Box, Room, World

ROOM = Room((6.0, 5.0, 3.0))
BOXES = (Box((3.0, 2.5, 0.4), (0.6, 1.2, 0.8)), Box((1.5, 1.2, 0.9), (0.4, 0.4, 1.8)),
         Box((4.6, 3.8, 0.3), (1.0, 0.5, 0.6)))


def _as_dict(imgs) -> dict:
    """(position rounded to 0.1 mm, order) -> band factors (a path off an obstacle face can land on the position of
    a wall image of another order)."""
    return {(*np.round(p, 4), int(o)): a for p, a, o in zip(imgs.positions, imgs.reflection, imgs.order)}


def test_wall_images_are_pyroomacoustics_wall_only_images():
    scene = AcousticScene(World(room=ROOM, obstacles=BOXES))
    bare = AcousticScene(World(room=ROOM))  # every wall image, visible everywhere (no obstacles)
    src = np.array([1.0, 4.0, 0.3])
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(12):
        rcv = np.array([rng.uniform(0.3, 5.7), rng.uniform(0.3, 4.7), 0.27])
        if not scene.inside_air(rcv, margin=0.05):
            continue
        full = _as_dict(scene.image_sources(src, rcv, 3))  # pyroomacoustics, walls + obstacle faces
        wall_keys = set(_as_dict(bare.image_sources(src, rcv, 3)))
        expected = {k: v for k, v in full.items() if k in wall_keys}  # visible paths that touch walls only
        got = _as_dict(scene.wall_images(src, rcv, 3))
        assert set(got) == set(expected)
        for k, a in got.items():
            assert np.allclose(a, expected[k], atol=1e-6)
        hybrid = scene.image_sources(src, rcv, 3, obstacle_order=2)
        assert set(_as_dict(hybrid)) == {k for k in full if k[3] <= 2} | {k for k in got if k[3] == 3}
        checked += 1
    assert checked >= 8
