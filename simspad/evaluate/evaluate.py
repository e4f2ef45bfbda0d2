"""``simspad evaluate``: run reconstruction methods on recordings and score them (DESIGN §8).

For each recording × method (a *task*):

1. the evaluation instants are the ``/gt/t`` instants that lie on the evaluation grid t₀ + k/rate_hz
   (default 1 kHz, or the dataset spec's ``evaluation.rate_hz``);
2. the white point W is the 99th percentile of ground truth over those instants (read in chunks, exact, once
   per recording);
3. the method reconstructs flux frames at those instants; each frame is scored as it arrives
   (:func:`simspad.evaluate.metrics.frame_scores`: display mapping, log-affine alignment for methods without
   absolute scale, PSNR, SSIM), so memory does not grow with the sequence length;
4. Siemens-star recordings (scene name containing ``siemens``) also get the MTF (mean over frames) and MTF50;
5. the method's bandwidth is read from the reconstruction once it has been iterated.

Tasks run in a process pool of at most 2 workers (``spawn``); rows come out in a deterministic order
(recordings in manifest/sorted order, methods in the requested order) whatever finishes first.

Failure policy: a method that fails on a recording (exception, wrong frame shape, NaN/inf output) does not stop
the run: its row is written with NaN metrics and the message in the ``error`` column, all other tasks complete and
the results directory is written; the command then exits with status 1 (:class:`EvaluationFailed`) so scripts
notice. Bad input (unknown method, unreadable recording, nothing to evaluate) is a :class:`SimSpadError` (exit 2)
before anything is written.
"""

from __future__ import annotations

import json
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from simspad import __version__, defaults
from simspad.errors import SimSpadError
from simspad.evaluate import metrics
from simspad.io.atomic import atomic_path
from simspad.io.results_dir import (
    CROP_PX,
    check_output_dir,
    crop,
    recording_key,
    save_png,
    slug,
    write_results_dir,
)

DEFAULT_RATE_HZ = defaults.GT_RATE_HZ
MAX_WORKERS = 2


class EvaluationFailed(SimSpadError):
    """Some method runs failed; the results (with an ``error`` column) were written. Exit status 1."""

    exit_code = 1


@dataclass
class RecordingEntry:
    """A recording to evaluate: its path and the key naming it in results and submissions."""

    path: Path
    rel: str
    sequence: str = ""
    scene: str = ""
    lux: float = float("nan")
    key: str = ""
    extra: dict = field(default_factory=dict)


# -- inputs ---------------------------------------------------------------------------------------------------

def read_manifest(dataset_dir: Path) -> dict | None:
    """The dataset's ``manifest.json`` (None when there is none); SimSpadError when it is malformed."""
    path = dataset_dir / "manifest.json"
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SimSpadError(f"not valid JSON ({exc})", path=path) from None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("recordings"), list):
        raise SimSpadError("expected an object with a 'recordings' list", path=path, field="recordings")
    return manifest


def list_recordings(target: Path) -> tuple[list[RecordingEntry], dict | None]:
    """The recordings of ``target`` (a ``.h5`` file, a dataset directory with ``manifest.json``, or a
    directory of ``.h5`` files) and the manifest (or None). Manifest entries whose status is not
    ``complete`` are skipped."""
    target = Path(target)
    if target.is_file():
        return [RecordingEntry(target, target.name)], None
    if not target.is_dir():
        raise SimSpadError("no such recording file or dataset directory", path=target)
    manifest = read_manifest(target)
    entries = []
    if manifest is not None:
        for i, r in enumerate(manifest["recordings"]):
            if not isinstance(r, dict) or not isinstance(r.get("path"), str):
                raise SimSpadError("each recording needs a 'path' string", path=target / "manifest.json",
                                   field=f"recordings[{i}].path")
            if r.get("status", "complete") != "complete":
                continue
            entries.append(RecordingEntry(target / r["path"], r["path"], extra=r))
    else:
        results_dirs = {d.parent for d in target.rglob("results.json")}
        for p in sorted(target.rglob("*.h5")):
            parts = p.relative_to(target).parts
            if any(part.startswith(".") for part in parts):
                continue  # temporary files of atomic writes
            if any(parent in results_dirs for parent in p.parents) or "renders" in parts[:-1]:
                continue  # saved reconstructions of an earlier evaluation, render caches
            entries.append(RecordingEntry(p, p.relative_to(target).as_posix()))
    if not entries:
        raise SimSpadError("no complete recordings to evaluate", path=target)
    return entries, manifest


def fill_entry(entry: RecordingEntry) -> RecordingEntry:
    """Read sequence, scene and lux from the recording's attributes (validating the file)."""
    from simspad.io.recording import open_recording

    with open_recording(entry.path) as rec:
        if not rec.has("gt"):
            raise SimSpadError("recording has no ground truth (/gt): nothing to score against", path=entry.path,
                               field="/gt")
        entry.sequence = str(rec.attrs.get("sequence") or entry.extra.get("sequence") or rec.scene
                             or Path(entry.rel).stem)
        entry.scene = str(rec.scene or entry.extra.get("scene") or entry.sequence)
        entry.lux = float(rec.lux)
    entry.key = recording_key(entry.sequence, entry.lux)
    return entry


def evaluation_indices(gt_t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of the ground-truth instants lying on the grid t₀ + k/rate_hz (one per grid point).

    A ground-truth instant is on the grid when it is within 10⁻⁶ of a period of it. When the ground truth is
    sampled more coarsely than the grid, every ground-truth instant is on it.
    """
    gt_t = np.asarray(gt_t, np.float64)
    if gt_t.size == 0:
        return np.empty(0, np.int64)
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise SimSpadError(f"evaluation rate must be > 0, got {rate_hz}", field="--rate")
    k = (gt_t - gt_t[0]) * rate_hz
    on_grid = np.abs(k - np.round(k)) < 1e-6
    idx = np.nonzero(on_grid)[0]
    _, first = np.unique(np.round(k[idx]).astype(np.int64), return_index=True)
    return idx[np.sort(first)]


def is_siemens_star(scene: str) -> bool:
    return "siemens" in scene.lower()


# -- one task ------------------------------------------------------------------------------------------------

def _gt_white_point(rec, idx: np.ndarray) -> float:
    def chunks():
        for i in range(0, idx.size, 16):
            yield rec.gt.flux(idx[i:i + 16].tolist())
    return metrics.white_point(chunks)


def score_frames(rec, idx: np.ndarray, frames, *, white: float, absolute_scale: bool, method: str,
                 recording: str, scene: str, image_frame: int, frame_sink=None):
    """Score a stream of reconstructed frames against the recording's ground truth at ``idx``.

    Parameters
    ----------
    rec : Recording
    idx : ndarray of int
        Ground-truth frame indices (the evaluation instants), in order.
    frames : iterable of ndarray [H,W]
        The reconstruction, one frame per index.
    white : float
        Sequence white point (ph s⁻¹ m⁻²).
    absolute_scale : bool
        False: each frame is aligned by the log-affine fit before scoring.
    image_frame : int
        Position (in ``idx``) of the instant whose display-mapped crops are returned.
    frame_sink : callable(i, frame), optional
        Receives each frame (to save the reconstructions).

    Returns
    -------
    dict with ``frame_rows``, ``psnr_db``, ``ssim``, ``n_frames``, ``mtf`` (freq, mtf) or None, ``images``
    (rec and gt display crops at ``image_frame``) and ``method_s`` (time spent inside the frame iterator).
    Raises ValueError on a frame of the wrong shape, a non-finite value or a wrong number of frames.
    """
    H, W = rec.height, rec.width
    t = rec.gt.t
    frame_rows, psnrs, ssims = [], [], []
    star = is_siemens_star(scene)
    geometry = None
    mtf_freq = mtf_sum = mtf_n = None
    images = None
    method_s = 0.0
    it = iter(frames)
    i = 0
    while True:
        t0 = time.perf_counter()
        try:
            img = next(it)
        except StopIteration:
            method_s += time.perf_counter() - t0
            break
        method_s += time.perf_counter() - t0
        if i >= idx.size:
            raise ValueError(f"more frames than the {idx.size} evaluation instants")
        img = np.asarray(img)
        if img.shape != (H, W):
            raise ValueError(f"frame {i} has shape {img.shape}, expected {(H, W)}")
        if not np.all(np.isfinite(img)):
            raise ValueError(f"frame {i} holds NaN or inf values")
        if frame_sink is not None:
            frame_sink(i, img)
        gt = rec.gt.flux(int(idx[i]))
        s = metrics.frame_scores(img, gt, white, absolute_scale)
        frame_rows.append({"method": method, "recording": recording, "frame": i, "t_s": float(t[idx[i]]), **s})
        psnrs.append(s["psnr_db"])
        ssims.append(s["ssim"])
        if star or i == image_frame:
            shown = img if absolute_scale else metrics.align_log_affine(img, gt, white)
        if star:
            if geometry is None:
                geometry = metrics.siemens_star_geometry(gt)
            f, m = metrics.mtf_siemens(shown, gt, geometry=geometry)
            if f.size:
                if mtf_sum is None:
                    mtf_freq, mtf_sum, mtf_n = f, np.zeros_like(m), np.zeros(m.shape, np.int64)
                ok = np.isfinite(m)
                mtf_sum[ok] += m[ok]
                mtf_n[ok] += 1
        if i == image_frame:
            images = (crop(metrics.display_map(shown, white)), crop(metrics.display_map(gt, white)))
        i += 1
    if i != idx.size:
        raise ValueError(f"{i} frames for {idx.size} evaluation instants")
    mtf = None
    if mtf_sum is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            mtf = (mtf_freq, np.where(mtf_n > 0, mtf_sum / np.maximum(mtf_n, 1), np.nan))
    return {"frame_rows": frame_rows, "psnr_db": float(np.mean(psnrs)) if psnrs else float("nan"),
            "ssim": float(np.nanmean(ssims)) if ssims and not np.all(np.isnan(ssims)) else float("nan"),
            "n_frames": i, "mtf": mtf, "images": images, "method_s": method_s}


@dataclass
class Task:
    entry: RecordingEntry
    method: str
    rate_hz: float
    work_dir: Path
    save_reconstructions: bool = True
    white: float | None = None
    """Sequence white point, computed once per recording by the caller (None: computed by the task)."""


def _base_row(task: Task, white: float) -> dict:
    e = task.entry
    return {"method": task.method, "label": task.method, "sensors": "", "scene": e.scene, "sequence": e.sequence,
            "lux": e.lux, "recording": e.rel, "psnr_db": float("nan"), "ssim": float("nan"),
            "mtf50_cyc_px": float("nan"), "bandwidth_khz_per_pixel": float("nan"),
            "bandwidth_bits_per_pixel_s": float("nan"), "absolute_scale": True, "n_frames": 0,
            "runtime_s": float("nan"), "white_point_ph_s_m2": white, "image": "", "error": ""}


def write_images(work_dir: Path, key: str, method: str, images) -> str:
    """Save the GT crop, the method's crop and the pair side by side; return the pair's relative path."""
    rec_img, gt_img = images
    d = work_dir / "images" / slug(key)
    save_png(d / "gt.png", gt_img)
    name = slug(method)
    save_png(d / f"{name}.png", rec_img)
    gap = np.ones((gt_img.shape[0], 4), np.float32)
    save_png(d / f"{name}_vs_gt.png", np.hstack([rec_img, gap, gt_img]))
    return (d / f"{name}_vs_gt.png").relative_to(work_dir).as_posix()


class _ReconstructionSink:
    """Appends frames to ``reconstructions/<rec>/<method>.h5`` as they are produced."""

    def __init__(self, path: Path, times_s: np.ndarray, shape: tuple[int, int], attrs: dict):
        import h5py

        path.parent.mkdir(parents=True, exist_ok=True)
        self.h5 = h5py.File(path, "w")
        self.h5.create_dataset("t", data=np.asarray(times_s, np.float64), track_times=False)
        self.ds = self.h5.create_dataset("flux", shape=(len(times_s), *shape), dtype=np.float32,
                                         chunks=(1, *shape), compression="lzf", track_times=False)
        for k, v in attrs.items():
            self.h5.attrs[k] = v

    def __call__(self, i: int, img: np.ndarray) -> None:
        self.ds[i] = img

    def close(self) -> None:
        self.h5.close()


def run_task(task: Task) -> dict:
    """Run one method on one recording and score it; never raises for a method failure (see module doc)."""
    from simspad.io.recording import open_recording
    from simspad.methods.registry import get_method

    e = task.entry
    with open_recording(e.path) as rec:
        idx = evaluation_indices(rec.gt.t, task.rate_hz)
        white = task.white if task.white is not None else _gt_white_point(rec, idx)
        row = _base_row(task, white)
        out = {"row": row, "frame_rows": [], "mtf_rows": []}
        try:
            method = get_method(task.method)
            row.update(label=method.label, sensors=method.sensors, absolute_scale=bool(method.absolute_scale))
            missing = [k for k in method.requires if not rec.has(k)]
            if missing:
                raise ValueError(f"recording lacks the sensor group(s) {', '.join(missing)}")
            times = rec.gt.t[idx]
            sink = None
            if task.save_reconstructions:
                sink = _ReconstructionSink(task.work_dir / "reconstructions" / slug(e.key) / f"{slug(task.method)}.h5",
                                           times, (rec.height, rec.width),
                                           {"method": task.method, "recording": e.rel, "units": "photons s-1 m-2"})
            try:
                reco = method.reconstruct(rec, times)
                res = score_frames(rec, idx, reco, white=white, absolute_scale=method.absolute_scale,
                                   method=task.method, recording=e.rel, scene=e.scene, image_frame=idx.size // 2,
                                   frame_sink=sink)
            finally:
                if sink is not None:
                    sink.close()
            bw = reco.bandwidth
            row.update(psnr_db=res["psnr_db"], ssim=res["ssim"], n_frames=res["n_frames"],
                       runtime_s=round(res["method_s"], 3),
                       bandwidth_khz_per_pixel=float(bw.readout_khz_per_pixel),
                       bandwidth_bits_per_pixel_s=float(bw.bits_per_pixel_s))
            if res["images"] is not None:
                row["image"] = write_images(task.work_dir, e.key, task.method, res["images"])
            if res["mtf"] is not None:
                f, m = res["mtf"]
                row["mtf50_cyc_px"] = metrics.mtf50(f, m)
                out["mtf_rows"] = [{"method": task.method, "recording": e.rel, "freq_cyc_px": float(a),
                                    "mtf": float(b)} for a, b in zip(f, m)]
            out["frame_rows"] = res["frame_rows"]
        except Exception as exc:  # a method's failure is a result, not the end of the run
            row["error"] = f"{type(exc).__name__}: {exc}".replace("\n", " ")
            (task.work_dir / "reconstructions" / slug(e.key) / f"{slug(task.method)}.h5").unlink(missing_ok=True)
        return out


def write_gt_image(work_dir: Path, entry: RecordingEntry, rate_hz: float, white: float) -> None:
    """The ground-truth crop of the chosen instant even when every method failed."""
    from simspad.io.recording import open_recording

    with open_recording(entry.path) as rec:
        idx = evaluation_indices(rec.gt.t, rate_hz)
        if idx.size == 0:
            return
        gt = rec.gt.flux(int(idx[idx.size // 2]))
    save_png(work_dir / "images" / slug(entry.key) / "gt.png", crop(metrics.display_map(gt, white)))


# -- the command ------------------------------------------------------------------------------------------------

def _spec_evaluation(manifest: dict | None, entry: RecordingEntry | None) -> dict:
    spec = (manifest or {}).get("spec")
    if not isinstance(spec, dict) and entry is not None:
        from simspad.io.recording import open_recording

        with open_recording(entry.path) as rec:
            spec = rec.spec
    ev = (spec or {}).get("evaluation", {}) if isinstance(spec, dict) else {}
    return ev if isinstance(ev, dict) else {}


def run_tasks(tasks: list[Task], workers: int | None = None) -> list[dict]:
    """Run tasks (process pool of ≤ 2 workers when there is more than one task); results in task order."""
    workers = min(MAX_WORKERS, len(tasks), workers or os.cpu_count() or 1)
    if workers <= 1:
        return [run_task(t) for t in tasks]
    import multiprocessing as mp

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
        return list(pool.map(run_task, tasks))


def evaluate(target, methods=None, out_dir=None, rate_hz=None, *, workers=None,
             save_reconstructions: bool = True) -> tuple[Path, list[dict]]:
    """Evaluate ``methods`` on every recording of ``target`` and write the results directory ``out_dir``.

    Parameters
    ----------
    target : path
        A recording (``.h5``), a dataset directory (``manifest.json``) or a directory of recordings.
    methods : sequence of str or comma-separated str, optional
        Method names; default: the dataset spec's ``evaluation.methods``, else every method the recording
        allows.
    out_dir : path
        Results directory (created atomically; an existing results directory is replaced).
    rate_hz : float, optional
        Evaluation rate; default the spec's ``evaluation.rate_hz`` or 1000 Hz.

    Returns
    -------
    (out_dir, rows) — rows as in ``results.csv``.
    """
    from simspad.io.recording import open_recording
    from simspad.methods.registry import available_methods, get_method

    if out_dir is None:
        raise SimSpadError("an output directory is required", field="--out")
    out_dir = Path(out_dir)
    check_output_dir(out_dir)
    entries, manifest = list_recordings(Path(target))
    entries = [fill_entry(e) for e in entries]
    ev = _spec_evaluation(manifest, entries[0])
    if rate_hz is None:
        rate_hz = float(ev.get("rate_hz", DEFAULT_RATE_HZ) or DEFAULT_RATE_HZ)
    if isinstance(methods, str):
        methods = [m.strip() for m in methods.split(",") if m.strip()]
    if not methods:
        methods = [m for m in (ev.get("methods") or []) if isinstance(m, str)] or None
    if methods:
        for m in methods:
            get_method(m)  # unknown names are bad input: fail before doing anything
    tasks = []
    whites = {}
    for e in entries:
        with open_recording(e.path) as rec:
            idx = evaluation_indices(rec.gt.t, rate_hz)
            if idx.size == 0:
                raise SimSpadError("no ground-truth instants to evaluate", path=e.path, field="/gt/t")
            names = list(methods) if methods else available_methods(rec)
            whites[e.rel] = _gt_white_point(rec, idx)  # once per recording, shared by its tasks
        tasks.extend(Task(e, m, float(rate_hz), Path(), save_reconstructions, whites[e.rel]) for m in names)
    if not tasks:
        raise SimSpadError("no method applies to these recordings", path=target, field="--methods")
    with atomic_path(out_dir) as tmp:
        tmp.mkdir(parents=True)
        for t in tasks:
            t.work_dir = tmp
        results = run_tasks(tasks, workers)
        rows = [r["row"] for r in results]
        for e in entries:
            if not (tmp / "images" / slug(e.key) / "gt.png").exists():
                write_gt_image(tmp, e, rate_hz, whites[e.rel])
        meta = {"format": "simspad-results", "format_version": 1, "simspad_version": __version__,
                "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                "kind": "evaluate", "target": str(target), "rate_hz": rate_hz,
                "methods": sorted({t.method for t in tasks}),
                "recordings": [{"recording": e.rel, "key": e.key, "sequence": e.sequence, "scene": e.scene,
                                "lux": e.lux} for e in entries],
                "protocol": protocol_metadata(),
                "dataset": {k: (manifest or {}).get(k) for k in ("spec_hash", "seed")}}
        write_results_dir(tmp, rows, [f for r in results for f in r["frame_rows"]],
                          [m for r in results for m in r["mtf_rows"]], meta)
    return out_dir, rows


def evaluate_recording(rec_path, methods=None, out_dir=None, rate_hz=None) -> list[dict]:
    """Evaluate ``methods`` on one recording into the results directory ``out_dir``; return the rows."""
    return evaluate(Path(rec_path), methods=methods, out_dir=out_dir, rate_hz=rate_hz)[1]


def protocol_metadata() -> dict:
    return {"white_point": f"{metrics.WHITE_PERCENTILE:g}th percentile of ground truth over the sequence",
            "display": "clip(x / W, 0, 1) then the sRGB transfer curve",
            "alignment": "methods without absolute scale: per-frame least-squares a*ln(rec)+b ~ ln(gt), "
                         f"floors {metrics.LOG_FLOOR_REL:g}*W (gt) and {metrics.LOG_FLOOR_REL:g}*p99(rec)",
            "psnr": f"scikit-image, data_range=1, capped at {metrics.PSNR_CAP_DB:g} dB, mean over frames",
            "ssim": "scikit-image, data_range=1, 7x7 window, mean over frames",
            "image_crop_px": CROP_PX}


def summary_table(rows: list[dict]) -> str:
    """A short text table of the rows (for the terminal)."""
    lines = [f"{'method':<20} {'recording':<28} {'PSNR dB':>8} {'SSIM':>6} {'kHz/px':>9}"]
    for r in rows:
        key = recording_key(r["sequence"], r["lux"])[:28]
        if r.get("error"):
            lines.append(f"{r['method'][:20]:<20} {key:<28} FAILED: {r['error'][:80]}")
        else:
            lines.append(f"{r['method'][:20]:<20} {key:<28} {r['psnr_db']:8.2f} {r['ssim']:6.3f} "
                         f"{r['bandwidth_khz_per_pixel']:9.3f}")
    return "\n".join(lines)


def evaluate_from_cli(target, methods=None, out_dir=None, rate_hz=None) -> Path:
    """The ``simspad evaluate`` command: evaluate, print a summary, raise EvaluationFailed if a run failed."""
    import click

    out, rows = evaluate(target, methods=methods, out_dir=out_dir, rate_hz=rate_hz)
    click.echo(summary_table(rows))
    click.echo(f"wrote {out / 'results.csv'}")
    failed = [r for r in rows if r.get("error")]
    if failed:
        raise EvaluationFailed(f"{len(failed)} of {len(rows)} method runs failed (see the error column)",
                               path=out / "results.csv", field="error")
    return out
