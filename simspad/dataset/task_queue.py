"""The driver's queue of dataset jobs: priorities, the executor's slots, and one retry for a job whose worker died.

Jobs (:mod:`simspad.dataset.jobs`) wait in queues served in :data:`~simspad.dataset.jobs.QUEUE_ORDER`: render
layouts (they unlock chunks), chunks of keyframes and noise probes (they unlock simulations, or a warp render's
synthesis jobs), synthesis jobs of warp renders, simulations. At most ``executor.slots()`` run at once, so a local
run never starts more processes than it has workers.

A worker killed under a job (the OOM killer, a segfault) takes its whole local pool down, and with it the other
jobs that pool was running. Each job so lost is retried once, *alone* — nothing else runs until the retries are
done — so a job that kills its worker again is the culprit and is reported failed, while its innocent neighbours
succeed on their retry. The executor replaces the broken pool before the next submit; the run goes on.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from typing import Any, Callable

from simspad.dataset.jobs import QUEUE_ORDER, Job, JobFailure, JobResult


class TaskQueue:
    """Submit jobs to an executor (its one ``submit(job)``) within its slots; yield ``(job, result)`` as they
    finish."""

    def __init__(self, executor, log: Callable[[str], None]):
        self.ex = executor
        self.log = log
        self.pending: dict[int, deque] = {rank: deque() for rank in sorted(set(QUEUE_ORDER.values()))}
        self.retry: deque = deque()
        self.running: dict[Any, Job] = {}
        self.deaths: dict[Job, int] = {}  # jobs whose worker died under them, and how often

    def add(self, job: Job) -> None:
        self.pending[QUEUE_ORDER[job.kind]].append(job)

    @property
    def busy(self) -> bool:
        return bool(self.running or self.retry or any(self.pending.values()))

    def _submit(self, job: Job) -> None:
        try:
            fut = self.ex.submit(job)
        except RuntimeError:  # BrokenProcessPool: the pool broke between the executor's check and this submit
            fut = self.ex.submit(job)
        self.running[fut] = job

    def pump(self) -> None:
        """Submit what the slots allow (after a worker died: only the retries, one at a time)."""
        if self.retry:
            if not self.running:
                self._submit(self.retry.popleft())
            return
        slots = self.ex.slots()
        for queue in self.pending.values():
            while queue and len(self.running) < slots:
                self._submit(queue.popleft())

    def finished(self) -> list[tuple[Job, JobResult]]:
        """Wait (≤ 1 s) for running jobs; return those that finished, with their results. A job whose worker died
        is queued for its one retry instead, or returned as failed if it already had it."""
        self.pump()
        out = []
        for fut in self.ex.wait(list(self.running)):
            job = self.running.pop(fut)
            res = self.ex.result(fut)
            if isinstance(res, JobFailure) and res.died:
                self.deaths[job] = self.deaths.get(job, 0) + 1
                if self.deaths[job] == 1:
                    self.log(f"a worker died while running {job.label}; retrying it alone")
                    self.retry.append(job)
                    continue
                res = dataclasses.replace(res, error=f"{res.error}, twice: given up")
            out.append((job, res))
        return out
