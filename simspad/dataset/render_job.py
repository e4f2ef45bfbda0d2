"""One render of a dataset as the driver runs it: a small state machine from its layout to ``timeline.json``.

Phases (:class:`Phase`), each a set of jobs of :mod:`simspad.dataset.jobs` spread over the executor's workers:

1. ``LAYOUT``: one :class:`~simspad.dataset.jobs.LayoutJob` (keyframe instants, poses, file names).
2. ``KEYFRAMES``: chunks of keyframes (:class:`~simspad.dataset.jobs.ChunkJob`; a warp render's anchors only) and
   the noise probe (:class:`~simspad.dataset.jobs.ProbeJob`). A faster speed's first keyframes are a slower
   render's files (:attr:`~simspad.dataset.plan.RenderTask.prefix`): while that render runs, their chunks wait
   and are queued by :meth:`RenderJob.release_shared` once it is done (linked where its files are, rendered
   where they are not).
3. ``SYNTHESIS`` (warp renders only): runs of segments between anchors (:class:`~simspad.dataset.jobs.WarpJob`),
   once every anchor and the probe are there.
4. ``DONE``: ``timeline.json`` written here, in the driver (it needs no Mitsuba), with the segments' reports
   merged in; or the first error. :attr:`RenderJob.outcome` says which.

Keyframes already in the render directory (a killed run's) are not rendered again. The keyframe bar (a tqdm bar
shared by every render) counts keyframes as their jobs finish; see
:func:`simspad.dataset.generate.show_written_keyframes` for the files of running chunks.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from simspad.dataset.jobs import (
    ChunkJob,
    ChunkResult,
    Job,
    JobFailure,
    JobResult,
    LayoutJob,
    LayoutResult,
    ProbeJob,
    WarpJob,
    WarpResult,
)
from simspad.dataset.plan import RenderTask
from simspad.errors import SimSpadError
from simspad.render.render_layout import RenderLayout, chunk_size_for, keyframe_chunks
from simspad.render.renderer import finalize_render, with_warp_results
from simspad.render.warp.schedule import anchor_indices

#: Most runs of warp segments in one synthesis job (each segment is ``stride`` keyframes).
MAX_SEGMENTS_PER_JOB = 8


class Phase(enum.Enum):
    """Where a render is (module docstring)."""

    LAYOUT = "layout"
    KEYFRAMES = "keyframes"
    SYNTHESIS = "synthesis"
    DONE = "done"


@dataclass(frozen=True)
class RenderOutcome:
    """How a render ended: ``ok`` with its keyframe count, or the first error; worker seconds summed over its jobs
    and the host that laid it out (manifest timings)."""

    ok: bool
    seconds: float
    host: str | None
    n_keyframes: int | None = None
    error: str | None = None


class RenderJob:
    """The state of one render (:class:`~simspad.dataset.plan.RenderTask`) while the driver runs it.

    :meth:`start` gives its first job; :meth:`on_result` takes each of its results and gives the jobs to queue next;
    once every job is back :attr:`outcome` is set (phase ``DONE``).

    Parameters
    ----------
    task : RenderTask
    out_dir : Path
        The dataset folder (the render goes to ``out_dir / task.rel_dir``).
    workers : int
        The executor's workers: chunks are sized to keep them all busy (:func:`chunk_size_for`).
    bar : tqdm-like
        The keyframe bar (``total``, ``update``, ``refresh``), shared by every render.
    log : callable
        One-line notices.
    """

    def __init__(self, task: RenderTask, out_dir: Path, workers: int, bar, log: Callable[[str], None]):
        self.task, self.out_dir, self.workers, self.bar, self.log = task, Path(out_dir), workers, bar, log
        self.phase = Phase.LAYOUT
        self.layout: RenderLayout | None = None
        self.names: tuple = ()  # keyframe files relative to the render directory (the layout's)
        self.seconds = 0.0  # summed over the layout and every chunk (worker time)
        self.host: str | None = None
        self.left = 0  # jobs (or waiting shared chunks) not finished yet in this phase
        self.error: str | None = None  # first job error
        self.anchors: list[int] = []  # a warp render's anchors (empty: linear)
        self.segments: list = []  # what the synthesis jobs reported (SegmentReport)
        self.shared: list[int] | None = None  # keyframes to link once the slower render is done (None: none wait)
        self.deferred: set = set()  # those keyframes: outside the bar's total until their chunk is done
        self.outcome: RenderOutcome | None = None

    def start(self) -> list[Job]:
        return [LayoutJob(self.task)]

    def on_result(self, job: Job, res: JobResult, *, shown: int = 0, prefix_pending: bool = False) -> list[Job]:
        """Take the result of one of this render's jobs; return the jobs to queue next.

        ``shown``: the job's keyframes the bar already counts from their files (a running chunk's); ``prefix_pending``:
        the render whose keyframes this one shares (its prefix) is not finished yet.
        """
        if isinstance(job, LayoutJob):
            if isinstance(res, JobFailure):
                self._end(RenderOutcome(False, res.seconds, res.host, error=res.error))
                return []
            return self._laid_out(res, prefix_pending)
        self.left -= 1
        self.seconds += res.seconds
        if isinstance(res, JobFailure):
            self.bar.update(-shown)
            if self.error is None:
                self.error = res.error
        elif isinstance(res, WarpResult):
            self.segments.append(res.segment)
            self.bar.update(job.anchors[-1] - job.anchors[0] + 1 - len(job.anchors))  # keyframes between anchors
        elif isinstance(res, ChunkResult):
            self.bar.total += len(self.deferred.intersection(job.indices))
            self.bar.update(len(job.indices) - shown)
        if self.left:
            return []
        if self.anchors and self.phase is Phase.KEYFRAMES and self.error is None:
            return self._synthesis_jobs()
        self._end(self._finish())
        return []

    def release_shared(self) -> list[Job]:
        """The slower render this one shares keyframes with is done (or failed): the shared chunks, to queue now."""
        if self.shared is None:
            return []
        shared, self.shared = self.shared, None
        jobs = self._chunk_jobs(shared)
        self.left += len(jobs) - 1
        return jobs

    # -------------------------------------------------------------------------------------------- phases
    def _laid_out(self, res: LayoutResult, prefix_pending: bool) -> list[Job]:
        layout, n = res.layout, res.n_keyframes
        self.phase, self.layout, self.names = Phase.KEYFRAMES, layout, tuple(layout.names)
        self.seconds, self.host = res.seconds, res.host
        existing = set(res.existing)
        warp, n_shared = layout.warp, layout.n_shared
        # A warp render renders its anchors (and a noise probe) first, then synthesizes between them.
        wanted = anchor_indices(n, warp["stride"]) if warp else range(n)
        todo = [i for i in wanted if i not in existing]
        if existing:
            self.log(f"render of {self.task.sequence.name}: {len(existing)} of {n} keyframes already there (kept "
                     "from an interrupted run)")
        n_todo = n - (len(wanted) - len(todo))
        if self.task.prefix is not None and prefix_pending and any(i < n_shared for i in todo):
            # The slower render is still running: its keyframes are linked once it is done. They join the bar's
            # total only then: counted now, the ETA would price them as renders.
            self.shared = [i for i in todo if i < n_shared]
            self.deferred = set(self.shared)
            todo = [i for i in todo if i >= n_shared]
            self.left += 1
        self.bar.total += n_todo - len(self.deferred)
        self.bar.refresh()
        jobs = self._chunk_jobs(todo)
        if warp:
            self.anchors = list(wanted)
        # Every render gets a noise probe (keyframe 0 again with the next seed): the warps are judged against it,
        # and timeline.json and every recording state the render-noise budget from it.
        jobs.append(ProbeJob(self.task, layout))
        self.left += len(jobs)
        return jobs

    def _chunk_jobs(self, indices: list[int]) -> list[Job]:
        """``indices`` of the layout in chunks over the workers."""
        chunks = keyframe_chunks(indices, chunk_size_for(len(indices), self.workers))
        return [ChunkJob(self.task, self.layout, tuple(c)) for c in chunks]

    def _synthesis_jobs(self) -> list[Job]:
        """A warp render's second phase: runs of consecutive segments between anchors spread over the workers (the
        segments are independent once their anchors and the noise probe exist)."""
        self.phase = Phase.SYNTHESIS
        anchors = self.anchors
        groups = keyframe_chunks(range(len(anchors) - 1),
                                 chunk_size_for(len(anchors) - 1, self.workers, largest=MAX_SEGMENTS_PER_JOB))
        self.left = len(groups)
        return [WarpJob(self.task, self.layout, tuple(anchors[g[0]:g[-1] + 2])) for g in groups]

    def _finish(self) -> RenderOutcome:
        """Once every job is back: ``timeline.json`` (in the driver; it needs no Mitsuba), or the first error."""
        if self.error is not None:
            return RenderOutcome(False, self.seconds, self.host, error=self.error)
        try:
            layout = self.layout
            if self.anchors:
                layout = with_warp_results(layout, self.segments)
            finalize_render(layout, self.out_dir / self.task.rel_dir)
        except SimSpadError as exc:
            return RenderOutcome(False, self.seconds, self.host, error=exc.format().replace("\n", "; "))
        return RenderOutcome(True, self.seconds, self.host, n_keyframes=layout.n_keyframes)

    def _end(self, outcome: RenderOutcome) -> None:
        self.phase, self.outcome = Phase.DONE, outcome
