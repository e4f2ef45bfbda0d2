"""``simspad render``: render a scene along a trajectory and print what the render did."""

from __future__ import annotations

from simspad.render.renderer import RenderSettings, render_sequence
from simspad.render.summary import RenderSummary
from simspad.sensors.presets import SpadParams


def render_from_cli(scene, trajectory, *, out_dir, progress: bool, **settings) -> RenderSummary:
    """``simspad render``: :func:`~simspad.render.renderer.render_sequence`, with the keyframe count compared to
    one render per bin of the SPAD preset. ``settings``: the fields of :class:`RenderSettings`."""
    return render_sequence(scene, trajectory, RenderSettings(**settings), out_dir=out_dir, progress=progress,
                           spad_bin_s=SpadParams().bin_s)


def describe_render(summary: RenderSummary) -> str:
    """A few lines for the CLI."""
    per_frame = (f"{summary.time_per_frame_s * 1e3:.1f} ms per frame (median)" if summary.frame_times_s
                 else "no frame rendered")
    comparison = ("" if summary.n_spad_bins is None else
                  f"versus one per {summary.spad_bin_s * 1e6:g} µs SPAD bin: {summary.n_spad_bins} renders -> "
                  f"{summary.reduction:.1f}x fewer; ")
    lines = [
        f"render dir: {summary.out_dir}",
        f"keyframes: {summary.n_keyframes} over {summary.duration_s:g} s from t = {summary.start_s:g} s "
        f"({summary.n_rendered} rendered, {summary.n_reused} re-used from the cache, "
        f"{summary.n_warped} synthesized by reprojection)",
        f"{comparison}largest predicted motion between keyframes {summary.max_predicted_flow_px:.3f} px",
        f"variant: {summary.variant}; {per_frame}; total {summary.render_s:.2f} s",
    ]
    noise = summary.render_noise
    if noise:
        cost = ""
        if summary.probe_s:  # the probe's time against the keyframes' (both wall time in this process)
            cost = f" (its probe: one more keyframe, {summary.probe_s / max(summary.render_s, 1e-9):.1%} of this render)"
        lines.append(f"render noise: one keyframe's luminance is off by {noise['relative_noise_median']:.1%} per "
                     f"pixel (median; RMS {noise['relative_noise_rms']:.1%}); drawing it anew fires "
                     f"{noise['spurious_event_fraction']:.1%} of pixels in a noise-free event sensor at threshold "
                     f"{noise['threshold_log']:g} in bright light{cost}")
    if summary.compiled_first_frame >= 0:
        lines.append(f"kernel compilations: {summary.compiled_first_frame} for the first frame, "
                     f"{summary.compiled_after_first} after it")
    return "\n".join(lines)
