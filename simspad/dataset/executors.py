"""Where dataset work runs: worker-side task functions and the ``local`` and ``dask`` executors.

Task functions (:func:`run_render`, :func:`run_simulation`) run inside a worker process (a local pool process or
a Dask worker, possibly on another machine). They take plain picklable task descriptions, apply the job's
environment (``DRJIT_LIBLLVM_PATH``) before Mitsuba is imported, choose the Mitsuba variant inside the worker,
write their output atomically, and never raise: they return a dict with ``ok`` and either results or a one-line
``error``, so an exception that does not pickle cannot hang the job.

Executors expose one small interface used by :mod:`simspad.dataset.generate`:
``submit_render(task)``, ``submit_simulation(task)``, ``wait(futures) -> done``, ``result(future)``,
``sim_slots(renders_running)`` (how many simulations may run now) and ``close()``.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import ctypes
import json
import multiprocessing
import os
import signal
import socket
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from simspad.errors import SimSpadError
from simspad.io.atomic import atomic_path
from simspad.io.hashing import file_sha256
from simspad.io.worker_signals import ignore_sigint, sigint_blocked
from simspad.render.mitsuba_env import select_variant
from simspad.render.renderer import render_sequence
from simspad.render.settings import RenderSettings
from simspad.sensors.presets import SpadParams
from simspad.sensors.simulate import RecordingSettings, simulate_recording

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


def run_render(task, out_dir: str, env: dict[str, str]) -> dict[str, Any]:
    """Render one sequence into ``<out_dir>/<task.rel_dir>`` (atomically: a temporary directory, then a rename).

    Returns
    -------
    dict
        ``ok``, ``seconds`` (wall time), ``n_keyframes``, ``host``; or ``ok=False`` and ``error``.
    """
    t0 = time.perf_counter()
    try:
        _apply_environment(env)
        # Mitsuba loads here, after the job's libLLVM path is set; the variant is per process: set it inside the
        # worker, never inherit it.
        select_variant()
        seq = task.sequence
        final = Path(out_dir) / task.rel_dir
        if not (final / "timeline.json").is_file():
            with atomic_path(final) as tmp:
                settings = RenderSettings(duration_s=seq.duration_s, start_s=seq.start_s,
                                          resolution=tuple(seq.resolution), spp=seq.spp, max_flow_px=seq.max_flow_px,
                                          min_rate_hz=seq.min_rate_hz, seed=task.seed)
                render_sequence(seq.scene, seq.trajectory, settings, out_dir=tmp, progress=False,
                                spad_bin_s=SpadParams().bin_s)
        return {"ok": True, "seconds": time.perf_counter() - t0, "n_keyframes": _count_keyframes(final),
                "host": socket.gethostname()}
    except BaseException as exc:  # noqa: BLE001 - reported to the driver, which marks the recordings failed
        return _error_result(exc, t0)


def _count_keyframes(render_dir: Path) -> int | None:
    try:
        return len(json.loads((render_dir / "timeline.json").read_text())["keyframes"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


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
        out_path = Path(out_dir) / task.rel_path
        settings = RecordingSettings(lux=task.lux, sensors=dict(task.sensors), start_s=task.start_s,
                                     duration_s=task.duration_s, seed=task.seed, stream_key=tuple(task.stream_key),
                                     gt_rate_hz=task.gt_rate_hz, optics=task.optics)
        simulate_recording(Path(out_dir) / task.render_rel_dir, out_path, settings, metadata=dict(task.metadata),
                           progress=False)
        seconds = time.perf_counter() - t0
        return {"ok": True, "seconds": seconds, "size": out_path.stat().st_size, "sha256": file_sha256(out_path),
                "host": socket.gethostname()}
    except BaseException as exc:  # noqa: BLE001
        return _error_result(exc, t0)


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


#: Per-keyframe render work (megapixels × samples per pixel) below which a render is "small": its time goes
#: mostly to serial work (scene building, kernel compilation), so several run side by side. Measured on the mini
#: dataset (80×60, 8 spp = 0.04 MP·spp): two render processes on 2 cores took 23 s against 35 s for one.
SMALL_RENDER_MP_SPP = 1.0


class LocalExecutor:
    """Process pools on this machine, sized so Mitsuba's own thread pool is not oversubscribed.

    Large renders run one at a time in a dedicated process and own the machine (Mitsuba's thread pool uses
    every core), simulations wait for them; small renders (``small_renders``, see :data:`SMALL_RENDER_MP_SPP`)
    run in up to ``workers`` processes, each taking one slot. Simulations run in up to ``workers`` processes,
    the slots the renders leave free.
    """

    name = "local"

    def __init__(self, out_dir: Path, env: dict[str, str], workers: int | None = None, small_renders: bool = False):
        self.out_dir = str(out_dir)
        self.env = env
        self.workers = max(1, int(workers or default_workers()))
        self.render_procs = self.workers if small_renders else 1
        ctx = multiprocessing.get_context("spawn")  # no fork: no inherited locks, threads or Mitsuba state
        self._render_pool = cf.ProcessPoolExecutor(self.render_procs, mp_context=ctx, initializer=_die_with_parent)
        self._sim_pool = cf.ProcessPoolExecutor(self.workers, mp_context=ctx, initializer=_die_with_parent)

    def describe(self) -> str:
        renders = "renders one at a time on all cores" if self.render_procs == 1 else \
            f"small renders in up to {self.render_procs} processes"
        return f"local: {renders}, {self.workers} simulation process(es)"

    def submit_render(self, task):
        with sigint_blocked():  # a worker spawned here starts deaf to Ctrl-C (no traceback from its imports)
            return self._render_pool.submit(run_render, task, self.out_dir, self.env)

    def submit_simulation(self, task):
        with sigint_blocked():
            return self._sim_pool.submit(run_simulation, task, self.out_dir, self.env)

    def sim_slots(self, renders_running: int) -> int:
        # A large render owns the machine; small renders each hold one process slot.
        if self.render_procs == 1:
            return 0 if renders_running else self.workers
        return max(0, self.workers - min(renders_running, self.render_procs))

    @staticmethod
    def wait(futures):
        done, _ = cf.wait(futures, timeout=1.0, return_when=cf.FIRST_COMPLETED)
        return done

    @staticmethod
    def result(future) -> dict[str, Any]:
        try:
            return future.result()
        except cf.process.BrokenProcessPool as exc:
            return {"ok": False, "error": f"worker process died ({exc})", "seconds": 0.0}

    def close(self, cancel: bool = False) -> None:
        for pool in (self._render_pool, self._sim_pool):
            if cancel:
                # Interrupted: stop the running tasks now (their temporary files are removed by the next run)
                # instead of waiting for them at interpreter exit. ``_processes`` is the pool's own table.
                for proc in list((getattr(pool, "_processes", None) or {}).values()):
                    with contextlib.suppress(Exception):
                        proc.kill()
            pool.shutdown(wait=not cancel, cancel_futures=cancel)


class DaskExecutor:
    """dask.distributed: join a running scheduler (``scheduler`` address) or start a LocalCluster.

    Every worker must see the output directory at the same path (a shared file system on a cluster) and have
    SimSPAD installed. Dask schedules the tasks itself; ``sim_slots`` does not throttle.
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
            try:
                self.client = Client(scheduler, timeout="15s")
            except (OSError, TimeoutError) as exc:
                raise SimSpadError(f"cannot connect to the Dask scheduler ({exc})", field="--scheduler") from None
        else:
            n = max(1, int(workers or default_workers()))
            for key, value in env.items():  # LocalCluster workers are spawned from this process: inherit env
                os.environ.setdefault(key, value)
            self._cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                         dashboard_address=None, silence_logs=40)
            self.client = Client(self._cluster)
        self.workers = len(self.client.scheduler_info().get("workers", {}))

    def describe(self) -> str:
        where = "LocalCluster" if self._cluster is not None else self.client.scheduler.address
        return f"dask: {where}, {self.workers} worker(s)"

    def submit_render(self, task):
        return self.client.submit(run_render, task, self.out_dir, self.env, pure=False,
                                  key=f"render-{task.sequence.name}-{task.render_hash[:12]}")

    def submit_simulation(self, task):
        return self.client.submit(run_simulation, task, self.out_dir, self.env, pure=False,
                                  key=f"simulate-{task.sequence_name}-{task.lux:g}lx-{task.recording_hash[:12]}")

    @staticmethod
    def sim_slots(renders_running: int) -> int:
        return 1 << 30

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


def make_executor(config: ExecutorConfig, out_dir: Path, *, render_mp_spp: float = 0.0):
    """The executor ``config`` names; ``render_mp_spp`` is the largest per-keyframe render work (megapixels × spp)
    of the job, which decides whether renders may run side by side."""
    config.check()
    env = job_environment()
    if config.kind == "local":
        return LocalExecutor(out_dir, env, config.workers, small_renders=render_mp_spp <= SMALL_RENDER_MP_SPP)
    return DaskExecutor(out_dir, env, config.scheduler, config.workers)
