"""What validating a recording on open costs, next to evaluating every method on it.

    python benchmarks/bench_validation.py RECORDING.h5 [--rounds 5] [--no-evaluate]

For the recording: the CPU and wall time of one full validation (:func:`simspad.io.recording.validation.
validate_recording`: structure and every value, streamed; median of ``--rounds``), the peak of memory it allocates
(tracemalloc), then the evaluation of every method the recording allows in one child process (``workers=1``:
its CPU time is all of it), and how many times the evaluation validated the file (it opens it once per job; a file
validated before in the process is not read again, and forked workers inherit that).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import h5py

from simspad.io.recording import validation

_COUNT = r"""
import sys, time
from pathlib import Path
from simspad.io.recording import reader
calls = []
original = reader.validate_recording
reader.validate_recording = lambda h5, path: (calls.append(path), original(h5, path))[1]
from simspad.evaluate.evaluate import evaluate
c0 = time.process_time()
evaluate(Path(sys.argv[1]), out_dir=Path(sys.argv[2]), workers=1)
print("CPU", time.process_time() - c0, "VALIDATIONS", len(calls))
"""


def _validate_once(path: Path) -> tuple[float, float]:
    with h5py.File(path, "r") as h5:
        c0, w0 = time.process_time(), time.perf_counter()
        validation.validate_recording(h5, path)
        return time.process_time() - c0, time.perf_counter() - w0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", type=Path)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-evaluate", action="store_true")
    args = ap.parse_args()
    path = args.recording
    _validate_once(path)  # warm the page cache and imports
    runs = [_validate_once(path) for _ in range(args.rounds)]
    cpu, wall = statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)
    tracemalloc.start()
    _validate_once(path)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(f"{path.name}: {path.stat().st_size / 2**20:.2f} MiB; validation {cpu * 1e3:.1f} ms CPU, "
          f"{wall * 1e3:.1f} ms wall (median of {args.rounds}); peak {peak / 2**20:.2f} MiB allocated")
    if args.no_evaluate:
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        w0 = time.perf_counter()
        res = subprocess.run([sys.executable, "-c", _COUNT, str(path), os.path.join(tmp, "results")],
                             capture_output=True, text=True)
        ev_wall = time.perf_counter() - w0
    line = next((ln for ln in res.stdout.splitlines() if ln.startswith("CPU")), None)
    if line is None:
        print(res.stdout[-1000:], res.stderr[-2000:])
        return 1
    ev_cpu, n_validations = float(line.split()[1]), int(line.split()[3])
    print(f"evaluate (every method, one process): {ev_wall:.2f} s wall with start-up, {ev_cpu:.2f} s CPU; "
          f"the file was validated {n_validations} time(s)")
    print(f"validation / evaluation: {cpu / ev_cpu:.2%} of the CPU, {wall / ev_wall:.2%} of the wall time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
