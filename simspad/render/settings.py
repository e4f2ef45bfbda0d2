"""What a render is asked for: its time span, image size, sampling, keyframe-schedule limits and seed.

:class:`RenderSettings` is the one record :func:`simspad.render.renderer.render_sequence` takes for them;
:meth:`RenderSettings.checked_size` validates every field before anything is written.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.render.warp_schedule import WARP_STRIDE, WARP_THRESHOLD


#: Keyframe interpolation modes: synthesize between sparse renders by reprojection, or render every keyframe.
INTERPOLATIONS = ("warp", "linear")


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
    """

    duration_s: float
    start_s: float = 0.0
    resolution: tuple = defaults.RESOLUTION_PX
    spp: int = defaults.SPP
    max_flow_px: float = defaults.MAX_FLOW_PX
    min_rate_hz: float = defaults.MIN_KEYFRAME_RATE_HZ
    seed: int = defaults.SEED
    interpolation: str = "warp"
    warp_stride: int = WARP_STRIDE
    warp_threshold: float = WARP_THRESHOLD

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
        if not (min_rate_hz > 0):
            bad("min_rate_hz", f"must be > 0 Hz, got {min_rate_hz!r}")
        if not isinstance(seed, numbers.Integral) or seed < 0:
            bad("seed", f"must be an integer >= 0, got {seed!r}")
        if self.interpolation not in INTERPOLATIONS:
            bad("interpolation", f"must be one of {', '.join(INTERPOLATIONS)}, got {self.interpolation!r}")
        if not (isinstance(self.warp_stride, numbers.Integral) and self.warp_stride >= 1):
            bad("warp_stride", f"must be an integer >= 1, got {self.warp_stride!r}")
        if not (isinstance(self.warp_threshold, numbers.Real) and self.warp_threshold >= 0):
            bad("warp_threshold", f"must be a number >= 0, got {self.warp_threshold!r}")
        return width, height
