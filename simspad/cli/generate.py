"""``simspad generate``: run the job and print the closing summary table."""

from __future__ import annotations

import sys
from pathlib import Path

from simspad.cli.text import format_bytes, recording_table
from simspad.dataset.estimate import (
    disk_needed_bytes,
    estimate_spec,
    format_estimate,
    free_disk_bytes,
    measure_unit_costs,
)
from simspad.dataset.executors import ExecutorConfig, default_workers
from simspad.dataset.generate import GenerateResult, generate, raise_for_failures
from simspad.dataset.spec import default_spec_path, find_spec
from simspad.dataset.spec_validation import load_spec
from simspad.errors import SimSpadError
from simspad.io.manifest import manifest_path


def summary_table(res: GenerateResult) -> str:
    """The closing summary: one row per recording (status, size, time), totals and where the files are."""
    recs = res.manifest["recordings"]
    done, skipped = set(res.done), set(res.skipped)
    lines = recording_table(recs, "", lambda e: "new" if e["path"] in done else "kept" if e["path"] in skipped else "")
    lines.insert(1, "-" * len(lines[0]))
    total = sum(e.get("size") or 0 for e in recs)
    n_complete = sum(e["status"] == "complete" for e in recs)
    render_s = sum((r.get("timings") or {}).get("render_s") or 0 for r in res.manifest["renders"]
                   if r["path"] in set(res.renders_done))
    lines += ["",
              f"{n_complete} of {len(recs)} recordings complete ({len(res.done)} generated, {len(res.skipped)} "
              f"already there), {format_bytes(total)} in all; {len(res.renders_done)} render(s) took {render_s:.1f} s",
              f"wall time {res.wall_s:.1f} s on {res.executor}",
              f"dataset:  {res.out_dir}",
              f"manifest: {manifest_path(res.out_dir)}"]
    return "\n".join(lines)


def generate_from_cli(spec_path=None, out_dir=None, executor: str = "local", scheduler: str | None = None,
                      workers: int | None = None, prune: bool = False, estimate_only: bool = False,
                      assume_yes: bool = False) -> Path:
    """``simspad generate``: load the spec (a path or a bundled name; default ``mini``), run, print the summary.

    ``estimate_only``: measure unit costs here and print the estimate instead. Without ``assume_yes`` a run whose
    recordings will not fit the free disk is refused with their size (before anything is written).
    """
    spec = load_spec(find_spec(spec_path) if spec_path is not None else default_spec_path())
    target = Path(out_dir if out_dir is not None else spec.output)
    n_workers = workers or default_workers()
    if estimate_only:
        costs = measure_unit_costs(spec, log=lambda msg: print(msg, file=sys.stderr, flush=True))
        print(format_estimate(estimate_spec(spec, costs), costs, workers=n_workers,
                              free_bytes=free_disk_bytes(target)), flush=True)
        return target
    if not assume_yes:
        need, free = disk_needed_bytes(spec, target), free_disk_bytes(target)
        if need > free:
            raise SimSpadError(f"the recordings need ≈ {format_bytes(need)} (SPAD, frames and ground truth at their "
                               f"stored sizes, before events and renders) but {format_bytes(free)} are free; "
                               "`--estimate` prints the full estimate, `--yes` runs anyway", path=target)
    res = generate(spec, out_dir=out_dir, executor=ExecutorConfig(executor, scheduler, workers), progress=True,
                   check=False, prune=prune)
    print(summary_table(res), flush=True)
    raise_for_failures(res)
    return res.out_dir
