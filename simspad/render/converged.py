"""Converged radiance: a world-space irradiance cache, converged once per sequence, queried by every keyframe.

A keyframe of the path tracer carries Monte Carlo noise that, under camera motion, changes from one keyframe to
the next (the paths a pixel traces change with what it sees). This module splits the light a pixel sees into

* what is **sharp and per pixel**: primary visibility (``spp`` jittered camera rays per pixel, the same pattern
  at every keyframe), the emission found on the first hit, the texture (albedo) there, and the chain of glossy
  and specular bounces (lacquer, metal, the coat of rough plastic), followed ray by ray;
* what is **smooth and view-independent**: the irradiance E of the diffuse component at every vertex of that
  chain, looked up in a **world-space cache** as Q = E / π (a white Lambertian surface's outgoing radiance), so
  the diffuse part of a vertex's light is ``w_d · Q`` with ``w_d`` the diffuse component's sampled weight (its
  albedo: a texture lookup, no noise).

The cache (:class:`IrradianceCache`) is a hashed grid of cells (position quantized at ``cell_m``, the dominant
axis of the oriented shading normal, and the animated object whose rest frame the point is stored in). It is
built once per sequence from probe views spread over the trajectory (:func:`build_cache`): every chain vertex
those views find gets ``q_samples`` estimates of Q by next-event estimation plus a cosine-sampled path continued
by Mitsuba's own path integrator (multiple importance sampling between the two), and each cell keeps their
mean. A keyframe's lookup interpolates trilinearly between the cells around a point, at the finest of
:data:`LEVELS` that has them, else in the cells of the next-closest normal bins; a vertex no cell covers gets its
own Q estimate then (``fallback_samples``). The finest level is looked up inside a Dr.Jit kernel, on every lane of
the chain, from an open-addressing copy of its cells (:meth:`IrradianceCache.open_table`); only the vertices it
leaves without light are read back to numpy for the rest.

What stays is a per-surface bias (the cache's cell size smooths irradiance, e.g. contact shadows, over a few
pixels) and the cache's own noise, which is fixed to the surfaces and moves with them like texture instead of
changing between keyframes. Animated objects' points are cached in their rest frame, so their irradiance is the
mean over the probe instants (a rotating star under even light keeps it; a shadow moving over a static surface
is averaged).
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from simspad.render.flow import object_poses
from simspad.render.mitsuba_scene import psf_blur

#: Cell sizes tried by a lookup, in multiples of the finest cell, finest first. The coarsest (256 finest cells:
#: a room at the probe views' depth) catches the few glossy-chain vertices no probe view saw, which would each
#: cost an irradiance estimate of their own (a kernel launch per keyframe: more than the rest of a small one).
LEVELS = (1, 4, 16, 64, 256)
#: Normal bins: the dominant axis and its sign (6 bins).
N_NORMAL_BINS = 6
#: The normal of each bin (bin 2·axis + (1 if negative)).
_BIN_NORMALS = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0]])
#: Chain vertices followed per camera sample (the first hit plus glossy/specular bounces).
CHAIN_VERTICES = 3
#: Path length used where the scene's integrator has none (max_depth = -1: Russian roulette only).
UNLIMITED_DEPTH = 16
#: Camera samples of one keyframe tile (whole pixel rows): each chain vertex keeps its interaction for the lookup,
#: about 0.6 kB per lane over the three depths, so an untiled 512×512 keyframe at 64 rays held ~10 GiB.
TILE_LANES = 1 << 20
#: Lanes (points × estimates) of one irradiance-estimate kernel launch.
Q_BATCH_LANES = 1 << 21
_PRIMES = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9, 0xD6E8FEB86659FD93,
                    0xFF51AFD7ED558CCD, 0xC4CEB9FE1A85EC53], dtype=np.uint64)


def _mix_key(c0, c1, c2, nbin, obj, level, primes, shift):
    """The key of a cell: unsigned 64-bit arithmetic that wraps, on numpy arrays or Dr.Jit lanes alike (``primes``
    :data:`_PRIMES` and ``shift`` the shift amounts' type, each in the caller's arithmetic)."""
    h = c0 * primes[0]
    h ^= h >> shift(29)
    h += c1 * primes[1]
    h ^= h >> shift(31)
    h += c2 * primes[2]
    h ^= h >> shift(27)
    h += nbin * primes[3] + obj * primes[4] + level * primes[5]
    h ^= h >> shift(33)
    h *= primes[4]
    h ^= h >> shift(33)
    return h


def _hash(cells: np.ndarray, nbin: np.ndarray, obj: np.ndarray, level: int) -> np.ndarray:
    """64-bit keys of integer cells [N, 3], normal bins [N] and object ids [N] at ``level``."""
    with np.errstate(over="ignore"):
        c = cells.astype(np.int64).view(np.uint64)
        return _mix_key(c[:, 0], c[:, 1], c[:, 2], nbin.astype(np.uint64), obj.astype(np.uint64), np.uint64(level),
                        _PRIMES, np.uint64)


def normal_bin(n: np.ndarray) -> np.ndarray:
    """Dominant axis of each normal [N, 3] and its sign: 0..5."""
    axis = np.argmax(np.abs(n), axis=1)
    sign = np.take_along_axis(n, axis[:, None], axis=1)[:, 0] < 0
    return (2 * axis + sign).astype(np.int64)


class IrradianceCache:
    """Cells of Q = E / π (W m⁻² sr⁻¹ per unit albedo, RGB) keyed by position, normal bin and object.

    Attributes
    ----------
    cell_m : float
        Edge of the finest cell, m.
    keys : dict level -> sorted uint64 array
    values : dict level -> [K, 3] float64, the mean Q of each cell
    counts : dict level -> [K] int64, the samples behind each cell
    half_values : dict level -> ([K, 3], [K, 3]), the cells' means over the first and the second half of each
        point's estimates (:meth:`half`); empty for a cache built without them
    """

    def __init__(self, cell_m: float):
        self.cell_m = float(cell_m)
        self.keys, self.values, self.counts, self.half_values = {}, {}, {}, {}

    @classmethod
    def from_samples(cls, cell_m: float, p: np.ndarray, n: np.ndarray, obj: np.ndarray, q: np.ndarray,
                     weight: np.ndarray, halves: tuple | None = None) -> "IrradianceCache":
        """Cells from Q estimates ``q`` [N, 3] at rest-frame points ``p`` with oriented normals ``n`` and object
        ids ``obj``; ``weight`` [N] is the number of samples behind each estimate. ``halves`` (optional): the
        estimates from the first and the second half of each point's samples ([N, 3] each), kept as the cells of
        two half caches (:meth:`half`)."""
        cache = cls(cell_m)
        nb = normal_bin(n)
        for level in LEVELS:
            h = cell_m * level
            keys = _hash(np.floor(p / h).astype(np.int64), nb, obj, level)
            uniq, inv = np.unique(keys, return_inverse=True)
            w = np.bincount(inv, weights=weight, minlength=uniq.size)

            def cell_means(values):
                return np.stack([np.bincount(inv, weights=values[:, c] * weight, minlength=uniq.size)
                                 for c in range(3)], axis=1) / w[:, None]

            cache.keys[level] = uniq
            cache.values[level] = cell_means(q)
            cache.counts[level] = w.astype(np.int64)
            if halves is not None:
                cache.half_values[level] = (cell_means(halves[0]), cell_means(halves[1]))
        return cache

    def half(self, which: int) -> "IrradianceCache | None":
        """The cache of the first (``which`` = 0) or second (1) half of every point's estimates: two independent
        caches, each with twice this one's noise variance, so that half their difference has this cache's noise
        (the render-noise budget measures it so). None for a cache built without its halves."""
        if not self.half_values:
            return None
        out = IrradianceCache(self.cell_m)
        out.keys, out.counts = self.keys, self.counts
        out.values = {level: pair[which] for level, pair in self.half_values.items()}
        return out

    def open_table(self, level: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The cells of ``level`` as an open-addressing hash table for a lookup inside a Dr.Jit kernel (which has
        no binary search): (keys [C] uint64, 0 = empty; values [C, 3] float32), C a power of two ≥ 4× the cells,
        each key at or after its home slot ``key & (C - 1)`` with no empty slot between (linear probing). Built
        once per cache (the same table in every process: insertion is in key order)."""
        tables = self.__dict__.setdefault("_open_tables", {})
        if level not in tables:
            keys, values = self.keys[level], self.values[level]
            cap = 1 << max(4, int(math.ceil(math.log2(max(keys.size, 1) * 4))))
            mask = np.uint64(cap - 1)
            tab_k = np.zeros(cap, dtype=np.uint64)
            tab_v = np.zeros((cap, 3), dtype=np.float32)
            slot = (keys & mask).astype(np.int64)
            pending = np.nonzero(keys != 0)[0]  # a key hashing to 0 (p = 2⁻⁶⁴) stays out: its points miss
            while pending.size:
                free = tab_k[slot[pending]] == 0
                cand = pending[free]
                _, first = np.unique(slot[cand], return_index=True)  # one key per free slot, the lowest
                win = cand[first]
                tab_k[slot[win]], tab_v[slot[win]] = keys[win], values[win]
                pending = pending[~np.isin(pending, win)]
                slot[pending] = (slot[pending] + 1) & (cap - 1)
            tables[level] = (tab_k, tab_v)
        return tables[level]

    def lookup(self, p: np.ndarray, n: np.ndarray, obj: np.ndarray, min_count: int = 1) -> tuple[np.ndarray,
                                                                                                   np.ndarray]:
        """Q at points ``p`` [N, 3] (trilinear between the cells around each point, at the finest level where
        any of them holds ``min_count`` samples) and whether any level had a cell there ([N, 3], [N] bool)."""
        nb = normal_bin(n)
        out = np.zeros((p.shape[0], 3))
        found = np.zeros(p.shape[0], dtype=bool)
        todo = np.arange(p.shape[0])
        for level in LEVELS:
            if todo.size == 0:
                break
            keys, values, counts = self.keys[level], self.values[level], self.counts[level]
            if keys.size == 0:  # no probe view saw a surface: every point falls back to its own estimate
                continue
            h = self.cell_m * level
            c = p[todo] / h - 0.5
            base = np.floor(c).astype(np.int64)
            frac = c - base
            # The camera rays of a keyframe fall many to a cell: the 8 corner cells are searched once per distinct
            # (base cell, normal bin, object), and each point gathers their values.
            _, first, inv = np.unique(_hash(base, nb[todo], obj[todo], level), return_index=True,
                                      return_inverse=True)
            ubase, unb, uobj = base[first], nb[todo][first], obj[todo][first]
            acc = np.zeros((todo.size, 3))
            wsum = np.zeros(todo.size)
            for corner in range(8):
                off = np.array([(corner >> k) & 1 for k in range(3)], dtype=np.int64)
                key = _hash(ubase + off, unb, uobj, level)
                slot = np.clip(np.searchsorted(keys, key), 0, keys.size - 1)
                hit = (keys[slot] == key) & (counts[slot] >= min_count)
                w = np.prod(np.where(off == 1, frac, 1.0 - frac), axis=1) * hit[inv]
                acc += w[:, None] * values[slot[inv]]
                wsum += w
            ok = wsum > 1e-6
            out[todo[ok]] = acc[ok] / wsum[ok, None]
            found[todo[ok]] = True
            todo = todo[~ok]
        return out, found


class ConvergedRenderer:
    """Converged keyframes of a :class:`~simspad.render.mitsuba_scene.MitsubaScene` at its current pose.

    Parameters
    ----------
    ms : MitsubaScene
        The loaded scene (its camera and objects are posed by ``ms.set_pose``).
    spp : int
        Camera rays per pixel (antialiasing, texture and the glossy chain).
    fallback_samples : int
        Q estimates for a vertex no cache cell covers.
    """

    def __init__(self, ms, spp: int, fallback_samples: int = 64):
        import drjit as dr  # deferred: heavy; the variant is set by MitsubaScene's loader
        import mitsuba as mi  # deferred: as above

        self.dr, self.mi, self.ms = dr, mi, ms
        self.spp = int(spp)
        self.fallback_samples = int(fallback_samples)
        self.max_depth = scene_max_depth(ms.scene)
        # The light arriving at a first-hit vertex, continued by Mitsuba's own path tracer for the remaining depth.
        self.sub = mi.load_dict({"type": "path", "max_depth": max(self.max_depth - 1, 1)})
        self.shape_index = self._shape_index_table()

    def _shape_index_table(self):
        """Registry index -> object id (k for the k-th sorted animated object, 0 otherwise)."""
        ms, dr, mi = self.ms, self.dr, self.mi
        if not ms.object_names:
            return None
        shapes = {s.id(): s for s in ms.scene.shapes()}
        index = {sid: int(np.asarray(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))).ravel()[0])
                 for sid, s in shapes.items()}
        table = np.zeros(max(index.values()) + 1, dtype=np.int64)
        for k, name in enumerate(ms.object_names, start=1):
            table[index[name]] = k
        return table

    # ------------------------------------------------------------------------------------------ camera rays
    def camera_samples(self, seed: int, spp: int | None = None) -> np.ndarray:
        """Film positions [H·W·spp, 2] in [0, 1]²: stratified jitter, the same for every keyframe of a seed
        (``spp``: the renderer's camera rays unless given)."""
        w, h, k = self.ms.width, self.ms.height, self.spp if spp is None else spp
        rng = np.random.default_rng([seed, 0x5C0FFEE])
        s = int(math.isqrt(k))
        if s * s == k:
            grid = (np.stack(np.meshgrid(np.arange(s), np.arange(s), indexing="xy"), -1).reshape(-1, 2) + 0.5) / s
        else:
            grid = np.full((k, 2), 0.5)
        jitter = (rng.random((h, w, k, 2)) - 0.5) / (s if s * s == k else 1)
        sub = np.clip(grid[None, None] + jitter, 0.0, 1.0 - 1e-7)
        xs = (np.arange(w)[None, :, None] + sub[..., 0]) / w
        ys = (np.arange(h)[:, None, None] + sub[..., 1]) / h
        return np.stack([xs, ys], axis=-1).reshape(-1, 2)

    def _camera_rays(self, pos: np.ndarray, time: float = 0.0):
        mi = self.mi
        n = pos.shape[0]
        ray, _ = self.ms.sensor.sample_ray(mi.Float(np.full(n, time, np.float32)), mi.Float(np.full(n, 0.5, np.float32)),
                                           mi.Point2f(pos[:, 0].astype(np.float32), pos[:, 1].astype(np.float32)),
                                           mi.Point2f(0.5, 0.5))
        return ray

    def _sampler(self, seed: int, n: int):
        """An independent sampler of ``n`` lanes; the seed is an opaque variable so the kernels that use it are
        compiled once per process, not once per seed (a literal seed would be baked into each kernel)."""
        mi, dr = self.mi, self.dr
        if not hasattr(self, "_sampler_obj"):
            self._sampler_obj = mi.load_dict({"type": "independent", "sample_count": 1})
        sampler = self._sampler_obj.clone()
        sampler.seed(dr.opaque(mi.UInt32, seed), n)
        return sampler

    # ------------------------------------------------------------------------------------------ chain
    def trace_chain(self, ray, seed: int):
        """Follow each camera ray through its first hit and glossy/specular bounces.

        Returns the emission gathered along the chain (a Dr.Jit ``Color3f``, one lane per camera sample) and, per
        chain vertex, its lanes: a dict of evaluated Dr.Jit values ``si`` (the interaction), ``ray`` (the ray that
        hit it), ``wd`` (throughput × the diffuse component's sampled weight) and ``hit``.
        :meth:`vertex_arrays` turns one into numpy arrays of the lanes that need diffuse light.
        """
        mi, dr = self.mi, self.dr
        n = dr.width(ray.o)
        sampler = self._sampler(seed, n)
        throughput = mi.Color3f(1.0)
        emitted = mi.Color3f(0.0)
        active = mi.Bool(True)
        ctx_d = mi.BSDFContext()
        ctx_d.type_mask = mi.BSDFFlags.Diffuse
        ctx_g = mi.BSDFContext()
        ctx_g.type_mask = mi.BSDFFlags.Glossy | mi.BSDFFlags.Delta
        lanes = []
        for depth in range(min(CHAIN_VERTICES, self.max_depth)):
            si = self.ms.scene.ray_intersect(ray, active)
            em = si.emitter(self.ms.scene, active)
            emitted += dr.select(active, throughput * em.eval(si, active), 0.0)
            hit = active & si.is_valid()
            bsdf = si.bsdf(ray)
            u_d, u_d2 = sampler.next_1d(hit), sampler.next_2d(hit)
            u_g, u_g2 = sampler.next_1d(hit), sampler.next_2d(hit)
            _, w_d = bsdf.sample(ctx_d, si, u_d, u_d2, hit)
            bs_g, w_g = bsdf.sample(ctx_g, si, u_g, u_g2, hit)
            wd = dr.select(hit, throughput * w_d, 0.0)
            last = depth + 1 == min(CHAIN_VERTICES, self.max_depth)
            if not last:
                throughput *= w_g
                active = hit & (bs_g.pdf > 0) & (dr.max(throughput) > 0)
                next_ray = si.spawn_ray(si.to_world(bs_g.wo))
                # One kernel for this depth: Dr.Jit is lazy, and each later read would otherwise trace the whole
                # chain again; the next depth starts from these stored values.
                dr.eval(wd, si, ray, hit, emitted, throughput, active, next_ray)
            else:
                dr.eval(wd, si, ray, hit, emitted)
            lanes.append({"si": si, "ray": ray, "wd": wd, "hit": hit})
            if last:
                break
            ray = next_ray
        return emitted, lanes

    def vertex_arrays(self, lane: dict, mask=None) -> dict:
        """The lanes of a chain vertex that need diffuse light (hit, ``wd`` > 0, and ``mask`` where given) as
        numpy arrays: ``idx`` (the camera sample), ``weight`` (``wd``), ``p``, ``n`` (oriented shading normal),
        ``obj`` (animated object id), ``ro``, ``rd`` (the ray that hit it, for an estimate of its own)."""
        mi, dr = self.mi, self.dr
        si, ray, wd = lane["si"], lane["ray"], lane["wd"]
        keep = lane["hit"] & (dr.max(wd) > 0)
        if mask is not None:
            keep &= mask
        sel = dr.compress(keep)  # only the kept lanes are read back (a keyframe reads back few)
        n_or = self._oriented_normal(si)
        take = lambda v: np.stack([np.array(dr.gather(mi.Float, v[i], sel), dtype=np.float64)  # noqa: E731
                                      for i in range(3)], axis=1)
        out = {"idx": np.array(sel, dtype=np.int64), "weight": take(wd), "p": take(si.p), "n": take(n_or),
               "ro": take(ray.o), "rd": take(ray.d)}
        if self.shape_index is not None:
            out["obj"] = np.array(dr.gather(mi.UInt32, self._lane_objects(si), sel), dtype=np.int64)
        else:
            out["obj"] = np.zeros(out["idx"].size, dtype=np.int64)
        return out

    def _oriented_normal(self, si):
        """The shading normal turned to the side the ray came from (what the cache's normal bins are keyed by)."""
        n_sh = si.sh_frame.n
        return self.dr.select(self.mi.Frame3f.cos_theta(si.wi) < 0, -n_sh, n_sh)

    def _lane_objects(self, si):
        """Animated object id of each lane's hit (0: static or no hit), a Dr.Jit UInt32."""
        mi, dr = self.mi, self.dr
        if self.shape_index is None:
            return mi.UInt32(0)
        if not hasattr(self, "_shape_index_dr"):
            self._shape_index_dr = mi.UInt32(self.shape_index.astype(np.uint32))
        sidx = dr.reinterpret_array(mi.UInt32, si.shape)
        known = sidx < self.shape_index.size
        return dr.gather(mi.UInt32, self._shape_index_dr, dr.minimum(sidx, self.shape_index.size - 1), known)

    # ------------------------------------------------------------------------------------------ Q estimates
    def estimate_q(self, ro: np.ndarray, rd: np.ndarray, n_samples: int, seed: int, halves: bool = False):
        """Q = E / π at the points the rays (``ro``, ``rd`` [N, 3]) hit: the mean of ``n_samples`` estimates,
        each next-event estimation plus a cosine-sampled direction continued by the path tracer, combined by
        the power heuristic ([N, 3]). ``halves``: also the means of the first and of the second half of the
        estimates (two independent caches of half the samples, whose difference is the cache's own noise)."""
        mi, dr = self.mi, self.dr
        scene = self.ms.scene
        m = ro.shape[0]
        if m == 0:
            return (np.zeros((0, 3)),) * 3 if halves else np.zeros((0, 3))
        rep = lambda a: np.repeat(a, n_samples, axis=0).astype(np.float32)  # noqa: E731
        ray = mi.Ray3f(mi.Point3f(*rep(ro).T), mi.Vector3f(*rep(rd).T))
        sampler = self._sampler(seed, m * n_samples)
        si = scene.ray_intersect(ray)
        active = si.is_valid()
        n_or = self._oriented_normal(si)
        frame = mi.Frame3f(n_or)
        q = mi.Color3f(0.0)
        # Next-event estimation.
        ds, em_w = scene.sample_emitter_direction(si, sampler.next_2d(active), True, active)
        cos_l = dr.maximum(dr.dot(n_or, ds.d), 0.0)
        pdf_cos = cos_l * dr.inv_pi
        mis_l = dr.select(ds.delta, 1.0, _power(ds.pdf, pdf_cos))
        q += dr.select(active & (ds.pdf > 0), em_w * cos_l * dr.inv_pi * mis_l, 0.0)
        # A cosine-sampled direction, continued by the path tracer; its first hit's emission gets the power
        # heuristic's weight instead of the tracer's 1.
        wo = frame.to_world(mi.warp.square_to_cosine_hemisphere(sampler.next_2d(active)))
        ray2 = si.spawn_ray(wo)
        li, _, _ = self.sub.sample(scene, sampler, mi.RayDifferential3f(ray2), None, active)
        si2 = scene.ray_intersect(ray2, active)
        em2 = si2.emitter(scene, active)
        le2 = em2.eval(si2, active)
        ds2 = mi.DirectionSample3f(scene, si2, si)
        pdf_l2 = scene.pdf_emitter_direction(si, ds2, active)
        pdf_b = dr.maximum(dr.dot(n_or, wo), 0.0) * dr.inv_pi
        mis_b = _power(pdf_b, pdf_l2)
        q += dr.select(active, li - le2 * (1.0 - mis_b), 0.0)
        dr.eval(q)  # one kernel (each channel read back would otherwise trace the paths again)
        samples = _to_np3(q).reshape(m, n_samples, 3)
        out = np.maximum(samples.mean(axis=1), 0.0)
        if not halves:
            return out
        k = max(n_samples // 2, 1)
        return out, np.maximum(samples[:, :k].mean(axis=1), 0.0), np.maximum(samples[:, k:].mean(axis=1), 0.0)

    # ------------------------------------------------------------------------------------------ keyframes
    def render(self, cache: IrradianceCache | None, seed: int, object_poses: dict | None = None) -> np.ndarray:
        """The keyframe at the current pose: [H, W, 3] float32 radiance, blurred like a path-traced keyframe.

        The camera samples are traced in tiles of whole pixel rows, at most :data:`TILE_LANES` lanes each, so a
        keyframe's memory is bounded whatever its size (:meth:`_render_lanes` per tile); the first tile's random
        numbers are those of the whole keyframe, so a keyframe of one tile is the same at any size limit."""
        h, w = self.ms.height, self.ms.width
        pos = self.camera_samples(seed)
        rows = max(1, TILE_LANES // (w * self.spp))
        total = np.empty((pos.shape[0], 3))
        for k, row in enumerate(range(0, h, rows)):
            a, b = row * w * self.spp, min(row + rows, h) * w * self.spp
            total[a:b] = self._render_lanes(cache, pos[a:b], seed if k == 0 else _mix(seed, 4000 + k), object_poses)
        rgb = total.reshape(h, w, self.spp, 3).mean(axis=2).astype(np.float32)
        return np.maximum(psf_blur(rgb), 0.0, dtype=np.float32)

    def _render_lanes(self, cache: IrradianceCache | None, pos: np.ndarray, seed: int,
                      object_poses: dict | None) -> np.ndarray:
        """Radiance [N, 3] of the camera samples at film positions ``pos`` [N, 2].

        The finest level's lookup runs in Dr.Jit on every lane of the chain (:meth:`_lookup_lanes`); only the
        vertices it leaves without light are read back to numpy, for the coarser levels, the next-closest normal
        bins and, where nothing covers them, an estimate of their own."""
        dr = self.dr
        ray = self._camera_rays(pos)
        emitted, lanes = self.trace_chain(ray, seed)
        total = emitted
        found = []
        for lane in lanes:
            if cache is None:
                found.append(None)
                continue
            q, ok = self._lookup_lanes(cache, lane, object_poses)
            total += dr.select(ok, lane["wd"] * q, 0.0)
            found.append(ok)
        dr.eval(total, [ok for ok in found if ok is not None])
        vertices = [self.vertex_arrays(lane, None if ok is None else ~ok) for lane, ok in zip(lanes, found)]
        total = _to_np3(total)
        qs, misses = [], []
        for v in vertices:
            p_rest = self.rest_points(v, object_poses)
            n_rest = self.rest_normals(v, object_poses)
            q, ok = (cache.lookup(p_rest, n_rest, v["obj"]) if cache is not None
                     else (np.zeros((v["idx"].size, 3)), np.zeros(v["idx"].size, dtype=bool)))
            miss = np.nonzero(~ok)[0]
            if miss.size and cache is not None:
                # A vertex whose normal bin no probe saw near it (a blade's edge): the cells of the next-closest
                # normal bins, before paying for an estimate of its own (a kernel launch per keyframe).
                order = np.argsort(-(n_rest[miss] @ _BIN_NORMALS.T), axis=1)
                for rank in range(1, N_NORMAL_BINS):
                    q_alt, hit = cache.lookup(p_rest[miss], _BIN_NORMALS[order[:, rank]], v["obj"][miss])
                    q[miss[hit]] = q_alt[hit]
                    miss, order = miss[~hit], order[~hit]
                    if not miss.size:
                        break
            qs.append(q)
            misses.append(miss)
        if any(m.size for m in misses):  # one estimate for the vertices of every depth that no cell covers
            est = self.estimate_q(np.concatenate([v["ro"][m] for v, m in zip(vertices, misses)]),
                                  np.concatenate([v["rd"][m] for v, m in zip(vertices, misses)]),
                                  self.fallback_samples, _mix(seed, 1000))
            for q, m in zip(qs, misses):
                q[m], est = est[:m.size], est[m.size:]
        for v, q in zip(vertices, qs):
            np.add.at(total, v["idx"], v["weight"] * q)
        return total

    def _lookup_lanes(self, cache: IrradianceCache, lane: dict, object_poses: dict | None):
        """Q at every lane of a chain vertex from the cache's finest level, trilinear between the 8 cells around
        each rest-frame point as :meth:`IrradianceCache.lookup` does there, in one Dr.Jit kernel: (Q ``Color3f``,
        whether any of the 8 cells holds samples ``Bool``; False where the lane has no diffuse light to take)."""
        mi, dr = self.mi, self.dr
        si, wd = lane["si"], lane["wd"]
        tables = cache.__dict__.setdefault("_dr_tables", {})
        if 1 not in tables:
            tab_k, tab_v = cache.open_table(1)
            tables[1] = (mi.UInt64(tab_k), mi.Float(tab_v.ravel()), dr.opaque(mi.UInt32, tab_k.size - 1))
        tab_k, tab_v, mask = tables[1]
        active = lane["hit"] & (dr.max(wd) > 0)
        n = self._oriented_normal(si)
        p = si.p
        obj = self._lane_objects(si)
        for k, name in enumerate(self.ms.object_names, start=1):  # points of animated objects in their rest frame
            if not object_poses or name not in object_poses:
                continue
            m = np.asarray(object_poses[name], dtype=np.float64)
            # Opaque: a literal pose would be baked into the kernel and compile it again for every keyframe.
            r = [[dr.opaque(mi.Float, float(v)) for v in row] for row in m[:3, :3]]
            t = [dr.opaque(mi.Float, float(v)) for v in m[:3, 3]]
            sel = obj == k
            d = p - mi.Vector3f(*t)
            p = dr.select(sel, mi.Point3f(*(d.x * r[0][j] + d.y * r[1][j] + d.z * r[2][j] for j in range(3))), p)
            n = dr.select(sel, mi.Vector3f(*(n.x * r[0][j] + n.y * r[1][j] + n.z * r[2][j] for j in range(3))), n)
        a = dr.abs(n)
        on_x = (a.x >= a.y) & (a.x >= a.z)
        on_y = ~on_x & (a.y >= a.z)
        along = dr.select(on_x, n.x, dr.select(on_y, n.y, n.z))
        nbin = mi.UInt64(dr.select(on_x, 0, dr.select(on_y, 2, 4)) + dr.select(along < 0, 1, 0))
        c = p / dr.opaque(mi.Float, cache.cell_m) - 0.5  # opaque: one kernel for every cache (as the mask below)
        base = dr.floor(c)
        frac = c - base
        b = [mi.Int64(base.x), mi.Int64(base.y), mi.Int64(base.z)]
        f = [frac.x, frac.y, frac.z]
        acc = mi.Color3f(0.0)
        wsum = mi.Float(0.0)
        for corner in range(8):
            off = [(corner >> k) & 1 for k in range(3)]
            key = _hash_lanes(mi, [b[k] + off[k] for k in range(3)], nbin, mi.UInt64(obj), 1)
            slot, hit = _probe(mi, dr, tab_k, mask, key, active)
            w = mi.Float(1.0)
            for k in range(3):
                w *= f[k] if off[k] else 1.0 - f[k]
            acc += dr.select(hit, w * dr.gather(mi.Color3f, tab_v, slot, hit), 0.0)
            wsum += dr.select(hit, w, 0.0)
        ok = active & (wsum > 1e-6)
        return dr.select(ok, acc / dr.maximum(wsum, 1e-6), 0.0), ok

    def rest_points(self, v: dict, object_poses: dict | None) -> np.ndarray:
        return self._to_rest(v["p"], v["obj"], object_poses, point=True)

    def rest_normals(self, v: dict, object_poses: dict | None) -> np.ndarray:
        return self._to_rest(v["n"], v["obj"], object_poses, point=False)

    def _to_rest(self, x, obj, object_poses, point: bool):
        if not object_poses or not np.any(obj):
            return x
        x = x.copy()
        for k, name in enumerate(self.ms.object_names, start=1):
            sel = obj == k
            if not np.any(sel) or name not in object_poses:
                continue
            m = np.asarray(object_poses[name], dtype=np.float64)
            r, t = m[:3, :3], m[:3, 3]
            x[sel] = ((x[sel] - t) if point else x[sel]) @ r  # r⁻¹ = rᵀ for a rigid motion
        return x

    def probe_samples(self, seed: int, block: int = 1) -> np.ndarray:
        """Film positions [N, 2] of a probe view: one ray per ``block`` × ``block`` pixels, jittered within it (block
        1: :meth:`camera_samples` at one ray per pixel, the positions of renders before blocks existed)."""
        if block == 1:
            return self.camera_samples(seed, spp=1)
        w, h = self.ms.width, self.ms.height
        bw, bh = probe_grid(w, h, block)
        u = np.random.default_rng([seed, 0xB10C]).random((bh, bw, 2))
        xs = np.minimum((np.arange(bw)[None, :] + u[..., 0]) * block, w * (1 - 1e-7)) / w
        ys = np.minimum((np.arange(bh)[:, None] + u[..., 1]) * block, h * (1 - 1e-7)) / h
        return np.stack([xs, ys], axis=-1).reshape(-1, 2)

    def cache_samples(self, seed: int, q_samples: int, object_poses: dict | None = None, block: int = 1):
        """Q estimates at the chain vertices of the current view (one probe ray per ``block`` × ``block``
        pixels: :meth:`probe_samples`): (rest-frame points, normals, object ids, Q, sample counts, Q of the
        first and of the second half of the samples)."""
        ray = self._camera_rays(self.probe_samples(seed, block))
        _, lanes = self.trace_chain(ray, seed)
        vertices = [v for v in map(self.vertex_arrays, lanes) if v["idx"].size]
        if not vertices:
            z = np.zeros((0, 3))
            return z, z, np.zeros(0, dtype=np.int64), z, np.zeros(0), z, z
        # One estimate over every vertex of the view (in batches of a fixed size: one kernel, bounded memory).
        ro = np.concatenate([v["ro"] for v in vertices])
        rd = np.concatenate([v["rd"] for v in vertices])
        per_batch = max(1, Q_BATCH_LANES // q_samples)
        parts = [self.estimate_q(ro[a:a + per_batch], rd[a:a + per_batch], q_samples, _mix(seed, 2000 + a),
                                 halves=True) for a in range(0, ro.shape[0], per_batch)]
        q, q_a, q_b = (np.concatenate([part[i] for part in parts]) for i in range(3))
        return (np.concatenate([self.rest_points(v, object_poses) for v in vertices]),
                np.concatenate([self.rest_normals(v, object_poses) for v in vertices]),
                np.concatenate([v["obj"] for v in vertices]), q, np.full(q.shape[0], float(q_samples)), q_a, q_b)


def scene_max_depth(scene) -> int:
    """The longest path (in segments) of the scene's path integrator, which Mitsuba's Python API exposes only in
    the integrator's description ("max_depth = 5"); 16 where it is unlimited (-1) or not stated."""
    match = re.search(r"max_depth\s*=\s*(-?\d+)", str(scene.integrator()))
    depth = int(match.group(1)) if match else -1
    return depth if depth > 0 else UNLIMITED_DEPTH


def _hash_lanes(mi, cells: list, nbin, obj, level: int):
    """:func:`_hash` on Dr.Jit lanes: ``cells`` three Int64 arrays, ``nbin`` and ``obj`` UInt64 (the same keys)."""
    c = [_as_u64(mi, v) for v in cells]
    return _mix_key(*c, nbin, obj, mi.UInt64(level), [mi.UInt64(int(v)) for v in _PRIMES], int)


def _as_u64(mi, v):
    import drjit as dr  # deferred: heavy

    return dr.reinterpret_array(mi.UInt64, v)  # two's complement, as numpy's int64 → uint64 view


def _probe(mi, dr, tab_k, mask, key, active):
    """Linear probing of an open-addressing table (:meth:`IrradianceCache.open_table`) for ``key`` from its home
    slot to the first match or empty slot: (slot, found)."""
    slot = mi.UInt32(key & mi.UInt64(mask))  # ``mask``: an int or an opaque UInt32

    def cond(slot, found, done):
        return ~done

    def body(slot, found, done):
        k = dr.gather(mi.UInt64, tab_k, slot, ~done)
        found = found | (~done & (k == key))
        done = done | found | (k == 0)
        slot = dr.select(done, slot, (slot + 1) & mask)
        return slot, found, done

    slot, found, _ = dr.while_loop((slot, mi.Bool(False), ~active), cond, body)
    return slot, found


def _power(a, b):
    import drjit as dr  # deferred: heavy

    a2, b2 = a * a, b * b
    return dr.select(a2 + b2 > 0, a2 / (a2 + b2), 0.0)


def _to_np3(v) -> np.ndarray:
    return np.stack([np.array(v[i], dtype=np.float64) for i in range(3)], axis=1)


def _mix(seed: int, k: int) -> int:
    return int((seed * 0x9E3779B1 + k * 0x85EBCA77) % (2**32))


# ---------------------------------------------------------------------------------------------- per render
#: Prefix of the cache file a converged render keeps in its render directory (``<prefix><key>.npz``).
CACHE_FILE_PREFIX = "irradiance-cache-"


def probe_indices(n_keyframes: int, n_probes: int) -> list[int]:
    """Keyframes whose views fill the cache: ``n_probes`` spread evenly, first and last included."""
    return sorted({int(round(x)) for x in np.linspace(0, n_keyframes - 1, max(1, min(n_probes, n_keyframes)))})


def cache_block(width: int, cache_width_px: int) -> int:
    """Pixels per probe ray along each axis for an image ``width`` px wide: the probe views are traced on a grid
    about ``cache_width_px`` wide (1 at or below it)."""
    return max(1, int(round(width / cache_width_px)))


def probe_grid(width: int, height: int, block: int) -> tuple[int, int]:
    """(columns, rows) of probe rays of a view ``width`` × ``height`` px traced one ray per ``block`` × ``block``
    pixels (:func:`cache_block`)."""
    return -(-width // block), -(-height // block)


def build_cache(cr: ConvergedRenderer, poses: list, seed: int, q_samples: int, cell_px: float,
                block: int = 1) -> IrradianceCache:
    """Converge the cache from the probe views ``poses`` (a list of (camera_to_world, {object: pose})): one
    camera ray per ``block`` × ``block`` pixels of each view (its own jitter), followed through its
    glossy/specular chain, and ``q_samples`` irradiance estimates at every vertex found. The finest cell is
    ``cell_px`` × ``block`` pixel footprints at the first view's median depth, so each cell gathers as many probe
    points whatever the block."""
    ms = cr.ms
    parts = []
    cell_m = None
    for k, (camera_to_world, objects) in enumerate(poses):
        ms.set_pose(np.asarray(camera_to_world), objects)
        if cell_m is None:
            z = ms.render_depth(seed)
            z = z[np.isfinite(z)]
            cell_m = cell_px * block * (float(np.median(z)) if z.size else 1.0) / ms.focal_px
        parts.append(cr.cache_samples(_mix(seed, 77 + k), q_samples, objects, block))
    p, n, obj, q, w, q_a, q_b = (np.concatenate([part[i] for part in parts]) for i in range(7))
    return IrradianceCache.from_samples(cell_m, p, n, obj.astype(np.int64), q, w, halves=(q_a, q_b))


def save_cache(cache: IrradianceCache, path) -> None:
    """Write ``cache`` to ``path`` (.npz) atomically."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    arrays = {"cell_m": np.array(cache.cell_m)}
    for level in LEVELS:
        arrays[f"keys{level}"] = cache.keys[level]
        arrays[f"values{level}"] = cache.values[level]
        arrays[f"counts{level}"] = cache.counts[level]
        if level in cache.half_values:
            arrays[f"half_a{level}"], arrays[f"half_b{level}"] = cache.half_values[level]
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    os.replace(tmp, path)


def load_cache(path) -> IrradianceCache | None:
    """The cache at ``path``, or None when it is missing or unreadable (then it is built again)."""
    try:
        with np.load(path) as d:
            cache = IrradianceCache(float(d["cell_m"]))
            for level in LEVELS:
                cache.keys[level] = d[f"keys{level}"]
                cache.values[level] = d[f"values{level}"]
                cache.counts[level] = d[f"counts{level}"]
                if f"half_a{level}" in d:
                    cache.half_values[level] = (d[f"half_a{level}"], d[f"half_b{level}"])
    except (OSError, KeyError, ValueError):
        return None
    return cache


def layout_convergence(layout) -> dict | None:
    """The ``renderer.convergence`` fields of a render layout's timeline (None: a path-traced render)."""
    return layout.timeline.get("renderer", {}).get("convergence") or None


def converged_renderer(layout, ms, ts, out_dir) -> tuple[ConvergedRenderer, IrradianceCache]:
    """The :class:`ConvergedRenderer` of a converged render ``layout`` and its cache: read from the render directory
    ``out_dir``, or built from the layout's probe keyframes (the same values in any process) and written there."""
    fields = layout_convergence(layout)
    cr = ConvergedRenderer(ms, layout.spp)
    path = Path(out_dir) / fields["cache_file"]
    cache = load_cache(path) if path.is_file() else None
    if cache is None:
        poses = [(np.asarray(layout.camera_to_world[i]),
                  {k: np.asarray(m) for k, m in layout.objects_to_world[i].items()} if layout.objects_to_world
                  else object_poses(ts, layout.times_s[i]))
                 for i in probe_indices(layout.n_keyframes, fields["cache_probes"])]
        cache = build_cache(cr, poses, layout.seed, fields["cache_samples"], fields["cache_cell_px"],
                            cache_block(layout.width, fields.get("cache_width_px", layout.width)))
        save_cache(cache, path)
    return cr, cache


def layout_radiance(layout, ms, ts, out_dir):
    """The radiance pass of ``layout``'s keyframes, as ``radiance(seed, objects) -> [H, W, 3]`` at the scene's
    current pose (``objects``: the animated objects' poses by name, as posed): None for a path-traced render (the
    caller uses ``ms.render_radiance(seed)``); for a converged one its cache's render (:func:`converged_renderer`:
    the cache is read or built now, before the caller poses the scene, since building it poses the probe views)."""
    if layout_convergence(layout) is None:
        return None
    cr, cache = converged_renderer(layout, ms, ts, out_dir)
    return lambda seed, objects: cr.render(cache, seed, objects)
