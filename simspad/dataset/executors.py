"""Where dataset work runs: worker-side task functions and the ``local`` and ``dask`` executors.

Task functions (:func:`run_render_plan`, :func:`run_render_chunk`, :func:`run_simulation`) run inside a worker process (a local pool process or
a Dask worker, possibly on another machine). They take plain picklable task descriptions, apply the job's
environment (``DRJIT_LIBLLVM_PATH``) before Mitsuba is imported, choose the Mitsuba variant inside the worker,
write their output atomically, and never raise: they return a dict with ``ok`` and either results or a one-line
``error``, so an exception that does not pickle cannot hang the job.

Executors expose one small interface used by :mod:`simspad.dataset.generate`:
``submit_render_plan(task)``, ``submit_render_chunk(task, plan, indices)``, ``submit_noise_probe(task, plan)`` and
``submit_warp_chunk(task, plan, anchors)`` (a warp render's second phase), ``submit_simulation(task)``,
``wait(futures) -> done``, ``result(future)``, ``slots()`` (how many tasks may run at once) and ``close()``.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import ctypes
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
from typing import Any

from tqdm import tqdm

from simspad import defaults
from simspad.dataset.fault_injection import maybe_inject_fault
from simspad.dataset.speed import sequence_trajectories
from simspad.errors import SimSpadError
from simspad.io.hashing import file_sha256
from simspad.io.worker_signals import ignore_sigint, sigint_blocked
from simspad.render.image_motion import measure_image_motion, motion_attrs
from simspad.render.keyframe_files import make_out_dir
from simspad.render.mitsuba_env import select_variant
from simspad.render.render_plan import RenderPlan
from simspad.render.geometry import missing_geometry, owned_instants
from simspad.render.renderer import (
    link_shared_keyframes,
    load_scene,
    plan_render,
    render_keyframes,
    render_missing_geometry,
)
from simspad.render.settings import RenderSettings
from simspad.render.warp_render import chunk_result, render_noise_probe, render_with_warps
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


def _error_result(exc: BaseException, t0: float) -> dict[str, Any]:
    if isinstance(exc, SimSpadError):
        message = exc.format().replace("\n", "; ")
    else:
        message = f"{type(exc).__name__}: {exc}".replace("\n", " ")
    return {"ok": False, "error": message, "traceback": traceback.format_exc(), "seconds": time.perf_counter() - t0,
            "host": socket.gethostname()}


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


def run_render_plan(task, out_dir: str, env: dict[str, str]) -> dict[str, Any]:
    """Plan the render of one sequence (stage 1, :func:`~simspad.render.renderer.plan_render`) and create its
    directory under ``<out_dir>/<task.rel_dir>``; keyframes already there (a killed run's) are kept and counted.

    Returns
    -------
    dict
        ``ok``, ``plan`` (:meth:`RenderPlan.to_dict`), ``n_keyframes``, ``existing`` (indices whose file is
        already there), ``seconds``, ``host``; or ``ok=False`` and ``error``.
    """
    t0 = time.perf_counter()
    try:
        _apply_environment(env)
        # Mitsuba loads here, after the job's libLLVM path is set; the variant is per process: set it inside the
        # worker, never inherit it.
        select_variant()
        final = Path(out_dir) / task.rel_dir
        plan = plan_render_task(task)
        make_out_dir(final)
        existing = [i for i, name in enumerate(plan.names) if (final / name).is_file()]
        return {"ok": True, "plan": plan.to_dict(), "n_keyframes": plan.n_keyframes, "existing": existing,
                "seconds": time.perf_counter() - t0, "host": socket.gethostname()}
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def plan_render_task(task, planned: dict | None = None) -> RenderPlan:
    """The keyframe plan of a render task: its sequence's trajectory retimed by the task's speed factor, its first
    keyframes those of its prefix (the next slower speed's render) when it has one (taken from ``planned``, plans
    by render directory, when it is there)."""
    seq = task.sequence
    trajectory = sequence_trajectories(seq.scene, seq.trajectory, task.speed_factor)
    prefix = None
    if task.prefix is not None:
        prefix = (planned or {}).get(task.prefix.rel_dir) or plan_render_task(task.prefix, planned)
    scale = 1.0 if task.prefix is None else task.prefix.speed_factor / task.speed_factor
    return plan_render(seq.scene, trajectory, render_settings_of(task), spad_bin_s=SpadParams().bin_s,
                       prefix=prefix, prefix_time_scale=scale)


#: The scene this worker process loaded last: the next chunk of the same render skips the reload (a keyframe's
#: pixels depend only on its pose and the plan's seed, not on what this process rendered before).
_SCENE_CACHE: dict = {}


def _cached_scene(seq, speed_factor: float, plan: RenderPlan):
    key = (repr(seq.scene), repr(seq.trajectory), float(speed_factor), plan.width, plan.height, plan.spp,
           plan.variant, plan.scene_hash, plan.trajectory_hash)
    if key not in _SCENE_CACHE:
        _SCENE_CACHE.clear()
        trajectory = sequence_trajectories(seq.scene, seq.trajectory, speed_factor)
        _SCENE_CACHE[key] = load_scene(seq.scene, trajectory, plan.width, plan.height, plan.spp, plan.variant)
    return _SCENE_CACHE[key]


def run_render_chunk(task, plan: dict, indices: list[int], out_dir: str, env: dict[str, str],
                     threads: int | None = None) -> dict[str, Any]:
    """Render the keyframes ``indices`` of a planned render (stage 2) into ``<out_dir>/<task.rel_dir>``, each
    written atomically under its final name, so a killed run keeps every keyframe it finished.

    Returns
    -------
    dict
        ``ok``, ``n_rendered``, ``n_reused``, ``seconds`` (wall), ``cpu_s`` (CPU time of this process, all
        threads), ``pid``, ``host``; or ``ok=False`` and ``error``.
    """
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        _apply_environment(env)
        maybe_inject_fault(f"render:{task.sequence.name}:{indices[0]}")
        select_variant()
        _set_render_threads(threads)
        seq = task.sequence
        render_plan = RenderPlan.from_dict(plan)
        final = Path(out_dir) / task.rel_dir
        n_linked = 0 if task.prefix is None else link_shared_keyframes(render_plan, indices,
                                                                       Path(out_dir) / task.prefix.rel_dir, final)
        n_rendered, n_reused = 0, n_linked
        geometry = render_plan.timeline.get("geometry")
        geometry_todo = missing_geometry(geometry, owned_instants(render_plan.times_s, geometry, indices), final,
                                         render_plan.width, render_plan.height)
        if n_linked < len(indices) or geometry_todo:  # else nothing left to render: no scene to load
            done = render_keyframes(seq.scene, None, render_plan, indices, out_dir=final,
                                    loaded=_cached_scene(seq, task.speed_factor, render_plan))
            n_rendered, n_reused = len(done.frame_times_s), done.n_reused
        return {"ok": True, "n_rendered": n_rendered, "n_reused": n_reused,
                "seconds": time.perf_counter() - t0, "cpu_s": time.process_time() - cpu0, "pid": os.getpid(),
                "host": socket.gethostname()}
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def _warp_worker(task, plan: dict, env: dict[str, str], threads: int | None):
    """A worker's set-up for a warp render's tasks: environment, variant, render threads; the plan and the scene
    (this process's cached one when it rendered the same sequence before)."""
    _apply_environment(env)
    select_variant()
    _set_render_threads(threads)
    render_plan = RenderPlan.from_dict(plan)
    return render_plan, _cached_scene(task.sequence, task.speed_factor, render_plan)


def run_noise_probe(task, plan: dict, out_dir: str, env: dict[str, str], threads: int | None = None) -> dict[str, Any]:
    """Render the noise probe of a planned render (:func:`~simspad.render.warp_render.render_noise_probe`: keyframe 0
    again with the next seed; the warp schedule's noise reference and every render's noise budget) into
    ``<out_dir>/<task.rel_dir>``, unless it is there.

    Returns
    -------
    dict
        ``ok``, ``n_rendered`` (0 or 1), ``seconds``, ``cpu_s``, ``host``; or ``ok=False`` and ``error``.
    """
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        render_plan, loaded = _warp_worker(task, plan, env, threads)
        new = render_noise_probe(loaded.ms, loaded.ts, render_plan, Path(out_dir) / task.rel_dir)
        return {"ok": True, "n_rendered": int(new), "seconds": time.perf_counter() - t0,
                "cpu_s": time.process_time() - cpu0, "host": socket.gethostname()}
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def run_warp_chunk(task, plan: dict, anchors: list[int], out_dir: str, env: dict[str, str],
                   threads: int | None = None) -> dict[str, Any]:
    """Synthesize the keyframes between consecutive ``anchors`` of a planned warp render (their files and the
    noise probe already there), rendering for real where the warps disagree
    (:func:`~simspad.render.warp_render.render_with_warps`).

    Returns
    -------
    dict
        ``ok``, ``warp`` (:func:`~simspad.render.warp_render.chunk_result`), ``n_rendered``, ``seconds``, ``cpu_s``,
        ``host``; or ``ok=False`` and ``error``.
    """
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        maybe_inject_fault(f"warp:{task.sequence.name}:{anchors[0]}")
        render_plan, loaded = _warp_worker(task, plan, env, threads)
        # the driver counts the keyframes of finished chunks: no bar here
        done = render_with_warps(loaded.ms, loaded.ts, render_plan, Path(out_dir) / task.rel_dir, loaded.counter,
                                 tqdm(disable=True), anchors=list(anchors))
        # The geometry passes these keyframes own (the last keyframe's only in the chunk that ends there).
        owners = range(anchors[0], anchors[-1] + (anchors[-1] == render_plan.n_keyframes - 1))
        render_missing_geometry(render_plan, owners, Path(out_dir) / task.rel_dir, loaded)
        return {"ok": True, "warp": chunk_result(done, anchors[0], anchors[-1]),
                "n_rendered": len(done.frame_times_s), "seconds": time.perf_counter() - t0,
                "cpu_s": time.process_time() - cpu0, "host": socket.gethostname()}
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def run_simulation(task, out_dir: str, env: dict[str, str]) -> dict[str, Any]:
    """Simulate one (sequence, lux) recording and hash it (in the worker, so hashing runs in parallel).

    Returns
    -------
    dict
        ``ok``, ``seconds``, ``size`` (bytes), ``sha256``, ``host``; or ``ok=False`` and ``error``.
    """
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
        return {"ok": True, "seconds": seconds, "size": out_path.stat().st_size, "sha256": file_sha256(out_path),
                "host": socket.gethostname(), "motion": measured}
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
    """Cores this process may use (``sched_getaffinity``), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def _die_with_parent() -> None:
    """Pool initializer: on Linux ask the kernel to SIGKILL this worker when the driver dies (even by kill -9),
    so no orphan keeps writing into the dataset after a crash."""
    with contextlib.suppress(Exception):
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        pr_set_pdeathsig = 1
        libc.prctl(pr_set_pdeathsig, signal.SIGKILL)
        if os.getppid() == 1:  # the parent already died before prctl took effect
            os._exit(1)
    ignore_sigint()  # Ctrl-C is handled by the driver, which shuts the pool down


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
        return cf.ProcessPoolExecutor(self.workers, mp_context=self._ctx, initializer=_die_with_parent)

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

    def submit_render_plan(self, task):
        with sigint_blocked():  # a worker spawned here starts deaf to Ctrl-C (no traceback from its imports)
            return self._pool("render").submit(run_render_plan, task, self.out_dir, self.env)

    def submit_render_chunk(self, task, plan: dict, indices: list[int]):
        with sigint_blocked():
            return self._pool("render").submit(run_render_chunk, task, plan, indices, self.out_dir, self.env,
                                               self.render_threads)

    def submit_noise_probe(self, task, plan: dict):
        with sigint_blocked():
            return self._pool("render").submit(run_noise_probe, task, plan, self.out_dir, self.env,
                                               self.render_threads)

    def submit_warp_chunk(self, task, plan: dict, anchors: list[int]):
        with sigint_blocked():
            return self._pool("render").submit(run_warp_chunk, task, plan, anchors, self.out_dir, self.env,
                                               self.render_threads)

    def submit_simulation(self, task):
        with sigint_blocked():
            return self._pool("sim").submit(run_simulation, task, self.out_dir, self.env)

    @staticmethod
    def wait(futures):
        done, _ = cf.wait(futures, timeout=1.0, return_when=cf.FIRST_COMPLETED)
        return done

    @staticmethod
    def result(future) -> dict[str, Any]:
        try:
            return future.result()
        except cf.process.BrokenProcessPool:
            return {"ok": False, "died": True, "seconds": 0.0,
                    "error": "worker process died (killed by the OS, e.g. out of memory, or crashed)"}

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

    def submit_render_plan(self, task):
        return self.client.submit(run_render_plan, task, self.out_dir, self.env, pure=False,
                                  key=f"render-plan-{task.sequence.name}-{task.render_hash[:12]}")

    def submit_render_chunk(self, task, plan: dict, indices: list[int]):
        # threads=None: each Dask worker renders with its own thread count (one per single-threaded worker).
        return self.client.submit(run_render_chunk, task, plan, indices, self.out_dir, self.env, None, pure=False,
                                  key=f"render-{task.sequence.name}-{task.render_hash[:12]}-{indices[0]:06d}")

    def submit_noise_probe(self, task, plan: dict):
        return self.client.submit(run_noise_probe, task, plan, self.out_dir, self.env, None, pure=False,
                                  key=f"noise-probe-{task.sequence.name}-{task.render_hash[:12]}")

    def submit_warp_chunk(self, task, plan: dict, anchors: list[int]):
        return self.client.submit(run_warp_chunk, task, plan, anchors, self.out_dir, self.env, None, pure=False,
                                  key=f"warp-{task.sequence.name}-{task.render_hash[:12]}-{anchors[0]:06d}")

    def submit_simulation(self, task):
        return self.client.submit(run_simulation, task, self.out_dir, self.env, pure=False,
                                  key=f"simulate-{task.sequence_name}-{task.lux:g}lx-{task.recording_hash[:12]}")

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
    def result(future) -> dict[str, Any]:
        try:
            return future.result()
        except Exception as exc:  # noqa: BLE001 - a lost worker or a killed task
            return {"ok": False, "error": f"dask task failed ({type(exc).__name__}: {exc})", "seconds": 0.0}

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
