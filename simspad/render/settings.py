"""What a render is asked for: its time span, image size, sampling, keyframe-schedule limits and seed.

:class:`RenderSettings` is the one record :func:`simspad.render.renderer.render_sequence` takes for them;
:meth:`RenderSettings.checked_size` validates every field before anything is written.
"""

from __future__ import annotations

import math
import numbers
import os
from dataclasses import dataclass

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.render.warp_schedule import WARP_STRIDE, WARP_THRESHOLD


#: Keyframe interpolation modes: synthesize between sparse renders by reprojection, or render every keyframe.
INTERPOLATIONS = ("warp", "linear")
#: Default interpolation. "linear" until warp synthesis meets its bar (≥ 8× fewer renders, error no larger, event
#: counts within 2 % of an all-render timeline) on every built-in scene. Measured (benchmarks/bench_warp.py, 16 spp,
#: render counts include the noise probe and the blocks rendered into synthesized keyframes, in whole renders):
#: - 64×48 over 192 ms (whole-keyframe bisection only): piano 12.9×, star 6.4×, fan 4.8×, office 2.8×, plant 2.6×
#:   fewer renders at 0.96–1.05× linear's error.
#: - 128×96 over 96 ms, blocks rendered where the warps disagree as long as they cost ≤ 1 render per segment: office
#:   3.9× (without blocks 1.6×) at 1.02× linear's error, plant 1.6× at 0.98×. With blocks wherever they cost ≤ ¼
#:   render per keyframe (no segment bound) the office reached 4.1× but at 1.09× linear's error, and the fan, star
#:   and office made 9–16 % more events (a block's frozen noise pattern differs from a whole render's, and
#:   switches at each segment's ends).
#: - Events: on camera-motion scenes at 16 spp the all-render timeline's own events are mostly Monte Carlo noise
#:   (under camera motion the fixed-seed noise does not stay frozen: plant 3344 ON at 16 spp, 1744 at 64, 1028 at
#:   256); warp's blend of two renders makes fewer such events (and matched the all-render count within 0.1 % at
#:   256 spp).
#: - Wall time: at these sizes a block's render call costs 0.05–0.15 s beyond its samples (tracing and launching
#:   the integrator), so blocks are costed with it (:data:`simspad.render.blocks.BLOCK_CALL_SAMPLES`); at 512²
#:   and 64 spp, where one office keyframe costs ≈ 60 CPU-s, that is well under 1 %.
#: The office is bounded by its window (a textured emitter 40× brighter than the room, behind thin mullions):
#: 99.5 % of a warp's squared error, above the noise test even between neighbouring keyframes. At 512×512 (office,
#: 24 ms) warp renders 2.1× fewer keyframes at 1.007× linear's error but makes +30 % ON / +26 % OFF events: the
#: frozen noise it moves with the content (docs/rendering.md, with what was tried against it). Opt in with
#: ``--interpolation warp`` (``interpolation = "warp"`` in a dataset spec).
DEFAULT_INTERPOLATION = "linear"


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
        where the warps disagree (:mod:`simspad.render.warp_schedule`); ``"linear"``: render every keyframe.
        Both give the same keyframe instants; the timeline is linear in time between keyframes either way.
    warp_stride : int
        With ``"warp"``: rendered keyframes are at most this many keyframes apart.
    warp_threshold : float
        With ``"warp"``: a synthesized keyframe whose two warps disagree by more than this many times a render's
        Monte Carlo noise (relative RMS of their luminance + hole fraction) makes the renderer render the
        keyframes between for real.
    warp_emission : bool
        With ``"warp"``: warp only reflected light and render each keyframe's directly visible emission (a
        depth-1 pass, about a fifteenth of a render), when the scene's integrator allows the split
        (:attr:`simspad.render.mitsuba_scene.MitsubaScene.splits_emission`).
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

    def checked_size(self) -> tuple[int, int]:
        """Check every field; return (width, height) in pixels.

        Raises
        ------
        SimSpadError
            The first bad field, named.
        """
        duration_s, start_s, resolution, spp = self.duration_s, self.start_s, self.resolution, self.spp
        max_flow_px, min_rate_hz, seed = self.max_flow_px, self.min_rate_hz, self.seed

        def bad(field_name, message):
            raise SimSpadError(message, field=field_name)

        if not (isinstance(duration_s, numbers.Real) and math.isfinite(duration_s) and duration_s > 0):
            bad("duration", f"must be a number of seconds > 0, got {duration_s!r}")
        if not (isinstance(start_s, numbers.Real) and math.isfinite(start_s)):
            bad("start", f"must be a finite number of seconds, got {start_s!r}")
        try:
            width, height = (int(v) for v in resolution)
        except (TypeError, ValueError):
            bad("resolution", f"expected (width, height), got {resolution!r}")
        if width <= 0 or height <= 0:
            bad("resolution", f"width and height must be positive, got {resolution!r}")
        if not (isinstance(spp, numbers.Integral) and spp >= 1):
            bad("spp", f"must be an integer >= 1, got {spp!r}")
        if not (max_flow_px > 0):
            bad("max_flow_px", f"must be > 0 pixels, got {max_flow_px!r}")
        if not (min_rate_hz > 0 and math.isfinite(min_rate_hz)):
            bad("min_rate_hz", f"must be a finite number of Hz > 0, got {min_rate_hz!r}")
        if not isinstance(seed, numbers.Integral) or not 0 <= seed < 2**64:
            bad("seed", f"must be an integer in [0, 2**64), got {seed!r}")
        for field_name, message in render_limit_problems(width, height, spp, max_flow_px, min_rate_hz, duration_s):
            bad(field_name, message)
        if self.interpolation not in INTERPOLATIONS:
            bad("interpolation", f"must be one of {', '.join(INTERPOLATIONS)}, got {self.interpolation!r}")
        if not (isinstance(self.warp_stride, numbers.Integral) and self.warp_stride >= 1):
            bad("warp_stride", f"must be an integer >= 1, got {self.warp_stride!r}")
        if not (isinstance(self.warp_threshold, numbers.Real) and self.warp_threshold >= 0):
            bad("warp_threshold", f"must be a number >= 0, got {self.warp_threshold!r}")
        if not isinstance(self.warp_emission, bool):
            bad("warp_emission", f"must be true or false, got {self.warp_emission!r}")
        return width, height


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
