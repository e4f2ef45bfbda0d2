"""Where dataset work runs: worker-side job functions and the ``local`` and ``dask`` executors.

:func:`run_job` runs one job of :mod:`simspad.dataset.jobs` inside a worker process (a local pool process or a
Dask worker, possibly on another machine) through the job kind's function (:func:`run_render_layout`,
:func:`run_render_chunk`, :func:`run_noise_probe`, :func:`run_warp_chunk`, :func:`run_simulation`). Each
applies the job's environment (``DRJIT_LIBLLVM_PATH``) before Mitsuba is imported, chooses the Mitsuba variant
inside the worker, writes its output atomically, and never raises: it returns its kind's result dataclass, or a
:class:`~simspad.dataset.jobs.JobFailure` with a one-line ``error``, so an exception that does not pickle cannot
hang the job.

Executors expose one small interface used by the driver (:mod:`simspad.dataset.generate`, through
:class:`~simspad.dataset.task_queue.TaskQueue`): ``submit(job) -> future``, ``wait(futures) -> done``,
``result(future) -> JobResult`` (a :class:`~simspad.dataset.jobs.JobFailure` with ``died=True`` where the worker
process died), ``slots()`` (how many jobs may run at once), ``workers``, ``describe()`` and ``close()``.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import os
import signal
import socket
import sys
import threading
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from simspad import defaults
from simspad.dataset.fault_injection import maybe_inject_fault
from simspad.dataset.jobs import (
    RENDER_JOBS,
    ChunkJob,
    ChunkResult,
    Job,
    JobFailure,
    JobResult,
    LayoutJob,
    LayoutResult,
    ProbeJob,
    ProbeResult,
    SimulationJob,
    SimulationResult,
    WarpJob,
    WarpResult,
)
from simspad.dataset.speed import sequence_trajectories
from simspad.errors import SimSpadError
from simspad.io.hashing import file_sha256
from simspad.processes import available_cores, die_with_parent_and_ignore_sigint, sigint_blocked
from simspad.render.image_motion import measure_image_motion, motion_attrs
from simspad.render.keyframe_files import make_out_dir
from simspad.render.mitsuba_env import select_variant
from simspad.render.render_layout import RenderLayout
from simspad.render.geometry import missing_geometry, owned_instants
from simspad.render.renderer import (
    build_convergence_cache,
    link_shared_keyframes,
    load_scene,
    layout_render,
    render_keyframes,
    render_missing_geometry,
)
from simspad.render.settings import RenderSettings
from simspad.render.warp.rendering import chunk_result, render_noise_probe, render_with_warps
from simspad.sensors.presets import SpadParams
from simspad.sensors.simulate import simulate_recording

#: Environment variables forwarded to workers (set before Mitsuba/Dr.Jit is imported there): the same libLLVM
#: and variant everywhere, so renders are bit-identical whichever worker runs them.
FORWARDED_ENV = ("DRJIT_LIBLLVM_PATH", "SIMSPAD_MITSUBA_VARIANT")
_DEBIAN_LIBLLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


def job_environment() -> dict[str, str]:
    """The environment the workers need: ``DRJIT_LIBLLVM_PATH`` from ours, or the Debian libLLVM if present."""
    env = {k: os.environ[k] for k in FORWARDED_ENV if os.environ.get(k)}
    if "DRJIT_LIBLLVM_PATH" not in env and Path(_DEBIAN_LIBLLVM).exists():
        env["DRJIT_LIBLLVM_PATH"] = _DEBIAN_LIBLLVM
    return env


def _apply_environment(env: dict[str, str]) -> None:
    for key, value in env.items():
        os.environ.setdefault(key, value)


def run_job(job: Job, out_dir: str, env: dict[str, str], threads: int | None = None) -> JobResult:
    """Run ``job`` in this (worker) process with its kind's function; ``threads``: Dr.Jit threads of a render job
    (None: the Dask worker's own thread count, else every core). Never raises."""
    if isinstance(job, LayoutJob):
        return run_render_layout(job.task, out_dir, env)
    if isinstance(job, ChunkJob):
        return run_render_chunk(job.task, job.layout, job.indices, out_dir, env, threads)
    if isinstance(job, ProbeJob):
        return run_noise_probe(job.task, job.layout, out_dir, env, threads)
    if isinstance(job, WarpJob):
        return run_warp_chunk(job.task, job.layout, job.anchors, out_dir, env, threads)
    if isinstance(job, SimulationJob):
        return run_simulation(job.task, out_dir, env)
    return JobFailure(error=f"unknown job {type(job).__name__}")


def _error_result(exc: BaseException, t0: float) -> JobFailure:
    if isinstance(exc, SimSpadError):
        message = exc.format().replace("\n", "; ")
    else:
        message = f"{type(exc).__name__}: {exc}".replace("\n", " ")
    return JobFailure(error=message, traceback=traceback.format_exc(), seconds=time.perf_counter() - t0,
                      host=socket.gethostname())


def render_settings_of(task) -> RenderSettings:
    """The render task's settings: its sequence's (:meth:`~simspad.dataset.spec.SequenceSpec.render_settings`)
    with the task's seed and ground-truth rate."""
    return task.sequence.render_settings(task.seed, task.gt_rate_hz)


def _set_render_threads(threads: int | None) -> None:
    """Give Dr.Jit's thread pool ``threads`` threads (None: the Dask worker's own thread count, else every core),
    so render processes side by side do not oversubscribe the cores. Pixels do not depend on the thread count."""
    if threads is None:
        threads = default_workers()
        if "distributed" in sys.modules:  # inside a Dask worker: its nthreads is this task's share of the node
            with contextlib.suppress(Exception):
                threads = int(sys.modules["distributed"].get_worker().state.nthreads)
    with contextlib.suppress(Exception):
        import drjit as dr  # deferred: heavy, and only after the variant (and libLLVM path) is set

        dr.set_thread_count(max(1, int(threads)))


def run_render_layout(task, out_dir: str, env: dict[str, str]) -> LayoutResult | JobFailure:
    """Lay out the render of one sequence (stage 1, :func:`~simspad.render.renderer.layout_render`) and create its
    directory under ``<out_dir>/<task.rel_dir>``; keyframes already there (a killed run's) are kept and counted
    (:class:`~simspad.dataset.jobs.LayoutResult` ``existing``)."""
    t0 = time.perf_counter()
    try:
        _apply_environment(env)
        # Mitsuba loads here, after the job's libLLVM path is set; the variant is per process: set it inside the
        # worker, never inherit it.
        select_variant()
        final = Path(out_dir) / task.rel_dir
        layout = render_layout_of(task)
        make_out_dir(final)
        existing = tuple(i for i, name in enumerate(layout.names) if (final / name).is_file())
        if layout.timeline.get("renderer", {}).get("convergence") and len(existing) < layout.n_keyframes:
            # One irradiance cache per render, built before the chunks start (they would each build it).
            build_convergence_cache(layout, _cached_scene(task.sequence, task.speed_factor, layout), final)
        return LayoutResult(layout=layout, existing=existing, seconds=time.perf_counter() - t0,
                            host=socket.gethostname())
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def render_layout_of(task, laid_out: dict | None = None) -> RenderLayout:
    """The keyframe layout of a render task: its sequence's trajectory retimed by the task's speed factor, its first
    keyframes those of its prefix (the next slower speed's render) when it has one (taken from ``laid_out``,
    layouts by render directory, when it is there)."""
    seq = task.sequence
    trajectory = sequence_trajectories(seq.scene, seq.trajectory, task.speed_factor)
    prefix = None
    if task.prefix is not None:
        prefix = (laid_out or {}).get(task.prefix.rel_dir) or render_layout_of(task.prefix, laid_out)
    scale = 1.0 if task.prefix is None else task.prefix.speed_factor / task.speed_factor
    return layout_render(seq.scene, trajectory, render_settings_of(task), spad_bin_s=SpadParams().bin_s,
                       prefix=prefix, prefix_time_scale=scale)


#: The scene this worker process loaded last: the next chunk of the same render skips the reload (a keyframe's
#: pixels depend only on its pose and the layout's seed, not on what this process rendered before).
_SCENE_CACHE: dict = {}


def _cached_scene(seq, speed_factor: float, layout: RenderLayout):
    key = (repr(seq.scene), repr(seq.trajectory), float(speed_factor), layout.width, layout.height, layout.spp,
           layout.variant, layout.scene_hash, layout.trajectory_hash)
    if key not in _SCENE_CACHE:
        _SCENE_CACHE.clear()
        trajectory = sequence_trajectories(seq.scene, seq.trajectory, speed_factor)
        _SCENE_CACHE[key] = load_scene(seq.scene, trajectory, layout.width, layout.height, layout.spp,
                                       layout.variant)
    return _SCENE_CACHE[key]


def run_render_chunk(task, layout: RenderLayout, indices: tuple[int, ...], out_dir: str, env: dict[str, str],
                     threads: int | None = None) -> ChunkResult | JobFailure:
    """Render the keyframes ``indices`` of a laid-out render (stage 2) into ``<out_dir>/<task.rel_dir>``, each
    written atomically under its final name, so a killed run keeps every keyframe it finished."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        _apply_environment(env)
        maybe_inject_fault(f"render:{task.sequence.name}:{indices[0]}")
        select_variant()
        _set_render_threads(threads)
        seq = task.sequence
        final = Path(out_dir) / task.rel_dir
        n_linked = 0 if task.prefix is None else link_shared_keyframes(layout, indices,
                                                                       Path(out_dir) / task.prefix.rel_dir, final)
        n_rendered, n_reused = 0, n_linked
        geometry = layout.timeline.get("geometry")
        geometry_todo = missing_geometry(geometry, owned_instants(layout.times_s, geometry, indices), final,
                                         layout.width, layout.height)
        if n_linked < len(indices) or geometry_todo:  # else nothing left to render: no scene to load
            done = render_keyframes(seq.scene, None, layout, indices, out_dir=final,
                                    loaded=_cached_scene(seq, task.speed_factor, layout))
            n_rendered, n_reused = len(done.frame_times_s), done.n_reused
        return ChunkResult(n_rendered=n_rendered, n_reused=n_reused, seconds=time.perf_counter() - t0,
                           cpu_s=time.process_time() - cpu0, pid=os.getpid(), host=socket.gethostname())
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def _warp_worker(task, layout: RenderLayout, env: dict[str, str], threads: int | None):
    """A worker's set-up for a render's probe and warp jobs: environment, variant, render threads; the scene
    (this process's cached one when it rendered the same sequence before)."""
    _apply_environment(env)
    select_variant()
    _set_render_threads(threads)
    return _cached_scene(task.sequence, task.speed_factor, layout)


def run_noise_probe(task, layout: RenderLayout, out_dir: str, env: dict[str, str],
                    threads: int | None = None) -> ProbeResult | JobFailure:
    """Render the noise probe of a laid-out render (:func:`~simspad.render.warp.rendering.render_noise_probe`:
    keyframe 0 again with the next seed; the warp schedule's noise reference and every render's noise budget) into
    ``<out_dir>/<task.rel_dir>``, unless it is there."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        loaded = _warp_worker(task, layout, env, threads)
        new = render_noise_probe(loaded.ms, loaded.ts, layout, Path(out_dir) / task.rel_dir)
        return ProbeResult(n_rendered=int(new), seconds=time.perf_counter() - t0, cpu_s=time.process_time() - cpu0,
                           host=socket.gethostname())
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def run_warp_chunk(task, layout: RenderLayout, anchors: tuple[int, ...], out_dir: str, env: dict[str, str],
                   threads: int | None = None) -> WarpResult | JobFailure:
    """Synthesize the keyframes between consecutive ``anchors`` of a laid-out warp render (their files and the
    noise probe already there), rendering for real where the warps disagree
    (:func:`~simspad.render.warp.rendering.render_with_warps`)."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        maybe_inject_fault(f"warp:{task.sequence.name}:{anchors[0]}")
        loaded = _warp_worker(task, layout, env, threads)
        # the driver counts the keyframes of finished chunks: no bar here
        done = render_with_warps(loaded.ms, loaded.ts, layout, Path(out_dir) / task.rel_dir, loaded.counter,
                                 tqdm(disable=True), anchors=list(anchors))
        # The geometry passes these keyframes own (the last keyframe's only in the chunk that ends there).
        owners = range(anchors[0], anchors[-1] + (anchors[-1] == layout.n_keyframes - 1))
        render_missing_geometry(layout, owners, Path(out_dir) / task.rel_dir, loaded)
        return WarpResult(segment=chunk_result(done, anchors[0], anchors[-1]), n_rendered=len(done.frame_times_s),
                          seconds=time.perf_counter() - t0, cpu_s=time.process_time() - cpu0,
                          host=socket.gethostname())
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def run_simulation(task, out_dir: str, env: dict[str, str]) -> SimulationResult | JobFailure:
    """Simulate one (sequence, lux) recording and hash it (in the worker, so hashing runs in parallel)."""
    t0 = time.perf_counter()
    try:
        _apply_environment(env)
        maybe_inject_fault(f"simulate:{task.rel_path}")
        out_path = Path(out_dir) / task.rel_path
        render_dir = Path(out_dir) / task.render_rel_dir
        measured = {}
        simulate_recording(render_dir, out_path, task.settings, metadata=dict(task.metadata), progress=False,
                           motion_attrs=_motion_measurement(render_dir, task, measured))
        seconds = time.perf_counter() - t0
        return SimulationResult(seconds=seconds, size=out_path.stat().st_size, sha256=file_sha256(out_path),
                                host=socket.gethostname(), motion=measured)
    except BaseException as exc:  # noqa: BLE001
        return _error_result(exc, t0)


def _motion_measurement(render_dir: Path, task, measured: dict):
    """``attrs(frame_exposure_s)``: the recording's motion attributes, measured on its render over its span (the
    blur over the frame camera's exposure, or over :data:`simspad.defaults.FRAME_BLUR_EXPOSURE_S` without one),
    also left in ``measured`` for the manifest."""
    def attrs(frame_exposure_s):
        exposure_s = defaults.FRAME_BLUR_EXPOSURE_S if frame_exposure_s is None else float(frame_exposure_s)
        start_s = task.settings.start_s
        motion = measure_image_motion(render_dir, start_s, start_s + task.settings.duration_s, exposure_s)
        measured.update(motion_attrs(motion, task.speed_factor))
        return measured
    return attrs


def default_workers() -> int:
    """The default number of workers: the cores this process may use (:func:`simspad.processes.available_cores`)."""
    return available_cores()


class LocalExecutor:
    """Process pools on this machine: one for render chunks (Mitsuba stays loaded between chunks), one for
    simulations, and together never more tasks at once than ``workers`` (default: the usable core count).

    Each render process gets ``cores // workers`` Dr.Jit threads (at least one), so chunks of keyframes side by
    side use the cores without oversubscribing them; more processes than cores only with an explicit ``workers``.
    A pool whose worker died (killed by the OS, a segfault) is replaced before the next task is submitted; the
    tasks it was running come back with ``died=True`` so the driver can retry them.
    """

    name = "local"

    def __init__(self, out_dir: Path, env: dict[str, str], workers: int | None = None):
        self.out_dir = str(out_dir)
        self.env = env
        self.workers = max(1, int(workers or default_workers()))
        self.render_threads = max(1, default_workers() // self.workers)
        self._ctx = multiprocessing.get_context("spawn")  # no fork: no inherited locks, threads or Mitsuba state
        self._pools = {"render": self._new_pool(), "sim": self._new_pool()}

    def _new_pool(self):
        return cf.ProcessPoolExecutor(self.workers, mp_context=self._ctx,
                                      initializer=die_with_parent_and_ignore_sigint)

    def _pool(self, kind: str):
        pool = self._pools[kind]
        if getattr(pool, "_broken", False):  # a worker died: its pool refuses every later submit
            pool.shutdown(wait=False, cancel_futures=True)
            pool = self._pools[kind] = self._new_pool()
        return pool

    def describe(self) -> str:
        return (f"local: {self.workers} process(es) for chunks of keyframes ({self.render_threads} render "
                f"thread(s) each) and simulations")

    def slots(self) -> int:
        """Tasks that may run at once (renders and simulations together)."""
        return self.workers

    def submit(self, job: Job):
        """Run ``job`` in the render pool (Mitsuba stays loaded between a render's jobs) or the simulation pool."""
        render = isinstance(job, RENDER_JOBS)
        threads = self.render_threads if render else None
        with sigint_blocked():  # a worker spawned here starts deaf to Ctrl-C (no traceback from its imports)
            return self._pool("render" if render else "sim").submit(run_job, job, self.out_dir, self.env, threads)

    @staticmethod
    def wait(futures):
        done, _ = cf.wait(futures, timeout=1.0, return_when=cf.FIRST_COMPLETED)
        return done

    @staticmethod
    def result(future) -> JobResult:
        try:
            return future.result()
        except cf.process.BrokenProcessPool:
            return JobFailure(died=True, error="worker process died (killed by the OS, e.g. out of memory, or crashed)")

    def close(self, cancel: bool = False) -> None:
        for pool in self._pools.values():
            if cancel:
                # Interrupted: stop the running tasks now (their temporary files are removed by the next run)
                # instead of waiting for them at interpreter exit. ``_processes`` is the pool's own table.
                for proc in list((getattr(pool, "_processes", None) or {}).values()):
                    with contextlib.suppress(Exception):
                        proc.kill()
            pool.shutdown(wait=not cancel, cancel_futures=cancel)


def dask_connect_timeout_s() -> float:
    """Seconds to wait for a Dask scheduler: ``SIMSPAD_DASK_CONNECT_TIMEOUT_S``, else
    :data:`~simspad.defaults.DASK_CONNECT_TIMEOUT_S`."""
    text = os.environ.get("SIMSPAD_DASK_CONNECT_TIMEOUT_S", "").strip()
    if not text:
        return defaults.DASK_CONNECT_TIMEOUT_S
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0 < value < 1e6:
        raise SimSpadError(f"expected a number of seconds > 0, got {text!r}", field="SIMSPAD_DASK_CONNECT_TIMEOUT_S")
    return value


def check_scheduler_answers(address: str, timeout_s: float) -> None:
    """Connect to the Dask scheduler at ``address`` and complete distributed's handshake within ``timeout_s``, or
    raise one :class:`SimSpadError`.

    ``distributed.Client(…, timeout=…)`` bounds the TCP connection but not the handshake after it: a listener
    that accepts and never speaks (a wrong port, a proxy, a hung scheduler) kept `generate` waiting forever with
    no output. A scheduler sends its handshake as soon as it accepts, so waiting for it is the whole check.
    """
    import asyncio  # deferred: only this check runs an event loop of its own

    from distributed.comm import connect  # deferred: dask is needed only by --executor dask
    from distributed.comm.addressing import parse_address, parse_host_port  # deferred: as above

    scheme, location = parse_address(address)
    if scheme == "tcp":
        # A plain connect first: distributed's connect retries a refusal until its timeout, and on a busy machine the
        # wait below could expire during a retry's back-off and report a refused address as one that did not answer.
        try:
            socket.create_connection(parse_host_port(location), timeout=timeout_s).close()
        except ConnectionRefusedError:
            raise SimSpadError(f"nothing accepts connections at {address} (refused): is the Dask scheduler running, "
                               "and is this its address?", field="--scheduler") from None
        except (OSError, ValueError):
            pass  # unreachable or slow: the handshake below says which, within the same timeout

    async def handshake():
        comm = await asyncio.wait_for(connect(address, timeout=timeout_s), timeout_s)
        await comm.close()

    outcome: list[BaseException | None] = []

    def run():  # a thread of its own: the caller may already run an event loop (a notebook)
        try:
            asyncio.run(handshake())
            outcome.append(None)
        except BaseException as exc:  # noqa: BLE001 - reported below
            outcome.append(exc)

    worker = threading.Thread(target=run, name="simspad-dask-probe", daemon=True)
    worker.start()
    worker.join(timeout_s + 5.0)
    exc = outcome[0] if outcome else TimeoutError()
    if exc is None:
        return
    cause, refused = exc, False
    while cause is not None and not refused:
        refused = isinstance(cause, ConnectionRefusedError)
        cause = cause.__cause__ or cause.__context__
    if refused:
        raise SimSpadError(f"nothing accepts connections at {address} (refused for {timeout_s:g} s): is the Dask "
                           "scheduler running, and is this its address?", field="--scheduler")
    if isinstance(exc, (TimeoutError, asyncio.TimeoutError)) or "timed out" in str(exc).lower():
        raise SimSpadError(f"the Dask scheduler at {address} did not answer within {timeout_s:g} s (is it a Dask "
                           "scheduler, and reachable? SIMSPAD_DASK_CONNECT_TIMEOUT_S=SECONDS waits longer)",
                           field="--scheduler")
    if isinstance(exc, (OSError, ValueError, TypeError)):
        raise SimSpadError(f"cannot connect to the Dask scheduler at {address} ({exc})", field="--scheduler")
    raise exc


class DaskExecutor:
    """dask.distributed: join a running scheduler (``scheduler`` address) or start a LocalCluster.

    Every worker must see the output directory at the same path (a shared file system on a cluster) and have
    SimSPAD installed. Dask schedules the tasks itself; ``slots`` does not throttle.
    """

    name = "dask"

    def __init__(self, out_dir: Path, env: dict[str, str], scheduler: str | None = None, workers: int | None = None):
        try:
            from distributed import (  # deferred: dask is needed only by --executor dask
                Client,
                LocalCluster,
            )
        except ImportError:  # pragma: no cover - dask[distributed] is a dependency
            raise SimSpadError("the dask executor needs dask.distributed (pip install 'dask[distributed]')") from None
        self.out_dir = str(out_dir)
        self.env = env
        self._cluster = None
        if scheduler:
            timeout_s = dask_connect_timeout_s()
            check_scheduler_answers(scheduler, timeout_s)
            try:
                self.client = Client(scheduler, timeout=f"{timeout_s}s")
            except (OSError, TimeoutError) as exc:
                raise SimSpadError(f"cannot connect to the Dask scheduler ({exc})", field="--scheduler") from None
        else:
            n = max(1, int(workers or default_workers()))
            for key, value in env.items():  # LocalCluster workers are spawned from this process: inherit env
                os.environ.setdefault(key, value)
            # Workers start with SIGINT ignored (inherited through exec), so Ctrl-C reaches only the driver, which
            # shuts the cluster down: one line instead of a traceback from every worker.
            previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
            try:
                self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                             dashboard_address=None, silence_logs=40)
            finally:
                signal.signal(signal.SIGINT, previous)
            self.client = Client(self._cluster)
        self.workers = len(self.client.scheduler_info().get("workers", {}))

    def describe(self) -> str:
        where = "LocalCluster" if self._cluster is not None else self.client.scheduler.address
        return f"dask: {where}, {self.workers} worker(s)"

    def submit(self, job: Job):
        # threads=None: each Dask worker renders with its own thread count (one per single-threaded worker).
        return self.client.submit(run_job, job, self.out_dir, self.env, None, pure=False, key=job.dask_key)

    @staticmethod
    def slots() -> int:
        return 1 << 30  # Dask schedules the tasks itself

    @staticmethod
    def wait(futures):
        from distributed import wait  # deferred: dask is needed only by --executor dask

        try:
            done, _ = wait(list(futures), timeout=1.0, return_when="FIRST_COMPLETED")
        except TimeoutError:
            return set()
        return done

    @staticmethod
    def result(future) -> JobResult:
        try:
            return future.result()
        except Exception as exc:  # noqa: BLE001 - a lost worker or a killed task
            return JobFailure(error=f"dask task failed ({type(exc).__name__}: {exc})")

    def close(self, cancel: bool = False) -> None:
        with contextlib.suppress(Exception):
            self.client.close()
        if self._cluster is not None:
            with contextlib.suppress(Exception):
                self._cluster.close()


@dataclass(frozen=True)
class ExecutorConfig:
    """Where dataset work runs.

    Attributes
    ----------
    kind : {"local", "dask"}
        Local worker processes, or a Dask cluster.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); none with ``kind="dask"`` starts a LocalCluster.
    workers : int, optional
        Simulation processes (local) or LocalCluster workers (dask); default: the usable core count.
    """

    kind: str = "local"
    scheduler: str | None = None
    workers: int | None = None

    def check(self) -> None:
        """:class:`SimSpadError` for an unknown executor, ``--scheduler`` without dask, or ``--workers`` < 1."""
        if self.kind not in ("local", "dask"):
            raise SimSpadError(f"unknown executor {self.kind!r} (expected local or dask)", field="--executor")
        workers = self.workers
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
            raise SimSpadError(f"must be an integer ≥ 1, got {workers!r}", field="--workers")
        if self.scheduler and self.kind != "dask":
            raise SimSpadError("--scheduler needs --executor dask", field="--scheduler")


def make_executor(config: ExecutorConfig, out_dir: Path):
    """The executor ``config`` names."""
    config.check()
    env = job_environment()
    if config.kind == "local":
        return LocalExecutor(out_dir, env, config.workers)
    return DaskExecutor(out_dir, env, config.scheduler, config.workers)
