"""The image motion a render contains, measured from its keyframes' depth and poses.

Every pixel of a keyframe is unprojected with its depth (the EXR ``Z`` channel) and the keyframe's
``camera_to_world``, moved with its object's transform if it shows an animated object (the keyframe's
``object_id`` channel and ``object_to_world`` poses), and projected with the pose of a later keyframe
(:func:`simspad.render.reprojection.image_motion_px`). The distance between the two image positions over the time
between the keyframes is the pixel's image speed (px/s). A pixel's motion blur (px) in one conventional-frame
exposure is the extent of the image path its scene point travels during the exposure, followed through the
keyframes inside it: the diagonal of the path's bounding box (the length of a straight smear; for hand-held
shake, which reverses within a fast exposure, the span it covers rather than the net displacement). Distributions are over pixels and time: every (pixel, keyframe interval) pair weighs its
interval's duration, so the adaptive schedule (keyframes dense where motion is fast) does not bias them. They are
accumulated in a fixed log-spaced histogram (bins :data:`SPEED_BIN_RATIO` wide), so memory does not grow with the
number of keyframes. Pixels that hit nothing (infinite depth) carry no measurable motion and are left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simspad.errors import InputError
from simspad.io.render_dir import read_keyframe, read_render_dir
from simspad.render.reprojection import PinholeCamera, image_motion_px, move_points, project, unproject

#: Histogram range of image speeds (px/s) and of blur lengths (px), log-spaced; below the range counts as 0.
SPEED_RANGE = (1e-4, 1e8)
#: Ratio between consecutive histogram edges: percentiles are resolved to ±0.1 %.
SPEED_BIN_RATIO = 1.002
#: Keyframe intervals measured at most: beyond, every n-th interval (evenly spread, so the time weighting stays
#: unbiased) keeps the cost of a long or fast render bounded.
MAX_INTERVALS = 256
#: Exposure windows measured at most (evenly spread start keyframes), and keyframes followed inside each.
MAX_BLUR_WINDOWS = 32
MAX_BLUR_STEPS = 64
#: Slack (s) when deciding whether a keyframe lies inside the measured span.
_TIME_TOLERANCE_S = 1e-9


@dataclass(frozen=True)
class ImageMotion:
    """Image motion of a render over a span, measured (not predicted).

    Attributes
    ----------
    speed_px_s_p50, speed_px_s_p95 : float
        Median and 95th percentile of the image speed over pixels and time, px/s.
    frame_blur_px_p95 : float or None
        95th percentile of the image motion during one exposure of ``exposure_s``, px (None: no exposure given).
    exposure_s : float or None
        The exposure the blur is measured over, s.
    n_intervals : int
        Keyframe intervals measured (at most :data:`MAX_INTERVALS`).
    """

    speed_px_s_p50: float
    speed_px_s_p95: float
    frame_blur_px_p95: float | None
    exposure_s: float | None
    n_intervals: int


class _LogHistogram:
    """Weighted histogram on log-spaced edges (plus an underflow bin for ~0), for percentiles in bounded memory."""

    def __init__(self):
        lo, hi = SPEED_RANGE
        self.log_lo = math.log(lo)
        self.log_step = math.log(SPEED_BIN_RATIO)
        self.n = int(math.ceil((math.log(hi) - self.log_lo) / self.log_step))
        self.weights = np.zeros(self.n + 2)  # [0]: below range, [1..n]: bins, [n+1]: above range

    def add(self, values: np.ndarray, weight: float) -> None:
        v = np.asarray(values, dtype=np.float64).ravel()
        idx = np.zeros(v.shape, dtype=np.int64)
        pos = v >= math.exp(self.log_lo)
        idx[pos] = np.minimum(np.floor((np.log(v[pos]) - self.log_lo) / self.log_step).astype(np.int64) + 1,
                              self.n + 1)
        self.weights += weight * np.bincount(idx, minlength=self.n + 2)

    def percentile(self, q: float) -> float:
        total = self.weights.sum()
        if not total > 0:
            return float("nan")
        cum = np.cumsum(self.weights)
        i = int(np.searchsorted(cum, q / 100.0 * total, side="left"))
        if i == 0:
            return 0.0
        if i > self.n:
            return float("inf")
        # geometric interpolation inside the bin
        below = cum[i - 1] - self.weights[i]
        frac = 0.0 if self.weights[i] <= 0 else (q / 100.0 * total - below) / self.weights[i]
        return float(math.exp(self.log_lo + (i - 1 + min(max(frac, 0.0), 1.0)) * self.log_step))


def _objects(index, i: int, names: list) -> list:
    """``object_to_world`` of the animated objects (in id order) at keyframe ``i``."""
    poses = index.meta["keyframes"][i].get("object_to_world") or {}
    return [np.asarray(poses[name], dtype=np.float64) for name in names if name in poses]


def _displacement_px(camera, frame: dict, index, i: int, j: int, names: list) -> np.ndarray:
    """Image displacement (px) of every pixel of keyframe ``i`` at keyframe ``j``, NaN-free (unknowns dropped)."""
    d = image_motion_px(camera, frame["z"], index.poses[i], index.poses[j], frame.get("object_id"),
                        _objects(index, i, names), _objects(index, j, names))
    length = np.hypot(d[..., 0], d[..., 1]).ravel()
    return length[np.isfinite(length)]


def measure_image_motion(render_dir, t0: float | None = None, t1: float | None = None,
                         exposure_s: float | None = None) -> ImageMotion:
    """Image speed and frame blur of a render directory over ``[t0, t1]`` (default: all of it).

    Parameters
    ----------
    render_dir : str or Path
        A render directory whose keyframes carry depth and ``camera_to_world`` (every SimSPAD render does).
    t0, t1 : float, optional
        Span to measure, s.
    exposure_s : float, optional
        Exposure of one conventional frame, s: the blur is the image motion over that long (None: not measured).

    Returns
    -------
    ImageMotion

    Raises
    ------
    InputError
        The render directory has no depth, no camera poses, no focal length, or fewer than two keyframes in the
        span.
    """
    index = read_render_dir(render_dir)
    path = Path(render_dir)
    if index.poses is None or not index.has_depth:
        raise InputError("keyframes need depth (Z) and camera_to_world to measure image motion", path=path)
    times = np.asarray(index.times_s, dtype=np.float64)
    t0 = float(times[0]) if t0 is None else float(t0)
    t1 = float(times[-1]) if t1 is None else float(t1)
    inside = np.flatnonzero((times >= t0 - _TIME_TOLERANCE_S) & (times <= t1 + _TIME_TOLERANCE_S))
    if inside.size < 2:
        raise InputError(f"fewer than two keyframes in {t0:g}–{t1:g} s: cannot measure image motion", path=path)
    try:
        camera = PinholeCamera.from_timeline_meta(index.meta)
    except (KeyError, TypeError, ValueError):
        raise InputError("no camera field of view (expected renderer.x_fov_deg) to measure image motion",
                         path=path / "timeline.json", field="renderer.x_fov_deg") from None
    names = list(index.meta.get("renderer", {}).get("animated_objects") or [])
    speed, blur = _LogHistogram(), _LogHistogram()
    first, last = int(inside[0]), int(inside[-1])
    stride = max(1, math.ceil((last - first) / MAX_INTERVALS))
    for i in range(first, last, stride):
        dt = times[i + 1] - times[i]
        frame = read_keyframe(index.files[i], index.width, index.height)
        speed.add(_displacement_px(camera, frame, index, i, i + 1, names) / dt, dt)
    if exposure_s is not None:
        # Exposure windows that fit in the span (if none fits, one window spans the whole render).
        starts = [i for i in range(first, last) if times[i] + exposure_s <= times[last] + _TIME_TOLERANCE_S] or [first]
        for i in starts[::max(1, math.ceil(len(starts) / MAX_BLUR_WINDOWS))]:
            frame = read_keyframe(index.files[i], index.width, index.height)
            blur.add(_path_extent_px(camera, frame, index, i, times, last, float(exposure_s), names),
                     times[i + 1] - times[i])
    return ImageMotion(speed_px_s_p50=speed.percentile(50), speed_px_s_p95=speed.percentile(95),
                       frame_blur_px_p95=None if exposure_s is None else blur.percentile(95),
                       exposure_s=None if exposure_s is None else float(exposure_s),
                       n_intervals=len(range(first, last, stride)))


def _path_extent_px(camera, frame: dict, index, i: int, times: np.ndarray, last: int, exposure_s: float,
                    names: list) -> np.ndarray:
    """Extent (px) of the image path of every pixel of keyframe ``i`` during one exposure starting there: its
    scene point (moved with its object, if any) projected at up to :data:`MAX_BLUR_STEPS` keyframes inside the
    exposure; the bounding-box diagonal, scaled linearly from the keyframe nearest the exposure's end to the
    exposure itself (keyframes lie ≤ ``max_flow_px`` of motion apart, so the correction is small)."""
    j, scale = _exposure_end(times, i, last, exposure_s)
    steps = np.unique(np.linspace(i + 1, j, min(MAX_BLUR_STEPS, j - i)).round().astype(int))
    points = unproject(camera, frame["z"], index.poses[i])
    origin = _objects(index, i, names)
    col0 = np.arange(camera.width, dtype=np.float64)[None, :] * np.ones((camera.height, 1))
    row0 = np.arange(camera.height, dtype=np.float64)[:, None] * np.ones((1, camera.width))
    lo_c, hi_c, lo_r, hi_r = col0.copy(), col0.copy(), row0.copy(), row0.copy()
    lost = ~np.isfinite(points).all(axis=-1)
    for k in steps:
        moved = move_points(points, frame.get("object_id"), origin, _objects(index, int(k), names))
        col, row, _ = project(camera, moved, index.poses[int(k)])
        lost |= ~(np.isfinite(col) & np.isfinite(row))
        lo_c, hi_c = np.fmin(lo_c, col), np.fmax(hi_c, col)
        lo_r, hi_r = np.fmin(lo_r, row), np.fmax(hi_r, row)
    extent = np.hypot(hi_c - lo_c, hi_r - lo_r) * scale
    return extent[~lost]


def _exposure_end(times: np.ndarray, i: int, last: int, exposure_s: float) -> tuple[int, float]:
    """The keyframe j nearest to ``times[i] + exposure_s`` (after i, at most ``last``) and the factor that scales
    the motion from ``times[i]`` to ``times[j]`` to one exposure (keyframes lie ≤ ``max_flow_px`` of motion apart,
    so the linear correction is small)."""
    target = times[i] + exposure_s
    j = int(np.clip(np.searchsorted(times, target), i + 1, last))
    if j > i + 1 and abs(times[j - 1] - target) < abs(times[j] - target):
        j -= 1
    return j, exposure_s / (times[j] - times[i])


def motion_attrs(motion: ImageMotion, speed_factor: float) -> dict:
    """Root attributes of a recording stating the motion it contains (names as results tables use them)."""
    attrs = {"speed_factor": float(speed_factor), "image_speed_px_s_p50": motion.speed_px_s_p50,
             "image_speed_px_s_p95": motion.speed_px_s_p95}
    if motion.frame_blur_px_p95 is not None:
        attrs["frame_blur_px_p95"] = motion.frame_blur_px_p95
        attrs["frame_blur_exposure_s"] = motion.exposure_s
    return attrs
