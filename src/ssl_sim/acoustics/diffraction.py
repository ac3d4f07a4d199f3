"""Edge diffraction around obstacles: the sound a box hides still bends over its top and around its
sides, arriving from the edge, delayed by the detour and attenuated by the barrier.

Model: ISO 9613-2:1996 section 7.4 barrier attenuation (Maekawa's chart as a formula) on the
path-length difference ``z = (path over the edges) - (straight path)`` per octave band,

    Dz = 10 lg(3 + (C2 / lambda) * C3 * z)   dB,   C2 = 20,
    C3 = 1 (one edge),  C3 = (1 + (5 lambda / e)^2) / (1/3 + (5 lambda / e)^2) (two edges e apart),

capped at 20 dB (one edge) / 25 dB (two edges) as the standard does (meteorological factor 1:
indoors). A diffracted arrival's amplitude is ``10^(-Dz/20) / d`` (d: the straight, unobstructed
path length; Dz is an insertion loss relative to it), its delay the path over the edges, its
direction at the microphones that of the last edge.

Which paths: the direct path and the first-order reflections off the room's six walls, when an
obstacle box blocks them (the image-source engine then drops them). For the blocking box, every edge
(12) and every pair of parallel edges of one face (12: over a thick box's top, around its end) is
tried; a path counts if none of its legs passes through any box (the diffracting one shrunk by 1 mm,
so legs may touch its edges) and its edges are not resting on the floor, a wall or the ceiling
(closed edges do not diffract). A two-edge path is used only where neither of its single-edge paths
is. A reflected path is bent around the box on the leg it blocks (before the wall: the receiver is
mirrored in the wall; after it: the image source is the source); blocked on both legs it is dropped.
Not modelled: diffraction of higher-order reflections and obstacle-face reflections, paths bending
around two different boxes, diffraction of unblocked paths (ISO's negative-z correction). Wavelengths
use c = 343 m/s.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .materials import OCTAVE_CENTERS_HZ

C2 = 20.0
CAP_SINGLE_DB = 20.0
CAP_DOUBLE_DB = 25.0
_SHRINK_M = 1e-3  # the diffracting box is shrunk by this for leg tests (legs touch its edges)
_CLOSED_TOL_M = 0.01  # an edge this close to a room surface rests on it (closed)


def barrier_attenuation_db(z_m, freqs_hz, e_m: float = 0.0) -> np.ndarray:
    """ISO 9613-2 barrier attenuation Dz (dB) for path difference ``z_m`` (m, >= 0) at ``freqs_hz``
    (Hz), single diffraction (``e_m = 0``) or double diffraction over two edges ``e_m`` apart.
    Broadcasts ``z_m`` against ``freqs_hz``."""
    lam = 343.0 / np.asarray(freqs_hz, float)
    z = np.maximum(np.asarray(z_m, float), 0.0)
    if e_m > 0:
        r = (5.0 * lam / e_m) ** 2
        c3, cap = (1.0 + r) / (1.0 / 3.0 + r), CAP_DOUBLE_DB
    else:
        c3, cap = 1.0, CAP_SINGLE_DB
    return np.minimum(10.0 * np.log10(3.0 + C2 / lam * c3 * z), cap)


@dataclass(frozen=True)
class BoxSet:
    """Oriented boxes: centres (n, 3) m, rotations (n, 3, 3) (columns: box axes in the world), half sizes (n, 3) m."""

    centers: np.ndarray
    rotations: np.ndarray
    halves: np.ndarray

    @classmethod
    def from_boxes(cls, boxes) -> "BoxSet":
        if not boxes:
            return cls(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)))
        return cls(np.array([b.center for b in boxes], float), np.array([b.rotation for b in boxes], float),
                   np.array([b.size for b in boxes], float) / 2)

    def __len__(self) -> int:
        return self.centers.shape[0]

    def segments_hit(self, p0: np.ndarray, p1: np.ndarray, shrink: np.ndarray | float = 0.0) -> np.ndarray:
        """Whether segments ``p0 -> p1`` ((n, 3) each, world m) pass through each box's interior (n, n_boxes).
        ``shrink`` (m, scalar or (n_boxes,)) shrinks boxes before the test. Slab test in box coordinates."""
        p0, p1 = np.atleast_2d(p0), np.atleast_2d(p1)
        if len(self) == 0:
            return np.zeros((p0.shape[0], 0), bool)
        h = self.halves - np.reshape(shrink, (-1, 1))  # (B, 3)
        a = np.einsum("bji,nbj->nbi", self.rotations, p0[:, None, :] - self.centers[None])  # local start (n, B, 3)
        d = np.einsum("bji,nbj->nbi", self.rotations, (p1 - p0)[:, None, :])
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-h - a) / d
            t2 = (h - a) / d
        lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
        par = d == 0  # parallel to a slab: inside it for all t or never
        inside = np.abs(a) < h
        lo = np.where(par, np.where(inside, -np.inf, np.inf), lo)
        hi = np.where(par, np.where(inside, np.inf, -np.inf), hi)
        t_in, t_out = lo.max(axis=-1), hi.min(axis=-1)
        return (t_out > t_in) & (t_out > 1e-9) & (t_in < 1 - 1e-9) & np.all(h > 0, axis=-1)[None]

    def edges(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The 12 edges of box ``k``: start points (12, 3) and end points (12, 3), world m."""
        r, c, h = self.rotations[k], self.centers[k], self.halves[k]
        starts, ends = [], []
        for ax in range(3):
            o1, o2 = [a for a in range(3) if a != ax]
            for s1 in (-1, 1):
                for s2 in (-1, 1):
                    p = np.zeros(3)
                    p[o1], p[o2] = s1 * h[o1], s2 * h[o2]
                    q = p.copy()
                    p[ax], q[ax] = -h[ax], h[ax]
                    starts.append(r @ p + c)
                    ends.append(r @ q + c)
        return np.array(starts), np.array(ends)


# Pairs of parallel edges on one face, as indices into BoxSet.edges' order (axis-major, then (s1, s2)
# in (-,-), (-,+), (+,-), (+,+)): two edges of one axis share a face when one sign agrees.
_FACE_PAIRS = [(4 * ax + i, 4 * ax + j) for ax in range(3) for i, j in ((0, 1), (2, 3), (0, 2), (1, 3))]


@dataclass(frozen=True)
class DiffractedPath:
    """One path bent over one or two edges: ``points`` the edge points in order from the source (k, 3) m,
    ``length`` the path length (m), ``straight`` the unobstructed length (m), ``e`` the edge spacing (0:
    one edge), ``attenuation_db`` Dz per octave band (:data:`OCTAVE_CENTERS_HZ`)."""

    points: np.ndarray
    length: float
    straight: float
    e: float
    attenuation_db: np.ndarray


def _points_on_edges(s, r, a: np.ndarray, b: np.ndarray, extra=0.0) -> np.ndarray:
    """The points on segments ``a[i]-b[i]`` ((k, 3) each) where the shortest paths ``s -> edge -> r`` bend
    (unfolded about each edge line; ``extra`` m added to r's distance from it: the rest of a two-edge
    path). ``s``, ``r``: (3,) or (k, 3) world m."""
    d = b - a
    ln = np.linalg.norm(d, axis=1)
    u = d / ln[:, None]
    ss, sr = np.sum((s - a) * u, axis=1), np.sum((r - a) * u, axis=1)
    rs = np.linalg.norm(s - a - ss[:, None] * u, axis=1)
    rr = np.linalg.norm(r - a - sr[:, None] * u, axis=1) + extra
    t = ss + (sr - ss) * rs / np.maximum(rs + rr, 1e-12)
    return a + np.clip(t, 0.0, ln)[:, None] * u


def _closed(a: np.ndarray, b: np.ndarray, room_size: np.ndarray) -> np.ndarray:
    """Whether each edge ``a[i]-b[i]`` lies on a room surface (k,)."""
    on = [(np.abs(a[:, ax] - v) < _CLOSED_TOL_M) & (np.abs(b[:, ax] - v) < _CLOSED_TOL_M)
          for ax in range(3) for v in (0.0, room_size[ax])]
    return np.any(on, axis=0)


def diffracted_paths(source: np.ndarray, receiver: np.ndarray, boxes: BoxSet, room_size,
                     freqs_hz=OCTAVE_CENTERS_HZ) -> list[DiffractedPath]:
    """Paths from ``source`` to ``receiver`` (world m) bent over the edges of the box that blocks their
    straight line (none if the line is clear or blocked by more than one box)."""
    s, r = np.asarray(source, float), np.asarray(receiver, float)
    size = np.asarray(room_size, float)
    hit = boxes.segments_hit(s[None], r[None])[0]
    if hit.sum() != 1:
        return []
    k = int(np.flatnonzero(hit)[0])
    straight = float(np.linalg.norm(r - s))
    shrink = np.zeros(len(boxes))
    shrink[k] = _SHRINK_M
    a_all, b_all = boxes.edges(k)
    open_edge = ~_closed(a_all, b_all, size)

    def clear(chains: list[np.ndarray]) -> np.ndarray:
        """Whether each path s -> chains[0][i] -> chains[1][i] ... -> r is clear; edge points in the room
        (s or r may be mirror images outside it)."""
        m = chains[0].shape[0]
        inside = np.all([np.all((c > -1e-6) & (c < size + 1e-6), axis=1) for c in chains], axis=0)
        nodes = [np.broadcast_to(s, (m, 3)), *chains, np.broadcast_to(r, (m, 3))]
        p0, p1 = np.concatenate(nodes[:-1]), np.concatenate(nodes[1:])
        blocked = boxes.segments_hit(p0, p1, shrink).any(axis=1).reshape(len(nodes) - 1, m).any(axis=0)
        return inside & ~blocked

    out: list[DiffractedPath] = []
    idx = np.flatnonzero(open_edge)
    single_ok = np.zeros(12, bool)
    if idx.size:
        e = _points_on_edges(s, r, a_all[idx], b_all[idx])
        ok = clear([e])
        single_ok[idx[ok]] = True
        for p in e[ok]:
            length = float(np.linalg.norm(p - s) + np.linalg.norm(r - p))
            out.append(DiffractedPath(p[None], length, straight, 0.0,
                                      barrier_attenuation_db(length - straight, freqs_hz)))
    for i, j in _FACE_PAIRS:
        if not (open_edge[i] and open_edge[j]) or single_ok[i] or single_ok[j]:
            continue
        sep = float(np.linalg.norm(a_all[j] - a_all[i]))
        first, second = np.array([i, j]), np.array([j, i])  # over the pair in either order
        e1 = _points_on_edges(s, r, a_all[first], b_all[first], extra=sep)
        e2 = _points_on_edges(e1, r, a_all[second], b_all[second])
        ok = clear([e1, e2])
        if ok.any():
            q = int(np.flatnonzero(ok)[0])
            length = float(np.linalg.norm(e1[q] - s) + np.linalg.norm(e2[q] - e1[q]) + np.linalg.norm(r - e2[q]))
            out.append(DiffractedPath(np.array([e1[q], e2[q]]), length, straight, sep,
                                      barrier_attenuation_db(length - straight, freqs_hz, sep)))
    return out


def room_images(source: np.ndarray, room_size, reflection: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The source and its six first-order images in the shoebox room (world m): positions (7, 3),
    band reflection factors (7, n_bands) (``reflection`` (6, n_bands) per wall in pyroomacoustics'
    order west, east, south, north, floor, ceiling), and the wall index (-1: direct)."""
    s = np.asarray(source, float)
    size = np.asarray(room_size, float)
    pos, refl, wall = [s], [np.ones(reflection.shape[1])], [-1]
    for w in range(6):
        ax, far = w // 2, w % 2
        p = s.copy()
        p[ax] = 2 * size[ax] - s[ax] if far else -s[ax]
        pos.append(p)
        refl.append(reflection[w])
        wall.append(w)
    return np.array(pos), np.array(refl), np.array(wall)


def diffracted_arrivals(source, receiver, boxes: BoxSet, room_size, wall_reflection: np.ndarray,
                        present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Diffracted arrivals at ``receiver`` for the direct path and the first-order wall reflections of
    ``source`` that the image-source model lost (``present`` (7,) bool per :func:`room_images` entry).

    Returned as virtual sources for :func:`~ssl_sim.acoustics.rir.early_rir`: positions (n, 3) on the
    ray from the receiver through the last edge, at the diffracted path's length (so delays and the
    wavefront direction are the diffracted path's), and band factors (n, n_bands) carrying the wall
    reflections, the barrier attenuation and ``length / straight`` (early_rir divides by the
    length; the ISO attenuation is relative to the straight path)."""
    r = np.asarray(receiver, float)
    size = np.asarray(room_size, float)
    imgs, refl, walls = room_images(source, size, wall_reflection)
    pos_out, fac_out = [], []
    for img, rf, w, here in zip(imgs, refl, walls, present):
        if here:
            continue
        if w < 0:
            src, rcv = img, r
        else:
            ax = w // 2
            plane = size[ax] if w % 2 else 0.0
            t = (plane - img[ax]) / (r[ax] - img[ax])
            p = img + t * (r - img)  # reflection point on the wall
            if not np.all((p >= -1e-6) & (p <= size + 1e-6)):
                continue
            s_real = np.asarray(source, float)
            first_blocked = boxes.segments_hit(s_real[None], p[None])[0].any()
            last_blocked = boxes.segments_hit(p[None], r[None])[0].any()
            if first_blocked and last_blocked:
                continue
            r_mirror = r.copy()
            r_mirror[ax] = 2 * plane - r[ax]
            # Blocked after the wall: the image is the source; before it: mirror the receiver.
            src, rcv = (img, r) if last_blocked else (s_real, r_mirror)
        for path in diffracted_paths(src, rcv, boxes, size):
            last = path.points[-1]
            if rcv is not r:
                # Receiver mirrored: the arrival comes from where the last leg meets the wall.
                ax = w // 2
                plane = size[ax] if w % 2 else 0.0
                t = (plane - last[ax]) / (rcv[ax] - last[ax])
                last = last + t * (rcv - last)
            u = last - r
            u /= np.linalg.norm(u)
            pos_out.append(r + path.length * u)
            fac_out.append(rf * 10 ** (-path.attenuation_db / 20) * path.length / path.straight)
    if not pos_out:
        return np.zeros((0, 3)), np.zeros((0, wall_reflection.shape[1]))
    return np.array(pos_out), np.array(fac_out)
