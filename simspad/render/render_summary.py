"""What a render did: keyframe counts, cache re-use, timing, kernel compilations (``simspad render`` prints it
with :func:`simspad.cli.render.describe_render`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass
class RenderSummary:
    """What a render did.

    Attributes
    ----------
    out_dir : Path
    n_keyframes : int
        Keyframes in the timeline.
    n_rendered, n_reused : int
        Frames rendered now / taken from the cache.
    duration_s, start_s : float
    n_spad_bins : int or None
        Keyframes one render per SPAD bin (``spad_bin_s``) would need; None when no bin was given.
    render_s : float
        Wall time spent rendering frames (both passes), seconds.
    variant : str
    compiled_first_frame, compiled_after_first : int
        Dr.Jit kernels new to this process (compiled, or loaded from the disk cache) while rendering the first
        frame / all later frames; -1 where not applicable (scalar variant).
    max_predicted_flow_px : float
        Largest predicted image motion between consecutive keyframes.
    spad_bin_s : float or None
        The SPAD bin the keyframe count is compared with, seconds.
    frame_times_s : list of float
        Wall time of each rendered keyframe (radiance + depth), seconds.
    n_warped : int
        Keyframes synthesized by reprojection (``interpolation = "warp"``) rather than rendered.
    render_noise : dict or None
        The render-noise budget written to ``timeline.json`` (:func:`simspad.render.renderer.measure_render_noise`).
    probe_s : float or None
        Wall time of the budget's noise probe (one keyframe render), seconds; 0 when it was re-used, None when the
        warp schedule rendered it (inside its own timing).
    """

    out_dir: Path
    n_keyframes: int
    n_rendered: int
    n_reused: int
    duration_s: float
    start_s: float
    n_spad_bins: int | None
    render_s: float
    variant: str
    compiled_first_frame: int = -1
    compiled_after_first: int = -1
    max_predicted_flow_px: float = 0.0
    spad_bin_s: float | None = None
    frame_times_s: list = field(default_factory=list, repr=False)
    n_warped: int = 0
    render_noise: dict | None = None
    probe_s: float | None = None

    @property
    def time_per_frame_s(self) -> float:
        """Median wall time of one rendered keyframe (radiance + depth), seconds; nan if none was rendered."""
        return float(np.median(self.frame_times_s)) if self.frame_times_s else float("nan")

    @property
    def reduction(self) -> float:
        """How many times fewer renders than one per SPAD bin; nan without a SPAD bin to compare with."""
        return float("nan") if self.n_spad_bins is None else self.n_spad_bins / self.n_keyframes
