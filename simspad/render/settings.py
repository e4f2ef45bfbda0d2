"""What a render is asked for: its time span, image size, sampling, keyframe-schedule limits and seed.

:class:`RenderSettings` is the one record :func:`simspad.render.renderer.render_sequence` takes for them;
:meth:`RenderSettings.problems` is the one check of each field (a dataset spec's sequences are checked by it too);
:meth:`RenderSettings.checked_size` raises the first problem before anything is written.
"""

from __future__ import annotations

import math
import numbers
import os
from dataclasses import dataclass

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.render.warp.schedule import WARP_STRIDE, WARP_THRESHOLD


#: Keyframe interpolation modes: synthesize between sparse renders by reprojection, or render every keyframe.
INTERPOLATIONS = ("warp", "linear")
#: Default interpolation. "linear" until warp synthesis meets its bar (≥ 8× less render work, error no larger,
#: event counts within 2 % of an all-render timeline) on every built-in scene. Measured at 64 spp, 256×192 over
#: 48 ms (benchmarks/bench_warp.py; render work counts every pass at its measured price, in whole renders): piano
#: 3.6× less at linear's error and events, plant 1.8× (with the emission layer; 1.0× without), office 2.5× but
#: +7.9 % ON / +6.7 % OFF events (2.0× without the layer, events within 2 %), fan 1.6×, Siemens star 1.0× (the
#: warps do not follow their rotation). At 512² the office gets 2.8× at 1.00× linear's error and +11.8 % / +7.4 %
#: events. What keeps warp from the bar: moving noise (a warp carries a rendered keyframe's frozen Monte Carlo
#: noise along with the content, and in the office's noisy room that makes events), fast rotation, and the emission
#: pass each synthesized keyframe pays where an emitter is in view (7 % of an office render, capping it at ≈ 7×);
#: docs/rendering.md has every figure and what was tried. Opt in with ``--interpolation warp``
#: (``interpolation = "warp"`` in a dataset spec).
DEFAULT_INTERPOLATION = "linear"
#: Radiance modes: ``"off"`` path-traces every pixel of a keyframe (the reference); ``"cache"`` converges the
#: diffuse irradiance once per render into a world-space cache and gives each keyframe primary visibility, its
#: glossy/specular chain and a cache lookup (:mod:`simspad.render.converged`): on every built-in scene at 48×36 px,
#: default and ×16 trajectories, 0.7-3.0 % off a 4096-spp pair per pixel (64 camera rays) where 64-spp path
#: tracing is 1.2-17.6 %; the office at 256×256 over 0.2 s at 16 rays in 0.17× the 64-spp schedule's CPU
#: (docs/rendering.md has the tables and what was tried). ``simspad render`` and both bundled specs converge; the
#: record's default stays ``"off"`` so a spec or script that does not ask keeps its pixels and hash. It works with
#: either interpolation: with ``"warp"`` the anchors are converged keyframes and the warps are judged against a
#: converged render's own noise.
CONVERGENCE_MODES = ("off", "cache")
DEFAULT_CONVERGENCE = "off"
#: Default irradiance estimates per cache point (``cache_samples``; ``--cache-samples``, and a dataset spec's) and
#: the finest cell's edge in pixel footprints: the fourth round's choice (docs/rendering.md), office and plant 3.0
#: and 2.9 % off a 4096-spp multi-jittered pair at 64 camera rays (256 estimates in 1-px cells: 4.4 and 4.3 %).
DEFAULT_CACHE_SAMPLES = 1024
DEFAULT_CACHE_CELL_PX = 2.0
#: Width (px) of the grid the cache's probe views are traced on (``cache_width_px``): a wider render traces one
#: probe ray per block of pixels and its cells are as many pixels wider, so the cells keep their size in the scene
#: and the cache's build stops growing with the resolution. At 256×192 on the office (keyframe 0, 4096-spp pair)
#: 2-px cells of a 128-px grid are 2.3-2.6 % off, of a 64-px grid 2.8-3.1 % (docs/rendering.md, fifth round).
DEFAULT_CACHE_WIDTH_PX = 128


@dataclass(frozen=True)
class RenderSettings:
    """Settings of one render.

    Attributes
    ----------
    duration_s, start_s : float
        The rendered span [start_s, start_s + duration_s], seconds.
    resolution : (int, int)
        Width, height in pixels.
    spp : int
        Samples per pixel of the radiance pass.
    max_flow_px : float
        Largest predicted image motion between consecutive keyframes, pixels.
    min_rate_hz : float
        Keyframes are at most ``1 / min_rate_hz`` apart.
    seed : int
        Render seed, the same for every frame (noise frozen in screen space).
    interpolation : str
        ``"warp"``: render sparse keyframes and synthesize those between by reprojection, rendering for real
        where the warps disagree (:mod:`simspad.render.warp.schedule`); ``"linear"``: render every keyframe.
        Both give the same keyframe instants; the timeline is linear in time between keyframes either way.
    warp_stride : int
        With ``"warp"``: rendered keyframes are at most this many keyframes apart.
    warp_threshold : float
        With ``"warp"``: a synthesized keyframe whose two warps disagree by more than this many times a render's
        Monte Carlo noise (relative RMS of their luminance + hole fraction) makes the renderer render the
        keyframes between for real.
    gt_rate_hz : float or None
        Rate of the ground-truth instants (the sensors' evaluation rate, Hz): a geometry pass (depth and instance
        ids at the pixel centres, :mod:`simspad.render.geometry`) is rendered at each, on the grid
        ``start_s + k / gt_rate_hz``; None renders none.
    warp_emission : bool
        With ``"warp"``: warp only reflected light and render the directly visible emission of the keyframes
        next to an emitter in view (a depth-1 pass: 7 % of an office render), when the scene's integrator allows
        the split (:attr:`simspad.render.mitsuba_scene.MitsubaScene.splits_emission`).
    convergence : str
        ``"off"``: every keyframe is path-traced at ``spp``; ``"cache"``: each keyframe traces ``spp`` camera
        rays per pixel through their glossy/specular bounces and takes the diffuse light from an irradiance cache
        converged once per render (:mod:`simspad.render.converged`).
    cache_samples : int
        With ``"cache"``: estimates of the irradiance at each point the cache's probe views find (the cache's
        convergence: its relative noise falls as 1/√(cache_samples · points per cell)).
    cache_cell_px : float
        With ``"cache"``: the cache's finest cell, in pixel footprints at the probe views' median depth.
    cache_probes : int
        With ``"cache"``: probe views, spread evenly over the render's keyframes, that fill the cache.
    cache_width_px : int
        With ``"cache"``: the probe views are traced on a grid about this many pixels wide (one ray per pixel
        at or below it, one per block of round(width / cache_width_px)² pixels above), and ``cache_cell_px``
        counts that grid's pixels.
    """

    duration_s: float
    start_s: float = 0.0
    resolution: tuple = defaults.RESOLUTION_PX
    spp: int = defaults.SPP
    max_flow_px: float = defaults.MAX_FLOW_PX
    min_rate_hz: float = defaults.MIN_KEYFRAME_RATE_HZ
    seed: int = defaults.SEED
    interpolation: str = DEFAULT_INTERPOLATION
    warp_stride: int = WARP_STRIDE
    warp_threshold: float = WARP_THRESHOLD
    warp_emission: bool = True
    gt_rate_hz: float | None = defaults.GT_RATE_HZ
    convergence: str = DEFAULT_CONVERGENCE
    cache_samples: int = DEFAULT_CACHE_SAMPLES
    cache_cell_px: float = DEFAULT_CACHE_CELL_PX
    cache_probes: int = 4
    cache_width_px: int = DEFAULT_CACHE_WIDTH_PX

    def checked_size(self) -> tuple[int, int]:
        """Check every field; return (width, height) in pixels.

        Raises
        ------
        SimSpadError
            The first bad field (:meth:`problems`), named.
        """
        for field_name, message in self.problems():
            raise SimSpadError(message, field=field_name)
        return int(self.resolution[0]), int(self.resolution[1])

    def problems(self) -> list[tuple[str, str]]:
        """(field, message) for every field that breaks its rule, in field order (empty: all fine).

        The one check of each field, whoever sets it: a dataset spec's sequences report all of them at once
        (``duration`` and ``start`` stand for ``duration_s`` and ``start_s``); :meth:`checked_size` raises the
        first. The resource bounds (:func:`render_limit_problems`) are checked once the size fields are valid.
        """
        duration_s, start_s, resolution, spp = self.duration_s, self.start_s, self.resolution, self.spp
        max_flow_px, min_rate_hz, seed = self.max_flow_px, self.min_rate_hz, self.seed
        out: list[tuple[str, str]] = []

        def bad(field_name, message):
            out.append((field_name, message))

        if problem := defaults.duration_problem(duration_s):
            bad("duration", problem)
        if not (_is_real(start_s) and math.isfinite(start_s)):
            bad("start", f"must be a finite number of seconds, got {start_s!r}")
        problem = resolution_problem(resolution)
        if problem:
            bad("resolution", problem)
        if not (isinstance(spp, numbers.Integral) and not isinstance(spp, bool) and spp >= 1):
            bad("spp", f"must be an integer > 0 (samples per pixel), got {spp!r}")
        if not (_is_real(max_flow_px) and max_flow_px > 0):
            bad("max_flow_px", f"must be a number of pixels > 0, got {max_flow_px!r}")
        if not (_is_real(min_rate_hz) and min_rate_hz > 0 and math.isfinite(min_rate_hz)):
            bad("min_rate_hz", f"must be a finite number of Hz > 0, got {min_rate_hz!r}")
        if problem := defaults.seed_problem(seed):
            bad("seed", problem)
        if not out:
            width, height = (int(v) for v in resolution)
            out += render_limit_problems(width, height, spp, max_flow_px, min_rate_hz, duration_s)
        if self.interpolation not in INTERPOLATIONS:
            bad("interpolation", f"must be one of {', '.join(INTERPOLATIONS)}, got {self.interpolation!r}")
        if not (isinstance(self.warp_stride, numbers.Integral) and self.warp_stride >= 1):
            bad("warp_stride", f"must be an integer >= 1, got {self.warp_stride!r}")
        if not (isinstance(self.warp_threshold, numbers.Real) and self.warp_threshold >= 0):
            bad("warp_threshold", f"must be a number >= 0, got {self.warp_threshold!r}")
        if not isinstance(self.warp_emission, bool):
            bad("warp_emission", f"must be true or false, got {self.warp_emission!r}")
        if self.gt_rate_hz is not None and (problem := defaults.gt_rate_problem(self.gt_rate_hz)):
            bad("gt_rate_hz", problem)
        if self.convergence not in CONVERGENCE_MODES:
            bad("convergence", f"must be one of {', '.join(CONVERGENCE_MODES)}, got {self.convergence!r}")
        samples = self.cache_samples
        if not (isinstance(samples, numbers.Integral) and not isinstance(samples, bool) and 1 <= samples <= 65536):
            bad("cache_samples", f"must be an integer in [1, 65536], got {self.cache_samples!r}")
        if not (isinstance(self.cache_cell_px, numbers.Real) and math.isfinite(self.cache_cell_px)
                and 0.25 <= self.cache_cell_px <= 64):
            bad("cache_cell_px", f"must be a number of pixels in [0.25, 64], got {self.cache_cell_px!r}")
        if not (isinstance(self.cache_probes, numbers.Integral) and 1 <= self.cache_probes <= 256):
            bad("cache_probes", f"must be an integer in [1, 256], got {self.cache_probes!r}")
        if not (isinstance(self.cache_width_px, numbers.Integral) and not isinstance(self.cache_width_px, bool)
                and 8 <= self.cache_width_px <= 65536):
            bad("cache_width_px", f"must be an integer number of pixels in [8, 65536], got {self.cache_width_px!r}")
        return out


def _is_real(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def resolution_problem(resolution) -> str | None:
    """What is wrong with an image size, or None: the one rule for a resolution, wherever it is given (a dataset
    spec's ``resolution``, ``simspad render --resolution``, :class:`RenderSettings`).

    Parameters
    ----------
    resolution : sequence
        (width, height) in pixels: two integers > 0.
    """
    try:
        ok = len(resolution) == 2 and all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and v > 0
                                          for v in resolution)
    except TypeError:
        ok = False
    return None if ok else f"got {resolution!r} (expected two positive integers [W, H])"


def limits_ignored() -> bool:
    """True when ``SIMSPAD_IGNORE_LIMITS=1`` lifts the size bounds (resolution, spp, keyframe count)."""
    return os.environ.get("SIMSPAD_IGNORE_LIMITS", "") == "1"


def render_limit_problems(width: int, height: int, spp: int, max_flow_px: float, min_rate_hz: float,
                          duration_s: float) -> list[tuple[str, str]]:
    """(field, message) for every value past the resource bounds of :mod:`simspad.defaults`, with the figure.

    The size bounds are refused with the memory or count they would need; ``SIMSPAD_IGNORE_LIMITS=1`` lifts
    them. ``max_flow_px`` below its floor is refused always (it only multiplies work).
    """
    out = []
    lift = " (set SIMSPAD_IGNORE_LIMITS=1 to try anyway)"
    if not max_flow_px >= defaults.MIN_MAX_FLOW_PX or not math.isfinite(max_flow_px):
        out.append(("max_flow_px", f"must be a finite number ≥ {defaults.MIN_MAX_FLOW_PX} px, got {max_flow_px!r} "
                    "(smaller steps only multiply the keyframes)"))
    if limits_ignored():
        return out
    pixels = width * height
    if pixels > defaults.MAX_RENDER_PIXELS:
        need = pixels * defaults.RENDER_BYTES_PER_PIXEL / 2**30
        out.append(("resolution", f"{width}×{height} = {pixels / 1e6:.1f} Mpx needs about {need:.1f} GiB of memory "
                    f"per render process; the limit is {defaults.MAX_RENDER_PIXELS / 1e6:.1f} Mpx{lift}"))
    if spp > defaults.MAX_SPP:
        out.append(("spp", f"{spp} samples per pixel is above the limit of {defaults.MAX_SPP}{lift}"))
    if duration_s > defaults.MAX_DURATION_S:
        out.append(("duration", f"{duration_s:g} s is above the limit of {defaults.MAX_DURATION_S:g} s (times "
                    f"in µs written as seconds?){lift}"))
    n_min = duration_s * min_rate_hz
    if math.isfinite(n_min) and n_min > defaults.MAX_KEYFRAMES:
        out.append(("min_rate_hz", f"{min_rate_hz:g} Hz over {duration_s:g} s asks for {n_min:.3g} keyframes; the "
                    f"limit is {defaults.MAX_KEYFRAMES:,}{lift}"))
    return out
