"""A preview anyone can watch: ground truth, SPAD, frame camera and events of a recording side by side.

:func:`write_preview` streams a recording into a video (``.mp4``, through imageio's ffmpeg plugin and the
``imageio-ffmpeg`` wheel's own ffmpeg), an animated ``.gif``, or a ``.png`` strip (a few instants stacked). Each
video frame is one instant t of recording time, and shows, in panels of the recording's own pixel grid:

- **ground truth**: the sharp flux at the last ground-truth instant ≤ t, tone-mapped (flux / white point,
  sRGB curve; the white point is the 99th percentile of the ground truth over the previewed span, fixed for the
  clip so that brightness changes are the scene's);
- **SPAD aggregate**: the fraction of binary frames that detected a photon over the window ``[t − w, t)``,
  ``w = 1 / spad_rate_hz`` (sRGB curve of the fraction, so dim pixels stay visible);
- **SPAD binary frame**: the single binary frame exposing at t (white = a detection);
- **frame camera**: the last frame whose exposure ended by t, in DN over full scale (sRGB curve);
- **events**: polarity accumulated over ``[t − w_e, t)``: red ON, blue OFF, saturating at 3 events;
- **flow** (recordings with geometry): the ground-truth motion field (its instantaneous image velocity) at the
  ground truth's instant, on a colour wheel (hue: direction, x right = red, y down = yellow-green; saturation:
  speed up to the clip's 99th percentile of the image speed; pixels whose flow is not valid dimmed to half);
- **instances**: the instance mask, one fixed colour per scene object (black: nothing hit).

Absent sensors leave their panels out. The panels are drawings of the three built-in sensors' data
(:data:`PANEL_SENSORS`); another sensor of the recording (one added through the sensor table) gets no panel, and
:attr:`PreviewResult.no_panel` names it. Labels give the scene, speed, lux, the instant, and each panel's window.
Memory is one video frame and one window of sensor data, whatever the recording's length: the ground truth,
frames and SPAD bits are read per instant, the events per window.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from simspad.errors import SimSpadError
from simspad.io.atomic import atomic_path, check_output_file
from simspad.io.recording import open_recording
from simspad.physics.colour import srgb_encode

#: Output kinds by suffix.
PREVIEW_SUFFIXES = (".mp4", ".gif", ".png")
#: Video frames per second of an ``.mp4`` or ``.gif``.
DEFAULT_FPS = 25
#: Recording seconds are stretched this many times by default: 1 ms of recording lasts 0.1 s of video.
DEFAULT_SLOWDOWN = 100.0
#: SPAD aggregate rate of the aggregate panel (Hz): the reference paper's NEDI+AKF reads SPAD aggregates at 0.4–
#: 1 kHz; 1 kHz shows motion without much blur.
DEFAULT_SPAD_RATE_HZ = 1000.0
#: Event accumulation window of the events panel, s.
DEFAULT_EVENT_WINDOW_S = 1e-3
#: Instants of a ``.png`` strip.
STRIP_INSTANTS = 5
#: A preview longer than this many video frames is refused (a slowdown of 10⁶ on a second of recording would
#: otherwise encode for hours); shorten ``--duration`` or lower ``--slowdown``.
MAX_VIDEO_FRAMES = 20_000
#: Each recording pixel is drawn as this many screen pixels (per side) at most, and the panels are scaled so
#: that the widest panel is about this many pixels wide.
TARGET_PANEL_PX = 320
#: Events of one sign at which a pixel's colour saturates in the events panel.
EVENT_SATURATION = 3


@dataclass(frozen=True)
class PreviewSettings:
    """What a preview shows.

    Attributes
    ----------
    start_s, duration_s : float or None
        Recording time span shown, s (default: the whole recording).
    slowdown : float
        Video seconds per recording second.
    fps : float
        Video frames per second.
    spad_rate_hz : float
        Aggregate rate of the SPAD aggregate panel, Hz.
    event_window_s : float
        Accumulation window of the events panel, s.
    panel_px : int
        About how many screen pixels the longer side of each panel takes (a recording pixel is an integer number
        of screen pixels, at least one).
    """

    start_s: float | None = None
    duration_s: float | None = None
    slowdown: float = DEFAULT_SLOWDOWN
    fps: float = DEFAULT_FPS
    spad_rate_hz: float = DEFAULT_SPAD_RATE_HZ
    event_window_s: float = DEFAULT_EVENT_WINDOW_S
    panel_px: int = TARGET_PANEL_PX

    def check(self) -> None:
        for name in ("slowdown", "fps", "spad_rate_hz", "event_window_s", "panel_px"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise SimSpadError(f"expected a finite number > 0, got {v!r}", field=f"--{name.replace('_', '-')}")
        if self.duration_s is not None and not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise SimSpadError(f"expected a duration > 0 s, got {self.duration_s!r}", field="--duration")
        if self.start_s is not None and not math.isfinite(self.start_s):
            raise SimSpadError(f"expected a finite start time, got {self.start_s!r}", field="--start")


@dataclass(frozen=True)
class PreviewResult:
    """What :func:`write_preview` wrote: the file, its frame count and size, the instants shown (s), and where
    each panel's image lies in a video frame (name → ``(x0, y0, x1, y1)`` px; in a ``.png`` strip, in its first
    instant, the others below it at multiples of the frame height ``height_px / len(times_s)``)."""

    path: Path
    n_frames: int
    width_px: int
    height_px: int
    times_s: np.ndarray
    panels: dict
    no_panel: tuple[str, ...] = ()  # the recording's sensors this preview has no panel for (not drawn)


#: The sensors with panels: each panel draws that sensor's own data (binary frames, DN frames, event polarity).
PANEL_SENSORS = ("spad", "frames", "events")


def sensors_without_panel(rec) -> tuple[str, ...]:
    """The sensors written into open recording ``rec`` (its ``sensors`` attribute, which also names groups this
    process has no table row for) that have no panel here."""
    written = [k for k in str(rec.attrs.get("sensors", "")).split(",") if k]
    return tuple(k for k in written if k not in PANEL_SENSORS)


def preview_times(t0: float, t1: float, settings: PreviewSettings, kind: str) -> np.ndarray:
    """The recording instants shown: every ``1 / (fps · slowdown)`` s over ``[t0, t1)`` for a video, or
    :data:`STRIP_INSTANTS` evenly spaced instants (the span's ends excluded) for a ``.png`` strip."""
    if kind == ".png":
        return t0 + (t1 - t0) * (np.arange(STRIP_INSTANTS) + 0.5) / STRIP_INSTANTS
    dt = 1.0 / (settings.fps * settings.slowdown)
    n = int(math.floor((t1 - t0) / dt + 1e-9))
    if n > MAX_VIDEO_FRAMES:
        raise SimSpadError(f"{n} video frames (span {(t1 - t0) * 1e3:g} ms × slowdown {settings.slowdown:g} × "
                           f"{settings.fps:g} fps) exceed {MAX_VIDEO_FRAMES}; shorten --duration or lower "
                           "--slowdown", field="--slowdown")
    return t0 + dt * np.arange(max(n, 1))


class _Sources:
    """Per-instant panel images of one open recording (each ``[H, W, 3]`` float in 0–1) and their labels."""

    def __init__(self, rec, settings: PreviewSettings, t0: float, t1: float):
        self.rec, self.settings = rec, settings
        self.H, self.W = int(rec.height), int(rec.width)
        self.panels: list[str] = []
        if rec.has("gt"):
            self.gt_t = rec.gt.t
            self.panels.append("gt")
            self.white = self._white_point(t0, t1)
            if rec.gt.has_geometry:
                self.panels += ["flow", "instances"]
                self.max_speed = self._max_speed(t0, t1)
        if rec.has("spad"):
            ds = rec.h5["spad"]["t_start"]
            self.spad_t0 = float(ds[0]) if ds.shape[0] else 0.0
            a = rec.spad.attrs
            self.bin_s = float(a["bin_s"]) if "bin_s" in a else 1.0 / float(a["frame_rate_hz"])
            self.n_bins = rec.spad.n_bins
            self.agg_bins = max(1, int(round(1.0 / (settings.spad_rate_hz * self.bin_s))))
            self.panels += ["spad_aggregate", "spad_bit"]
        if rec.has("frames"):
            self.frame_t_end = rec.frames.t_end
            self.full_scale = float(2 ** int(rec.frames.attrs.get("bit_depth", 12)) - 1)
            self.panels.append("frames")
        if rec.has("events"):
            self.panels.append("events")
        if not self.panels:
            raise SimSpadError("nothing to preview: the recording has no ground truth and no sensor group",
                               path=rec.path)

    def _white_point(self, t0: float, t1: float) -> float:
        """99th percentile of the ground truth at up to 16 instants of the span (> 0)."""
        idx = np.flatnonzero((self.gt_t >= t0) & (self.gt_t <= t1))
        if idx.size == 0:
            idx = np.array([int(np.clip(np.searchsorted(self.gt_t, t0), 0, len(self.gt_t) - 1))])
        pick = idx[np.linspace(0, idx.size - 1, min(16, idx.size)).round().astype(int)]
        values = np.concatenate([self.rec.gt.flux(int(i)).ravel() for i in np.unique(pick)])
        finite = values[np.isfinite(values)]
        white = float(np.percentile(finite, 99)) if finite.size else 0.0
        return white if white > 0 else 1.0

    def _max_speed(self, t0: float, t1: float) -> float:
        """99th percentile of the image speed (px s⁻¹) at up to 16 instants of the span (> 0): the colour wheel's
        full saturation, fixed for the clip."""
        idx = np.flatnonzero((self.gt_t >= t0) & (self.gt_t <= t1))
        if idx.size == 0:
            idx = np.array([self._gt_index(t0)])
        pick = np.unique(idx[np.linspace(0, idx.size - 1, min(16, idx.size)).round().astype(int)])
        speed = np.concatenate([np.hypot(*np.moveaxis(self.rec.gt.velocity(int(i)), -1, 0)).ravel() for i in pick])
        speed = speed[np.isfinite(speed)]
        top = float(np.percentile(speed, 99)) if speed.size else 0.0
        return top if top > 0 else 1.0

    def labels(self, t: float) -> list[str]:
        s = self.settings
        out = []
        for p in self.panels:
            if p == "gt":
                i = self._gt_index(t)
                out.append(f"ground truth (t = {self.gt_t[i] * 1e3:.2f} ms)")
            elif p == "spad_aggregate":
                out.append(f"SPAD, {self.agg_bins} bins ({self.agg_bins * self.bin_s * 1e3:.2f} ms)")
            elif p == "spad_bit":
                out.append(f"SPAD binary frame ({self.bin_s * 1e6:.2f} µs)")
            elif p == "frames":
                k = self._frame_index(t)
                out.append("frame camera (none yet)" if k < 0 else
                           f"frame {k}, exposure ended {self.frame_t_end[k] * 1e3:.2f} ms")
            elif p == "events":
                out.append(f"events, last {s.event_window_s * 1e3:g} ms (red ON, blue OFF)")
            elif p == "flow":
                out.append(f"motion field (wheel: up to {self.max_speed:.3g} px/s)")
            elif p == "instances":
                out.append(f"instances ({len(self.rec.gt.instance_names) - 1} objects)")
        return out

    def _gt_index(self, t: float) -> int:
        return int(np.clip(np.searchsorted(self.gt_t, t + 1e-12, side="right") - 1, 0, len(self.gt_t) - 1))

    def _frame_index(self, t: float) -> int:
        return int(np.searchsorted(self.frame_t_end, t + 1e-12, side="right") - 1)

    def _bin_index(self, t: float) -> int:
        return int(math.floor((t - self.spad_t0) / self.bin_s + 1e-9))

    def images(self, t: float) -> list[np.ndarray]:
        out = []
        for p in self.panels:
            out.append(getattr(self, f"_{p}")(t))
        return out

    def _gt(self, t: float) -> np.ndarray:
        v = np.nan_to_num(self.rec.gt.flux(self._gt_index(t)).astype(np.float64) / self.white, nan=0.0)
        return _grey(srgb_encode(np.clip(v, 0.0, 1.0)))

    def _spad_aggregate(self, t: float) -> np.ndarray:
        stop = int(np.clip(self._bin_index(t), 0, self.n_bins))
        start = max(0, stop - self.agg_bins)
        if stop <= start:
            return np.zeros((self.H, self.W, 3))
        frac = self.rec.spad.counts(start, stop) / float(stop - start)
        return _grey(srgb_encode(frac))

    def _spad_bit(self, t: float) -> np.ndarray:
        i = self._bin_index(t)
        if not 0 <= i < self.n_bins:
            return np.zeros((self.H, self.W, 3))
        return _grey(self.rec.spad.bits(i, i + 1)[0].astype(np.float64))

    def _frames(self, t: float) -> np.ndarray:
        k = self._frame_index(t)
        if k < 0:
            return np.zeros((self.H, self.W, 3))
        return _grey(srgb_encode(np.clip(self.rec.frames.dn(k).astype(np.float64) / self.full_scale, 0.0, 1.0)))

    def _events(self, t: float) -> np.ndarray:
        ev = self.rec.events.window(t - self.settings.event_window_s, t)
        on = np.zeros(self.H * self.W)
        off = np.zeros(self.H * self.W)
        if ev["t"].size:
            flat = ev["y"].astype(np.int64) * self.W + ev["x"].astype(np.int64)
            positive = ev["p"].astype(np.int64) > 0
            np.add.at(on, flat[positive], 1.0)
            np.add.at(off, flat[~positive], 1.0)
        on = np.clip(on / EVENT_SATURATION, 0, 1).reshape(self.H, self.W)
        off = np.clip(off / EVENT_SATURATION, 0, 1).reshape(self.H, self.W)
        # white background; ON removes green and blue (red), OFF removes red and green (blue)
        return np.stack([1 - off, 1 - np.maximum(on, off), 1 - on], axis=-1)


    def _flow(self, t: float) -> np.ndarray:
        i = self._gt_index(t)
        return flow_colours(self.rec.gt.velocity(i), self.max_speed, self.rec.gt.flow_valid(i))

    def _instances(self, t: float) -> np.ndarray:
        return instance_colours(self.rec.gt.instance(self._gt_index(t)))


def flow_colours(flow: np.ndarray, full_scale: float, valid: np.ndarray | None = None) -> np.ndarray:
    """Colour-wheel image ``[H, W, 3]`` in 0–1 of a flow field ``[H, W, 2]`` (x right, y down): hue is the
    direction (0°, red, along +x; angles turn from +x towards +y, i.e. clockwise on screen), saturation the length
    over ``full_scale`` (clipped at 1), value 1; half value where ``valid`` is False; black where undefined."""
    from matplotlib.colors import hsv_to_rgb  # deferred: matplotlib is heavy and only the preview draws

    f = np.asarray(flow, np.float64)
    finite = np.all(np.isfinite(f), axis=-1)
    f = np.where(finite[..., None], f, 0.0)
    hue = (np.arctan2(f[..., 1], f[..., 0]) / (2 * np.pi)) % 1.0
    sat = np.clip(np.hypot(f[..., 0], f[..., 1]) / float(full_scale), 0.0, 1.0)
    val = np.where(finite, 1.0, 0.0)
    if valid is not None:
        val = np.where(np.asarray(valid, bool), val, 0.5 * val)
    return hsv_to_rgb(np.stack([hue, sat, val], axis=-1))


def instance_colours(instance: np.ndarray) -> np.ndarray:
    """``[H, W, 3]`` in 0–1: instance k ≥ 1 gets hue k·φ (golden ratio: neighbouring ids differ), 0 is black."""
    from matplotlib.colors import hsv_to_rgb  # deferred: matplotlib is heavy and only the preview draws

    ids = np.asarray(instance, np.int64)
    hue = (ids * 0.6180339887498949) % 1.0
    sat = np.where(ids % 2 == 0, 0.55, 0.85)
    return hsv_to_rgb(np.stack([hue, sat, np.where(ids > 0, 0.95, 0.0)], axis=-1))


def _grey(v: np.ndarray) -> np.ndarray:
    return np.repeat(np.asarray(v, np.float64)[..., None], 3, axis=-1)


class _Canvas:
    """One matplotlib figure reused for every video frame: a title line and one labelled panel per image."""

    def __init__(self, n_panels: int, H: int, W: int, title: str, panel_px: int = TARGET_PANEL_PX):
        import matplotlib  # deferred: heavy, and only previews draw

        matplotlib.use("Agg")
        from matplotlib.figure import Figure  # deferred: as above
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # deferred: as above

        self.scale = max(1, int(panel_px // max(W, H)))
        cols = min(n_panels, 3)
        rows = -(-n_panels // cols)
        dpi = 100
        panel_w, panel_h = W * self.scale / dpi, H * self.scale / dpi
        # even pixel sizes: H.264 in yuv420p needs them
        fig_w = math.ceil(cols * (panel_w + 0.2) * dpi / 2) * 2 / dpi
        fig_h = math.ceil((rows * (panel_h + 0.35) + 0.45) * dpi / 2) * 2 / dpi
        self.fig = Figure(figsize=(fig_w, fig_h), dpi=dpi, facecolor="black")
        self.canvas = FigureCanvasAgg(self.fig)
        self.title = self.fig.suptitle(title, color="white", fontsize=9, y=1 - 0.12 / fig_h)
        self.axes, self.artists, self.labels = [], [], []
        top = 1 - 0.45 / fig_h
        cell_h = (top - 0.02) / rows
        for k in range(n_panels):
            r, c = divmod(k, cols)
            ax = self.fig.add_axes((c / cols + 0.05 / fig_w, top - (r + 1) * cell_h + 0.02 / fig_h,
                                    1 / cols - 0.1 / fig_w, cell_h - 0.3 / fig_h))
            ax.set_axis_off()
            self.artists.append(ax.imshow(np.zeros((H, W, 3)), interpolation="nearest", vmin=0, vmax=1))
            self.labels.append(ax.set_title("", color="white", fontsize=7))
            self.axes.append(ax)

    def draw(self, title: str, labels: list[str], images: list[np.ndarray]) -> np.ndarray:
        self.title.set_text(title)
        for artist, label, text, img in zip(self.artists, self.labels, labels, images):
            artist.set_data(np.clip(img, 0.0, 1.0))
            label.set_text(text)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def boxes(self) -> list[tuple[float, float, float, float]]:
        """Each panel's image as ``(x0, y0, x1, y1)`` pixels of a video frame (row 0 at the top)."""
        height = self.canvas.get_width_height()[1]
        out = []
        for artist in self.artists:
            b = artist.get_window_extent(self.canvas.get_renderer())
            out.append((float(b.x0), height - float(b.y1), float(b.x1), height - float(b.y0)))
        return out


def _span(rec, settings: PreviewSettings) -> tuple[float, float]:
    """The previewed span ``[t0, t1)`` of recording time, s, checked against the recording's."""
    settings.check()
    r0 = float(rec.attrs.get("t_start_s", 0.0))
    r1 = r0 + float(rec.duration_s)
    t0 = r0 if settings.start_s is None else float(settings.start_s)
    t1 = r1 if settings.duration_s is None else t0 + float(settings.duration_s)
    if not (r0 - 1e-9 <= t0 < r1) or t1 > r1 + 1e-9:
        raise SimSpadError(f"span [{t0 * 1e3:g}, {t1 * 1e3:g}] ms is outside the recording's [{r0 * 1e3:g}, "
                           f"{r1 * 1e3:g}] ms", path=rec.path, field="--start/--duration")
    return t0, t1


def iter_preview_frames(rec, settings: PreviewSettings, kind: str = ".mp4",
                        panels: dict | None = None) -> Iterator[tuple[float, np.ndarray]]:
    """``(t, RGB uint8 image)`` of each previewed instant of an open recording (see the module docstring);
    ``panels`` (optional) receives each panel's box in a frame (:class:`PreviewResult`)."""
    t0, t1 = _span(rec, settings)
    times = preview_times(t0, t1, settings, kind)
    sources = _Sources(rec, settings, t0, t1)
    speed = float(rec.attrs.get("speed_factor", 1.0))
    head = f"{rec.scene} · ×{speed:g} · {rec.lux:g} lx"
    canvas = _Canvas(len(sources.panels), sources.H, sources.W, head, int(settings.panel_px))
    for t in times:
        title = f"{head} · t = {t * 1e3:.3f} ms" + ("" if kind == ".png" else f" · {settings.slowdown:g}× slower")
        img = canvas.draw(title, sources.labels(float(t)), sources.images(float(t)))
        if panels is not None and not panels:
            panels.update(zip(sources.panels, canvas.boxes()))
        yield float(t), img


def write_preview(recording, out, settings: PreviewSettings = PreviewSettings(), *,
                  progress: bool = False) -> PreviewResult:
    """Write the preview of ``recording`` to ``out`` (``.mp4``, ``.gif`` or ``.png``: a strip of
    :data:`STRIP_INSTANTS` instants stacked top to bottom), atomically.

    Raises
    ------
    SimSpadError
        An unknown suffix, a bad setting, a span outside the recording, or an unreadable recording.
    """
    import imageio.v2 as imageio  # deferred: only previews encode images
    from tqdm import tqdm  # deferred: as above

    out = Path(out)
    kind = out.suffix.lower()
    if kind not in PREVIEW_SUFFIXES:
        raise SimSpadError(f"unknown preview kind {out.suffix or '(no suffix)'!r} (expected "
                           f"{', '.join(PREVIEW_SUFFIXES)})", path=out, field="--out")
    check_output_file(out)
    with open_recording(recording) as rec:
        boxes: dict = {}
        no_panel = sensors_without_panel(rec)
        n_expected = None if kind == ".png" else int(preview_times(*_span(rec, settings), settings, kind).size)
        frames = iter_preview_frames(rec, settings, kind, boxes)
        shown, size = [], (0, 0)
        with atomic_path(out) as tmp:
            tmp = Path(tmp)
            if kind == ".png":
                images = []
                for t, img in frames:
                    shown.append(t)
                    images.append(img)
                strip = np.concatenate(images, axis=0)
                imageio.imwrite(tmp, strip, format="PNG")
                size = strip.shape[1], strip.shape[0]
            else:
                options = ({"format": "FFMPEG", "fps": settings.fps, "codec": "libx264", "quality": 8,
                            "macro_block_size": 2, "output_params": ["-pix_fmt", "yuv420p", "-f", "mp4"]} if kind == ".mp4"
                           else {"format": "GIF", "duration": 1.0 / settings.fps, "loop": 0})
                # the encoders choose the container by the name's suffix, which the temporary name lacks
                named = tmp.with_name(tmp.name + kind)
                try:
                    with imageio.get_writer(named, **options) as writer:
                        for t, img in tqdm(frames, desc="preview", unit="frame", disable=not progress,
                                           total=n_expected):
                            writer.append_data(img)
                            shown.append(t)
                            size = img.shape[1], img.shape[0]
                    os.replace(named, tmp)
                finally:
                    named.unlink(missing_ok=True)
    return PreviewResult(out, len(shown) if kind != ".png" else 1, size[0], size[1], np.asarray(shown), boxes,
                         no_panel)


#: A leaderboard strip's preview: the first few milliseconds, slowed so that a GIF of a dozen frames shows them.
SHORT_PREVIEW_S = 0.004
SHORT_PREVIEW_SLOWDOWN = 250.0
SHORT_PREVIEW_FPS = 10.0
#: Its panels' size (px): small enough that a board embeds one GIF per strip (≈ 0.1 MB each on the mini).
SHORT_PREVIEW_PANEL_PX = 160


def write_short_preview(recording, out) -> PreviewResult:
    """A short GIF of ``recording`` for the leaderboard: its first :data:`SHORT_PREVIEW_S` s (all of a shorter
    one), :data:`SHORT_PREVIEW_SLOWDOWN` times slower at :data:`SHORT_PREVIEW_FPS` frames per second."""
    with open_recording(recording) as rec:
        duration = min(SHORT_PREVIEW_S, float(rec.duration_s))
    settings = PreviewSettings(duration_s=duration, slowdown=SHORT_PREVIEW_SLOWDOWN, fps=SHORT_PREVIEW_FPS,
                               panel_px=SHORT_PREVIEW_PANEL_PX)
    return write_preview(recording, out, settings)


__all__ = ["PreviewSettings", "PreviewResult", "write_preview", "write_short_preview", "iter_preview_frames",
           "preview_times"]
