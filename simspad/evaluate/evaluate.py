"""``simspad evaluate``: run reconstruction methods on recordings and score them.

For each recording × method (a *task*), following the protocol of :mod:`simspad.evaluate.protocol`:

1. the evaluation instants are the ``/gt/t`` instants that lie on the evaluation grid t₀ + k/rate_hz
   (default 1 kHz, or the dataset spec's ``evaluation.rate_hz``);
2. the white point W is the 99th percentile of ground truth over those instants (read in chunks, exact, once
   per recording);
3. the method reconstructs flux frames at those instants; each frame is scored as it arrives
   (:func:`simspad.evaluate.metrics.frame_scores`: display mapping, log-affine alignment for methods without
   absolute scale, PSNR, SSIM), so memory does not grow with the sequence length;
4. Siemens-star recordings (scene name containing ``siemens``) also get the MTF (mean over frames), its value at
   fixed frequencies and MTF50 (:func:`simspad.evaluate.protocol.star_figures`);
5. the method's bandwidth is read from the reconstruction once it has been iterated.

Recordings without ground truth (real captures from ``simspad import``) are evaluated too
(:mod:`simspad.evaluate.real_data`): every method the sensors allow runs at the instants ``t_start_s + k/rate_hz``
of the recorded span; reconstructions, an image per method, the bandwidth and (where the recording declares a
Siemens-star region) the MTF are saved; PSNR, SSIM and the white point are NaN, ``results.json`` says why, and the
caller's ``preview`` writes a strip of the sensors per such recording.

Tasks run in a process pool of at most 2 workers (forked where safe, else spawned), one recording's methods per job so that its ground
truth is read, display-mapped and (Siemens star) analysed once for all of them
(:class:`simspad.evaluate.protocol.GroundTruthCache`); rows come out in a deterministic order (recordings in
manifest/sorted order, methods in the requested order) whatever finishes first. A progress bar counts method
runs; per-method timings go to ``results.json`` and the command's output.

Failure policy: a method that fails on a recording (exception, wrong frame shape, NaN/inf output) does not stop
the run: its row is written with NaN metrics and the message in the ``error`` column, all other tasks complete and
the results directory is written; the command then exits with status 1 (:class:`EvaluationFailed`) so scripts
notice. Bad input (unknown method, unreadable recording, nothing to evaluate) is a :class:`SimSpadError` (exit 2)
before anything is written.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from simspad.errors import SimSpadError
from simspad.evaluate import metrics
from simspad.evaluate.protocol import (
    DEFAULT_RATE_HZ,
    GroundTruthCache,
    ScoringRun,
    evaluation_indices,
    gt_white_point,
    protocol_metadata,
    score_frames,
    star_figures,
)
from simspad.evaluate.real_data import NO_GT_NOTE, evaluation_times, score_without_gt, star_region
from simspad.evaluate.recordings import QuietBar, RecordingEntry, fill_entries, list_recordings, spec_evaluation
from simspad.io.atomic import is_disk_full
from simspad.io.output_dirs import owned_output_dir
from simspad.io.reconstructions import ReconstructionSink
from simspad.io.recording import open_recording
from simspad.io.results_dir import (
    check_output_dir,
    crop,
    legacy_results,
    save_png,
    ResultRow,
    slug,
    write_images,
    write_results_dir,
)
from simspad.methods.registry import available_methods, check_method_params, get_method
from simspad.physics.pairwise_sum import pairwise_sum
from simspad.processes import available_cores, die_with_parent_and_ignore_sigint, kill_pool_workers, sigint_blocked

MAX_WORKERS = 2


class EvaluationFailed(SimSpadError):
    """Some method runs failed; the results (with an ``error`` column) were written. Exit status 1."""

    exit_code = 1


@dataclass
class Task:
    entry: RecordingEntry
    method: str
    rate_hz: float
    work_dir: Path
    save_reconstructions: bool = True
    white: float | None = None
    """Sequence white point, computed once per recording by the caller (None: computed by the task)."""
    params: dict = field(default_factory=dict)
    """The method's parameters (validated by :func:`~simspad.methods.registry.check_method_params`)."""


def _base_row(task: Task, white: float) -> ResultRow:
    """The task's row before the run: what the recording and the task say; every measurement NaN."""
    return ResultRow.for_recording(task.method, task.entry, white_point_ph_s_m2=white,
                                   params=params_text(task.params))


def params_text(params: dict) -> str:
    """A method's parameters as results.csv holds them: compact JSON with sorted keys ("" for the defaults)."""
    return json.dumps(params, sort_keys=True, separators=(",", ":")) if params else ""


def run_task(task: Task, gt_cache: GroundTruthCache | None = None, rec=None) -> dict:
    """Run one method on one recording and score it; never raises for a method failure (see module doc).

    ``gt_cache`` (optional) shares the recording's ground truth with the other methods scored on it, ``rec``
    (optional) the open recording (else it is opened here). The output holds ``seconds``, the task's wall time
    (method, scoring and writing).
    """
    start = time.perf_counter()
    if rec is None:
        with open_recording(task.entry.path) as rec:
            out = _run_task(task, gt_cache, rec)
    else:
        out = _run_task(task, gt_cache, rec)
    out["seconds"] = time.perf_counter() - start
    return out


def _run_task(task: Task, gt_cache: GroundTruthCache | None, rec) -> dict:
    if not rec.has("gt"):
        return _run_task_without_gt(task, rec)
    e = task.entry
    idx = evaluation_indices(rec.gt.t, task.rate_hz)
    white = task.white if task.white is not None else gt_white_point(rec, idx)
    row = _base_row(task, white)
    out = {"row": row, "frame_rows": [], "mtf_rows": []}
    try:
        method = _method_for(task, rec, row)
        times = rec.gt.t[idx]
        sink = None
        if task.save_reconstructions:
            sink = ReconstructionSink(task.work_dir / "reconstructions" / slug(e.key) / f"{slug(task.method)}.h5",
                                      times, (rec.height, rec.width),
                                      {"method": task.method, "recording": e.rel, "units": "photons s-1 m-2"})
        try:
            reco = method.reconstruct(rec, times)
            run = ScoringRun(method=task.method, recording=e.rel, scene=e.scene, white=white,
                             absolute_scale=method.absolute_scale, image_frame=idx.size // 2)
            res = score_frames(rec, idx, reco, run, frame_sink=sink, gt_cache=gt_cache)
        finally:
            if sink is not None:
                sink.close()
        bw = reco.bandwidth
        row.update(psnr_db=res["psnr_db"], ssim=res["ssim"], n_frames=res["n_frames"],
                   runtime_s=round(res["method_s"], 3),
                   bandwidth_khz_per_pixel=float(bw.readout_khz_per_pixel),
                   bandwidth_bits_per_pixel_s=float(bw.bits_per_pixel_s))
        if res["images"] is not None:
            row.image = write_images(task.work_dir, e.key, task.method, res["images"])
        if res["mtf"] is not None:
            f, m = res["mtf"]
            row.update(**star_figures(res["mtf"]))
            out["mtf_rows"] = [{"method": task.method, "recording": e.rel, "freq_cyc_px": float(a),
                                "mtf": float(b)} for a, b in zip(f, m)]
        out["frame_rows"] = res["frame_rows"]
    except Exception as exc:  # a method's failure is a result, not the end of the run
        if is_disk_full(exc):
            raise  # the end of the run: one line naming the results directory (evaluate's atomic_path)
        row.error = f"{type(exc).__name__}: {exc}".replace("\n", " ")
        (task.work_dir / "reconstructions" / slug(e.key) / f"{slug(task.method)}.h5").unlink(missing_ok=True)
    return out


def _method_for(task: Task, rec, row: ResultRow):
    """The task's method, built with its parameters; its label, sensors and scale into ``row``. A recording
    lacking a group the method reads is that run's failure (ValueError), not the end of the evaluation."""
    method = get_method(task.method, **task.params)
    row.update(label=method.label, sensors=method.sensors, absolute_scale=bool(method.absolute_scale))
    missing = [k for k in method.requires if not rec.has(k)]
    if missing:
        raise ValueError(f"recording lacks the sensor group(s) {', '.join(missing)}")
    return method


def _run_task_without_gt(task: Task, rec) -> dict:
    """One method on a recording without ground truth (:mod:`simspad.evaluate.real_data`): reconstructions,
    bandwidth, an image and the declared star's MTF; PSNR and SSIM stay NaN."""
    e = task.entry
    row = _base_row(task, float("nan"))
    out = {"row": row, "frame_rows": [], "mtf_rows": []}
    try:
        method = _method_for(task, rec, row)
        times = evaluation_times(rec, task.rate_hz)
        sink = None
        if task.save_reconstructions:
            sink = ReconstructionSink(task.work_dir / "reconstructions" / slug(e.key) / f"{slug(task.method)}.h5",
                                      times, (rec.height, rec.width),
                                      {"method": task.method, "recording": e.rel, "units": "photons s-1 m-2"})
        try:
            reco = method.reconstruct(rec, times)
            res = score_without_gt(rec, times, reco, star_region(rec), frame_sink=sink)
        finally:
            if sink is not None:
                sink.close()
        bw = reco.bandwidth
        row.update(n_frames=res["n_frames"], runtime_s=round(res["method_s"], 3),
                   bandwidth_khz_per_pixel=float(bw.readout_khz_per_pixel),
                   bandwidth_bits_per_pixel_s=float(bw.bits_per_pixel_s))
        if res["image"] is not None:
            path = task.work_dir / "images" / slug(e.key) / f"{slug(task.method)}.png"
            save_png(path, crop(res["image"]))
            row.image = path.relative_to(task.work_dir).as_posix()
        if res["mtf"] is not None:
            f, m = res["mtf"]
            row.update(**star_figures(res["mtf"]))
            out["mtf_rows"] = [{"method": task.method, "recording": e.rel, "freq_cyc_px": float(a),
                                "mtf": float(b)} for a, b in zip(f, m)]
    except Exception as exc:  # a method's failure is a result, not the end of the run
        row.error = f"{type(exc).__name__}: {exc}".replace("\n", " ")
        (task.work_dir / "reconstructions" / slug(e.key) / f"{slug(task.method)}.h5").unlink(missing_ok=True)
    return out


def write_gt_image(work_dir: Path, entry: RecordingEntry, rate_hz: float, white: float) -> None:
    """The ground-truth crop of the chosen instant even when every method failed."""
    with open_recording(entry.path) as rec:
        if not rec.has("gt"):
            return  # a real capture: nothing to show
        idx = evaluation_indices(rec.gt.t, rate_hz)
        if idx.size == 0:
            return
        gt = rec.gt.flux(int(idx[idx.size // 2]))
    save_png(work_dir / "images" / slug(entry.key) / "gt.png", crop(metrics.display_map(gt, white)))


def run_recording(tasks: list[Task]) -> list[dict]:
    """Run tasks of one recording in order, sharing its ground truth (:class:`GroundTruthCache`) and the open
    file (opened and validated once; its views keep what they read, such as the event index, and attributes)."""
    white = tasks[0].white
    cache = GroundTruthCache(white) if white is not None and all(t.white == white for t in tasks) else None
    if any(t.entry.path != tasks[0].entry.path for t in tasks):
        return [run_task(t, cache if t.white == white else None) for t in tasks]
    with open_recording(tasks[0].entry.path) as rec:
        return [run_task(t, cache, rec) for t in tasks]


#: Jobs per worker below which a recording's methods are split over several jobs (load balance).
_JOBS_PER_WORKER = 4


def _batches(tasks: list[Task], workers: int) -> list[list[Task]]:
    """Tasks grouped by recording (consecutive), so a worker scores one recording's methods against ground
    truth it has read once; with few recordings each group is split in parts, so that the workers stay busy."""
    groups: list[list[Task]] = []
    for t in tasks:
        if groups and groups[-1][0].entry.rel == t.entry.rel:
            groups[-1].append(t)
        else:
            groups.append([t])
    if workers > 1 and len(groups) < _JOBS_PER_WORKER * workers:
        parts = -(-_JOBS_PER_WORKER * workers // len(groups))
        # contiguous parts: the flattened results stay in task order
        groups = [part for g in groups for part in (g[i:i + -(-len(g) // parts)]
                                                    for i in range(0, len(g), -(-len(g) // parts)))]
    return groups


def _start_method() -> str:
    """How pool workers start: ``fork`` where it is safe, else ``spawn``.

    A forked worker starts with this process's imports (numpy, scipy, h5py, numba and the methods: ≈ 2 s of CPU
    that every spawned worker spends again, as long as a small dataset's whole evaluation). Forking is safe when
    this process runs no other thread (a lock held by one would stay locked in the child) and holds no renderer
    state (``simspad generate`` evaluates after Mitsuba has started its own native threads); then spawn.
    """
    if ("fork" in mp.get_all_start_methods() and threading.active_count() == 1
            and not any(m in sys.modules for m in ("mitsuba", "drjit", "distributed"))):
        return "fork"
    return "spawn"


def run_tasks(tasks: list[Task], workers: int | None = None, progress: bool = True) -> list[dict]:
    """Run tasks (process pool of ≤ 2 workers when there is more than one task); results in task order.

    A progress bar on stderr counts method runs (recordings × methods) with an estimate of the time left.
    """
    workers = min(MAX_WORKERS, len(tasks), workers or available_cores())
    batches = _batches(tasks, workers)
    results: list[list[dict] | None] = [None] * len(batches)
    pool = futures = None
    if workers > 1:
        start_method = _start_method()
        if start_method == "fork":
            # The first compiled function a process loads from numba's cache sets up numba's code generator
            # (≈ 0.5 s of CPU): done here once, the forked workers inherit it.
            pairwise_sum(np.zeros(1), 0, 1)
        # Workers start before the progress bar, whose monitor thread would make forking unsafe.
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context(start_method),
                                   initializer=die_with_parent_and_ignore_sigint)
        try:
            with sigint_blocked():  # workers start deaf to Ctrl-C: the driver alone reports it
                futures = {pool.submit(run_recording, b): i for i, b in enumerate(batches)}
        except BaseException:
            kill_pool_workers(pool)
            raise
    with tqdm(total=len(tasks), desc="evaluate", unit="run", file=sys.stderr, dynamic_ncols=True,
              disable=not progress) as bar:
        def done(i: int, out: list[dict]) -> None:
            results[i] = out
            bar.set_postfix_str(batches[i][0].entry.key, refresh=False)
            bar.update(len(out))

        if pool is None:
            for i, b in enumerate(batches):
                done(i, run_recording(b))
        else:
            try:
                for fut in as_completed(futures):
                    done(futures[fut], fut.result())
            except BaseException:
                kill_pool_workers(pool)  # interrupted or failed: do not wait for the other recordings
                raise
            pool.shutdown()
    return [r for out in results for r in out]


def timing_rows(tasks: list[Task], results: list[dict]) -> list[dict]:
    """Per method: runs, seconds inside the method, seconds in all (scoring and writing included)."""
    table: dict[str, dict] = {}
    for t, r in zip(tasks, results):
        m = table.setdefault(t.method, {"method": t.method, "runs": 0, "method_s": 0.0, "total_s": 0.0})
        m["runs"] += 1
        rt = r["row"].runtime_s
        m["method_s"] += rt if rt == rt else 0.0
        m["total_s"] += r.get("seconds", 0.0)
    return list(table.values())


def evaluate(target, methods=None, out_dir=None, rate_hz=None, *, workers=None,
             save_reconstructions: bool = True, progress: bool = True,
             timings: list | None = None, params: dict | None = None,
             preview=None) -> tuple[Path, list[dict]]:
    """Evaluate ``methods`` on every recording of ``target`` and write the results directory ``out_dir``.

    Parameters
    ----------
    target : path
        A recording (``.h5``), a dataset directory (``manifest.json``) or a directory of recordings.
    methods : sequence of str or comma-separated str, optional
        Method names; default: the dataset spec's ``evaluation.methods``, else every method the recording
        allows.
    out_dir : path
        Results directory: new, empty, or written by `evaluate` before (its files are replaced, files that
        others put there are kept: :mod:`simspad.io.output_dirs`); locked while the run writes it.
    rate_hz : float, optional
        Evaluation rate; default the spec's ``evaluation.rate_hz`` or 1000 Hz.
    progress : bool
        Show a progress bar on stderr.
    timings : list, optional
        Receives one dict per method (:func:`timing_rows`: runs, ``method_s``, ``total_s``), also written to
        ``results.json`` as ``timings``.
    params : dict of str to dict, optional
        Method name → parameters (``--param``), over the dataset spec's ``evaluation.params``; recorded in
        results.csv's ``params`` column and results.json's ``params``.
    preview : callable(recording_path, png_path), optional
        Writes a preview strip of each recording without ground truth into the results directory
        (``previews/<key>.png``); the CLI passes :func:`simspad.analysis.preview.write_preview`, which this layer
        cannot import.

    Returns
    -------
    (out_dir, rows) — rows as in ``results.csv`` (:meth:`~simspad.io.results_dir.ResultRow.to_dict`).
    """
    if out_dir is None:
        raise SimSpadError("an output directory is required", field="--out")
    out_dir = Path(out_dir)
    check_output_dir(out_dir, "evaluate")
    entries, manifest = list_recordings(Path(target))
    entries = fill_entries(entries, progress)
    ev = spec_evaluation(manifest, entries[0])
    if rate_hz is None:
        rate_hz = float(ev.get("rate_hz", DEFAULT_RATE_HZ) or DEFAULT_RATE_HZ)
    if isinstance(methods, str):
        methods = [m.strip() for m in methods.split(",") if m.strip()]
    if not methods:
        methods = [m for m in (ev.get("methods") or []) if isinstance(m, str)] or None
    if methods:
        for m in methods:
            get_method(m)  # unknown names are bad input: fail before doing anything
    method_params = _method_params(ev.get("params"), params, manifest_path=Path(target) / "manifest.json"
                                   if manifest else None)
    tasks = []
    whites = {}
    for e in QuietBar(entries, desc="white points", unit="rec", file=sys.stderr, delay=2.0, disable=not progress,
                      leave=False):
        with open_recording(e.path) as rec:
            names = list(methods) if methods else available_methods(rec)
            if not rec.has("gt"):  # a real capture (simspad import): scored without ground truth
                if evaluation_times(rec, float(rate_hz)).size == 0:
                    raise SimSpadError(f"no instant at {rate_hz:g} Hz inside the recorded span", path=e.path,
                                       field="/.t_end_s")
                whites[e.rel] = None
                tasks.extend(Task(e, m, float(rate_hz), Path(), save_reconstructions, None,
                                  method_params.get(m, {})) for m in names)
                continue
            idx = evaluation_indices(rec.gt.t, rate_hz)
            if idx.size == 0:
                raise SimSpadError("no ground-truth instants to evaluate", path=e.path, field="/gt/t")
            whites[e.rel] = gt_white_point(rec, idx)  # once per recording, shared by its tasks
        tasks.extend(Task(e, m, float(rate_hz), Path(), save_reconstructions, whites[e.rel],
                          method_params.get(m, {})) for m in names)
    if not tasks:
        raise SimSpadError("no method applies to these recordings", path=target, field="--methods")
    with owned_output_dir(out_dir, "evaluate", legacy=legacy_results("evaluate")) as tmp:
        for t in tasks:
            t.work_dir = tmp
        results = run_tasks(tasks, workers, progress)
        rows = [r["row"] for r in results]
        timing = timing_rows(tasks, results)
        if timings is not None:
            timings.extend(timing)
        for e in entries:
            if whites[e.rel] is not None and not (tmp / "images" / slug(e.key) / "gt.png").exists():
                write_gt_image(tmp, e, rate_hz, whites[e.rel])
            elif whites[e.rel] is None and preview is not None:
                preview(e.path, tmp / "previews" / f"{slug(e.key)}.png")
        meta = {"target": str(target), "rate_hz": rate_hz,
                "methods": sorted({t.method for t in tasks}),
                "recordings": [e.summary(ground_truth=whites[e.rel] is not None,
                                         **({"preview": f"previews/{slug(e.key)}.png"}
                                            if whites[e.rel] is None and preview is not None else {}))
                               for e in entries],
                **({"notes": [NO_GT_NOTE]} if any(w is None for w in whites.values()) else {}),
                "protocol": protocol_metadata(), "timings": timing,
                **({"params": {m: p for m, p in sorted(method_params.items())
                               if any(t.method == m for t in tasks)}} if method_params else {}),
                "dataset": {k: (manifest or {}).get(k) for k in ("name", "spec_hash", "seed")}}
        write_results_dir(tmp, "evaluate", rows, [f for r in results for f in r["frame_rows"]],
                          [m for r in results for m in r["mtf_rows"]], meta)
    return out_dir, [r.to_dict() for r in rows]


def _method_params(spec_params, cli_params, *, manifest_path) -> dict[str, dict]:
    """Each method's parameters: the dataset spec's ``evaluation.params`` (validated again: the manifest may have
    been edited), then ``--param`` over them, key by key."""
    out: dict[str, dict] = {}
    if spec_params is not None:
        if not isinstance(spec_params, dict):
            raise SimSpadError(f"expected a table of method parameters, got {spec_params!r}", path=manifest_path,
                               field="spec.evaluation.params")
        for m, p in spec_params.items():
            out[m] = check_method_params(m, p, path=manifest_path, field="spec.evaluation.params")
    for m, p in (cli_params or {}).items():
        out[m] = check_method_params(m, {**out.get(m, {}), **p}, field="--param")
    return {m: p for m, p in out.items() if p}
