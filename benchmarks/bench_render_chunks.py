"""Benchmark chunked rendering: one sequence rendered by 1 worker and by N workers (chunks of keyframes through
the local executor, as ``simspad generate`` runs them), wall time and speed-up, and a byte comparison of every
keyframe and of ``timeline.json``.

Run::

    python benchmarks/bench_render_chunks.py                       # office, 96×72, 16 spp, 20 ms; 1 vs 2 workers
    python benchmarks/bench_render_chunks.py --workers 1 2 4 --scene piano --duration 0.05

The reference is the same code with one worker (one process renders every chunk in turn), run in this process
right before; the machine's load average is printed with each figure, since a shared machine skews wall times.
On a saturated machine wall time cannot show the speed-up (each process gets a share of the cores whatever the
split), so the CPU time of every chunk is printed too: total over the busiest worker's is the speed-up the
split gives on free cores.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from simspad.dataset.executors import LocalExecutor, job_environment  # noqa: E402
from simspad.dataset.plan import RenderTask  # noqa: E402
from simspad.dataset.spec import SequenceSpec  # noqa: E402
from simspad.dataset.jobs import ChunkJob, ChunkResult, JobFailure, LayoutJob, LayoutResult  # noqa: E402
from simspad.dataset.task_queue import TaskQueue  # noqa: E402
from simspad.render.render_layout import chunk_size_for, keyframe_chunks  # noqa: E402
from simspad.processes import available_cores  # noqa: E402
from simspad.render.renderer import finalize_render  # noqa: E402
from simspad.render.settings import RenderSettings  # noqa: E402


def render_with(task, out: Path, workers: int) -> tuple[float, int, float, float]:
    """Lay out once, render every keyframe in chunks on ``workers`` processes, finalize: wall seconds, keyframes,
    total CPU seconds of the chunks, and the CPU seconds of the busiest worker process (the critical path)."""
    per_pid: dict[int, float] = {}
    ex = LocalExecutor(out, job_environment(), workers)
    try:
        queue = TaskQueue(ex, print)
        t0 = time.perf_counter()
        queue.add(LayoutJob(task))
        layout = None
        while queue.busy:
            for job, res in queue.finished():
                if isinstance(res, JobFailure):
                    raise SystemExit(f"{job.label} failed: {res.error}")
                if isinstance(res, ChunkResult):
                    per_pid[res.pid] = per_pid.get(res.pid, 0.0) + res.cpu_s
                if isinstance(res, LayoutResult):
                    layout = res.layout
                    todo = [i for i in range(res.n_keyframes) if i not in set(res.existing)]
                    for c in keyframe_chunks(todo, chunk_size_for(len(todo), workers)):
                        queue.add(ChunkJob(task, layout, tuple(c)))
        finalize_render(layout, out / task.rel_dir)
        return time.perf_counter() - t0, len(layout.names), sum(per_pid.values()), max(per_pid.values())
    finally:
        ex.close()


def digest(render_dir: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(render_dir.rglob("*")):
        if p.is_file():
            h.update(p.name.encode() + p.read_bytes())
    return h.hexdigest()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="office")
    ap.add_argument("--resolution", type=int, nargs=2, default=(96, 72))
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--duration", type=float, default=0.02)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args(argv)
    defaults = RenderSettings(duration_s=args.duration)
    # the real task types, as `simspad generate` builds them (stand-ins drifted from them once: a field the
    # workers read was missing)
    seq = SequenceSpec(name="bench", scene=args.scene, trajectory=None, duration_s=args.duration, start_s=0.0,
                       resolution=tuple(args.resolution), spp=args.spp, max_flow_px=defaults.max_flow_px,
                       min_rate_hz=defaults.min_rate_hz)
    task = RenderTask(seq, "0" * 64, "renders/bench", 1)
    print(f"one sequence: {args.scene}, {args.resolution[0]}×{args.resolution[1]} px, {args.spp} spp, "
          f"{args.duration * 1e3:g} ms; {available_cores()} cores")
    base_s, base_digest = None, None
    with tempfile.TemporaryDirectory(prefix="bench_render_chunks_") as d:
        for n in args.workers:
            out = Path(d) / f"w{n}"
            load = os.getloadavg()[0]
            wall, n_kf, cpu, busiest = render_with(task, out, n)
            dig = digest(out / task.rel_dir)
            base_s = base_s or wall
            base_digest = base_digest or dig
            print(f"  {n:3d} worker(s): {wall:7.1f} s for {n_kf} keyframes ({n_kf / wall:.2f} keyframes/s), "
                  f"speed-up {base_s / wall:.2f}× against {args.workers[0]} worker(s); bytes "
                  f"{'identical' if dig == base_digest else 'DIFFERENT'}; load average before {load:.1f}")
            print(f"      CPU: {cpu:.1f} s in all chunks, busiest worker {busiest:.1f} s → work spread "
                  f"{cpu / busiest:.2f}× (the speed-up on {n} free cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
