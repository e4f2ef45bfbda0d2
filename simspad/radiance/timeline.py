"""Radiance in time: a piecewise-linear interpolation between rendered keyframes (DESIGN §1, §5).

A :class:`Timeline` holds the keyframe instants and reads keyframes lazily (from the EXR files of a render
directory, or from arrays for in-memory use) through a small LRU cache, so memory does not grow with the number
of keyframes. Between keyframes radiance is linear in time, so :meth:`Timeline.integrate` is exact: the
trapezoid rule on each linear piece.

Values are luminance ``Y`` (from linear sRGB with :func:`simspad.physics.radiometry.luminance_from_rgb`) times
:attr:`Timeline.scale`: relative units as rendered, or photons s⁻¹ m⁻² after :meth:`Timeline.photon_flux`.
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from pathlib import Path
from typing import Iterator

import numpy as np

from simspad.errors import InputError
from simspad.io.exr import read_exr, read_exr_info
from simspad.physics.radiometry import Optics, flux_scale, luminance_from_rgb

TIMELINE_FORMAT = "simspad-timeline"
TIMELINE_VERSION = 1
TIMELINE_FILE = "timeline.json"
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
        """Open and validate a render directory (DESIGN §5).

        Checks ``timeline.json`` (format, version, size, keyframe instants and files, optional poses) and every
        frame's EXR header (size, channels). Pixel values (NaN, negative radiance) are checked as each frame is
        read.

        Raises
        ------
        InputError
            Naming the file and the field at fault.
        """
        render_dir = Path(render_dir)
        meta_path = render_dir / TIMELINE_FILE
        if not render_dir.is_dir():
            raise InputError("render directory does not exist", path=render_dir)
        if not meta_path.is_file():
            raise InputError(f"missing {TIMELINE_FILE}: not a render directory", path=render_dir)
        try:
            meta = json.loads(meta_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"not valid JSON ({exc})", path=meta_path) from None
        if not isinstance(meta, dict):
            raise InputError("expected a JSON object", path=meta_path)
        if meta.get("format") != TIMELINE_FORMAT:
            raise InputError(f"expected {TIMELINE_FORMAT!r}, got {meta.get('format')!r}", path=meta_path,
                             field="format")
        if meta.get("version") != TIMELINE_VERSION:
            raise InputError(f"unsupported version {meta.get('version')!r} (this reader knows {TIMELINE_VERSION})",
                             path=meta_path, field="version")
        width, height = (_positive_int(meta, key, meta_path) for key in ("width", "height"))
        keyframes = meta.get("keyframes")
        if not isinstance(keyframes, list) or not keyframes:
            raise InputError("expected a non-empty list of {t, file}", path=meta_path, field="keyframes")

        times, files, poses = [], [], []
        for i, kf in enumerate(keyframes):
            field = f"keyframes[{i}]"
            if not isinstance(kf, dict):
                raise InputError("expected an object {t, file}", path=meta_path, field=field)
            t = kf.get("t")
            if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t):
                raise InputError(f"expected a finite time in seconds, got {t!r}", path=meta_path, field=f"{field}.t")
            if times and t <= times[-1]:
                raise InputError(f"times must be strictly increasing: {t!r} follows {times[-1]!r}", path=meta_path,
                                 field=f"{field}.t")
            name = kf.get("file")
            if not isinstance(name, str) or not name:
                raise InputError("expected a frame file name", path=meta_path, field=f"{field}.file")
            file = render_dir / name
            if not file.is_file():
                raise InputError(f"frame file {name!r} is missing", path=meta_path, field=f"{field}.file")
            info = read_exr_info(file)
            if (info.width, info.height) != (width, height):
                raise InputError(f"size {info.width}x{info.height} differs from timeline.json's {width}x{height}",
                                 path=file, field="dataWindow")
            if "camera_to_world" in kf:
                pose = np.asarray(kf["camera_to_world"], dtype=object)
                try:
                    pose = pose.astype(np.float64)
                except (TypeError, ValueError):
                    pose = None
                if pose is None or pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
                    raise InputError("expected a finite 4x4 matrix", path=meta_path, field=f"{field}.camera_to_world")
                poses.append(pose)
            times.append(float(t))
            files.append((file, info))
        if poses and len(poses) != len(times):
            raise InputError("camera_to_world must be given for every keyframe or for none", path=meta_path,
                             field="keyframes[].camera_to_world")
        has_depth = all(info.depth_channel is not None for _, info in files)

        def load(i: int) -> dict:
            file, info = files[i]
            data = read_exr(file)
            radiance = data.get("rgb", data.get("y"))
            if radiance.shape[:2] != (height, width):
                raise InputError(f"size {radiance.shape[1]}x{radiance.shape[0]} differs from timeline.json's "
                                 f"{width}x{height}", path=file, field="dataWindow")
            _check_radiance(radiance, file, "R,G,B" if "rgb" in data else "Y")
            frame = {"y": luminance_from_rgb(data["rgb"]) if "rgb" in data else data["y"]}
            if "rgb" in data:
                frame["rgb"] = data["rgb"]
            if has_depth:
                frame["z"] = data["z"]
            return frame

        return cls(times, _FrameCache(load, cache_frames), width=width, height=height, has_depth=has_depth,
                   poses=np.stack(poses) if poses else None, meta=meta, render_dir=render_dir)

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
        """This timeline in sensor-plane photons s⁻¹ m⁻² at ``lux`` (DESIGN §3: first keyframe's mean sets the level)."""
        mean = float(np.mean(self.keyframe(0), dtype=np.float64))
        if not mean > 0:
            raise InputError("the first keyframe is black: a lux level cannot be assigned", path=self.render_dir,
                             field="keyframes[0]")
        return self.scaled(flux_scale(mean, lux, optics))

    # ------------------------------------------------------------------ values
    def keyframe(self, i: int) -> np.ndarray:
        """Luminance of keyframe ``i`` × scale, [H, W] float32."""
        return self._y(i) * np.float32(self.scale)

    def rgb_keyframe(self, i: int) -> np.ndarray:
        """Linear sRGB of keyframe ``i`` × scale, [H, W, 3] float32 (luminance repeated for Y-only frames)."""
        frame = self._cache.get(self._index(i))
        rgb = frame.get("rgb")
        if rgb is None:
            rgb = np.repeat(frame["y"][..., None], 3, axis=-1)
        return rgb * np.float32(self.scale)

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


def _positive_int(meta: dict, key: str, path: Path) -> int:
    value = meta.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise InputError(f"expected a positive integer, got {value!r}", path=path, field=key)
    return value


def _check_radiance(radiance: np.ndarray, file: Path, channels: str) -> None:
    bad = ~np.isfinite(radiance)
    if bad.any():
        row, col = np.argwhere(bad)[0][:2]
        raise InputError(f"radiance is NaN or infinite at pixel (row {row}, col {col})", path=file, field=channels)
    if (radiance < 0).any():
        row, col = np.argwhere(radiance < 0)[0][:2]
        raise InputError(f"negative radiance {radiance[row, col]} at pixel (row {row}, col {col})", path=file,
                         field=channels)


# ---------------------------------------------------------------------- writing render directories
def keyframe_filename(index: int) -> str:
    """Relative path of keyframe ``index`` inside a render directory."""
    return f"frames/{index:06d}.exr"


def write_timeline_json(render_dir: str | Path, *, width: int, height: int, keyframes: list[dict],
                        **meta) -> Path:
    """Write ``timeline.json`` atomically (the last step of a render: its presence marks the directory complete).

    Parameters
    ----------
    keyframes : list of dict
        ``{"t": seconds, "file": relative path, "camera_to_world": 4x4 list (optional)}``, strictly increasing t.
    **meta
        Further top-level fields (``scene``, ``trajectory``, ``renderer``, ...); must be JSON-serialisable.
    """
    from simspad.io.atomic import atomic_path

    doc = {"format": TIMELINE_FORMAT, "version": TIMELINE_VERSION, "width": int(width), "height": int(height),
           "keyframes": keyframes, "radiance_units": meta.pop("radiance_units", "relative"), **meta}
    path = Path(render_dir) / TIMELINE_FILE
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(doc, indent=1))
    return path


def write_render_dir(render_dir: str | Path, times_s, frames, depth=None, poses=None, **meta) -> Path:
    """Write a complete render directory from arrays (tests, converters, other renderers' output).

    Parameters
    ----------
    times_s : array (K,)
        Strictly increasing instants, seconds.
    frames : array (K, H, W, 3) linear sRGB, or (K, H, W) luminance Y
    depth : array (K, H, W), optional
        Depth in metres, stored as channel ``Z``.
    poses : array (K, 4, 4), optional
        Camera-to-world matrices.
    """
    from simspad.io.exr import write_exr

    render_dir = Path(render_dir)
    times = np.asarray(times_s, dtype=np.float64)
    frames = np.asarray(frames, dtype=np.float32)
    if np.any(np.diff(times) <= 0):
        raise ValueError("times_s must be strictly increasing")
    keyframes = []
    for i, t in enumerate(times):
        channels = ({"R": frames[i, ..., 0], "G": frames[i, ..., 1], "B": frames[i, ..., 2]} if frames.ndim == 4
                    else {"Y": frames[i]})
        if depth is not None:
            channels["Z"] = np.asarray(depth[i], dtype=np.float32)
        name = keyframe_filename(i)
        write_exr(render_dir / name, channels)
        kf = {"t": float(t), "file": name}
        if poses is not None:
            kf["camera_to_world"] = np.asarray(poses[i], dtype=np.float64).tolist()
        keyframes.append(kf)
    return write_timeline_json(render_dir, width=frames.shape[2], height=frames.shape[1], keyframes=keyframes,
                               **meta)
