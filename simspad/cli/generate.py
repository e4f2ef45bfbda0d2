"""``simspad generate``: run the job and print the closing summary table."""

from __future__ import annotations

import sys
from pathlib import Path

from simspad.cli.text import format_bytes, recording_table
from simspad.dataset.estimate import (
    dataset_bytes_on_disk,
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


#: ``generate`` measures the estimate before running unless this many times the uncompressed size of the SPAD bits,
#: frames and ground truth fits the free disk. The bound leaves out events and renders: with them the embedded mini
#: dataset takes 2.2× the bound (182 MiB against 84: its renders are 102 MiB), the paper-scale spec 0.7× (its
#: compressed SPAD bits are far below one bit per pixel and bin).
DISK_CHECK_MARGIN = 4


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


def _measured_estimate(spec):
    """(estimate, unit costs) of ``spec``, measured here as ``--estimate`` does, with progress on stderr."""
    costs = measure_unit_costs(spec, log=lambda msg: print(msg, file=sys.stderr, flush=True))
    return estimate_spec(spec, costs), costs


def refuse_if_it_will_not_fit(spec, target: Path, n_workers: int) -> None:
    """Raise :class:`SimSpadError` (after printing the estimate) when the run will not fit the free disk.

    The uncompressed size of the SPAD bits, frames and ground truth still to write (no measurement) is checked
    first: when :data:`DISK_CHECK_MARGIN` times it fits, the run goes ahead at once. Otherwise the estimate is
    measured as ``--estimate`` does (compressed SPAD bits, events, renders; ≈ 10 s to a minute) and decides, less
    what the dataset folder already holds.
    """
    bound, free = disk_needed_bytes(spec, target), free_disk_bytes(target)
    if DISK_CHECK_MARGIN * bound <= free:
        return
    print(f"the recordings' uncompressed size (≈ {format_bytes(bound)}) is more than 1/{DISK_CHECK_MARGIN} of the "
          f"free disk ({format_bytes(free)}): measuring what the run will write", file=sys.stderr, flush=True)
    est, costs = _measured_estimate(spec)
    need = max(est.disk_bytes - dataset_bytes_on_disk(target), 0)
    if need > free:
        print(format_estimate(est, costs, workers=n_workers, free_bytes=free), file=sys.stderr, flush=True)
        raise SimSpadError(f"the run needs ≈ {format_bytes(need)} more (recordings and renders, estimate above) but "
                           f"{format_bytes(free)} are free; `--yes` runs anyway", path=target)
    print(f"estimated ≈ {format_bytes(need)} to write, {format_bytes(free)} free: running", file=sys.stderr,
          flush=True)


def generate_from_cli(spec_path=None, out_dir=None, executor: str = "local", scheduler: str | None = None,
                      workers: int | None = None, prune: bool = False, estimate_only: bool = False,
                      assume_yes: bool = False) -> Path:
    """``simspad generate``: load the spec (a path or a bundled name; default ``mini``), run, print the summary.

    ``estimate_only``: measure unit costs here and print the estimate instead. Without ``assume_yes`` a run that
    will not fit the free disk is refused with the estimate (before anything is written:
    :func:`refuse_if_it_will_not_fit`).
    """
    spec = load_spec(find_spec(spec_path) if spec_path is not None else default_spec_path())
    target = Path(out_dir if out_dir is not None else spec.output)
    n_workers = workers or default_workers()
    if estimate_only:
        est, costs = _measured_estimate(spec)
        print(format_estimate(est, costs, workers=n_workers, free_bytes=free_disk_bytes(target)), flush=True)
        return target
    if not assume_yes:
        refuse_if_it_will_not_fit(spec, target, n_workers)
    res = generate(spec, out_dir=out_dir, executor=ExecutorConfig(executor, scheduler, workers), progress=True,
                   check=False, prune=prune)
    print(summary_table(res), flush=True)
    raise_for_failures(res)
    return res.out_dir
