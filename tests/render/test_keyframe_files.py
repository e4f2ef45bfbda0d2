"""Render directories created by several processes at once (the chunks of one render start side by side)."""

from __future__ import annotations

import multiprocessing

from simspad.render.keyframe_files import make_out_dir

N_PROCESSES = 8


def _create(barrier, out_dir, results):
    barrier.wait()  # every process checks and creates the same new directories at the same moment
    try:
        make_out_dir(out_dir)
        results.put("ok")
    except Exception as exc:  # noqa: BLE001 - reported to the test
        results.put(f"{type(exc).__name__}: {exc}")


def test_render_directory_created_by_many_processes_at_once(tmp_path):
    """Each of 8 processes creates the same new render directory (and its parents and ``frames/``) at once: every
    one succeeds. A check-then-create race once failed a chunk with "cannot create the output directory (File
    exists)" when two chunks of a render started together, and the render had to be run again."""
    ctx = multiprocessing.get_context("fork")
    failures = []
    for attempt in range(5):  # the race window is short: several fresh directories
        out_dir = tmp_path / f"a{attempt}" / "renders" / "office-0123"
        barrier, results = ctx.Barrier(N_PROCESSES), ctx.Queue()
        procs = [ctx.Process(target=_create, args=(barrier, out_dir, results)) for _ in range(N_PROCESSES)]
        for p in procs:
            p.start()
        outcomes = [results.get(timeout=60) for _ in procs]
        for p in procs:
            p.join(timeout=60)
        failures += [o for o in outcomes if o != "ok"]
        assert (out_dir / "frames").is_dir()
    assert not failures, failures[:3]
