"""The driver's queue of dataset tasks: priorities, the executor's slots, and one retry for a task whose worker died.

Tasks wait in four queues, served in order: render plans (they unlock chunks), chunks of keyframes (they unlock
simulations, or a warp render's synthesis chunks), synthesis chunks of warp renders, simulations. At most ``executor.slots()`` run at once, so a local run never starts more processes
than it has workers.

A worker killed under a task (the OOM killer, a segfault) takes its whole local pool down, and with it the other
tasks that pool was running. Each task so lost is retried once, *alone* — nothing else runs until the retries are
done — so a task that kills its worker again is the culprit and is reported failed, while its innocent neighbours
succeed on their retry. The executor replaces the broken pool before the next submit; the run goes on.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

#: Queues in the order they are served.
KINDS = ("plan", "chunk", "warp", "sim")


@dataclass(eq=False)
class Job:
    """One task: its kind (one of :data:`KINDS`), what the driver needs to handle its result, and how to submit it."""

    kind: str
    payload: Any
    submit: Callable[[], Any] = field(repr=False)
    label: str = ""
    deaths: int = 0


class TaskQueue:
    """Submit jobs to an executor within its slots; yield ``(job, result)`` as they finish."""

    def __init__(self, executor, log: Callable[[str], None]):
        self.ex = executor
        self.log = log
        self.pending = {kind: deque() for kind in KINDS}
        self.retry: deque[Job] = deque()
        self.running: dict[Any, Job] = {}

    def add(self, job: Job) -> None:
        self.pending[job.kind].append(job)

    @property
    def busy(self) -> bool:
        return bool(self.running or self.retry or any(self.pending.values()))

    def _submit(self, job: Job) -> None:
        try:
            fut = job.submit()
        except RuntimeError:  # BrokenProcessPool: the pool broke between the executor's check and this submit
            fut = job.submit()
        self.running[fut] = job

    def pump(self) -> None:
        """Submit what the slots allow (after a worker died: only the retries, one at a time)."""
        if self.retry:
            if not self.running:
                self._submit(self.retry.popleft())
            return
        slots = self.ex.slots()
        for kind in KINDS:
            queue = self.pending[kind]
            while queue and len(self.running) < slots:
                self._submit(queue.popleft())

    def finished(self) -> list[tuple[Job, dict]]:
        """Wait (≤ 1 s) for running jobs; return those that finished, with their result dicts. A job whose worker
        died is queued for its one retry instead, or returned as failed if it already had it."""
        self.pump()
        out = []
        for fut in self.ex.wait(list(self.running)):
            job = self.running.pop(fut)
            res = self.ex.result(fut)
            if res.get("died"):
                job.deaths += 1
                if job.deaths == 1:
                    self.log(f"a worker died while running {job.label}; retrying it alone")
                    self.retry.append(job)
                    continue
                res = dict(res, error=f"{res.get('error')}, twice: given up")
            out.append((job, res))
        return out
