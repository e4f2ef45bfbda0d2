"""``simspad score``: score an external method's reconstructions (an HDF5 submission) against a dataset.

The submission layout is documented in ``docs/submission.md`` and checked by :mod:`simspad.io.submission`.
Everything is validated before any scoring: here, that every group names one complete recording of the dataset
(by key, relative path or relative path without ``.h5``), once, and holds that recording's evaluation instants.

Scoring follows the same protocol as ``simspad evaluate`` (:func:`simspad.evaluate.protocol.score_frames`), and
the output is a results directory that ``simspad leaderboard`` reads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simspad.errors import InputError
from simspad.evaluate.protocol import (
    DEFAULT_RATE_HZ,
    ScoringRun,
    evaluation_indices,
    gt_white_point,
    protocol_metadata,
    score_frames,
    star_figures,
)
from simspad.evaluate.recordings import RecordingEntry, fill_entry, list_recordings, spec_evaluation
from simspad.io.output_dirs import owned_output_dir
from simspad.io.recording import open_recording
from simspad.io.results_dir import ResultRow, check_output_dir, legacy_results, write_images, write_results_dir
from simspad.io.submission import (
    check_group_frames,
    check_group_members,
    open_submission,
    read_attrs,
    recording_groups,
)


def _validate_group(group, name: str, entry: RecordingEntry, rate_hz: float, path: Path) -> np.ndarray:
    """Check one recording group against its recording; return the ground-truth evaluation indices."""
    check_group_members(group, name, path)
    with open_recording(entry.path) as rec:
        idx = evaluation_indices(rec.gt.t, rate_hz)
        gt_t = rec.gt.t[idx]
        H, W = rec.height, rec.width
    check_group_frames(group, name, gt_t, (H, W), entry.rel, path)
    return idx


def _match_keys(entries: list[RecordingEntry]) -> dict[str, RecordingEntry]:
    keys: dict[str, RecordingEntry] = {}
    for e in entries:
        for k in (e.key, e.rel, e.rel[:-3] if e.rel.endswith(".h5") else e.rel):
            keys[k.strip("/")] = e
    return keys


def read_submission(submission: Path, entries: list[RecordingEntry], rate_hz: float):
    """Validate the submission; return (attrs, [(group name, entry, eval indices)], h5 file open for reading)."""
    submission = Path(submission)
    h5 = open_submission(submission)
    try:
        attrs = read_attrs(h5, submission)
        keys = _match_keys(entries)
        parts = []
        seen: dict[str, str] = {}
        for name, group in sorted(recording_groups(h5, submission).items()):
            entry = keys.get(name)
            if entry is None:
                known = ", ".join(sorted(e.key for e in entries)[:8])
                raise InputError(f"unknown recording (not a complete recording of the dataset; known: {known})",
                                 path=submission, field=f"/{name}")
            if entry.rel in seen:
                raise InputError(f"recording {entry.rel} given twice (also as /{seen[entry.rel]})",
                                 path=submission, field=f"/{name}")
            seen[entry.rel] = name
            parts.append((name, entry, _validate_group(group, name, entry, rate_hz, submission)))
    except BaseException:
        h5.close()
        raise
    order = {e.rel: i for i, e in enumerate(entries)}
    parts.sort(key=lambda p: order[p[1].rel])
    return attrs, parts, h5


def score(submission, dataset_dir, out_dir=None, rate_hz=None) -> tuple[Path, list[dict]]:
    """Score a submission against the dataset; write a results directory (default ``<submission>_results``).

    Returns
    -------
    (out_dir, rows) — rows as in ``results.csv`` (:meth:`~simspad.io.results_dir.ResultRow.to_dict`).
    """
    submission = Path(submission)
    dataset_dir = Path(dataset_dir)
    entries, manifest = list_recordings(dataset_dir)
    entries = [fill_entry(e) for e in entries]
    if rate_hz is None:
        ev = spec_evaluation(manifest, entries[0])
        rate_hz = float(ev.get("rate_hz", DEFAULT_RATE_HZ) or DEFAULT_RATE_HZ)
    out_dir = Path(out_dir) if out_dir is not None else submission.with_name(submission.stem + "_results")
    check_output_dir(out_dir, "score")
    attrs, parts, h5 = read_submission(submission, entries, rate_hz)
    rows, frame_rows, mtf_rows = [], [], []
    try:
        with owned_output_dir(out_dir, "score", legacy=legacy_results("score")) as tmp:
            for name, e, idx in parts:
                with open_recording(e.path) as rec:
                    white = gt_white_point(rec, idx)
                    ds = h5[name]["flux"]
                    run = ScoringRun(method=attrs["method"], recording=e.rel, scene=e.scene, white=white,
                                     absolute_scale=attrs["absolute_scale"], image_frame=idx.size // 2)
                    res = score_frames(rec, idx, (ds[i] for i in range(ds.shape[0])), run)
                row = ResultRow.for_recording(
                    attrs["method"], e, label=attrs["label"], sensors=attrs["sensors"], psnr_db=res["psnr_db"],
                    ssim=res["ssim"], bandwidth_khz_per_pixel=attrs["bandwidth_khz_per_pixel"],
                    bandwidth_bits_per_pixel_s=attrs["bandwidth_bits_per_pixel_s"],
                    absolute_scale=attrs["absolute_scale"], n_frames=res["n_frames"], white_point_ph_s_m2=white)
                if res["mtf"] is not None:
                    row.update(**star_figures(res["mtf"]))
                    mtf_rows.extend({"method": attrs["method"], "recording": e.rel, "freq_cyc_px": float(a),
                                     "mtf": float(b)} for a, b in zip(*res["mtf"]))
                if res["images"] is not None:
                    row.image = write_images(tmp, e.key, attrs["method"], res["images"])
                rows.append(row)
                frame_rows.extend(res["frame_rows"])
            missing = [e.rel for e in entries if e.rel not in {p[1].rel for p in parts}]
            meta = {"submission": str(submission), "target": str(dataset_dir),
                    "rate_hz": rate_hz, "methods": [attrs["method"]], "submission_attrs": attrs,
                    "recordings": [e.summary() for _, e, _ in parts],
                    "missing_recordings": missing, "protocol": protocol_metadata(),
                    "dataset": {k: (manifest or {}).get(k) for k in ("name", "spec_hash", "seed")}}
            write_results_dir(tmp, "score", rows, frame_rows, mtf_rows, meta)
    finally:
        h5.close()
    return out_dir, [r.to_dict() for r in rows]
