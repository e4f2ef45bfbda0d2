"""Dataset generation (``simspad generate``): render each sequence once per speed, simulate every
sequence × speed × lux.

The work is a small dependency graph of typed jobs (:mod:`simspad.dataset.jobs`) run by an executor
(:mod:`simspad.dataset.executors`, one ``submit(job)``) through the driver's
:class:`~simspad.dataset.task_queue.TaskQueue`: one render per (sequence, speed) (shared by all lux levels and
sensors) into ``<out>/renders/<sequence>[_x<k>]-<hash>/`` — a layout job, then chunks of keyframes and the noise
probe spread over every worker (and a warp render's synthesis jobs), then ``timeline.json`` written here once
every job is back, each render's phases kept by a :class:`~simspad.dataset.render_job.RenderJob` — then one
simulation per (sequence, speed, lux) into ``<out>/recordings/<sequence>/<sequence>[_x<k>]_<lux>lx.h5``, which
also states the image motion measured on its render (:mod:`simspad.render.image_motion`). Keyframes are written
under their final names (each atomically), so a killed run's keyframes are kept and the next run renders only the
missing ones. The driver (this module, in the calling process, with :mod:`~simspad.dataset.manifest_state`) is the
only writer of ``manifest.json``, which it rewrites atomically as results arrive.

Determinism: every recording draws from ``child_seed(spec.seed, sequence, lux, kind)`` (stream key
``(sequence, lux)``), every render from ``child_seed(spec.seed, sequence, "render")``, so outputs are the same
whatever the executor, the worker count or the order: byte for byte (the renderer loads scenes with a
canonical emitter order and the recording writer's HDF5 layout depends only on the data). The recordings'
``created_utc`` attr is the dataset's creation time kept in the manifest (or ``$SOURCE_DATE_EPOCH``, or the
``created_utc`` argument), not the wall-clock time of each write, so re-running or resuming does not change any
file's bytes; two separate datasets from one spec differ only in that attr unless ``SOURCE_DATE_EPOCH`` pins it.

Resume: a recording is skipped when its manifest entry is complete, its ``recording_hash`` (a hash of
everything that affects that file) is unchanged, and the file's size and sha256 match. Temporary files of a
killed run are removed on the next run (the lock guarantees no one else is writing them). A lock
(``fcntl.flock`` on ``<out>/.simspad.lock``) refuses a second concurrent run on one output directory.
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from tqdm import tqdm

from simspad.dataset.directory import (
    RENDERS_DIR,
    DatasetLock,
    check_dataset_owner,
    check_inside_dataset,
    check_no_links_out,
    check_prune,
    check_render_cache,
    remove_temporaries,
)
from simspad.dataset.executors import ExecutorConfig, make_executor
from simspad.dataset.manifest_state import (
    ManifestState,
    dataset_created_utc,
    load_previous_manifest,
)
from simspad.dataset.plan import DatasetPlan, RecordingTask, RenderTask, make_plan
from simspad.dataset.spec import DatasetSpec
from simspad.dataset.spec_validation import load_spec
from simspad.dataset.jobs import ChunkJob, Job, JobFailure, SimulationJob, SimulationResult
from simspad.dataset.render_job import RenderJob, RenderOutcome
from simspad.dataset.task_queue import TaskQueue
from simspad.errors import SimSpadError
from simspad.io.atomic import ensure_writable_dir
from simspad.io.manifest import recording_is_complete


@dataclass
class GenerateResult:
    """What :func:`generate` did: the dataset folder and the per-recording outcome."""

    out_dir: Path
    manifest: dict
    done: list[str]          # recordings (re)generated in this run
    skipped: list[str]       # recordings already complete
    failed: list[str]
    renders_done: list[str]
    wall_s: float
    executor: str            # how it ran, in words


def generate(spec, out_dir=None, executor: ExecutorConfig = ExecutorConfig(), *, progress: bool = True,
             created_utc: str | None = None, log: Callable[[str], None] | None = None,
             check: bool = True, prune: bool = False) -> GenerateResult:
    """Generate (or finish) a dataset.

    Parameters
    ----------
    spec : DatasetSpec or str or Path
        The validated spec, or the path of a spec TOML.
    out_dir : str or Path, optional
        Dataset folder (default ``spec.output``).
    executor : ExecutorConfig
        Where the work runs: ``local`` processes or a ``dask`` cluster, its scheduler address and worker count
        (default: local, one simulation process per usable core).
    progress : bool
        Show tqdm progress bars on stderr.
    created_utc : str, optional
        The ``created_utc`` of a new dataset (default ``$SOURCE_DATE_EPOCH``, else the manifest's, else now).
    log : callable, optional
        Receives one-line notices (default: print to stderr when ``progress``).
    check : bool
        Raise :class:`SimSpadError` if any recording failed (after the manifest records why).
    prune : bool
        Delete recordings and renders of the previous manifest that the spec no longer lists (without it such a
        run is refused, naming them).

    Returns
    -------
    GenerateResult
        The dataset folder (``out_dir``, holding ``manifest.json``) and what this run did.

    Raises
    ------
    SimSpadError
        Bad spec, a concurrent run on ``out_dir``, or recordings that failed (listed in the manifest).
    """
    t_start = time.perf_counter()
    executor.check()
    if not isinstance(spec, DatasetSpec):
        spec = load_spec(spec)
    out_dir = Path(out_dir if out_dir is not None else spec.output).expanduser().resolve()
    if log is None:
        log = (lambda msg: print(msg, file=sys.stderr, flush=True)) if progress else (lambda msg: None)
    ensure_writable_dir(out_dir, what="dataset output")
    check_dataset_owner(out_dir, load_previous_manifest(out_dir), spec.name)  # before the lock file is made
    check_no_links_out(out_dir)
    with DatasetLock(out_dir):
        for p in remove_temporaries(out_dir):
            log(f"removed temporary {p.relative_to(out_dir)} left by an interrupted run")
        previous = load_previous_manifest(out_dir)
        created = dataset_created_utc(previous, created_utc)
        plan = make_plan(spec, created)
        manifest = ManifestState(out_dir, spec, plan, created, previous)
        check_prune(out_dir, manifest.obsolete_recordings + manifest.obsolete_renders, prune, log)
        _remove_obsolete(out_dir, manifest, log)
        outcome = _run(out_dir, plan, manifest, executor, progress, log)
    outcome.wall_s = time.perf_counter() - t_start
    if check:
        raise_for_failures(outcome)
    return outcome


def raise_for_failures(outcome: "GenerateResult") -> None:
    """:class:`SimSpadError` naming the first failed recording, if any failed."""
    if not outcome.failed:
        return
    entries = {e["path"]: e for e in outcome.manifest["recordings"]}
    first = entries[outcome.failed[0]]
    raise SimSpadError(f"{len(outcome.failed)} of {len(entries)} recordings failed; first: {first['path']}: "
                       f"{first.get('error', 'unknown error')} (details in manifest.json; re-run to retry)",
                       path=outcome.out_dir)


def _remove_obsolete(out_dir: Path, manifest: ManifestState, log) -> None:
    """Recordings and renders of the previous manifest that the new spec no longer has are deleted, so the
    folder holds exactly the dataset its manifest describes."""
    for rel in manifest.obsolete_recordings:
        p = check_inside_dataset(out_dir, rel)  # never through a link leading out of the dataset
        if p.is_file():
            p.unlink()
            log(f"removed {rel} (no longer in the spec)")
    for rel in manifest.obsolete_renders:
        if not rel:
            continue
        p = check_inside_dataset(out_dir, rel)
        if p.is_dir() and p.parent == out_dir / RENDERS_DIR:
            shutil.rmtree(p, ignore_errors=True)


def _run(out_dir: Path, plan: DatasetPlan, manifest: ManifestState, executor: ExecutorConfig, progress, log):
    # Which recordings are already there (verified: hash of the spec inputs and sha256 of the bytes)?
    todo, skipped = [], []
    for task in plan.recordings:
        entry = manifest.rec[task.rel_path]
        if recording_is_complete(out_dir, entry, task.recording_hash):
            skipped.append(task.rel_path)
        else:
            if entry["status"] == "complete":
                log(f"redoing {task.rel_path}: file missing or changed since it was written")
            entry.update(status="pending", size=None, sha256=None, timings={})
            entry.pop("error", None)
            todo.append(task)
    needed = {t.render_rel_dir for t in todo}
    for rel in sorted(needed):
        check_render_cache(out_dir / rel, log)  # a damaged cached render is rendered again, not re-used forever
    renders = [r for r in plan.renders if r.rel_dir in needed and not (out_dir / r.rel_dir / "timeline.json").is_file()]
    for r in plan.renders:
        if r.rel_dir in needed and r not in renders:
            manifest.ren[r.rel_dir]["status"] = "complete"
    for r in renders:
        manifest.ren[r.rel_dir].update(status="pending", n_keyframes=None, timings={})
    manifest.save()
    outcome = GenerateResult(out_dir, manifest.data, [], skipped, [], [], 0.0, executor.kind)
    if skipped:
        log(f"{len(skipped)} of {len(plan.recordings)} recordings already complete")
    if not todo:
        return outcome

    ex = make_executor(executor, out_dir)
    outcome.executor = ex.describe()
    bar_k = tqdm(total=0, desc="keyframes", unit="kf", disable=not progress or not renders, position=0,
                 leave=True, dynamic_ncols=True)
    bar_s = tqdm(total=len(todo), desc="recordings", unit="rec", disable=not progress, position=1, leave=True,
                 dynamic_ncols=True)
    queue = TaskQueue(ex, log)
    books = _Books(manifest, outcome, queue, bar_s, log,
                   {r.rel_dir: manifest.ren[r.rel_dir].get("timings", {}).get("render_s") for r in plan.renders})
    for task in todo:
        if any(r.rel_dir == task.render_rel_dir for r in renders):
            books.waiting.setdefault(task.render_rel_dir, []).append(task)
        else:
            queue.add(SimulationJob(task))
    running_renders = {r.rel_dir: RenderJob(r, out_dir, ex.workers, bar_k, log) for r in renders}
    for render in running_renders.values():
        for job in render.start():
            queue.add(job)
    partial: dict[Job, int] = {}  # running render chunk -> its keyframes already written (shown on the bar)
    pending_renders = {r.rel_dir for r in renders}  # not finished (or failed) yet in this run
    clean_exit = False
    try:
        while queue.busy:
            for job, res in queue.finished():
                if isinstance(job, SimulationJob):
                    books.simulation_done(job.task, res)
                    bar_s.update(1)
                    manifest.save()
                    continue
                r = job.task
                render = running_renders[r.rel_dir]
                prefix_pending = r.prefix is not None and r.prefix.rel_dir in pending_renders
                for follow in render.on_result(job, res, shown=partial.pop(job, 0), prefix_pending=prefix_pending):
                    queue.add(follow)
                if render.outcome is None:
                    continue
                books.render_done(r, render.outcome)
                manifest.save()
                pending_renders.discard(r.rel_dir)
                for faster in running_renders.values():  # renders sharing this one's keyframes go on
                    if faster.task.prefix is not None and faster.task.prefix.rel_dir == r.rel_dir:
                        for follow in faster.release_shared():
                            queue.add(follow)
            if not bar_k.disable:
                show_written_keyframes(out_dir, queue.running.values(), running_renders, partial, bar_k)
        clean_exit = True
    finally:
        bar_k.close()
        bar_s.close()
        ex.close(cancel=not clean_exit)
    return outcome


def show_written_keyframes(out_dir: Path, running, renders: dict[str, RenderJob], partial: dict, bar) -> None:
    """Move the keyframe ``bar`` by the keyframes that ``running`` render chunks have written so far.

    A chunk reports when all its keyframes are done: at 512² and 64 spp a chunk of 64 office keyframes takes about
    an hour on one core, an hour with the bar at 0 and no ETA. Each keyframe is written under its final name when
    it is finished, so the files tell how far a chunk is (where the driver sees the workers' folder). ``renders``
    maps render directories to their :class:`~simspad.dataset.render_job.RenderJob`; ``partial`` (job ->
    keyframes counted) is updated; a faster speed's keyframes linked from a slower render are left to their
    chunk's end, when they join the bar's total.
    """
    listed: dict[Path, set] = {}  # one directory listing per folder and poll, not a stat per keyframe (cluster
    # file systems serve metadata slowly: 256 workers' chunks would be ~16 000 stats a second)

    def files_in(folder: Path) -> set:
        if folder not in listed:
            try:
                listed[folder] = set(os.listdir(folder))
            except OSError:  # not created yet
                listed[folder] = set()
        return listed[folder]

    for job in list(running):
        if not isinstance(job, ChunkJob):
            continue
        r, c = job.task, job.indices
        render = renders.get(r.rel_dir)
        if not c or render is None or not render.names or render.deferred.intersection(c):
            continue
        paths = [out_dir / r.rel_dir / render.names[i] for i in c]
        written = sum(p.name in files_in(p.parent) for p in paths)
        if written != partial.get(job, 0):
            bar.update(written - partial.get(job, 0))
            partial[job] = written


@dataclass
class _Books:
    """The driver's bookkeeping of finished renders and recordings: manifest entries, the outcome, the recordings
    waiting for a render (queued once it is done), the recordings bar."""

    manifest: ManifestState
    outcome: GenerateResult
    queue: TaskQueue
    bar_s: object
    log: Callable[[str], None]
    render_times: dict  # render rel_dir -> its render seconds (None: not rendered yet)
    waiting: dict = field(default_factory=dict)  # render rel_dir -> [RecordingTask] waiting for that render

    def render_done(self, task: RenderTask, res: RenderOutcome) -> None:
        entry = self.manifest.ren[task.rel_dir]
        entry["timings"] = {"render_s": round(res.seconds, 3), "host": res.host}
        dependants = self.waiting.pop(task.rel_dir, [])
        if res.ok:
            entry.update(status="complete", n_keyframes=res.n_keyframes)
            self.render_times[task.rel_dir] = entry["timings"]["render_s"]
            self.outcome.renders_done.append(task.rel_dir)
            for rec in dependants:
                self.queue.add(SimulationJob(rec))
            return
        entry.update(status="failed", error=res.error)
        self.log(f"render of {task.sequence.name} ×{task.speed_factor:g} failed: {res.error}")
        for rec in dependants:
            self.manifest.rec[rec.rel_path].update(status="failed", error=f"render failed: {res.error}")
            self.outcome.failed.append(rec.rel_path)
            self.bar_s.update(1)

    def simulation_done(self, task: RecordingTask, res: SimulationResult | JobFailure) -> None:
        entry = self.manifest.rec[task.rel_path]
        timings = {"simulate_s": round(res.seconds, 3), "host": res.host}
        if self.render_times.get(task.render_rel_dir) is not None:
            timings["render_s_shared"] = self.render_times[task.render_rel_dir]
        entry["timings"] = timings
        if isinstance(res, SimulationResult):
            entry.update(status="complete", size=res.size, sha256=res.sha256)
            if res.motion:
                entry["motion"] = res.motion
            entry.pop("error", None)
            self.outcome.done.append(task.rel_path)
        else:
            entry.update(status="failed", error=res.error)
            self.outcome.failed.append(task.rel_path)
            self.log(f"{task.rel_path} failed: {res.error}")
