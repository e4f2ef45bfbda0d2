"""The CLI stage of the fuzz test, run in a child process: ``python -m tests.hostile.fuzz_driver JOBS.json OUT.json``.

JOBS.json lists jobs ``{"name", "argv"}``; each is run through ``simspad.cli.main(argv)``, the command line's own
entry point, in this one process (a process per command would cost ≈ 1.5 s of imports each). Before the jobs, the
methods run once on the valid base recording, so that the evaluation workers forked later start with the numba
kernels loaded (tqdm's monitor thread is kept off: with a second thread running, evaluate spawns its workers).
Each job's exit status, stderr and seconds go to OUT.json; the name of the job about to run is printed first, so
a signal that kills the process (a crash in native code) names the job that caused it.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import time
import traceback
from pathlib import Path


def run(argv: list[str]) -> tuple[object, str]:
    """``simspad ARGV`` in this process: (exit status, or "raised" when an exception escaped main; stderr)."""
    from simspad.cli import main  # deferred: imported once the child runs, after PYTHONPATH is set

    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 1
        except BaseException:  # noqa: BLE001 - an escaped exception is a finding: recorded, not raised
            rc = "raised"
            err.write(traceback.format_exc())
    return rc, err.getvalue()


def main(jobs_path: str, out_path: str, warm: str | None = None) -> int:
    import tqdm  # deferred: only to keep its monitor thread from starting

    # evaluate forks its workers only while this process runs no other thread (else it spawns them, and each
    # spawned worker imports everything again); tqdm's monitor thread, started by the first progress bar and
    # kept for the process's life, would make every evaluation after the first spawn.
    tqdm.tqdm.monitor_interval = 0
    jobs = json.loads(Path(jobs_path).read_text())
    if warm:
        from simspad.evaluate.evaluate import evaluate  # deferred: warm-up only

        evaluate(Path(warm), out_dir=Path(out_path).with_suffix(".warm"), workers=1)
    results = []
    for job in jobs:
        print("RUN", job["name"], *job["argv"], flush=True)
        start = time.perf_counter()
        rc, err = run(job["argv"])
        results.append({"name": job["name"], "argv": job["argv"], "rc": rc, "stderr": err,
                        "seconds": time.perf_counter() - start})
    Path(out_path).write_text(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
