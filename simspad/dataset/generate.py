"""Dataset generation (``simspad generate``): render each sequence once per speed, simulate every
sequence × speed × lux.

The job is a small dependency graph run by an executor (:mod:`simspad.dataset.executors`) through the driver's
:class:`~simspad.dataset.task_queue.TaskQueue`: one render per (sequence, speed) (shared by all lux levels and
sensors) into ``<out>/renders/<sequence>[_x<k>]-<hash>/`` — a plan task, then chunks of keyframes spread over every
worker, then ``timeline.json`` written here once every chunk is back — then one simulation per (sequence, speed,
lux) into ``<out>/recordings/<sequence>/<sequence>[_x<k>]_<lux>lx.h5``, which also states the image motion
measured on its render (:mod:`simspad.render.image_motion`). Keyframes are written under their final names (each
atomically), so a killed run's keyframes are kept and the next run renders only the missing ones. The driver (this
module, in the calling process, with :mod:`~simspad.dataset.manifest_state`) is the only writer of
``manifest.json``, which it rewrites atomically as results arrive.

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
from typing import Any, Callable

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
from simspad.dataset.task_queue import Job, TaskQueue
from simspad.errors import SimSpadError
from simspad.io.atomic import ensure_writable_dir
from simspad.io.manifest import recording_is_complete
from simspad.render.render_layout import RenderLayout, chunk_size_for, keyframe_chunks
from simspad.render.renderer import finalize_render, with_warp_results
from simspad.render.warp.schedule import anchor_indices


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
    render_times = {r.rel_dir: manifest.ren[r.rel_dir].get("timings", {}).get("render_s") for r in plan.renders}
    waiting = {}  # render rel_dir -> [RecordingTask] waiting for that render
    queue = TaskQueue(ex, log)
    for task in todo:
        if any(r.rel_dir == task.render_rel_dir for r in renders):
            waiting.setdefault(task.render_rel_dir, []).append(task)
        else:
            queue.add(_simulation_job(ex, task))
    for r in renders:
        queue.add(Job("plan", r, lambda r=r: ex.submit_render_plan(r), label=f"the render plan of {r.sequence.name}"))
    chunked: dict[str, _ChunkedRender] = {}
    partial: dict[Job, int] = {}  # running render chunk -> its keyframes already written (shown on the bar)
    pending_renders = {r.rel_dir for r in renders}  # not finished (or failed) yet in this run
    clean_exit = False
    try:
        while queue.busy:
            for job, res in queue.finished():
                if job.kind == "sim":
                    _simulation_done(manifest, job.payload, res, render_times, outcome, log)
                    bar_s.update(1)
                    manifest.save()
                    continue
                if job.kind == "plan":
                    r = job.payload
                    if not res.get("ok"):
                        _render_done(manifest, r, res, waiting, queue, ex, outcome, render_times, bar_s, log)
                        manifest.save()
                        pending_renders.discard(r.rel_dir)
                        _release_shared(queue, ex, r.rel_dir, chunked, renders)
                        continue
                    state = chunked[r.rel_dir] = _ChunkedRender(res["plan"], seconds=res.get("seconds", 0.0),
                                                                host=res.get("host"),
                                                                names=tuple(res["plan"]["names"]))
                    existing = set(res.get("existing", ()))
                    planned = RenderLayout.from_dict(res["plan"])
                    warp, n_shared = planned.warp, planned.n_shared
                    # A warp render renders its anchors (and a noise probe) first, then synthesizes between them.
                    wanted = (anchor_indices(res["n_keyframes"], warp["stride"]) if warp
                              else range(res["n_keyframes"]))
                    todo_kf = [i for i in wanted if i not in existing]
                    if existing:
                        log(f"render of {r.sequence.name}: {len(existing)} of {res['n_keyframes']} keyframes "
                            "already there (kept from an interrupted run)")
                    n_todo = res["n_keyframes"] - (len(wanted) - len(todo_kf))
                    if (r.prefix is not None and r.prefix.rel_dir in pending_renders
                            and any(i < n_shared for i in todo_kf)):
                        # The slower render is still running: its keyframes are linked once it is done. They
                        # join the bar's total only then: counted now, the ETA would price them as renders.
                        state.shared = [i for i in todo_kf if i < n_shared]
                        state.deferred = set(state.shared)
                        todo_kf = [i for i in todo_kf if i >= n_shared]
                        state.left += 1
                    bar_k.total += n_todo - len(state.deferred)
                    bar_k.refresh()
                    state.left += _submit_chunks(queue, ex, r, res["plan"], todo_kf)
                    if warp:
                        state.anchors = list(wanted)
                    # Every render gets a noise probe (keyframe 0 again with the next seed): the warps are judged
                    # against it, and timeline.json and every recording state the render-noise budget from it.
                    state.left += 1
                    queue.add(Job("chunk", (r, []), lambda r=r, p=res["plan"]: ex.submit_noise_probe(r, p),
                                  label=f"the noise probe of {r.sequence.name}"))
                else:
                    r, c = job.payload
                    state = chunked[r.rel_dir]
                    state.left -= 1
                    state.seconds += res.get("seconds", 0.0)
                    shown = partial.pop(job, 0)  # its keyframes the bar already counts from their files
                    if res.get("ok"):
                        if job.kind == "warp":
                            state.warp_chunks.append(res["warp"])
                            bar_k.update(c[-1] - c[0] + 1 - len(c))  # the keyframes between its anchors
                        else:
                            bar_k.total += len(state.deferred.intersection(c))
                            bar_k.update(len(c) - shown)
                    else:
                        bar_k.update(-shown)
                        if state.error is None:
                            state.error = res.get("error")
                if state.left == 0 and state.anchors and not state.warp_started and state.error is None:
                    state.warp_started = True
                    _submit_warp_chunks(queue, ex, r, state)
                elif state.left == 0:
                    final = _finish_render(out_dir, r, state)
                    _render_done(manifest, r, final, waiting, queue, ex, outcome, render_times, bar_s, log)
                    manifest.save()
                    pending_renders.discard(r.rel_dir)
                    _release_shared(queue, ex, r.rel_dir, chunked, renders)
            if not bar_k.disable:
                show_written_keyframes(out_dir, queue.running.values(), chunked, partial, bar_k)
        clean_exit = True
    finally:
        bar_k.close()
        bar_s.close()
        ex.close(cancel=not clean_exit)
    return outcome


def show_written_keyframes(out_dir: Path, running, chunked: dict, partial: dict, bar) -> None:
    """Move the keyframe ``bar`` by the keyframes that ``running`` render chunks have written so far.

    A chunk reports when all its keyframes are done: at 512² and 64 spp a chunk of 64 office keyframes takes about
    an hour on one core, an hour with the bar at 0 and no ETA. Each keyframe is written under its final name when
    it is finished, so the files tell how far a chunk is (where the driver sees the workers' folder). ``partial``
    (job -> keyframes counted) is updated; a faster speed's keyframes linked from a slower render are left to
    their chunk's end, when they join the bar's total.
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
        if job.kind != "chunk":
            continue
        r, c = job.payload
        state = chunked.get(r.rel_dir)
        if not c or state is None or not state.names or state.deferred.intersection(c):
            continue
        paths = [out_dir / r.rel_dir / state.names[i] for i in c]
        written = sum(p.name in files_in(p.parent) for p in paths)
        if written != partial.get(job, 0):
            bar.update(written - partial.get(job, 0))
            partial[job] = written


@dataclass
class _ChunkedRender:
    """A planned render whose chunks of keyframes are running."""

    plan: dict
    seconds: float = 0.0  # summed over the plan and every chunk (worker time)
    host: Any = None
    left: int = 0  # chunks not finished yet
    error: str | None = None  # first chunk error
    anchors: list = field(default_factory=list)  # a warp render's anchors (empty: linear)
    warp_started: bool = False  # its synthesis chunks are submitted
    warp_chunks: list = field(default_factory=list)  # what they reported (chunk_result)
    shared: list | None = None  # keyframes to link from the slower render once it is done (None: none waiting)
    deferred: set = field(default_factory=set)  # those keyframes: outside the bar's total until their chunk is done
    names: tuple = ()  # keyframe files relative to the render directory (the plan's)


def _submit_chunks(queue, ex, r: RenderTask, plan: dict, indices: list[int]) -> int:
    """Queue ``indices`` of a planned render in chunks over the workers; returns the number of chunks."""
    chunks = keyframe_chunks(indices, chunk_size_for(len(indices), ex.workers))
    for c in chunks:
        queue.add(Job("chunk", (r, c), lambda r=r, c=c, p=plan: ex.submit_render_chunk(r, p, c),
                      label=f"keyframes {c[0]}–{c[-1]} of {r.sequence.name}"))
    return len(chunks)


def _release_shared(queue, ex, done_rel_dir: str, chunked: dict, renders) -> None:
    """The render ``done_rel_dir`` finished (or failed): the faster renders waiting for its keyframes get their
    shared chunks now (linked where its files are, rendered where they are not)."""
    for r in renders:
        state = chunked.get(r.rel_dir)
        if r.prefix is None or r.prefix.rel_dir != done_rel_dir or state is None or state.shared is None:
            continue
        shared, state.shared = state.shared, None
        state.left += _submit_chunks(queue, ex, r, state.plan, shared) - 1


def _submit_warp_chunks(queue, ex, r: RenderTask, state: _ChunkedRender) -> None:
    """A warp render's second phase: runs of consecutive segments between anchors spread over the workers (the
    segments are independent once their anchors and the noise probe exist)."""
    anchors = state.anchors
    groups = keyframe_chunks(range(len(anchors) - 1), chunk_size_for(len(anchors) - 1, ex.workers, largest=8))
    state.left = len(groups)
    for g in groups:
        a = anchors[g[0]:g[-1] + 2]
        queue.add(Job("warp", (r, a), lambda r=r, a=a, p=state.plan: ex.submit_warp_chunk(r, p, a),
                      label=f"synthesis of keyframes {a[0]}–{a[-1]} of {r.sequence.name}"))


def _finish_render(out_dir: Path, task: RenderTask, state: _ChunkedRender) -> dict:
    """Once every chunk is back: ``timeline.json`` (in the driver; it needs no Mitsuba), or the first error."""
    res = {"ok": False, "seconds": state.seconds, "host": state.host, "error": state.error}
    if state.error is None:
        try:
            render_plan = RenderLayout.from_dict(state.plan)
            if state.anchors:
                render_plan = with_warp_results(render_plan, state.warp_chunks)
            finalize_render(render_plan, out_dir / task.rel_dir)
            res.update(ok=True, n_keyframes=render_plan.n_keyframes)
        except SimSpadError as exc:
            res["error"] = exc.format().replace("\n", "; ")
    return res


def _simulation_job(ex, task: RecordingTask) -> Job:
    return Job("sim", task, lambda: ex.submit_simulation(task), label=task.rel_path)


def _render_done(manifest, task: RenderTask, res, waiting, queue, ex, outcome, render_times, bar_s, log) -> None:
    entry = manifest.ren[task.rel_dir]
    entry["timings"] = {"render_s": round(res.get("seconds", 0.0), 3), "host": res.get("host")}
    dependants = waiting.pop(task.rel_dir, [])
    if res.get("ok"):
        entry.update(status="complete", n_keyframes=res.get("n_keyframes"))
        render_times[task.rel_dir] = entry["timings"]["render_s"]
        outcome.renders_done.append(task.rel_dir)
        for rec in dependants:
            queue.add(_simulation_job(ex, rec))
        return
    entry.update(status="failed", error=res.get("error"))
    log(f"render of {task.sequence.name} ×{task.speed_factor:g} failed: {res.get('error')}")
    for rec in dependants:
        manifest.rec[rec.rel_path].update(status="failed", error=f"render failed: {res.get('error')}")
        outcome.failed.append(rec.rel_path)
        bar_s.update(1)


def _simulation_done(manifest, task: RecordingTask, res, render_times, outcome, log) -> None:
    entry = manifest.rec[task.rel_path]
    timings = {"simulate_s": round(res.get("seconds", 0.0), 3), "host": res.get("host")}
    if render_times.get(task.render_rel_dir) is not None:
        timings["render_s_shared"] = render_times[task.render_rel_dir]
    entry["timings"] = timings
    if res.get("ok"):
        entry.update(status="complete", size=res["size"], sha256=res["sha256"])
        if res.get("motion"):
            entry["motion"] = res["motion"]
        entry.pop("error", None)
        outcome.done.append(task.rel_path)
    else:
        entry.update(status="failed", error=res.get("error"))
        outcome.failed.append(task.rel_path)
        log(f"{task.rel_path} failed: {res.get('error')}")
