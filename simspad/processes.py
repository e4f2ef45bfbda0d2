"""Worker processes: how many cores there are to use, and workers that die with their driver and leave Ctrl-C to it.

The process plumbing shared by the dataset driver's pools (:mod:`simspad.dataset.executors`) and the evaluation's
(:mod:`simspad.evaluate.evaluate`); it knows nothing of SimSPAD's data.

Cores: :func:`available_cores` counts the cores this process may run on (its CPU affinity, which a batch system
or ``taskset`` narrows), not the machine's; both default worker counts come from it.

Driver death: a worker started with :func:`die_with_parent_and_ignore_sigint` as its initializer is SIGKILLed by
the kernel (Linux's ``PR_SET_PDEATHSIG``) when its driver dies, even by kill -9, so no orphan keeps computing or
writing after a crash.

Ctrl-C: a terminal sends SIGINT to every process of the foreground group, so each pool worker would raise
``KeyboardInterrupt`` where it happens to be — often while still importing numpy or scipy — and print its own
traceback. Workers therefore start with SIGINT blocked (:func:`sigint_blocked` around the call that spawns them;
a child inherits its parent's signal mask, as CPython's own resource tracker does) and ignore it from their
initializer on (:func:`ignore_sigint`). The driver alone turns Ctrl-C into one line and stops its workers
(:func:`kill_pool_workers`).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import threading
from typing import Iterator


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity, ``sched_getaffinity``; the machine's count where affinity
    does not exist), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """Block SIGINT in the calling thread while processes started inside are spawned.

    A SIGINT that arrives meanwhile stays pending (or goes to another thread of this process) and is handled as
    usual afterwards: nothing is lost. Outside the main thread, or where signal masks do not exist, a no-op.
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def ignore_sigint() -> None:
    """Worker initializer: ignore SIGINT (discarding one pending since the spawn), then unblock it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def die_with_parent_and_ignore_sigint() -> None:
    """Worker initializer: on Linux the kernel SIGKILLs this worker when its driver dies (even by kill -9), so
    no orphan keeps computing (and holding the driver's stderr) after a crash; Ctrl-C is the driver's."""
    with contextlib.suppress(Exception):
        pr_set_pdeathsig = 1
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL)
        if os.getppid() == 1:  # the driver already died before prctl took effect
            os._exit(1)
    ignore_sigint()


def kill_pool_workers(pool) -> None:
    """Stop a ``concurrent.futures.ProcessPoolExecutor``'s workers now and shut it down without waiting.

    Used when the driver is interrupted: the workers ignore Ctrl-C, and waiting for their running tasks could
    take minutes. Their temporary files are removed by the next run. ``_processes`` is the pool's own table.
    """
    manager = getattr(pool, "_executor_manager_thread", None)  # shutdown() forgets it
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        with contextlib.suppress(Exception):
            proc.kill()
    pool.shutdown(wait=False, cancel_futures=True)
    if manager is not None and manager is not threading.current_thread():
        # The pool's thread sees its workers die and closes its wake-up pipe; the interpreter's exit hook writes
        # to that pipe unlocked, so an exit during the closing raised "OSError: Bad file descriptor". Wait for it.
        manager.join(timeout=10)
