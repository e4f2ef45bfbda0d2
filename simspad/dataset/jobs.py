"""The dataset driver's units of work and what they report: one frozen dataclass per job kind and per result.

A job says what to run (:class:`LayoutJob`, :class:`ChunkJob`, :class:`ProbeJob`, :class:`WarpJob`,
:class:`SimulationJob`); :func:`simspad.dataset.executors.run_job` runs it inside a worker process and returns
its result (:class:`LayoutResult`, :class:`ChunkResult`, :class:`ProbeResult`, :class:`WarpResult`,
:class:`SimulationResult`), or a :class:`JobFailure` with a one-line error. Every executor has one
``submit(job)``. Jobs and results are plain picklable data (a Dask worker on another machine receives and returns
them), and hold nothing that depends on which executor, worker or order ran them, so neither can change a byte.

A render is several jobs (:mod:`simspad.dataset.render_job` runs them in order); a recording is one.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import ClassVar, Union

from simspad.dataset.plan import RecordingTask, RenderTask
from simspad.render.render_layout import RenderLayout
from simspad.render.warp.rendering import SegmentReport


class JobKind(enum.Enum):
    """What a job does; :data:`QUEUE_ORDER` says which waiting jobs are submitted first."""

    LAYOUT = "layout"  # a render's keyframe instants, poses and file names (unlocks its chunks)
    CHUNK = "chunk"  # a run of consecutive keyframes rendered (a warp render's anchors, or every keyframe)
    PROBE = "probe"  # a render's noise probe: keyframe 0 again with the next seed
    WARP = "warp"  # a warp render's keyframes between a run of anchors, synthesized
    SIMULATION = "simulation"  # one recording simulated from its finished render


#: Waiting jobs are submitted in this order (a job of a smaller rank first): layouts unlock chunks, chunks (and
#: probes, queued with them) unlock simulations or a warp render's synthesis.
QUEUE_ORDER: dict[JobKind, int] = {JobKind.LAYOUT: 0, JobKind.CHUNK: 1, JobKind.PROBE: 1, JobKind.WARP: 2,
                                   JobKind.SIMULATION: 3}


# ---------------------------------------------------------------------------------------------------- jobs
# eq=False: a job is one submission (the driver keys its bookkeeping by the job object), and a layout is no key.
@dataclass(frozen=True, eq=False)
class LayoutJob:
    """Lay out a render (:func:`simspad.render.renderer.layout_render`) and create its directory."""

    task: RenderTask
    kind: ClassVar[JobKind] = JobKind.LAYOUT

    @property
    def label(self) -> str:
        return f"the render layout of {self.task.sequence.name}"

    @property
    def dask_key(self) -> str:
        return f"render-layout-{self.task.sequence.name}-{self.task.render_hash[:12]}"


@dataclass(frozen=True, eq=False)
class ChunkJob:
    """Render the keyframes ``indices`` (consecutive) of a laid-out render."""

    task: RenderTask
    layout: RenderLayout
    indices: tuple[int, ...]
    kind: ClassVar[JobKind] = JobKind.CHUNK

    @property
    def label(self) -> str:
        return f"keyframes {self.indices[0]}–{self.indices[-1]} of {self.task.sequence.name}"

    @property
    def dask_key(self) -> str:
        return f"render-{self.task.sequence.name}-{self.task.render_hash[:12]}-{self.indices[0]:06d}"


@dataclass(frozen=True, eq=False)
class ProbeJob:
    """Render the noise probe of a laid-out render (every render has one: its render-noise budget)."""

    task: RenderTask
    layout: RenderLayout
    kind: ClassVar[JobKind] = JobKind.PROBE

    @property
    def label(self) -> str:
        return f"the noise probe of {self.task.sequence.name}"

    @property
    def dask_key(self) -> str:
        return f"noise-probe-{self.task.sequence.name}-{self.task.render_hash[:12]}"


@dataclass(frozen=True, eq=False)
class WarpJob:
    """Synthesize the keyframes between consecutive ``anchors`` of a warp render (anchors and probe rendered)."""

    task: RenderTask
    layout: RenderLayout
    anchors: tuple[int, ...]
    kind: ClassVar[JobKind] = JobKind.WARP

    @property
    def label(self) -> str:
        return f"synthesis of keyframes {self.anchors[0]}–{self.anchors[-1]} of {self.task.sequence.name}"

    @property
    def dask_key(self) -> str:
        return f"warp-{self.task.sequence.name}-{self.task.render_hash[:12]}-{self.anchors[0]:06d}"


@dataclass(frozen=True, eq=False)
class SimulationJob:
    """Simulate one (sequence, speed, lux) recording from its finished render, and hash it."""

    task: RecordingTask
    kind: ClassVar[JobKind] = JobKind.SIMULATION

    @property
    def label(self) -> str:
        return self.task.rel_path

    @property
    def dask_key(self) -> str:
        return f"simulate-{self.task.sequence_name}-{self.task.lux:g}lx-{self.task.recording_hash[:12]}"


Job = Union[LayoutJob, ChunkJob, ProbeJob, WarpJob, SimulationJob]
#: Jobs that render (in the executors' render pool, with Mitsuba loaded); the others simulate.
RENDER_JOBS = (LayoutJob, ChunkJob, ProbeJob, WarpJob)


# ---------------------------------------------------------------------------------------------------- results
@dataclass(frozen=True, kw_only=True)
class JobResult:
    """What every finished job reports: its wall time in the worker (s) and the worker's host."""

    seconds: float = 0.0
    host: str | None = None
    #: True for a job that did its work; :class:`JobFailure` says False.
    ok: ClassVar[bool] = True


@dataclass(frozen=True, kw_only=True)
class JobFailure(JobResult):
    """A job that raised, or whose worker died. ``error`` is one line; ``died``: the worker process was killed
    under it (out of memory, a segfault), so the driver retries it once."""

    error: str
    died: bool = False
    traceback: str = field(default="", repr=False)
    ok: ClassVar[bool] = False


@dataclass(frozen=True, kw_only=True)
class LayoutResult(JobResult):
    """A render laid out: its :class:`RenderLayout` and the keyframes whose files are already there (a killed
    run's, kept)."""

    layout: RenderLayout
    existing: tuple[int, ...] = ()

    @property
    def n_keyframes(self) -> int:
        return self.layout.n_keyframes


@dataclass(frozen=True, kw_only=True)
class ChunkResult(JobResult):
    """A chunk rendered: keyframes rendered now and re-used (files there, or linked from a slower render);
    ``cpu_s`` is the worker's CPU time (all threads)."""

    n_rendered: int
    n_reused: int
    cpu_s: float = 0.0
    pid: int | None = None


@dataclass(frozen=True, kw_only=True)
class ProbeResult(JobResult):
    """The noise probe: rendered now (1) or already there (0)."""

    n_rendered: int
    cpu_s: float = 0.0


@dataclass(frozen=True, kw_only=True)
class WarpResult(JobResult):
    """A run of warp segments done: what it did (:class:`~simspad.render.warp.rendering.SegmentReport`, merged
    into ``timeline.json`` by the driver) and the keyframes it rendered for real."""

    segment: SegmentReport
    n_rendered: int
    cpu_s: float = 0.0


@dataclass(frozen=True, kw_only=True)
class SimulationResult(JobResult):
    """A recording written: its size (bytes), sha256 and the image motion measured on its render (manifest
    fields)."""

    size: int
    sha256: str
    motion: dict = field(default_factory=dict)
