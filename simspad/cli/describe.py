"""``simspad info`` for recordings and datasets: what is inside, how big, how fast the data streams.

Each sensor group of a recording is described by its row of the sensor table (:mod:`simspad.sensors.registry`):
its ``describe`` gives a headline and detail lines (bandwidths as in docs/methods.md: a SPAD pixel reads out 1 bit
per binary frame, a conventional frame ``bit_depth`` bits per pixel per frame, an event 32 bits), its
``describe_attrs`` the parameters shown; this module adds the group's size on disk.
"""

from __future__ import annotations

import json
import math

from pathlib import Path

from simspad.cli.text import format_bytes, format_duration_s, recording_table
from simspad.io.manifest import read_manifest, recording_mismatch
from simspad.io.recording import open_recording
from simspad.sensors.registry import SENSORS


def _group_bytes(h5, group: str) -> int:
    """Bytes stored on disk by the datasets of ``group``."""
    total = 0

    def visit(_name, obj):
        nonlocal total
        if hasattr(obj, "id") and hasattr(obj.id, "get_storage_size"):
            total += obj.id.get_storage_size()

    h5[group].visititems(visit)
    return total


def _attr_line(attrs: dict, keys: tuple[str, ...]) -> str:
    parts = []
    for k in keys:
        if k in attrs:
            v = attrs[k]
            if k.endswith("_s"):
                v = format_duration_s(v)
            elif isinstance(v, float):
                v = f"{v:.4g}"
            parts.append(f"{k}={v}")
    return ", ".join(parts)


def describe_recording(path) -> str:
    """Summary of a recording: scene, lux, grid, sensors with their parameters, sizes, event rates and the
    readout bandwidth of each sensor (kHz and bits per pixel per second).

    Raises
    ------
    InputError
        A missing, corrupt or foreign file (from :func:`simspad.io.recording.open_recording`).
    """
    path = Path(path)
    with open_recording(path) as rec:
        a = rec.attrs
        W, H, dur = rec.width, rec.height, rec.duration_s
        lines = [f"recording {path}",
                 f"  size        {format_bytes(path.stat().st_size)}",
                 f"  sequence    {rec.sequence} (scene {rec.scene}, trajectory {a.get('trajectory', '-')})",
                 f"  speed       ×{float(a.get('speed_factor', 1.0)):g} (trajectory played this many times faster)",
                 f"  lux         {rec.lux:g}",
                 f"  grid        {W}×{H} px, {dur * 1e3:.4g} ms",
                 f"  seed        {a.get('seed', '-')}, created {a.get('created_utc', '-')}",
                 f"  software    simspad {a.get('simspad_version', '-')}"]
        if a.get("recording_hash"):
            lines.append(f"  hash        {str(a['recording_hash'])[:16]}")
        if "image_speed_px_s_p50" in a:
            lines.append(f"  motion      {_motion_text(a)}")
        if "render_noise_relative" in a:
            lines.append(f"  noise       {_render_noise_text(a)}")
        if "render_convergence" in a:
            lines.append(f"  radiance    {_convergence_text(a['render_convergence'])}")
        if rec.has("gt"):
            t = rec.gt.t
            rate = (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else float("nan")
            lines.append(f"  gt          {len(t)} sharp frames at {rate:.4g} Hz, {format_bytes(_group_bytes(rec.h5, 'gt'))}"
                         + (", depth" if "gt/depth" in rec.h5 else ""))
            if rec.gt.has_geometry:
                cam = rec.gt.camera or {}
                moving = rec.gt.object_names
                lines.append(f"  geometry    {len(rec.gt.instance_names) - 1} instances, flow + validity + velocity, "
                             f"pinhole f = {float(cam.get('focal_px', float('nan'))):.4g} px "
                             f"(x fov {float(cam.get('x_fov_deg', float('nan'))):.4g}°)"
                             + (f", moving: {', '.join(moving)}" if moving else ""))
        lines.append("  sensors")
        for kind in rec.sensors:
            lines += _sensor_lines(rec, kind)
        if not rec.sensors:
            lines.append("    (none)")
    return "\n".join(lines)


def _sensor_lines(rec, kind: str) -> list[str]:
    """The lines of sensor group ``kind``: its row's headline with the group's size on disk, its parameters, its
    detail lines (a kind without a row in this process: its size and attributes alone)."""
    row = SENSORS.get(kind)
    attrs = rec.view(kind).attrs
    headline, details = row.describe(rec) if row else ("(no sensor-table row in this installation)", [])
    keys = row.describe_attrs if row else tuple(attrs)
    return [f"    {kind:<9} {headline}, {format_bytes(_group_bytes(rec.h5, kind))}",
            f"              {_attr_line(attrs, keys)}",
            *(f"              {line}" for line in details)]


def _convergence_text(text) -> str:
    """A converged render's mode and knobs (the ``render_convergence`` attribute, docs/format.md) in one line."""
    try:
        c = json.loads(text)
    except (TypeError, ValueError):
        return f"converged, unreadable settings {str(text)[:60]!r}"
    if not isinstance(c, dict):
        return f"converged, unreadable settings {str(text)[:60]!r}"
    return (f"convergence {c.get('mode', '?')}: {c.get('cache_samples', '?')} irradiance estimates per cache point, "
            f"{c.get('cache_probes', '?')} probe views, cells of {c.get('cache_cell_px', '?')} px"
            + (f" of a {c['cache_width_px']}-px probe grid" if "cache_width_px" in c else ""))


def _render_noise_text(a) -> str:
    """The recording's render-noise budget (docs/format.md section 3) in one line."""
    relative = float(a["render_noise_relative"])
    fraction = float(a.get("render_noise_spurious_event_fraction", float("nan")))
    if not math.isfinite(relative):
        return "render noise not measured (the render has no noise probe)"
    split = ""
    try:
        doc = json.loads(a.get("render_noise", "null"))
    except (TypeError, ValueError):
        doc = None
    if isinstance(doc, dict) and "cache_relative_noise_median" in doc:  # a converged render: two kinds of noise
        try:
            split = (f": {float(doc['keyframe_relative_noise_median']):.1%} changing between keyframes, "
                     f"{float(doc['cache_relative_noise_median']):.1%} the cache's, fixed to the surfaces")
        except (KeyError, TypeError, ValueError):
            split = ""
    what = "the keyframes' " if split else "that "
    return (f"render {relative:.1%} per pixel (median error of one keyframe's luminance{split}); drawing {what}noise "
            f"anew fires {fraction:.1%} of pixels (a noise-free event sensor at this lux)")


def _motion_text(a) -> str:
    """The measured motion attributes of a recording (or its manifest entry) in one line."""
    text = (f"speed ×{float(a.get('speed_factor', 1.0)):g}: image speed p50 {float(a['image_speed_px_s_p50']):.4g} "
            f"px/s, p95 {float(a['image_speed_px_s_p95']):.4g} px/s")
    if "frame_blur_px_p95" in a:
        text += (f"; blur p95 {float(a['frame_blur_px_p95']):.4g} px in one "
                 f"{format_duration_s(float(a.get('frame_blur_exposure_s', float('nan'))))} frame")
    return text


#: ``simspad info DATASET`` hashes the complete recordings up to this many bytes in all (about 10 s per 10 GB).
_VERIFY_MAX_BYTES = 20 * 2**30


def _verification_lines(path: Path, recs: list[dict], corrupt: list | None = None) -> list[str]:
    """Whether the complete recordings' bytes still match the manifest's sha256 (or that the check was skipped);
    the mismatches, (path, why), are appended to ``corrupt`` when given."""
    complete = [e for e in recs if e["status"] == "complete"]
    total = sum(e.get("size") or 0 for e in complete)
    if not complete:
        return []
    if total > _VERIFY_MAX_BYTES:
        return [f"  verified    no: {format_bytes(total)} to hash (simspad evaluate verifies each recording it reads)"]
    bad = [(e["path"], why) for e in complete if (why := recording_mismatch(path, e))]
    lines = [f"  verified    {len(complete) - len(bad)} of {len(complete)} complete recordings match their sha256"]
    lines += [f"  CORRUPT     {rel}: {why}" for rel, why in bad]
    if corrupt is not None:
        corrupt.extend(bad)
    return lines


def describe_dataset(path, corrupt: list | None = None) -> str:
    """Summary of a dataset directory: spec, and every recording's status, size and timings; the recordings
    whose bytes no longer match the manifest's sha256 are appended to ``corrupt`` as (path, why) when given.

    Raises
    ------
    InputError
        No manifest, or a manifest that is not a SimSPAD dataset's.
    """
    path = Path(path)
    m = read_manifest(path)
    recs = m["recordings"]
    by_status = {s: sum(e["status"] == s for e in recs) for s in ("complete", "pending", "failed")}
    total = sum(e.get("size") or 0 for e in recs)
    spec = m.get("spec") or {}
    lines = [f"dataset {path}",
             f"  name        {m.get('name')} (spec hash {str(m.get('spec_hash', ''))[:16]}, seed {m.get('seed')})",
             f"  created     {m.get('created_utc')}, updated {m.get('updated_utc', '-')}",
             f"  lux         {', '.join(f'{x:g}' for x in spec.get('lux', []))}",
             f"  speed       {', '.join(f'×{x:g}' for x in spec.get('speed', [1.0]))}",
             f"  sensors     {', '.join(spec.get('sensors', {})) or '-'}",
             f"  recordings  {len(recs)}: {by_status['complete']} complete, {by_status['pending']} pending, "
             f"{by_status['failed']} failed; {format_bytes(total)}"]
    lines += ["    " + line for line in recording_table(recs, "path", lambda e: e["path"])]
    lines += _verification_lines(path, recs, corrupt)
    for e in recs:
        if e["status"] == "failed" and e.get("error"):
            lines.append(f"  failed {e['path']}: {e['error']}")
    measured = [e for e in recs if e.get("motion")]
    if measured:
        lines.append("  motion      measured on the renders (image speed over pixels and time)")
        lines += [f"    {e['path']}: {_motion_text(e['motion'])}" for e in measured]
    renders = m.get("renders", [])
    if renders:
        lines.append(f"  renders     {len(renders)}")
        for r in renders:
            t = (r.get("timings") or {}).get("render_s")
            lines.append(f"    {r.get('path')}: {r.get('status')}, {r.get('n_keyframes') or '-'} keyframes"
                         + ("" if t is None else f", {t:.1f} s"))
    return "\n".join(lines)


__all__ = ["describe_recording", "describe_dataset"]
