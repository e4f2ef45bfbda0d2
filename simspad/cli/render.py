"""``simspad render``: render a scene along a trajectory and print what the render did."""

from __future__ import annotations

import re
from pathlib import Path

from simspad.bundled import find_trajectory
from simspad.io.output_dirs import owned_dir_in_place, write_marker
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.render.render_summary import RenderSummary
from simspad.sensors.presets import SpadParams


#: What a render directory written before markers holds: keyframes (and warp renders' noise probe), temporaries.
_RENDER_FILE = re.compile(r"\d{6}-[0-9a-f]{16}\.exr|noise-probe-[0-9a-f]{16}\.exr|\..+\.tmp-\d+-[0-9a-f]{8}")


def _legacy_render_dir(path: Path) -> set[str] | None:
    """Recognise a render directory written before markers: it has ``timeline.json``, or (an interrupted
    render) nothing but ``frames/`` holding keyframe files. The renderer deletes only stale keyframes of its
    own naming, so no file list is needed: an empty set."""
    if (path / "timeline.json").is_file():
        return set()
    names = {p.name for p in path.iterdir()}
    frames = path / "frames"
    if names == {"frames"} and frames.is_dir() and not frames.is_symlink() \
            and all(_RENDER_FILE.fullmatch(p.name) for p in frames.iterdir()):
        return set()
    return None


def render_from_cli(scene, trajectory, *, out_dir, progress: bool, **settings) -> RenderSummary:
    """``simspad render``: :func:`~simspad.render.renderer.render_sequence`, with the keyframe count compared to
    one render per bin of the SPAD preset. ``settings``: the fields of :class:`RenderSettings`, checked by
    the record (:meth:`RenderSettings.checked_size`: the one check of each, as for a dataset's renders). ``trajectory``: a
    file, or a bundled trajectory named as ``simspad scenes`` prints it (``trajectories/office.toml``, ``office``).

    ``out_dir`` must be new, empty or a render directory (marker ``.simspad-render``, or ``timeline.json``), so
    keyframes are never mixed into a dataset or another folder; it is locked while the render writes it.
    """
    out_dir = Path(out_dir)
    render_settings = RenderSettings(**settings)
    render_settings.checked_size()  # the record's own checks (one message per field), before the folder is made
    if trajectory is not None:
        trajectory = find_trajectory(trajectory)
    with owned_dir_in_place(out_dir, "render", legacy=_legacy_render_dir):
        summary = render_sequence(scene, trajectory, render_settings, out_dir=out_dir,
                                  progress=progress, spad_bin_s=SpadParams().bin_s)
        files = {"timeline.json", *(f"frames/{p.name}" for p in (out_dir / "frames").iterdir()
                                    if _RENDER_FILE.fullmatch(p.name) and not p.name.startswith("."))}
        write_marker(out_dir, "render", files)
    return summary


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
