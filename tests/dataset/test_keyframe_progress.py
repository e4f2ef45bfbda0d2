"""The keyframe bar moves as a render chunk writes its keyframes, not only when the whole chunk is done (a chunk of
64 paper-scale keyframes takes about an hour on one core)."""

from __future__ import annotations

import io

from tqdm import tqdm

from simspad.dataset.generate import show_written_keyframes
from simspad.dataset.jobs import ChunkJob, ProbeJob
from simspad.dataset.plan import RenderTask
from simspad.dataset.render_job import RenderJob


def test_bar_counts_the_keyframe_files_running_chunks_have_written(tmp_path):
    names = tuple(f"frames/{i:06d}-k{i}.exr" for i in range(8))
    fast = RenderTask(sequence=None, render_hash="h", rel_dir="renders/a", seed=0)
    bar = tqdm(total=6, file=io.StringIO())
    state = RenderJob(fast, tmp_path, 1, bar, print)
    state.names, state.deferred = names, {6, 7}
    chunked = {fast.rel_dir: state}
    (tmp_path / fast.rel_dir / "frames").mkdir(parents=True)
    render = ChunkJob(fast, None, (0, 1, 2, 3))
    linked = ChunkJob(fast, None, (6, 7))  # linked from a slower render: counted at its end
    probe = ProbeJob(fast, None)  # the noise probe: no keyframe of the layout
    running, partial = [render, linked, probe], {}

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
