"""The acoustic simulator: what the 8-microphone cube hears in a :class:`~ssl_sim.world.World`.

``AcousticSimulator(world, config).listen(mic_positions_world, duration_s, t0)`` returns the
ADC output (8, n) for the interval ``[t0, t0 + duration_s)`` of simulation time. Blocks are
keyed on time: rendering ``[0, 1)`` then ``[1, 2)`` gives exactly the samples of ``[0, 2)``
at a fixed pose, so consecutive listen steps of a continuing voice are continuous.

Pipeline per listen step:
1. room impulse responses per (source, microphone) - early part from the image-source model
   (pyroomacoustics engine on the room + obstacle faces), late part a diffuse tail with the
   room's Eyring decay (see :mod:`.rir`); paths an obstacle blocks bend over/around its edges
   (:mod:`.diffraction`); cached per pose (positions rounded to 0.1 mm);
2. each source's time-keyed signal, scaled to its level (Pa at 1 m), convolved (FFT) with its RIRs;
3. diffuse ambient noise (:mod:`.noise`);
4. the sensor chain (:mod:`.sensor`): self-noise, gain mismatch, device timing, 16-bit ADC.
"""
from __future__ import annotations

import warnings
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import fft as sfft

from ssl_sim.world import World

from .diffraction import BoxSet, diffracted_arrivals, room_images
from .materials import eyring_absorption_for_rt60, uniform_material
from .noise import AmbientNoise, DiffuseNoiseField
from .pose import ArrayMount, RobotPose
from .rir import FRAC_HALF_TAPS, DiffuseTail, array_distances, early_rir, tail_gain
from .scene import AcousticScene, ImageSet
from .sensor import Sensor, SensorConfig
from .sources import PAPER_LEVEL_DB_SPL, SoundSource, victim_source


#: Default RIR length cap (s).
DEFAULT_MAX_RIR_S = 4.0
#: How deep (m) a microphone may lie inside an obstacle its cube is pressed against (soft-contact penetration).
MIC_CONTACT_DEPTH_M = 0.02


@dataclass(frozen=True)
class AcousticConfig:
    """Simulation settings.

    ``ism_order``: image-source order of the early part (reduced automatically when the obstacle
    count makes the search cost exceed ``ism_budget``, see ``AcousticScene.max_order_for_budget``).
    ``late_reverb``: add the diffuse tail (Eyring decay of the room). ``rt60_s``: if set, every
    surface gets the uniform absorption giving this Eyring RT60 (0 = free field).
    ``max_rir_s``: RIR length cap (the diffuse tail is truncated there). ``visibility_grid_m``: image-source visibility is evaluated at
    the array centre snapped to this grid (the 15 cm array shares one visibility set; delays and
    amplitudes are exact per microphone). ``position_quantum_m``: microphone positions are
    rounded to this before simulating (cache key). ``victim_*``: defaults for ``world.victims``.
    ``diffraction``: add the paths bent over/around an obstacle that blocks the direct sound or a
    first-order wall reflection (ISO 9613-2 barrier attenuation, see :mod:`.diffraction`).
    ``obstacle_order``: if set (< ``ism_order``), reflections off obstacle faces are modelled up to this order
    only; the orders above it keep the paths between the room walls (checked for occlusion by the boxes) and
    leave the rest to the diffuse tail (``AcousticScene.image_sources``; the search's cost falls from
    ``n_surfaces ** ism_order`` to ``n_surfaces ** obstacle_order``). ``noise_loop_s``: if set, the ambient
    field and the sensor self-noise repeat with this period (rounded up to 8192-sample frames, at most 16 s):
    computed once, then cached - the env's fast fidelity.
    """

    fs: int = 16000
    c: float = 343.0
    ism_order: int = 3
    ism_budget: float = 3e7  # image-source search cost allowed (~ surfaces ** order); the order drops to fit
    late_reverb: bool = True
    rt60_s: float | None = None
    max_rir_s: float = DEFAULT_MAX_RIR_S
    visibility_grid_m: float = 0.05
    position_quantum_m: float = 1e-4
    min_obstacle_extent_m: float = 0.05  # boxes whose largest side is smaller are ignored (small at speech wavelengths)
    ambient: AmbientNoise | None = field(default_factory=AmbientNoise)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    seed: int = 0
    rir_cache_size: int = 32  # room impulse responses kept per simulator (poses revisited are not recomputed)
    diffraction: bool = True
    noise_loop_s: float | None = None
    obstacle_order: int | None = None
    victim_sound: str = "calls"
    victim_level_db_spl: float = PAPER_LEVEL_DB_SPL

    def __post_init__(self) -> None:
        if self.sensor.fs != self.fs:
            raise ValueError(f"AcousticConfig.sensor.fs ({self.sensor.fs}) must equal AcousticConfig.fs ({self.fs})")
        if not 0 <= self.ism_order <= 12:
            raise ValueError(f"AcousticConfig.ism_order: expected 0..12, got {self.ism_order}")
        if self.max_rir_s <= 0:
            raise ValueError(f"AcousticConfig.max_rir_s: expected > 0 s, got {self.max_rir_s}")
        if self.rt60_s is not None and (not np.isfinite(self.rt60_s) or self.rt60_s < 0):
            raise ValueError(f"AcousticConfig.rt60_s: expected None or a time >= 0 s, got {self.rt60_s}")
        if self.noise_loop_s is not None and not 0 < self.noise_loop_s <= 16.384:
            raise ValueError(f"AcousticConfig.noise_loop_s: expected None or 0 < s <= 16.384, got {self.noise_loop_s}")
        if self.obstacle_order is not None and not 0 <= self.obstacle_order <= self.ism_order:
            raise ValueError(f"AcousticConfig.obstacle_order: expected None or 0..ism_order ({self.ism_order}), "
                             f"got {self.obstacle_order}")
        if self.position_quantum_m <= 0 or self.visibility_grid_m <= 0:
            raise ValueError("AcousticConfig.position_quantum_m and visibility_grid_m must be > 0 m")


class _PoseRirs:
    """RIRs (n_sources, n_mics, L) at one pose, before the sources' burial filters, and their spectra per
    FFT size with the burial filters applied (zero-phase: one multiplication in the convolution's domain)."""

    def __init__(self, rirs: np.ndarray, sources: Sequence[SoundSource], fs: int,
                 responses: dict[int, list] | None = None) -> None:
        self.rirs, self.sources, self.fs = rirs, sources, fs
        self.spectra: dict[int, np.ndarray] = {}
        # the burial filters per FFT size, shared by every pose of these sources (they do not depend on the pose)
        self._responses = {} if responses is None else responses

    def spectrum(self, n_fft: int) -> np.ndarray:
        s = self.spectra.get(n_fft)
        if s is None:
            s = sfft.rfft(self.rirs, n_fft, axis=-1)
            responses = self._responses.get(n_fft)
            if responses is None:
                freqs = np.fft.rfftfreq(n_fft, 1.0 / self.fs)
                responses = [src.burial_response(freqs) for src in self.sources]
                if len(self._responses) >= 4:
                    self._responses.pop(next(iter(self._responses)))
                self._responses[n_fft] = responses
            for k, resp in enumerate(responses):
                if resp is not None:
                    s[k] *= resp
            self.spectra = {n_fft: s}  # one block size at a time is the normal case
        return s

    def buried_rirs(self) -> np.ndarray:
        """The RIRs with the burial filters applied (time domain)."""
        if not any(src.buried > 0 for src in self.sources):
            return self.rirs
        L = self.rirs.shape[-1]
        n_fft = sfft.next_fast_len(L)
        return sfft.irfft(self.spectrum(n_fft), n_fft, axis=-1)[..., :L]


class AcousticSimulator:
    """Renders what microphones hear in ``world``; ``sources`` default to the world's victim sites."""

    N_PRE = 256  # RIR samples before the emission instant (see rir.py)

    def __init__(self, world: World, config: AcousticConfig | None = None,
                 sources: Sequence[SoundSource] | None = None) -> None:
        self.world = world
        self.config = cfg = config or AcousticConfig()
        scene = AcousticScene(world, cfg.min_obstacle_extent_m)
        if cfg.rt60_s is not None:
            areas, _ = scene.surface_table()
            alpha = eyring_absorption_for_rt60(cfg.rt60_s, scene.volume, float(areas.sum()), cfg.c)
            scene = AcousticScene(world, cfg.min_obstacle_extent_m, material_override=uniform_material(alpha))
        self.scene = scene
        if cfg.obstacle_order is not None and cfg.obstacle_order < cfg.ism_order:
            # The general search runs to obstacle_order only (the budget applies to it); walls go to ism_order.
            self.ism_order = cfg.ism_order
            self.obstacle_order = scene.max_order_for_budget(cfg.obstacle_order, cfg.ism_budget)
        else:
            self.ism_order = scene.max_order_for_budget(cfg.ism_order, cfg.ism_budget)
            self.obstacle_order = None
        if self.ism_order < cfg.ism_order:
            warnings.warn(
                f"image-source order reduced from {cfg.ism_order} to {self.ism_order}: {len(scene.surfaces)} surfaces "
                f"({len(scene.obstacle_surfaces)} obstacle faces) exceed ism_budget={cfg.ism_budget:g}",
                stacklevel=2,
            )
        rt = scene.rt60(cfg.c) if cfg.late_reverb else np.zeros(7)
        self.rt60_bands = np.where(np.isfinite(rt), rt, 1e3)
        diag = float(np.linalg.norm(scene.size))
        need = (float(self.rt60_bands.max()) if self.rt60_bands.max() > 0 else 0.0) + 2 * diag / cfg.c
        if self.rt60_bands.max() > cfg.max_rir_s:
            warnings.warn(
                f"room RT60 up to {self.rt60_bands.max():.2f} s exceeds max_rir_s={cfg.max_rir_s} s: "
                "the reverberant tail is truncated", stacklevel=2)
        self.rir_length = self.N_PRE + int(np.ceil(min(need, cfg.max_rir_s) * cfg.fs))
        # The diffuse tail is drawn at the length the default cap would give and then cut to rir_length, so
        # a shorter max_rir_s (the env's fast fidelity) truncates the same realisation instead of drawing another.
        self._tail_draw_length = max(self.rir_length - self.N_PRE,
                                     int(np.ceil(min(need, DEFAULT_MAX_RIR_S) * cfg.fs)))
        self._boxes = BoxSet.from_boxes([b for _, b in scene.boxes])
        self._wall_reflection = np.array([m.reflection_amplitude for m in scene.room_materials])
        self._sensors: dict[int, Sensor] = {}
        self._images: OrderedDict[tuple, ImageSet] = OrderedDict()
        self._first_missing: dict[tuple, float] = {}
        self._tails: dict[tuple[int, bytes], DiffuseTail] = {}
        self._rirs: OrderedDict[bytes, _PoseRirs] = OrderedDict()
        self._responses: dict[int, list] = {}   # burial filters per FFT size (see _PoseRirs)
        #: Samples of the sources' sound rendered beyond a request at the same pose (0: none): an array held at
        #: one pose over successive short reads (``SimAudioSource.pose_hold_m``) convolves its response once
        #: for all of them (the FFT's length is the response's, ~0.8 s, whatever the read's).
        self.render_ahead = 0
        self._ahead: tuple[tuple, int, np.ndarray] | None = None   # (pose and channels, first sample, pressure)
        self._sources: list[SoundSource] = []
        if sources is None:
            sources = [victim_source(v, i, seed=cfg.seed, fs=cfg.fs, sound=cfg.victim_sound,
                                     level_db_spl=cfg.victim_level_db_spl) for i, v in enumerate(world.victims)]
        for s in sources:
            self.add_source(s)
        self._loop = None if cfg.noise_loop_s is None else int(np.ceil(cfg.noise_loop_s * cfg.fs / DiffuseNoiseField.FRAME))
        self.ambient = (DiffuseNoiseField(cfg.ambient, cfg.fs, cfg.seed, cfg.c, loop_frames=self._loop)
                        if cfg.ambient is not None else None)

    def scene_materials_rt60(self) -> np.ndarray:
        """Eyring RT60 (s) per octave band that the world's own surface materials give (whatever ``rt60_s`` says)."""
        return AcousticScene(self.world, self.config.min_obstacle_extent_m).rt60(self.config.c)

    # ------------------------------------------------------------------ sources
    @property
    def sources(self) -> tuple[SoundSource, ...]:
        return tuple(self._sources)

    def add_source(self, source: SoundSource) -> int:
        """Add a source (validated to be in the room's air); returns its index."""
        if not isinstance(source, SoundSource):
            raise ValueError(f"source: expected a SoundSource, got {type(source).__name__}")
        i = len(self._sources)
        self.scene.check_point(source.position, f"sources[{i}].position ({source.name or source.kind})")
        if source.signal.fs != self.config.fs:
            raise ValueError(f"sources[{i}].signal.fs: {source.signal.fs} Hz differs from the simulation rate {self.config.fs} Hz")
        self._sources.append(source)
        self._rirs.clear()
        self._responses = {}
        return i

    # ------------------------------------------------------------------ impulse responses
    def _quantise(self, p: np.ndarray, q: float) -> np.ndarray:
        return np.round(np.asarray(p, float) / q) * q

    def _image_set(self, k: int, centre: np.ndarray) -> tuple[ImageSet, float]:
        cfg = self.config
        src = np.asarray(self._sources[k].position)
        if self.scene.is_shoebox:
            recv = None  # every image is visible everywhere in a shoebox
        else:
            grid = self._quantise(centre, cfg.visibility_grid_m)
            recv = grid if self.scene.inside_air(grid, margin=0.005) else centre
        key = (k, None if recv is None else tuple(np.round(recv, 6)))
        imgs = self._images.get(key)
        if imgs is not None:
            self._images.move_to_end(key)
        else:
            ref = self.scene.size / 2 if recv is None else recv
            imgs = self.scene.image_sources(src, ref, self.ism_order, cfg.c, obstacle_order=self.obstacle_order)
            self._images[key] = imgs
            if len(self._images) > 512:
                self._images.popitem(last=False)
        # Where the tail starts (path length of the first reflection the model misses), at the visibility grid
        # point: within 5 cm (0.15 ms) of the exact start, and cached with the image set.
        fm_key = (k, tuple(np.round(self._quantise(centre, cfg.visibility_grid_m), 6)))
        first_missing = self._first_missing.get(fm_key) if cfg.late_reverb else np.inf
        if first_missing is None:
            first_missing = self.scene.first_missing_distance(src, self._quantise(centre, cfg.visibility_grid_m),
                                                              self.ism_order, cfg.c)
            self._first_missing[fm_key] = first_missing
            if len(self._first_missing) > 512:
                self._first_missing.pop(next(iter(self._first_missing)))
        return imgs, first_missing

    def _diffracted(self, k: int, imgs: ImageSet, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Virtual sources of the diffracted arrivals of source ``k`` at the array ``centre`` for the direct
        path and first-order wall reflections the image-source set lacks (blocked by an obstacle)."""
        src = np.asarray(self._sources[k].position)
        cand, _, _ = room_images(src, self.scene.size, self._wall_reflection)
        low = imgs.positions[imgs.order <= 1]
        present = (np.linalg.norm(cand[:, None] - low[None], axis=-1) < 1e-3).any(axis=1)
        return diffracted_arrivals(src, centre, self._boxes, self.scene.size, self._wall_reflection, present)

    def _tail(self, k: int, mics: np.ndarray) -> DiffuseTail:
        # Rigid array: one tail per source serves every pose (keyed on the inter-mic distances rounded to 1 um
        # from the unquantised ``mics``: every pose of a rigid array gives the same key, whatever came before).
        key = (k, array_distances(mics).tobytes())
        t = self._tails.get(key)
        if t is not None:
            return t
        cfg = self.config
        rng = np.random.default_rng([cfg.seed & 0xFFFFFFFF, 0x7A11, k])
        t = DiffuseTail(self.rt60_bands, self.scene.volume, cfg.fs, cfg.c, self._tail_draw_length, rng, mics)
        L = self.rir_length - self.N_PRE
        t.tail, t.expected_energy, t.length = t.tail[:, :L], t.expected_energy[:L], L
        self._tails[key] = t
        if len(self._tails) > 4 * max(1, len(self._sources)):
            self._tails.pop(next(iter(self._tails)))
        return t

    def impulse_responses(self, mic_positions_world) -> np.ndarray:
        """RIRs (n_sources, n_mics, rir_length) in Pa per (Pa at 1 m); index 0 is ``N_PRE`` samples before emission."""
        mics = self._check_mics(mic_positions_world)
        return self._pose_rirs(mics).buried_rirs()

    def _pose_rirs(self, mics: np.ndarray) -> _PoseRirs:
        cfg = self.config
        raw, mics = mics, self._quantise(mics, cfg.position_quantum_m)
        key = mics.tobytes()
        hit = self._rirs.get(key)
        if hit is not None:
            self._rirs.move_to_end(key)
            return hit
        centre = mics.mean(axis=0)
        L, n_pre = self.rir_length, self.N_PRE
        out = np.zeros((len(self._sources), mics.shape[0], L))
        for k, src in enumerate(self._sources):
            imgs, first_missing = self._image_set(k, centre)
            positions, reflection = imgs.positions, imgs.reflection
            l_early = n_pre   # the early part's end (samples): zeros after it
            if cfg.diffraction and len(self._boxes):
                dpos, dref = self._diffracted(k, imgs, centre)
                positions, reflection = np.vstack([positions, dpos]), np.vstack([reflection, dref])
            if positions.shape[0]:
                d_max = float(np.max(np.linalg.norm(positions - centre, axis=1))) + 0.2
                l_early = min(L, n_pre + int(np.ceil(d_max / cfg.c * cfg.fs)) + FRAC_HALF_TAPS + 2 * n_pre)
                out[k, :, :l_early] = early_rir(positions, reflection, mics, cfg.fs, cfg.c, n_pre, l_early)
            if cfg.late_reverb and self.rt60_bands.max() > 0:
                tail = self._tail(k, raw)
                start = int(round(first_missing / cfg.c * cfg.fs)) if np.isfinite(first_missing) else L
                # the early part's energy from its nonzero span (the zeros after it add nothing)
                g = tail_gain(out[k, :, n_pre:max(l_early, n_pre)], tail.expected_energy, start, cfg.fs)
                out[k, :, n_pre:] += g * tail.tail
        pr = _PoseRirs(out, tuple(self._sources), cfg.fs, self._responses)
        self._rirs[key] = pr
        if len(self._rirs) > cfg.rir_cache_size:
            self._rirs.popitem(last=False)
        return pr

    # ------------------------------------------------------------------ rendering
    def _check_mics(self, mic_positions_world) -> np.ndarray:
        mics = np.asarray(mic_positions_world, float)
        if mics.ndim != 2 or mics.shape[1] != 3 or mics.shape[0] < 1:
            raise ValueError(f"mic_positions_world: expected shape (n_mics, 3) in world metres, got {mics.shape}")
        # The robot's microphones sit on the faces of a cube that collides with the rubble: MuJoCo's soft contacts
        # let a face pressed against a slab sink a few millimetres into it, so a microphone up to
        # MIC_CONTACT_DEPTH_M inside an obstacle is a contact, not a misplaced microphone.
        ok = dict(margin=0.005, obstacle_margin=-MIC_CONTACT_DEPTH_M)
        if not self.scene.inside_air_all(mics, **ok):  # fast path; the loop names the bad one
            for i, p in enumerate(mics):
                self.scene.check_point(p, f"mic_positions_world[{i}]", **ok)
        return mics

    def pressure(self, mic_positions_world, n0: int, n: int, channels: Sequence[int] | None = None,
                 include_sources: bool = True, include_ambient: bool = True) -> np.ndarray:
        """Sound pressure (len(channels), n) in Pa at the microphones for absolute samples ``n0 .. n0+n-1``
        (no sensor effects). ``channels`` selects microphones (default all)."""
        return self._pressure(self._check_mics(mic_positions_world), n0, n, channels, include_sources, include_ambient)

    def _pressure(self, mics: np.ndarray, n0: int, n: int, channels: Sequence[int] | None = None,
                  include_sources: bool = True, include_ambient: bool = True) -> np.ndarray:
        """:meth:`pressure` at microphones ``mics`` already checked by ``_check_mics``."""
        ch = np.arange(mics.shape[0]) if channels is None else np.asarray(channels, int)
        n0, n = int(n0), int(n)
        out = np.zeros((ch.size, n))
        if include_sources and self._sources and self.render_ahead > 0:
            key = (mics.tobytes(), ch.tobytes())
            a = self._ahead
            if a is None or a[0] != key or not (a[1] <= n0 and n0 + n <= a[1] + a[2].shape[1]):
                a = self._ahead = (key, n0, self._sources_pressure(mics, ch, channels, n0,
                                                                   max(n, int(self.render_ahead))))
            out += a[2][:, n0 - a[1]: n0 - a[1] + n]
        elif include_sources and self._sources:
            out += self._sources_pressure(mics, ch, channels, n0, n)
        if include_ambient and self.ambient is not None:
            amb = self.ambient.render(mics, n0, n)
            out += amb if channels is None else amb[ch]
        return out

    def _sources_pressure(self, mics: np.ndarray, ch: np.ndarray, channels, n0: int, n: int,
                          separate: bool = False) -> np.ndarray:
        """The sources' sound (len(ch), n) Pa at ``mics`` through the pose's responses, samples ``n0 ..``; with
        ``separate`` each source's alone, (n_sources, len(ch), n)."""
        pr = self._pose_rirs(mics)
        L = self.rir_length
        n_fft = sfft.next_fast_len(n + L - 1, real=True)
        H = pr.spectrum(n_fft)  # (S, C, F)
        if channels is not None:   # a subset: copied (2.8 MB for three sources at 1 s: not for all channels)
            H = H[:, ch, :]
        terms = (H[k] * sfft.rfft(src.signal.render(n0 + self.N_PRE - L + 1, n + L - 1) * src.pressure_at_1m,
                                  n_fft)[None, :] for k, src in enumerate(self._sources))
        if separate:
            Y = np.stack(list(terms))
        else:
            Y = next(terms)
            for term in terms:
                Y += term
        return sfft.irfft(Y, n_fft, axis=-1)[..., L - 1: L - 1 + n]

    def line_of_sight(self, point) -> np.ndarray:
        """Whether the straight path from each source to ``point`` (3, world m) is clear of every obstacle box
        (n_sources,) bool. Ground truth for analysis: where it is blocked, the sound arrives diffracted over an
        edge or reflected, from another direction than the source's."""
        p = np.asarray(point, float).reshape(1, 3)
        if not self._sources:
            return np.zeros(0, bool)
        src = np.array([s.position for s in self._sources])
        return ~self._boxes.segments_hit(src, np.repeat(p, len(src), axis=0)).any(axis=1)

    def band_snr_db(self, mic_positions_world, n0: int, n: int, band_hz: tuple[float, float] = (300.0, 6000.0)
                    ) -> np.ndarray:
        """Each source's signal-to-rest ratio (n_sources,) in dB at microphones ``mic_positions_world`` (n_mics, 3)
        over samples ``n0 .. n0 + n - 1``: its own pressure's energy in ``band_hz`` (Hz; summed over the
        microphones, direct sound and reverberation) against that of every other source and the ambient field
        together (not the sensor's self-noise). Ground truth for analysis: how loud each source is at the array,
        whatever it is doing in the window. -inf for a source silent in it, +inf for one alone in a silent room."""
        mics = self._check_mics(mic_positions_world)
        n0, n = int(n0), int(n)
        if not self._sources:
            return np.zeros(0)
        each = self._sources_pressure(mics, np.arange(mics.shape[0]), None, n0, n, separate=True)
        f = np.fft.rfftfreq(n, 1.0 / self.config.fs)
        band = (f >= band_hz[0]) & (f <= band_hz[1])

        def energy(x: np.ndarray) -> np.ndarray:
            return (np.abs(sfft.rfft(x, axis=-1)[..., band]) ** 2).sum(axis=(-2, -1))

        e = energy(each)
        ambient = float(energy(self.ambient.render(mics, n0, n))) if self.ambient is not None else 0.0
        rest = e.sum() - e + ambient
        with np.errstate(divide="ignore"):
            return 10 * np.log10(e) - 10 * np.log10(rest)

    def _sensor(self, n_mics: int) -> Sensor:
        s = self._sensors.get(n_mics)
        if s is None:
            s = self._sensors[n_mics] = Sensor(self.config.sensor, n_mics, self.config.seed, loop_chunks=self._loop)
        return s

    def listen(self, mic_positions_world, duration_s: float, t0: float = 0.0,
               extra_pressure: np.ndarray | None = None) -> np.ndarray:
        """ADC output (n_mics, n) for simulation time ``[t0, t0 + duration_s)``, ``n = round(duration_s * fs)``:
        int16 (default) or float32 per ``config.sensor.output``. ``mic_positions_world`` (n_mics, 3) m.
        ``extra_pressure`` (n_mics, n) Pa: sound rendered elsewhere (the robot's ego-noise) added before the sensor."""
        cfg = self.config
        if not np.isfinite(duration_s) or duration_s <= 0:
            raise ValueError(f"duration_s: expected a duration > 0 s, got {duration_s}")
        if not np.isfinite(t0):
            raise ValueError(f"t0: expected a finite time in s, got {t0}")
        mics = self._check_mics(mic_positions_world)
        n0, n = int(round(t0 * cfg.fs)), int(round(duration_s * cfg.fs))
        sensor = self._sensor(mics.shape[0])
        timing = sensor.device_timing(n0, n)
        p = np.zeros((mics.shape[0], n))
        offsets = {float(t[0] - n0) for _, t in timing}
        if sensor.timing_exact() and len(offsets) == 1:
            p = self._pressure(mics, n0 + int(offsets.pop()), n)
        else:
            h = Sensor.HALF_TAPS
            for chans, times in timing:
                a = int(np.floor(times.min())) - h - 1
                b = int(np.ceil(times.max())) + h + 2
                pch = self._pressure(mics, a, b - a, channels=chans)
                p[list(chans)] = Sensor.interpolate(pch, a, times)
        if extra_pressure is not None:
            if np.shape(extra_pressure) != p.shape:
                raise ValueError(f"extra_pressure: expected shape {p.shape} (n_mics, n) Pa, got {np.shape(extra_pressure)}")
            p = p + extra_pressure
        return sensor.digitise(p, n0)

    def listen_pose(self, pose: RobotPose, duration_s: float, t0: float = 0.0, mount: ArrayMount | None = None) -> np.ndarray:
        """:meth:`listen` with microphones placed by the robot ``pose`` and array ``mount``."""
        mount = mount or ArrayMount()
        return self.listen(mount.mic_positions_world(pose), duration_s, t0)
