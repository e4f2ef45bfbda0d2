"""Dataset generation (``simspad generate``): render each sequence once, simulate every sequence × lux.

The job is a small dependency graph run by an executor (:mod:`simspad.dataset.executors`): one render per sequence
(shared by all lux levels and sensors) into ``<out>/renders/<sequence>-<hash>/``, then one simulation per
(sequence, lux) into ``<out>/recordings/<sequence>/<sequence>_<lux>lx.h5``. The driver (this module, in the
calling process) is the only writer of ``manifest.json``, which it rewrites atomically as results arrive.

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

import dataclasses
import fcntl
import os
import re
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from simspad import __version__
from simspad.errors import SimSpadError
from simspad.io.atomic import ensure_writable_dir
from simspad.io.manifest import (
    FORMAT,
    VERSION,
    manifest_path,
    read_manifest,
    recording_is_complete,
    utc_now,
    write_manifest,
)
from simspad.io.provenance import source_date_epoch

LOCK_NAME = ".simspad.lock"
RENDERS_DIR = "renders"
RECORDINGS_DIR = "recordings"
#: Bump when the job's output for an unchanged spec would change (part of every recording and render hash).
JOB_SCHEME_VERSION = 1
#: Temporary names written by simspad.io.atomic.temporary_sibling: ``.<name>.tmp-<pid>-<8 hex>``.
_TMP_NAME = re.compile(r"^\..+\.tmp-\d+-[0-9a-f]{8}$")


# ----------------------------------------------------------------------------------------------------------------
# Plan


@dataclass(frozen=True)
class RenderTask:
    """One render: a sequence into ``<out>/<rel_dir>`` with Monte Carlo seed ``seed``."""

    sequence: Any  # simspad.dataset.spec.SequenceSpec
    render_hash: str
    rel_dir: str
    seed: int


@dataclass(frozen=True)
class RecordingTask:
    """One simulation: a (sequence, lux) recording at ``<out>/<rel_path>`` from the render ``render_rel_dir``."""

    sequence_name: str
    scene: str
    lux: float
    rel_path: str
    render_rel_dir: str
    recording_hash: str
    sensors: tuple  # ((kind, params dataclass), ...)
    start_s: float
    duration_s: float
    seed: int
    stream_key: tuple
    gt_rate_hz: float
    optics: Any  # simspad.physics.radiometry.Optics
    metadata: tuple  # ((key, value), ...): root attrs of the recording


@dataclass(frozen=True)
class Plan:
    renders: tuple[RenderTask, ...]
    recordings: tuple[RecordingTask, ...]


def lux_label(lux: float) -> str:
    """The lux level as it appears in file names: ``1``, ``10000``, ``0.5``."""
    lux = float(lux)
    return str(int(lux)) if lux.is_integer() and abs(lux) < 1e15 else repr(lux)


def recording_rel_path(sequence_name: str, lux: float) -> str:
    """``recordings/<sequence>/<sequence>_<lux>lx.h5``."""
    return f"{RECORDINGS_DIR}/{sequence_name}/{sequence_name}_{lux_label(lux)}lx.h5"


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"simspad": __version__, "job_scheme": str(JOB_SCHEME_VERSION)}
    for pkg in ("mitsuba", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "absent"
    return out


def _render_seed(dataset_seed: int, sequence_name: str) -> int:
    from simspad.physics.seeding import child_seed

    return int(child_seed(dataset_seed, sequence_name, "render").generate_state(1)[0])


def _scene_name(scene: str) -> str:
    from simspad.scenes.library import resolve_scene

    return resolve_scene(scene).name


def make_plan(spec, created_utc: str) -> Plan:
    """Every render and recording of ``spec``, with the hashes that decide whether each must be (re)done.

    Resolving the scenes and hashing the scene and trajectory files happens here, in the calling process, so
    an unknown scene or a missing file fails before any work starts.
    """
    from simspad.dataset.spec import canonical_json, sequence_hash, spec_hash
    from simspad.physics.radiometry import Optics

    versions = _versions()
    optics = Optics()
    sensors = tuple((kind, s.params) for kind, s in spec.sensors.items())
    sensors_dict = {kind: s.to_dict() for kind, s in spec.sensors.items()}
    renders, recordings = [], []
    for seq in spec.sequences:
        seed = _render_seed(spec.seed, seq.name)
        render_hash = spec_hash({"render": sequence_hash(seq), "seed": seed, "versions": versions})
        render = RenderTask(seq, render_hash, f"{RENDERS_DIR}/{seq.name}-{render_hash[:12]}", seed)
        renders.append(render)
        seq_hash = sequence_hash(seq, spec)
        scene = _scene_name(seq.scene)
        for lux in spec.lux:
            lux = float(lux)
            stream_key = (seq.name, lux)
            # What the file depends on; stored in the recording as its "spec" attr, so the hash and the file agree.
            rec_spec = {"dataset": spec.name, "seed": spec.seed, "sequence": seq.to_dict(), "lux": lux,
                        "stream_key": list(stream_key), "sensors": sensors_dict,
                        "evaluation": spec.evaluation.to_dict(), "optics": dataclasses.asdict(optics)}
            rec_hash = spec_hash({"dataset": spec.name, "sequence": seq_hash, "render": render_hash, "lux": lux,
                                  "stream_key": list(stream_key), "optics": dataclasses.asdict(optics),
                                  "versions": versions})
            metadata = {"sequence": seq.name, "scene": scene, "dataset": spec.name, "spec": canonical_json(rec_spec), "recording_hash": rec_hash,
                        "created_utc": created_utc}
            recordings.append(RecordingTask(
                sequence_name=seq.name, scene=scene, lux=lux, rel_path=recording_rel_path(seq.name, lux),
                render_rel_dir=render.rel_dir, recording_hash=rec_hash, sensors=sensors, start_s=seq.start_s,
                duration_s=seq.duration_s, seed=spec.seed, stream_key=stream_key,
                gt_rate_hz=spec.evaluation.rate_hz, optics=optics, metadata=tuple(sorted(metadata.items()))))
    return Plan(tuple(renders), tuple(recordings))


# ----------------------------------------------------------------------------------------------------------------
# Lock and cleanup


class DatasetLock:
    """``fcntl.flock`` on ``<out>/.simspad.lock`` for the whole run: a second run on the same directory is
    refused at once with a clear message. The kernel releases the lock when the process dies, even by kill -9."""

    def __init__(self, out_dir: Path):
        self.path = Path(out_dir) / LOCK_NAME
        self.fd: int | None = None

    def __enter__(self) -> "DatasetLock":
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 200).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise SimSpadError(f"another `simspad generate` is already writing this dataset ({holder}); wait for "
                               "it to finish or choose another --out", path=self.path.parent) from None
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} on {os.uname().nodename} since {utc_now()}\n".encode())
        self.fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = None


def remove_temporaries(out_dir: Path) -> list[Path]:
    """Delete the temporary files and folders a killed run left behind (``.<name>.tmp-<pid>-<hex>``)."""
    removed = []
    roots = [out_dir, out_dir / RENDERS_DIR, out_dir / RECORDINGS_DIR]
    rec_root = out_dir / RECORDINGS_DIR
    if rec_root.is_dir():
        roots += [p for p in rec_root.iterdir() if p.is_dir()]
    for root in roots:
        if not root.is_dir():
            continue
        for p in root.iterdir():
            if _TMP_NAME.match(p.name):
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
                removed.append(p)
    return removed


# ----------------------------------------------------------------------------------------------------------------
# Manifest bookkeeping


def _created_utc(previous: dict | None, override: str | None) -> str:
    if override:
        return override
    pinned = source_date_epoch()
    if pinned:
        return pinned
    if previous and isinstance(previous.get("created_utc"), str):
        return previous["created_utc"]
    return utc_now()


def _load_previous(out_dir: Path) -> dict | None:
    if not manifest_path(out_dir).exists():
        return None
    return read_manifest(out_dir)  # InputError for a foreign or corrupt manifest: do not overwrite someone's data


class _Manifest:
    """The manifest being built: entries keyed by path, rewritten atomically on every change."""

    def __init__(self, out_dir: Path, spec, plan: Plan, created_utc: str, previous: dict | None):
        from simspad.dataset.spec import spec_hash

        self.out_dir = out_dir
        old = {e["path"]: e for e in (previous or {}).get("recordings", [])}
        old_renders = {e.get("path"): e for e in (previous or {}).get("renders", []) if isinstance(e, dict)}
        self.data = {"format": FORMAT, "version": VERSION, "name": spec.name, "spec": spec.to_dict(),
                     "spec_hash": spec_hash(spec), "seed": spec.seed, "created_utc": created_utc,
                     "updated_utc": utc_now(), "simspad_version": __version__,
                     "source": str(spec.source_path) if spec.source_path else None,
                     "recordings": [], "renders": []}
        self.rec = {}
        for task in plan.recordings:
            entry = {"sequence": task.sequence_name, "scene": task.scene, "lux": task.lux, "path": task.rel_path,
                     "size": None, "sha256": None, "status": "pending", "recording_hash": task.recording_hash,
                     "render": task.render_rel_dir, "timings": {}}
            prev = old.get(task.rel_path)
            if prev and prev.get("recording_hash") == task.recording_hash and prev.get("status") == "complete":
                for key in ("size", "sha256", "status", "timings"):
                    entry[key] = prev.get(key)
            self.rec[task.rel_path] = entry
            self.data["recordings"].append(entry)
        self.ren = {}
        for task in plan.renders:
            prev = old_renders.get(task.rel_dir) or {}
            entry = {"sequence": task.sequence.name, "scene": _scene_name(task.sequence.scene), "path": task.rel_dir,
                     "render_hash": task.render_hash, "status": prev.get("status", "pending"),
                     "n_keyframes": prev.get("n_keyframes"), "timings": prev.get("timings", {})}
            self.ren[task.rel_dir] = entry
            self.data["renders"].append(entry)
        self.obsolete_recordings = [p for p in old if p not in self.rec]
        self.obsolete_renders = [p for p in old_renders if p not in self.ren]

    def save(self) -> None:
        self.data["updated_utc"] = utc_now()
        write_manifest(self.out_dir, self.data)


# ----------------------------------------------------------------------------------------------------------------
# Driver


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
    executor: str


def generate(spec, out_dir=None, executor: str = "local", scheduler: str | None = None, workers: int | None = None,
             progress: bool = True, *, created_utc: str | None = None, log: Callable[[str], None] | None = None,
             result: bool = False, check: bool = True):
    """Generate (or finish) a dataset.

    Parameters
    ----------
    spec : DatasetSpec or str or Path
        The validated spec, or the path of a spec TOML.
    out_dir : str or Path, optional
        Dataset folder (default ``spec.output``).
    executor : {"local", "dask"}
    scheduler : str, optional
        Dask scheduler address (``tcp://host:8786``); none with ``executor="dask"`` starts a LocalCluster.
    workers : int, optional
        Simulation processes (local) or LocalCluster workers (dask); default: the usable core count.
    progress : bool
        Show tqdm progress bars on stderr.
    created_utc : str, optional
        The ``created_utc`` of a new dataset (default ``$SOURCE_DATE_EPOCH``, else the manifest's, else now).
    log : callable, optional
        Receives one-line notices (default: print to stderr when ``progress``).
    result : bool
        Return a :class:`GenerateResult` instead of the folder.
    check : bool
        Raise :class:`SimSpadError` if any recording failed (after the manifest records why).

    Returns
    -------
    Path or GenerateResult
        The dataset folder (holding ``manifest.json``).

    Raises
    ------
    SimSpadError
        Bad spec, a concurrent run on ``out_dir``, or recordings that failed (listed in the manifest).
    """
    from simspad.dataset.executors import check_executor_options
    from simspad.dataset.spec import DatasetSpec, load_spec

    t_start = time.perf_counter()
    check_executor_options(executor, scheduler, workers)
    if not isinstance(spec, DatasetSpec):
        spec = load_spec(spec)
    out_dir = Path(out_dir if out_dir is not None else spec.output).expanduser().resolve()
    if log is None:
        log = (lambda msg: print(msg, file=sys.stderr, flush=True)) if progress else (lambda msg: None)
    ensure_writable_dir(out_dir, what="dataset output")
    with DatasetLock(out_dir):
        for p in remove_temporaries(out_dir):
            log(f"removed temporary {p.relative_to(out_dir)} left by an interrupted run")
        previous = _load_previous(out_dir)
        created = _created_utc(previous, created_utc)
        plan = make_plan(spec, created)
        manifest = _Manifest(out_dir, spec, plan, created, previous)
        _remove_obsolete(out_dir, manifest, log)
        outcome = _run(out_dir, plan, manifest, executor, scheduler, workers, progress, log)
    outcome.wall_s = time.perf_counter() - t_start
    if check:
        raise_for_failures(outcome)
    return outcome if result else out_dir


def raise_for_failures(outcome: "GenerateResult") -> None:
    """:class:`SimSpadError` naming the first failed recording, if any failed."""
    if not outcome.failed:
        return
    entries = {e["path"]: e for e in outcome.manifest["recordings"]}
    first = entries[outcome.failed[0]]
    raise SimSpadError(f"{len(outcome.failed)} of {len(entries)} recordings failed; first: {first['path']}: "
                       f"{first.get('error', 'unknown error')} (details in manifest.json; re-run to retry)",
                       path=outcome.out_dir)


def _remove_obsolete(out_dir: Path, manifest: _Manifest, log) -> None:
    """Recordings and renders of the previous manifest that the new spec no longer has are deleted, so the
    folder holds exactly the dataset its manifest describes."""
    for rel in manifest.obsolete_recordings:
        p = out_dir / rel
        if p.is_file():
            p.unlink()
            log(f"removed {rel} (no longer in the spec)")
    for rel in manifest.obsolete_renders:
        p = out_dir / rel
        if rel and p.is_dir() and p.parent == out_dir / RENDERS_DIR:
            shutil.rmtree(p, ignore_errors=True)


def _run(out_dir: Path, plan: Plan, manifest: _Manifest, executor_kind, scheduler, workers, progress, log):
    from tqdm import tqdm

    from simspad.dataset.executors import make_executor

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
    renders = [r for r in plan.renders if r.rel_dir in needed and not (out_dir / r.rel_dir / "timeline.json").is_file()]
    for r in plan.renders:
        if r.rel_dir in needed and r not in renders:
            manifest.ren[r.rel_dir]["status"] = "complete"
    for r in renders:
        manifest.ren[r.rel_dir].update(status="pending", n_keyframes=None, timings={})
    manifest.save()
    outcome = GenerateResult(out_dir, manifest.data, [], skipped, [], [], 0.0, executor_kind)
    if skipped:
        log(f"{len(skipped)} of {len(plan.recordings)} recordings already complete")
    if not todo:
        return outcome

    render_mp_spp = max((r.sequence.resolution[0] * r.sequence.resolution[1] * r.sequence.spp / 1e6
                         for r in renders), default=0.0)
    ex = make_executor(executor_kind, out_dir, scheduler=scheduler, workers=workers, render_mp_spp=render_mp_spp)
    outcome.executor = ex.describe()
    bar_r = tqdm(total=len(renders), desc="renders", unit="seq", disable=not progress or not renders, position=0,
                 leave=True, dynamic_ncols=True)
    bar_s = tqdm(total=len(todo), desc="recordings", unit="rec", disable=not progress, position=1, leave=True,
                 dynamic_ncols=True)
    render_times = {r.rel_dir: manifest.ren[r.rel_dir].get("timings", {}).get("render_s") for r in plan.renders}
    waiting = {}  # render rel_dir -> [RecordingTask] waiting for that render
    ready = []    # simulations whose render exists, not yet submitted
    for task in todo:
        if any(r.rel_dir == task.render_rel_dir for r in renders):
            waiting.setdefault(task.render_rel_dir, []).append(task)
        else:
            ready.append(task)
    running: dict[Any, tuple[str, Any]] = {}
    clean_exit = False
    try:
        for r in renders:
            running[ex.submit_render(r)] = ("render", r)
        while running or ready:
            renders_running = sum(1 for kind, _ in running.values() if kind == "render")
            sims_running = len(running) - renders_running
            while ready and sims_running < ex.sim_slots(renders_running):
                task = ready.pop(0)
                running[ex.submit_simulation(task)] = ("sim", task)
                sims_running += 1
            for fut in ex.wait(list(running)):
                kind, task = running.pop(fut)
                res = ex.result(fut)
                if kind == "render":
                    _render_done(manifest, task, res, waiting, ready, outcome, render_times, bar_s, log)
                    bar_r.update(1)
                else:
                    _simulation_done(manifest, task, res, render_times, outcome, log)
                    bar_s.update(1)
                manifest.save()
        clean_exit = True
    finally:
        bar_r.close()
        bar_s.close()
        ex.close(cancel=not clean_exit)
    return outcome


def _render_done(manifest, task: RenderTask, res, waiting, ready, outcome, render_times, bar_s, log) -> None:
    entry = manifest.ren[task.rel_dir]
    entry["timings"] = {"render_s": round(res.get("seconds", 0.0), 3), "host": res.get("host")}
    dependants = waiting.pop(task.rel_dir, [])
    if res.get("ok"):
        entry.update(status="complete", n_keyframes=res.get("n_keyframes"))
        render_times[task.rel_dir] = entry["timings"]["render_s"]
        outcome.renders_done.append(task.rel_dir)
        ready.extend(dependants)
        return
    entry.update(status="failed", error=res.get("error"))
    log(f"render of {task.sequence.name} failed: {res.get('error')}")
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
        entry.pop("error", None)
        outcome.done.append(task.rel_path)
    else:
        entry.update(status="failed", error=res.get("error"))
        outcome.failed.append(task.rel_path)
        log(f"{task.rel_path} failed: {res.get('error')}")


# ----------------------------------------------------------------------------------------------------------------
# Summary and CLI


def _fmt_bytes(n: int | None) -> str:
    if n is None:
        return "-"
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"


def summary_table(res: GenerateResult) -> str:
    """The closing summary: one row per recording (status, size, time), totals and where the files are."""
    recs = res.manifest["recordings"]
    done, skipped = set(res.done), set(res.skipped)
    rows = [("sequence", "lux", "status", "size", "simulate", "")]
    for e in recs:
        note = "new" if e["path"] in done else ("kept" if e["path"] in skipped else "")
        t = e.get("timings", {}).get("simulate_s")
        rows.append((e["sequence"], f"{e['lux']:g}", e["status"], _fmt_bytes(e.get("size")),
                     "-" if t is None else f"{t:.1f} s", note))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) if i in (0, 2, 5) else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
             .rstrip() for r in rows]
    lines.insert(1, "-" * len(lines[0]))
    total = sum(e.get("size") or 0 for e in recs)
    n_complete = sum(e["status"] == "complete" for e in recs)
    render_s = sum((r.get("timings") or {}).get("render_s") or 0 for r in res.manifest["renders"]
                   if r["path"] in set(res.renders_done))
    lines += ["",
              f"{n_complete} of {len(recs)} recordings complete ({len(res.done)} generated, {len(res.skipped)} "
              f"already there), {_fmt_bytes(total)} in all; {len(res.renders_done)} render(s) took {render_s:.1f} s",
              f"wall time {res.wall_s:.1f} s on {res.executor}",
              f"dataset:  {res.out_dir}",
              f"manifest: {manifest_path(res.out_dir)}"]
    return "\n".join(lines)


def generate_from_cli(spec_path=None, out_dir=None, executor: str = "local", scheduler: str | None = None,
                      workers: int | None = None) -> Path:
    """``simspad generate``: load the spec (default ``datasets/mini.toml``), run, print the summary table."""
    from simspad.dataset.spec import default_spec_path, load_spec

    spec = load_spec(spec_path if spec_path is not None else default_spec_path())
    res = generate(spec, out_dir=out_dir, executor=executor, scheduler=scheduler, workers=workers, progress=True,
                   result=True, check=False)
    print(summary_table(res), flush=True)
    raise_for_failures(res)
    return res.out_dir
