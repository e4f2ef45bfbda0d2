"""The keyframe bar moves as a render chunk writes its keyframes, not only when the whole chunk is done (a chunk of
64 paper-scale keyframes takes about an hour on one core)."""

from __future__ import annotations

import io

from tqdm import tqdm

from simspad.dataset.generate import _ChunkedRender, show_written_keyframes
from simspad.dataset.plan import RenderTask
from simspad.dataset.task_queue import Job


def test_bar_counts_the_keyframe_files_running_chunks_have_written(tmp_path):
    names = tuple(f"frames/{i:06d}-k{i}.exr" for i in range(8))
    fast = RenderTask(sequence=None, render_hash="h", rel_dir="renders/a", seed=0)
    chunked = {fast.rel_dir: _ChunkedRender({}, names=names, deferred={6, 7})}
    (tmp_path / fast.rel_dir / "frames").mkdir(parents=True)
    render = Job("chunk", (fast, [0, 1, 2, 3]), submit=lambda: None)
    linked = Job("chunk", (fast, [6, 7]), submit=lambda: None)  # linked from a slower render: counted at its end
    probe = Job("chunk", (fast, []), submit=lambda: None)  # a warp render's noise probe: no keyframe of the plan
    running, partial = [render, linked, probe], {}
    bar = tqdm(total=6, file=io.StringIO())

    def write(*indices):
        for i in indices:
            (tmp_path / fast.rel_dir / names[i]).write_bytes(b"exr")

    show_written_keyframes(tmp_path, running, chunked, partial, bar)
    assert bar.n == 0
    write(0, 1, 6, 7)
    show_written_keyframes(tmp_path, running, chunked, partial, bar)
    assert bar.n == 2 and partial == {render: 2}
    write(2)
    show_written_keyframes(tmp_path, running, chunked, partial, bar)
    show_written_keyframes(tmp_path, running, chunked, partial, bar)  # nothing new: no double count
    assert bar.n == 3 and partial == {render: 3}
