"""Radiance in time: a piecewise-linear interpolation between rendered keyframes (docs/internals.md, docs/format.md).

A :class:`Timeline` holds the keyframe instants and reads keyframes lazily (from the EXR files of a render
directory, or from arrays for in-memory use) through a small LRU cache, so memory does not grow with the number
of keyframes. Between keyframes radiance is linear in time, so :meth:`Timeline.integrate` is exact: the
trapezoid rule on each linear piece.

Values are luminance ``Y`` (from linear sRGB with :func:`simspad.physics.radiometry.luminance_from_rgb`) times
:attr:`Timeline.scale`: relative units as rendered, or photons s⁻¹ m⁻² after :meth:`Timeline.photon_flux`.
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path
from typing import Iterator

import numpy as np

from simspad.errors import InputError
from simspad.io.render_dir import read_keyframe, read_render_dir
from simspad.physics.radiometry import Optics, flux_scale, luminance_from_planes, luminance_from_rgb

#: Instants this close outside [t_start, t_end] (seconds) are clamped, so bin edges computed as
#: t0 + n·bin_s do not fail on round-off.
TIME_TOLERANCE_S = 1e-9
DEFAULT_CACHE_FRAMES = 4


class _FrameCache:
    """Keyframes decoded on demand, at most ``size`` kept (least recently used dropped first)."""

    def __init__(self, loader, size: int):
        self._loader = loader
        self._size = max(2, int(size))
        self._frames: OrderedDict[int, dict] = OrderedDict()

    def get(self, i: int) -> dict:
        frame = self._frames.get(i)
        if frame is None:
            frame = self._loader(i)
            for a in frame.values():
                a.setflags(write=False)  # cached arrays are shared; callers get fresh arrays
            self._frames[i] = frame
            if len(self._frames) > self._size:
                self._frames.popitem(last=False)
        else:
            self._frames.move_to_end(i)
        return frame


class Timeline:
    """Piecewise-linear luminance between keyframes.

    Build with :meth:`open` (a render directory) or :meth:`from_arrays` (in memory).

    Attributes
    ----------
    times_s : ndarray (K,)
        Keyframe instants, strictly increasing, seconds.
    width, height : int
        Image size in pixels.
    t_start, t_end : float
        First and last keyframe instants, seconds.
    has_depth : bool
        Whether every keyframe carries depth (``Z``, metres).
    poses : ndarray (K, 4, 4) or None
        Camera-to-world of each keyframe (Mitsuba convention), if known.
    scale : float
        Factor applied to every returned luminance value.
    meta : dict
        The ``timeline.json`` content (empty for in-memory timelines).
    render_dir : Path or None
        Where the keyframes live.
    """

    def __init__(self, times_s, cache: _FrameCache, *, width: int, height: int, has_depth: bool,
                 poses: np.ndarray | None = None, scale: float = 1.0, meta: dict | None = None,
                 render_dir: Path | None = None):
        self.times_s = np.asarray(times_s, dtype=np.float64)
        self.times_s.setflags(write=False)
        self._cache = cache
        self.width, self.height = int(width), int(height)
        self.has_depth = bool(has_depth)
        self.poses = poses
        self.scale = float(scale)
        self.meta = dict(meta or {})
        self.render_dir = render_dir

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_arrays(cls, times_s, frames_Y, depth=None, poses=None, *, scale: float = 1.0) -> "Timeline":
        """An in-memory timeline.

        Parameters
        ----------
        times_s : array (K,)
            Strictly increasing instants, seconds.
        frames_Y : array (K, H, W) or (K, H, W, 3)
            Luminance keyframes, or linear sRGB keyframes (luminance is then derived).
        depth : array (K, H, W), optional
            Depth in metres.
        poses : array (K, 4, 4), optional
            Camera-to-world matrices.
        scale : float
            Factor applied to every returned value.
        """
        times = np.asarray(times_s, dtype=np.float64)
        frames = np.asarray(frames_Y, dtype=np.float32)
        if times.ndim != 1 or times.size < 1 or not np.all(np.isfinite(times)):
            raise ValueError("times_s must be a non-empty 1-D array of finite instants")
        if np.any(np.diff(times) <= 0):
            raise ValueError("times_s must be strictly increasing")
        if frames.ndim not in (3, 4) or frames.shape[0] != times.size or (frames.ndim == 4 and frames.shape[3] != 3):
            raise ValueError(f"frames_Y must be (K, H, W) or (K, H, W, 3) with K = {times.size}, got {frames.shape}")
        if not np.all(np.isfinite(frames)) or np.any(frames < 0):
            raise ValueError("frames_Y must be finite and non-negative")
        height, width = frames.shape[1:3]
        if depth is not None:
            depth = np.asarray(depth, dtype=np.float32)
            if depth.shape != (times.size, height, width):
                raise ValueError(f"depth must be {(times.size, height, width)}, got {depth.shape}")
        if poses is not None:
            poses = np.asarray(poses, dtype=np.float64)
            if poses.shape != (times.size, 4, 4):
                raise ValueError(f"poses must be {(times.size, 4, 4)}, got {poses.shape}")

        def load(i: int) -> dict:
            frame = {"y": luminance_from_rgb(frames[i]) if frames.ndim == 4 else frames[i].copy()}
            if frames.ndim == 4:
                frame["rgb"] = frames[i].copy()
            if depth is not None:
                frame["z"] = depth[i].copy()
            return frame

        return cls(times, _FrameCache(load, DEFAULT_CACHE_FRAMES), width=width, height=height,
                   has_depth=depth is not None, poses=poses, scale=scale)

    @classmethod
    def open(cls, render_dir: str | Path, *, cache_frames: int = DEFAULT_CACHE_FRAMES) -> "Timeline":
        """Open and validate a render directory (docs/format.md; format in :mod:`simspad.io.render_dir`).

        Checks ``timeline.json`` (format, version, size, keyframe instants and files, optional poses) and every
        frame's EXR header (size, channels). Pixel values (NaN, negative radiance) are checked as each frame is
        read.

        Raises
        ------
        InputError
            Naming the file and the field at fault.
        """
        index = read_render_dir(render_dir)

        def load(i: int) -> dict:
            # R, G, B kept as the file's planes: luminance is computed from them, and only the frame camera's
            # rgb_keyframe interleaves them
            data = read_keyframe(index.files[i], index.width, index.height, rgb_planes=True)
            if "y" in data:
                frame = {"y": data["y"]}
            else:
                frame = {"y": luminance_from_planes(data["r"], data["g"], data["b"]),
                         **{k: data[k] for k in "rgb"}}
            if index.has_depth:
                frame["z"] = data["z"]
            return frame

        return cls(index.times_s, _FrameCache(load, cache_frames), width=index.width, height=index.height,
                   has_depth=index.has_depth, poses=index.poses, meta=index.meta, render_dir=index.render_dir)

    # ------------------------------------------------------------------ basic properties
    @property
    def t_start(self) -> float:
        return float(self.times_s[0])

    @property
    def t_end(self) -> float:
        return float(self.times_s[-1])

    @property
    def n_keyframes(self) -> int:
        return int(self.times_s.size)

    def __len__(self) -> int:
        return self.n_keyframes

    def __repr__(self) -> str:
        where = f" {self.render_dir}" if self.render_dir else ""
        return (f"Timeline({self.n_keyframes} keyframes, {self.width}x{self.height}, "
                f"[{self.t_start:.6g}, {self.t_end:.6g}] s, scale={self.scale:.6g}{where})")

    def scaled(self, factor: float) -> "Timeline":
        """The same keyframes with every value multiplied by ``factor`` (shares the frame cache)."""
        return Timeline(self.times_s, self._cache, width=self.width, height=self.height, has_depth=self.has_depth,
                        poses=self.poses, scale=self.scale * float(factor), meta=self.meta,
                        render_dir=self.render_dir)

    def photon_flux(self, lux: float, optics: Optics | None = None) -> "Timeline":
        """This timeline in sensor-plane photons s⁻¹ m⁻² at ``lux`` (docs/sensors.md: first keyframe's mean sets the level)."""
        mean = float(np.mean(self.keyframe(0), dtype=np.float64))
        if not mean > 0:
            raise InputError("the first keyframe is black: a lux level cannot be assigned", path=self.render_dir,
                             field="keyframes[0]")
        return self.scaled(flux_scale(mean, lux, optics))

    # ------------------------------------------------------------------ values
    def keyframe(self, i: int, out: np.ndarray | None = None) -> np.ndarray:
        """Luminance of keyframe ``i`` × scale, [H, W] float32 (written into ``out`` when given: no temporary)."""
        if out is not None:
            return np.multiply(self._y(i), np.float32(self.scale), out=out)
        return self._y(i) * np.float32(self.scale)

    def rgb_keyframe(self, i: int) -> np.ndarray:
        """Linear sRGB of keyframe ``i`` × scale, [H, W, 3] float32 (luminance repeated for Y-only frames)."""
        frame = self._cache.get(self._index(i))
        scale = np.float32(self.scale)
        if "rgb" in frame:
            return frame["rgb"] * scale
        planes = [frame[k] for k in "rgb"] if "r" in frame else [frame["y"]] * 3
        out = np.empty(planes[0].shape + (3,), np.float32)
        for c, plane in enumerate(planes):
            np.multiply(plane, scale, out=out[..., c])
        return out

    def keyframe_depth(self, i: int) -> np.ndarray | None:
        """Depth of keyframe ``i`` in metres, [H, W] float32, or None."""
        if not self.has_depth:
            return None
        return self._cache.get(self._index(i))["z"].copy()

    def locate(self, t: float) -> tuple[int, float]:
        """Piece index ``i`` and weight ``w`` so that value(t) = (1 − w)·keyframe(i) + w·keyframe(i + 1)."""
        t = self._clamp(t)
        if self.n_keyframes == 1:
            return 0, 0.0
        i = int(np.clip(np.searchsorted(self.times_s, t, side="right") - 1, 0, self.n_keyframes - 2))
        ta, tb = self.times_s[i], self.times_s[i + 1]
        return i, float((t - ta) / (tb - ta))

    def sample(self, t: float) -> np.ndarray:
        """Luminance at instant ``t`` (linear between keyframes), [H, W] float32.

        Raises
        ------
        ValueError
            ``t`` outside [t_start, t_end].
        """
        i, w = self.locate(t)
        return self._blend(i, w)

    def depth(self, t: float) -> np.ndarray | None:
        """Depth at instant ``t`` in metres (linear between keyframes), or None without depth."""
        if not self.has_depth:
            return None
        i, w = self.locate(t)
        za = self._cache.get(i)["z"]
        if w == 0.0:
            return za.copy()
        zb = self._cache.get(i + 1)["z"]
        with np.errstate(invalid="ignore"):
            z = (za + np.float32(w) * (zb - za)).astype(np.float32)
        # Where a ray hits nothing (+inf) at either end, take the nearer keyframe's value instead of inf − inf.
        return np.where(np.isfinite(za) & np.isfinite(zb), z, za if w < 0.5 else zb).astype(np.float32)

    def segments(self, t0: float, t1: float) -> Iterator[tuple[float, float, np.ndarray, np.ndarray]]:
        """Linear pieces covering [t0, t1]: ``(ta, tb, Ya, Yb)`` with values at ta and tb, in time order.

        Only the keyframes the pieces touch are read, so iterating a long interval streams.
        """
        t0, t1 = self._clamp(t0), self._clamp(t1)
        if t1 < t0:
            raise ValueError(f"t1 = {t1!r} precedes t0 = {t0!r}")
        if t1 == t0 or self.n_keyframes == 1:
            return
        i0, _ = self.locate(t0)
        i1, w1 = self.locate(t1)
        if w1 == 0.0 and i1 > i0:
            i1 -= 1  # t1 is exactly a keyframe: the last piece ends there
        ta, ya = t0, self.sample(t0)
        for i in range(i0, i1 + 1):
            tb = min(t1, float(self.times_s[i + 1]))
            yb = self._blend(i, (tb - self.times_s[i]) / (self.times_s[i + 1] - self.times_s[i]))
            yield ta, tb, ya, yb
            ta, ya = tb, yb

    def integrate(self, t0: float, t1: float) -> np.ndarray:
        """Exact ∫_{t0}^{t1} value(t) dt, [H, W] float32 (units × seconds); trapezoid rule per linear piece."""
        total = np.zeros((self.height, self.width), dtype=np.float64)
        for ta, tb, ya, yb in self.segments(t0, t1):
            total += (0.5 * (tb - ta)) * (ya.astype(np.float64) + yb)
        return total.astype(np.float32)

    def mean(self, t0: float, t1: float) -> np.ndarray:
        """Time average over [t0, t1] (the value at t0 if the interval is empty)."""
        if t1 == t0:
            return self.sample(t0)
        return (self.integrate(t0, t1) / np.float32(t1 - t0)).astype(np.float32)

    # ------------------------------------------------------------------ helpers
    def _index(self, i: int) -> int:
        i = int(i)
        if i < 0:
            i += self.n_keyframes
        if not 0 <= i < self.n_keyframes:
            raise IndexError(f"keyframe {i} out of range (0..{self.n_keyframes - 1})")
        return i

    def _y(self, i: int) -> np.ndarray:
        return self._cache.get(self._index(i))["y"]

    def _blend(self, i: int, w: float) -> np.ndarray:
        scale = np.float32(self.scale)
        ya = self._y(i)
        if w <= 0.0:
            return ya * scale
        yb = self._y(i + 1)
        if w >= 1.0:
            return yb * scale
        return (ya * np.float32((1.0 - w) * self.scale) + yb * np.float32(w * self.scale)).astype(np.float32)

    def _clamp(self, t: float) -> float:
        t = float(t)
        if not (self.t_start - TIME_TOLERANCE_S <= t <= self.t_end + TIME_TOLERANCE_S):
            raise ValueError(f"t = {t!r} s is outside the timeline [{self.t_start!r}, {self.t_end!r}] s")
        return min(max(t, self.t_start), self.t_end)
