"""World -> acoustic geometry: room walls plus the exposed faces of obstacle boxes, and the
image-source model of pyroomacoustics' C++ engine (``pyroomacoustics.libroom``) on it.

Frames: world frame of ``ssl_sim.world`` (metres, +z up, room ``[0, L]``).

Obstacles become extra walls so that rubble reflects, absorbs and occludes. Each box face
is clipped to the room (Sutherland-Hodgman against the six room planes); faces lying on a
room plane (a block resting on the floor) or entirely inside another modelled box are
dropped. Room walls have normals pointing out of the air volume, box faces normals
pointing into the box (pyroomacoustics' convention: reflect only from the air side), and
box faces are declared *obstructing* so that they block paths (occlusion).

The engine is driven directly (not through ``pyroomacoustics.Room``) because Room's
point-in-room test counts wall crossings, which is wrong for open boxes resting on the
floor; validation of points is done here instead (:meth:`AcousticScene.check_point`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from ssl_sim.world import Box, World

from .materials import N_BANDS, AcousticMaterial, eyring_rt60, get_material

_PLANE_TOL = 1e-3  # m: a face closer than this to a room plane lies on it


def _box_faces_local() -> list[np.ndarray]:
    """Unit-box faces (corners in [-1/2, 1/2]^3), counter-clockwise about the normal pointing INTO the box."""
    x0 = y0 = z0 = -0.5
    x1 = y1 = z1 = 0.5
    return [np.array(f, float) for f in (
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],  # bottom, normal +z
        [[x0, y0, z1], [x0, y1, z1], [x1, y1, z1], [x1, y0, z1]],  # top, normal -z
        [[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]],  # -x face, normal +x
        [[x1, y0, z0], [x1, y0, z1], [x1, y1, z1], [x1, y1, z0]],  # +x face, normal -x
        [[x0, y0, z0], [x0, y0, z1], [x1, y0, z1], [x1, y0, z0]],  # -y face, normal +y
        [[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],  # +y face, normal -y
    )]


_FACE_NAMES = ("bottom", "top", "-x", "+x", "-y", "+y")
# pyroomacoustics shoebox wall order: west (x=0), east (x=L), south (y=0), north (y=L), floor, ceiling.
_ROOM_WALLS = ("west", "east", "south", "north", "floor", "ceiling")


def _polygon_area_normal(corners: np.ndarray) -> tuple[float, np.ndarray]:
    """Area and unit normal (right-hand rule on the corner order) of a planar polygon (n, 3)."""
    c = corners - corners.mean(axis=0)
    s = np.cross(c, np.roll(c, -1, axis=0)).sum(axis=0) / 2.0
    a = float(np.linalg.norm(s))
    return a, (s / a if a > 0 else np.zeros(3))


def _clip_polygon(poly: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Keep the part of a convex polygon where ``normal . p <= offset`` (Sutherland-Hodgman)."""
    if len(poly) == 0:
        return poly
    d = poly @ normal - offset
    out = []
    n = len(poly)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        dp, dq = d[i], d[(i + 1) % n]
        if dp <= 0:
            out.append(p)
        if (dp < 0 < dq) or (dq < 0 < dp):
            out.append(p + (q - p) * (dp / (dp - dq)))
    return np.array(out).reshape(-1, 3)


def _room_halfspaces(size) -> list[tuple[np.ndarray, float]]:
    lx, ly, lz = size
    return [(np.array([-1.0, 0, 0]), 0.0), (np.array([1.0, 0, 0]), lx), (np.array([0, -1.0, 0]), 0.0),
            (np.array([0, 1.0, 0]), ly), (np.array([0, 0, -1.0]), 0.0), (np.array([0, 0, 1.0]), lz)]


def _box_halfspaces(box: Box) -> list[tuple[np.ndarray, float]]:
    r, c, h = box.rotation, np.asarray(box.center), np.asarray(box.size) / 2
    out = []
    for k in range(3):
        ax = r[:, k]
        out.append((ax, float(ax @ c + h[k])))
        out.append((-ax, float(-ax @ c + h[k])))
    return out


@dataclass(frozen=True)
class Surface:
    """A planar polygon ``corners`` (n, 3) in world metres, counter-clockwise about ``normal``,
    which points out of the air volume; ``obstructing`` surfaces (obstacle faces) can block paths."""

    corners: np.ndarray
    material: AcousticMaterial
    label: str
    obstructing: bool
    area: float = field(init=False)
    normal: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        a, n = _polygon_area_normal(self.corners)
        object.__setattr__(self, "area", a)
        object.__setattr__(self, "normal", n)


@dataclass(frozen=True)
class ImageSet:
    """Image sources of one real source, as seen from one receiver point (world frame).

    ``positions`` (n, 3) m; ``reflection`` (n, n_bands) product of pressure reflection factors
    along the path; ``order`` (n,) reflection order (0 = direct path, present only if visible)."""

    positions: np.ndarray
    reflection: np.ndarray
    order: np.ndarray

    @property
    def direct_visible(self) -> bool:
        return bool(np.any(self.order == 0))


class AcousticScene:
    """The acoustic view of a :class:`~ssl_sim.world.World`.

    ``min_obstacle_extent`` (m): boxes whose largest side is smaller are ignored (acoustically
    small at speech wavelengths); climbable debris is ignored unless ``include_climbable``.
    ``material_override``: one material for every surface (used to set a target RT60).
    """

    def __init__(self, world: World, min_obstacle_extent: float = 0.05, include_climbable: bool = False,
                 material_override: AcousticMaterial | None = None) -> None:
        self.world = world
        self.size = np.asarray(world.room.size, float)
        self.material_override = material_override
        room = world.room

        def mat(name: str, where: str) -> AcousticMaterial:
            if material_override is not None:
                return material_override
            try:
                return get_material(name)
            except ValueError as exc:
                raise ValueError(f"{where}: {exc}") from None

        wall_m = mat(room.wall_material, "world.room.wall_material")
        f_open = float(getattr(room, "wall_open_fraction", 0.0))
        if f_open > 0 and material_override is None:
            # Openings spread over the walls: the area-weighted absorption of wall and hole (alpha = 1).
            wall_m = AcousticMaterial(f"{wall_m.name} ({100 * f_open:.0f} % open)",
                                      tuple(f_open + (1 - f_open) * np.asarray(wall_m.absorption)),
                                      wall_m.scattering, wall_m.description)
        floor_m = mat(room.floor_material, "world.room.floor_material")
        ceil_m = mat(room.ceiling_material, "world.room.ceiling_material")
        self.room_materials = (wall_m, wall_m, wall_m, wall_m, floor_m, ceil_m)

        self.boxes: list[tuple[int, Box]] = [
            (i, b) for i, b in enumerate(world.obstacles)
            if (include_climbable or not b.climbable) and max(b.size) >= min_obstacle_extent
        ]
        halfspaces = _room_halfspaces(self.size)
        local = _box_faces_local()
        surfaces: list[Surface] = []
        hidden_area = np.zeros(6)  # room-wall area covered by boxes resting against it
        self.obstacle_volume = 0.0
        for bi, (i, box) in enumerate(self.boxes):
            m = mat(box.material, f"world.obstacles[{i}].material")
            corners_all = []
            for fname, f in zip(_FACE_NAMES, local):
                poly = (f * np.asarray(box.size)) @ box.rotation.T + np.asarray(box.center)
                for nrm, off in halfspaces:
                    poly = _clip_polygon(poly, nrm, off)
                if len(poly) < 3:
                    continue
                area, _ = _polygon_area_normal(poly)
                if area < 1e-6:
                    continue
                corners_all.append(poly)
                on_plane = [k for k, (nrm, off) in enumerate(halfspaces) if np.all(np.abs(poly @ nrm - off) < _PLANE_TOL)]
                if on_plane:
                    hidden_area[on_plane[0]] += area
                    continue
                inside_other = any(
                    np.all(other.contains(poly, margin=1e-6)) for bj, (_, other) in enumerate(self.boxes) if bj != bi
                )
                if inside_other:
                    continue
                surfaces.append(Surface(poly, m, f"obstacle[{i}].{fname}", True))
            self.obstacle_volume += self._clipped_volume(box, corners_all)

        room_local = [f[::-1].copy() for f in local]  # reversed order: normals point out of the room
        # Map unit-box faces (bottom, top, -x, +x, -y, +y) to pyroomacoustics' wall order.
        order = {"west": 2, "east": 3, "south": 4, "north": 5, "floor": 0, "ceiling": 1}
        room_surfaces = []
        for k, wname in enumerate(_ROOM_WALLS):
            poly = (room_local[order[wname]] + 0.5) * self.size
            room_surfaces.append(Surface(poly, self.room_materials[k], f"room.{wname}", False))
        self._room_hidden_area = hidden_area[[0, 1, 2, 3, 4, 5]]  # halfspace order == pyroomacoustics order
        self.surfaces: tuple[Surface, ...] = tuple(room_surfaces + surfaces)
        self.volume = float(np.prod(self.size) - self.obstacle_volume)
        self._wall_objs = None
        self._box_set = None  # the boxes for wall_images' occlusion tests (diffraction.BoxSet), built on first use

    # ------------------------------------------------------------------ geometry helpers
    def _clipped_volume(self, box: Box, box_face_polys: list[np.ndarray]) -> float:
        """Volume (m^3) of box intersected with the room: hull of clipped box faces and box-clipped room faces."""
        pts = list(box_face_polys)
        for f in _box_faces_local():
            poly = (f[::-1] + 0.5) * self.size
            for nrm, off in _box_halfspaces(box):
                poly = _clip_polygon(poly, nrm, off)
            if len(poly):
                pts.append(poly)
        if not pts:
            return 0.0
        allp = np.vstack(pts)
        try:
            return float(ConvexHull(allp).volume)
        except (QhullError, ValueError):
            return 0.0

    @property
    def is_shoebox(self) -> bool:
        """No obstacle surfaces: the fast shoebox image-source algorithm applies."""
        return len(self.surfaces) == 6

    @property
    def obstacle_surfaces(self) -> tuple[Surface, ...]:
        return self.surfaces[6:]

    def surface_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Exposed areas (n,) m^2 and absorption (n, n_bands) of all surfaces (room walls minus covered parts)."""
        areas = np.array([s.area for s in self.surfaces])
        areas[:6] = np.maximum(areas[:6] - self._room_hidden_area, 0.0)
        alpha = np.array([s.material.absorption for s in self.surfaces])
        return areas, alpha

    def rt60(self, c: float = 343.0) -> np.ndarray:
        """Eyring reverberation time (s) per octave band for the air volume and exposed surfaces."""
        areas, alpha = self.surface_table()
        return eyring_rt60(self.volume, areas, alpha, c)

    def mean_free_path(self) -> float:
        """Mean free path ``4 V / S`` (m)."""
        areas, _ = self.surface_table()
        return 4.0 * self.volume / float(areas.sum())

    def check_point(self, point, what: str, margin: float = 0.01, obstacle_margin: float | None = None) -> np.ndarray:
        """Validate that ``point`` (world, m) is in the room's air (not in a modelled obstacle); return it.

        ``what`` names the point in the error (e.g. ``"sources[1].position"``); ``margin``: clearance (m) from the
        walls and, unless ``obstacle_margin`` is given, from the obstacles (negative: that deep inside is let
        pass)."""
        ob_margin = margin if obstacle_margin is None else obstacle_margin
        p = np.asarray(point, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"{what}: expected 3 finite coordinates (world, m), got {point!r}")
        if not np.all((p >= margin) & (p <= self.size - margin)):
            raise ValueError(
                f"{what}: {np.round(p, 3).tolist()} is outside the room [0, {self.size.tolist()}] m "
                f"(needs {margin * 100:.0f} cm clearance from the walls)"
            )
        for i, b in self.boxes:
            if b.contains(p, margin=ob_margin):
                raise ValueError(
                    f"{what}: {np.round(p, 3).tolist()} is inside obstacle {i} ({b.kind}, centre {list(b.center)}, "
                    f"size {list(b.size)}); sources and microphones must be in air"
                )
        return p

    def inside_air_all(self, points, margin: float = 0.0, obstacle_margin: float | None = None) -> bool:
        """Whether all ``points`` (n, 3) (world, m) are finite, in the room and outside every modelled obstacle,
        with ``margin`` (m) clearance (vectorised :meth:`check_point` without the error message)."""
        p = np.asarray(points, float).reshape(-1, 3)
        if not np.all(np.isfinite(p)) or not np.all((p >= margin) & (p <= self.size - margin)):
            return False
        if not self.boxes:
            return True
        c = np.array([b.center for _, b in self.boxes])
        r = np.array([b.rotation for _, b in self.boxes])
        h = np.array([b.size for _, b in self.boxes]) / 2 + (margin if obstacle_margin is None else obstacle_margin)
        local = np.einsum("bji,nbj->nbi", r, p[:, None, :] - c[None])
        return not np.any(np.all(np.abs(local) <= h[None], axis=-1))

    def inside_air(self, point, margin: float = 0.0) -> bool:
        p = np.asarray(point, float)
        if not np.all((p >= margin) & (p <= self.size - margin)):
            return False
        return not any(b.contains(p, margin=margin) for _, b in self.boxes)

    # ------------------------------------------------------------------ image sources
    def max_order_for_budget(self, requested: int, budget: float = 3e7) -> int:
        """Largest order <= ``requested`` whose image-tree cost ``n_walls^k * n_obstructing`` fits ``budget``.

        The general-room engine visits every wall sequence up to the order and tests each
        path against every obstructing wall, so cost grows like ``n_walls^order``; the budget
        (~50 ms per source on one core) keeps a listen step at a new pose fast."""
        if self.is_shoebox:
            return requested
        n_w, n_o = len(self.surfaces), max(1, len(self.obstacle_surfaces))
        k = requested
        while k > 1 and float(n_w) ** k * n_o > budget:
            k -= 1
        return k

    def _walls(self):
        if self._wall_objs is None:
            from pyroomacoustics import libroom

            scat = np.zeros(N_BANDS, np.float32)
            self._wall_objs = [libroom.Wall(np.ascontiguousarray(s.corners.T, np.float32),
                                            np.asarray(s.material.absorption, np.float32), scat, s.label)
                               for s in self.surfaces]
        return self._wall_objs

    def image_sources(self, source, receiver, order: int, c: float = 343.0, force_general: bool = False,
                      obstacle_order: int | None = None) -> ImageSet:
        """Image sources of ``source`` up to reflection ``order`` visible from ``receiver`` (world, m).

        Shoebox rooms use the engine's closed-form shoebox enumeration (all images visible);
        rooms with obstacles the general depth-first search with visibility/occlusion tests.
        ``obstacle_order`` (< ``order``): the general search stops there, and the orders above it keep only
        paths between the room walls (:meth:`wall_images`): reflections off obstacle faces beyond that order
        are left to the diffuse tail. The search's cost grows like ``n_surfaces ** order``; this keeps it at
        ``n_surfaces ** obstacle_order`` plus a few dozen occlusion tests."""
        if obstacle_order is not None and obstacle_order < order and not self.is_shoebox and not force_general:
            low = self.image_sources(source, receiver, obstacle_order, c)
            high = self.wall_images(source, receiver, order, c, min_order=obstacle_order + 1)
            return ImageSet(np.vstack([low.positions, high.positions]), np.vstack([low.reflection, high.reflection]),
                            np.concatenate([low.order, high.order]))
        return self._engine_images(source, receiver, order, c, shoebox=self.is_shoebox and not force_general)

    def _engine_images(self, source, receiver, order: int, c: float, shoebox: bool) -> ImageSet:
        """The visible images from pyroomacoustics' engine: the shoebox enumeration of the room walls alone
        (``shoebox``: every image, no obstacles) or the general search over all surfaces."""
        from pyroomacoustics import libroom

        if shoebox:
            absorption = np.array([m.absorption for m in self.room_materials], np.float32).T  # (bands, 6)
            eng = libroom.Room(self.size.astype(np.float32), absorption, np.zeros_like(absorption), [], float(c),
                               int(order), 1e-7, 1.0, 0.5, 0.004, False)
        else:
            obstructing = [i for i, s in enumerate(self.surfaces) if s.obstructing]
            eng = libroom.Room(self._walls(), obstructing, [], float(c), int(order), 1e-7, 1.0, 0.5, 0.004, False)
        eng.add_mic(np.asarray(receiver, np.float32).reshape(3, 1))
        n = eng.image_source_model(np.asarray(source, np.float32))
        if n == 0:
            return ImageSet(np.zeros((0, 3)), np.zeros((0, N_BANDS)), np.zeros(0, int))
        pos = np.array(eng.sources, float).T
        att = np.array(eng.attenuations, float).T
        if att.shape[1] == 1:
            att = np.repeat(att, N_BANDS, axis=1)
        orders = np.array(eng.orders, int)
        visible = np.array(eng.visible_mics, bool)[0]
        return ImageSet(pos[visible], att[visible], orders[visible])

    def wall_images(self, source, receiver, order: int, c: float = 343.0, min_order: int = 0) -> ImageSet:
        """Images of ``source`` off the room walls only, of order ``min_order .. order``, whose paths to
        ``receiver`` (world, m) no obstacle box blocks: each image's straight line to the receiver, folded back
        into the room at the walls it crosses, is the real path; every leg is tested against the boxes."""
        from .diffraction import BoxSet

        imgs = self._engine_images(source, receiver, order, c, shoebox=True)
        keep = imgs.order >= min_order
        pos, att, orders = imgs.positions[keep], imgs.reflection[keep], imgs.order[keep]
        if self._box_set is None:
            self._box_set = BoxSet.from_boxes([b for _, b in self.boxes])
        if pos.shape[0] == 0 or len(self._box_set) == 0:
            return ImageSet(pos, att, orders)
        r = np.asarray(receiver, float)
        size = self.size
        # Crossings of the line r -> image with the planes k * L (per axis), as fractions t of the line.
        span = pos - r  # (n, 3)
        cell = np.floor(pos / size).astype(int)  # the image's room copy; its crossings are |cell| per axis
        ts = []
        for ax in range(3):
            k = np.arange(1, int(np.abs(cell[:, ax]).max(initial=0)) + 1)  # crossing number
            planes = np.where(cell[:, ax, None] > 0, k[None] * size[ax], (1 - k[None]) * size[ax])
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (planes - r[ax]) / span[:, ax, None]
            ts.append(np.where(k[None] <= np.abs(cell[:, ax, None]), t, np.nan))
        t = np.sort(np.concatenate([np.zeros((pos.shape[0], 1)), *ts, np.ones((pos.shape[0], 1))], axis=1), axis=1)
        pts = r + t[..., None] * span[:, None, :]  # (n, k, 3) unfolded breakpoints (NaN: padding, sorted last)
        u = np.mod(pts, 2 * size)
        folded = np.where(u > size, 2 * size - u, u)  # back into the room: the real path's nodes
        a, b = folded[:, :-1], folded[:, 1:]
        valid = ~np.isnan(b[..., 0])
        hit = self._box_set.segments_hit(a[valid], b[valid]).any(axis=1)
        blocked = np.zeros(valid.shape, bool)
        blocked[valid] = hit
        ok = ~blocked.any(axis=1)
        return ImageSet(pos[ok], att[ok], orders[ok])

    def first_missing_distance(self, source, receiver, order: int, c: float = 343.0) -> float:
        """Path length (m) of the earliest reflection of order ``order + 1`` off the room walls: up to
        there an image-source model of ``order`` is complete (obstacles only remove paths)."""
        from pyroomacoustics import libroom

        absorption = np.zeros((N_BANDS, 6), np.float32)
        eng = libroom.Room(self.size.astype(np.float32), absorption, absorption.copy(), [], float(c),
                           int(order) + 1, 1e-7, 1.0, 0.5, 0.004, False)
        eng.add_mic(np.asarray(receiver, np.float32).reshape(3, 1))
        eng.image_source_model(np.asarray(source, np.float32))
        pos = np.array(eng.sources, float).T
        orders = np.array(eng.orders, int)
        d = np.linalg.norm(pos[orders == order + 1] - np.asarray(receiver, float), axis=1)
        return float(d.min()) if d.size else float("inf")
