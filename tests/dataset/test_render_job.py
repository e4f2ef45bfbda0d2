"""A render's state machine (dataset/render_job.py) on typed results, without Mitsuba: which jobs follow which
result, how the keyframe bar moves, and how a failure ends the render; jobs and results survive pickling (they
travel to local pool processes and Dask workers)."""

from __future__ import annotations

import io
import pickle
from types import SimpleNamespace

from tqdm import tqdm

from simspad.dataset.jobs import (
    ChunkJob,
    ChunkResult,
    JobFailure,
    LayoutJob,
    LayoutResult,
    ProbeJob,
    ProbeResult,
    WarpJob,
    WarpResult,
)
from simspad.dataset.plan import RenderTask
from simspad.dataset.render_job import Phase, RenderJob
from simspad.render.render_layout import RenderLayout
from simspad.render.warp.rendering import SegmentReport


def _layout(n: int, warp_stride: int | None = None) -> RenderLayout:
    schedule = {"n_keyframes": n, "interpolation": "warp" if warp_stride else "linear"}
    if warp_stride:
        schedule["warp"] = {"stride": warp_stride, "threshold": 2.0, "emission_layer": False}
    eye = tuple(tuple(float(i == j) for j in range(4)) for i in range(4))
    return RenderLayout(times_s=tuple(0.001 * i for i in range(n)),
                        names=tuple(f"frames/{i:06d}.exr" for i in range(n)), camera_to_world=(eye,) * n, width=8,
                        height=6, spp=1, seed=7, variant="scalar_rgb",
                        scene_hash="s", trajectory_hash="t", timeline={"schedule": schedule})


def _render(tmp_path, workers=2):
    task = RenderTask(sequence=SimpleNamespace(name="seq"), render_hash="h" * 16, rel_dir="renders/seq-h", seed=7)
    bar = tqdm(total=0, file=io.StringIO())
    return task, RenderJob(task, tmp_path, workers, bar, lambda msg: None), bar


def test_linear_render_queues_chunks_and_probe_and_a_failed_chunk_fails_it(tmp_path):
    task, render, bar = _render(tmp_path)
    (layout_job,) = render.start()
    assert isinstance(layout_job, LayoutJob) and render.phase is Phase.LAYOUT
    jobs = render.on_result(layout_job, LayoutResult(layout=_layout(10), existing=(0, 1), seconds=1.0, host="a"))
    chunks = [j for j in jobs if isinstance(j, ChunkJob)]
    assert [j for j in jobs if isinstance(j, ProbeJob)] == [jobs[-1]]  # the probe after the chunks
    assert sorted(i for c in chunks for i in c.indices) == list(range(2, 10))  # files already there: not again
    assert render.phase is Phase.KEYFRAMES and bar.total == 8 and render.left == len(jobs)
    assert render.on_result(chunks[0], ChunkResult(n_rendered=len(chunks[0].indices), n_reused=0, seconds=2.0)) == []
    assert bar.n == len(chunks[0].indices)
    render.on_result(chunks[1], JobFailure(error="boom", seconds=0.5))
    for job in jobs[2:-1]:
        render.on_result(job, ChunkResult(n_rendered=len(job.indices), n_reused=0))
    assert render.outcome is None  # the probe is still out
    render.on_result(jobs[-1], ProbeResult(n_rendered=1, seconds=0.25))
    assert render.phase is Phase.DONE and not render.outcome.ok and render.outcome.error == "boom"
    assert render.outcome.seconds == 3.75 and render.outcome.host == "a"


def test_warp_render_synthesizes_between_anchors_after_they_and_the_probe_are_back(tmp_path):
    task, render, bar = _render(tmp_path, workers=1)
    (layout_job,) = render.start()
    jobs = render.on_result(layout_job, LayoutResult(layout=_layout(10, warp_stride=4)))
    anchors = sorted(i for j in jobs if isinstance(j, ChunkJob) for i in j.indices)
    assert anchors == [0, 4, 8, 9] and bar.total == 10
    follow = []
    for job in jobs:
        follow += render.on_result(job, ChunkResult(n_rendered=1, n_reused=0) if isinstance(job, ChunkJob)
                                   else ProbeResult(n_rendered=1))
    assert render.phase is Phase.SYNTHESIS and all(isinstance(j, WarpJob) for j in follow) and bar.n == 4
    assert [j.anchors for j in follow] == [(0, 4), (4, 8), (8, 9)]  # consecutive anchors, segments spread
    for job in follow:
        lo, hi = job.anchors[0], job.anchors[-1]
        segment = SegmentReport(lo=lo, hi=hi, names=_layout(10).names[lo:hi + 1], sources=("warp",) * (hi - lo + 1),
                                scores={}, holes={}, patched={}, noise=0.01, n_geometry=0, n_blocks=0)
        render.on_result(job, WarpResult(segment=segment, n_rendered=0))
    assert bar.n == 10  # the keyframes between the anchors
    # Finishing writes timeline.json in the driver: here the keyframe files are missing, and it says so.
    assert render.phase is Phase.DONE and not render.outcome.ok and "not rendered yet" in render.outcome.error
    # What travels to workers and back pickles whole.
    for obj in (follow[0], WarpResult(segment=segment, n_rendered=0), LayoutResult(layout=_layout(3)),
                JobFailure(error="x", died=True)):
        again = pickle.loads(pickle.dumps(obj))
        assert type(again) is type(obj) and (again == obj if not isinstance(obj, WarpJob) else
                                             (again.task, again.layout, again.anchors) == (obj.task, obj.layout,
                                                                                           obj.anchors))


def test_a_faster_render_waits_for_its_shared_keyframes(tmp_path):
    task, render, bar = _render(tmp_path)
    schedule = {"interpolation": "linear", "shared_keyframes": {"n_keyframes": 3}}
    layout = RenderLayout(**{**_layout(8).__dict__, "timeline": {"schedule": schedule}})
    slower = RenderTask(sequence=task.sequence, render_hash="g" * 16, rel_dir="renders/seq-g", seed=7)
    render.task = RenderTask(**{**task.__dict__, "prefix": slower})
    jobs = render.on_result(LayoutJob(render.task), LayoutResult(layout=layout), prefix_pending=True)
    assert sorted(i for j in jobs if isinstance(j, ChunkJob) for i in j.indices) == [3, 4, 5, 6, 7]
    assert bar.total == 5  # the shared three join the total when their chunk is done
    for job in jobs:
        render.on_result(job, ChunkResult(n_rendered=1, n_reused=0) if isinstance(job, ChunkJob)
                         else ProbeResult(n_rendered=1))
    assert render.outcome is None  # the shared keyframes still wait
    shared = render.release_shared()
    assert [i for j in shared for i in j.indices] == [0, 1, 2] and render.release_shared() == []
    render.on_result(shared[0], JobFailure(error="link failed"))
    for job in shared[1:]:
        assert render.outcome is None
        render.on_result(job, ChunkResult(n_rendered=0, n_reused=len(job.indices)))
    assert render.outcome is not None and render.outcome.error == "link failed"
    assert bar.total == 7  # the shared ones join as their chunks are done (not the failed one's)
