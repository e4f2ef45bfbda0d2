"""``simspad score``: score an external method's reconstructions (an HDF5 submission) against a dataset.

The submission layout is documented in ``docs/submission.md``. Everything is validated before any scoring,
and each problem is reported as one :class:`~simspad.errors.InputError` naming the submission file and the
field (an attribute as ``/.name``, a dataset as ``/group/name``). The file is opened with h5py and only numeric
datasets and scalar/string attributes are read: nothing is executed, evaluated or unpickled.

Scoring follows the same protocol as ``simspad evaluate`` (:func:`simspad.evaluate.evaluate.score_frames`), and
the output is a results directory that ``simspad leaderboard`` reads.
"""

from __future__ import annotations

import math
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from simspad import __version__
from simspad.errors import InputError
from simspad.evaluate import metrics
from simspad.evaluate.evaluate import (
    DEFAULT_RATE_HZ,
    RecordingEntry,
    _gt_white_point,
    _spec_evaluation,
    evaluation_indices,
    fill_entry,
    list_recordings,
    protocol_metadata,
    score_frames,
    write_images,
)
from simspad.io.atomic import atomic_path
from simspad.io.results_dir import check_output_dir, write_results_dir

FORMAT = "simspad-submission"
FORMAT_VERSION = 1
REQUIRED_ATTRS = {
    "method": "str", "label": "str", "sensors": "str", "absolute_scale": "bool",
    "bandwidth_khz_per_pixel": "float", "bandwidth_bits_per_pixel_s": "float",
}
TIME_ATOL_S = 1e-7


def _attr(h5, name: str, kind: str, path: Path):
    field = f"/.{name}"
    if name not in h5.attrs:
        raise InputError("required attribute missing", path=path, field=field)
    try:
        v = h5.attrs[name]
    except Exception:  # unreadable attribute type (references, opaque, ...)
        raise InputError("attribute of an unsupported type", path=path, field=field) from None
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray):
        if v.shape not in ((), (1,)):
            raise InputError(f"expected a scalar, got an array of shape {v.shape}", path=path, field=field)
        v = v.reshape(-1)[0]
    if isinstance(v, np.generic):
        v = v.item()
    if kind == "str":
        if not isinstance(v, str) or not v.strip():
            raise InputError(f"expected a non-empty string, got {v!r}", path=path, field=field)
        return v
    if kind == "bool":
        if isinstance(v, bool) or (isinstance(v, int) and v in (0, 1)):
            return bool(v)
        if isinstance(v, str) and v.lower() in ("true", "false"):
            return v.lower() == "true"
        raise InputError(f"expected a boolean (true/false or 1/0), got {v!r}", path=path, field=field)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(f"expected a number, got {v!r}", path=path, field=field)
    if not math.isfinite(v) or v < 0:
        raise InputError(f"expected a finite number ≥ 0, got {v!r}", path=path, field=field)
    return float(v)


def _recording_groups(h5, path: Path) -> dict[str, object]:
    """Groups holding the per-recording datasets, by name (without the leading '/')."""
    import h5py

    groups: dict[str, object] = {}
    problems: list[tuple[str, str]] = []

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            parent = name.rsplit("/", 1)[0] if "/" in name else ""
            if not parent:
                problems.append((f"/{name}", "datasets must sit inside one group per recording"))
            else:
                groups[parent] = obj.parent
        elif not isinstance(obj, h5py.Group):
            problems.append((f"/{name}", "unsupported HDF5 object"))

    h5.visititems(visit)
    if problems:
        field, msg = problems[0]
        raise InputError(msg, path=path, field=field)
    if not groups:
        raise InputError("no recording groups (expected one group per recording holding t and flux)", path=path)
    return groups


def _numeric(ds, field: str, path: Path, kind: str):
    if ds.dtype.kind not in "fiu" or ds.dtype.names is not None or ds.dtype.subdtype is not None:
        raise InputError(f"dtype {ds.dtype} is not numeric", path=path, field=field)
    if ds.dtype != np.dtype(kind):
        raise InputError(f"dtype {ds.dtype}, expected {kind}", path=path, field=field)


def _validate_group(group, name: str, entry: RecordingEntry, rate_hz: float, path: Path) -> np.ndarray:
    """Check one recording group against its recording; return the ground-truth evaluation indices."""
    import h5py

    from simspad.io.recording import open_recording

    for member in group:
        if member not in ("t", "flux"):
            raise InputError("unexpected member (a recording group holds only t and flux)", path=path,
                             field=f"/{name}/{member}")
    for member in ("t", "flux"):
        if member not in group or not isinstance(group[member], h5py.Dataset):
            raise InputError("dataset missing", path=path, field=f"/{name}/{member}")
    t_ds, f_ds = group["t"], group["flux"]
    _numeric(t_ds, f"/{name}/t", path, "float64")
    _numeric(f_ds, f"/{name}/flux", path, "float32")
    with open_recording(entry.path) as rec:
        idx = evaluation_indices(rec.gt.t, rate_hz)
        gt_t = rec.gt.t[idx]
        H, W = rec.height, rec.width
    if t_ds.ndim != 1:
        raise InputError(f"shape {t_ds.shape}, expected [N] with N = {gt_t.size}", path=path, field=f"/{name}/t")
    if t_ds.shape[0] != gt_t.size:
        raise InputError(f"{t_ds.shape[0]} instants, expected the {gt_t.size} ground-truth evaluation instants "
                         f"of {entry.rel}", path=path, field=f"/{name}/t")
    t = t_ds[()]
    if not np.all(np.isfinite(t)):
        raise InputError("timestamps hold NaN or inf", path=path, field=f"/{name}/t")
    bad = np.nonzero(np.abs(t - gt_t) > TIME_ATOL_S)[0]
    if bad.size:
        i = int(bad[0])
        raise InputError(f"timestamps do not match the ground-truth instants (t[{i}] = {float(t[i])!r} s, expected "
                         f"{float(gt_t[i])!r} s; {bad.size} differ by more than {TIME_ATOL_S:g} s)",
                         path=path, field=f"/{name}/t")
    if f_ds.shape != (gt_t.size, H, W):
        raise InputError(f"shape {f_ds.shape}, expected {(gt_t.size, H, W)} (N instants × height × width)",
                         path=path, field=f"/{name}/flux")
    for i in range(0, gt_t.size, 8):
        block = f_ds[i:i + 8]
        if not np.all(np.isfinite(block)):
            j = i + int(np.nonzero(~np.isfinite(block).reshape(block.shape[0], -1).all(axis=1))[0][0])
            raise InputError(f"frame {j} holds NaN or inf values", path=path, field=f"/{name}/flux")
        if np.any(block < 0):
            j = i + int(np.nonzero((block < 0).reshape(block.shape[0], -1).any(axis=1))[0][0])
            raise InputError(f"frame {j} holds negative values (photon irradiance is ≥ 0)", path=path,
                             field=f"/{name}/flux")
    return idx


def _match_keys(entries: list[RecordingEntry]) -> dict[str, RecordingEntry]:
    keys: dict[str, RecordingEntry] = {}
    for e in entries:
        for k in (e.key, e.rel, e.rel[:-3] if e.rel.endswith(".h5") else e.rel):
            keys[k.strip("/")] = e
    return keys


def read_submission(submission: Path, entries: list[RecordingEntry], rate_hz: float):
    """Validate the submission; return (attrs, [(group name, entry, eval indices)], h5 file open for reading)."""
    import h5py

    submission = Path(submission)
    if not submission.is_file():
        raise InputError("no such submission file", path=submission)
    try:
        h5 = h5py.File(submission, "r")
    except OSError:
        raise InputError("not a readable HDF5 file (corrupt or truncated?)", path=submission) from None
    try:
        fmt = h5.attrs.get("format")
        fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
        if fmt != FORMAT:
            raise InputError(f"not a SimSPAD submission (format attr is {fmt!r}, expected {FORMAT!r})",
                             path=submission, field="/.format")
        version = h5.attrs.get("format_version", FORMAT_VERSION)
        if isinstance(version, np.generic):
            version = version.item()
        if version != FORMAT_VERSION:
            raise InputError(f"unsupported format_version {version!r} (expected {FORMAT_VERSION})",
                             path=submission, field="/.format_version")
        attrs = {k: _attr(h5, k, kind, submission) for k, kind in REQUIRED_ATTRS.items()}
        keys = _match_keys(entries)
        parts = []
        seen: dict[str, str] = {}
        for name, group in sorted(_recording_groups(h5, submission).items()):
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
    (out_dir, rows)
    """
    from simspad.io.recording import open_recording

    submission = Path(submission)
    dataset_dir = Path(dataset_dir)
    entries, manifest = list_recordings(dataset_dir)
    entries = [fill_entry(e) for e in entries]
    if rate_hz is None:
        ev = _spec_evaluation(manifest, entries[0])
        rate_hz = float(ev.get("rate_hz", DEFAULT_RATE_HZ) or DEFAULT_RATE_HZ)
    out_dir = Path(out_dir) if out_dir is not None else submission.with_name(submission.stem + "_results")
    check_output_dir(out_dir)
    attrs, parts, h5 = read_submission(submission, entries, rate_hz)
    rows, frame_rows, mtf_rows = [], [], []
    try:
        with atomic_path(out_dir) as tmp:
            tmp.mkdir(parents=True)
            for name, e, idx in parts:
                with open_recording(e.path) as rec:
                    white = _gt_white_point(rec, idx)
                    ds = h5[name]["flux"]
                    res = score_frames(rec, idx, (ds[i] for i in range(ds.shape[0])), white=white,
                                       absolute_scale=attrs["absolute_scale"], method=attrs["method"],
                                       recording=e.rel, scene=e.scene, image_frame=idx.size // 2)
                row = {"method": attrs["method"], "label": attrs["label"], "sensors": attrs["sensors"],
                       "scene": e.scene, "sequence": e.sequence, "lux": e.lux, "recording": e.rel,
                       "psnr_db": res["psnr_db"], "ssim": res["ssim"], "mtf50_cyc_px": float("nan"),
                       "bandwidth_khz_per_pixel": attrs["bandwidth_khz_per_pixel"],
                       "bandwidth_bits_per_pixel_s": attrs["bandwidth_bits_per_pixel_s"],
                       "absolute_scale": attrs["absolute_scale"], "n_frames": res["n_frames"],
                       "runtime_s": float("nan"), "white_point_ph_s_m2": white, "image": "", "error": ""}
                if res["mtf"] is not None:
                    row["mtf50_cyc_px"] = metrics.mtf50(*res["mtf"])
                    mtf_rows.extend({"method": attrs["method"], "recording": e.rel, "freq_cyc_px": float(a),
                                     "mtf": float(b)} for a, b in zip(*res["mtf"]))
                if res["images"] is not None:
                    row["image"] = write_images(tmp, e.key, attrs["method"], res["images"])
                rows.append(row)
                frame_rows.extend(res["frame_rows"])
            missing = [e.rel for e in entries if e.rel not in {p[1].rel for p in parts}]
            meta = {"format": "simspad-results", "format_version": 1, "simspad_version": __version__,
                    "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                    "kind": "score", "submission": str(submission), "target": str(dataset_dir),
                    "rate_hz": rate_hz, "methods": [attrs["method"]], "submission_attrs": attrs,
                    "recordings": [{"recording": e.rel, "key": e.key, "sequence": e.sequence, "scene": e.scene,
                                    "lux": e.lux} for _, e, _ in parts],
                    "missing_recordings": missing, "protocol": protocol_metadata()}
            write_results_dir(tmp, rows, frame_rows, mtf_rows, meta)
    finally:
        h5.close()
    return out_dir, rows


def score_from_cli(submission, dataset_dir, out_dir=None) -> Path:
    """The ``simspad score`` command."""
    import click

    from simspad.evaluate.evaluate import summary_table

    out, rows = score(submission, dataset_dir, out_dir)
    click.echo(summary_table(rows))
    import json

    missing = json.loads((out / "results.json").read_text(encoding="utf-8")).get("missing_recordings", [])
    click.echo(f"scored {len(rows)} recording(s)" + (f"; {len(missing)} of the dataset not in the submission"
                                                    if missing else "") + f"; wrote {out / 'results.csv'}")
    return out
