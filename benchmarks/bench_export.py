"""Export memory: peak RSS of the streaming exporters versus a whole-recording-in-memory reference, two lengths.

Run: ``python benchmarks/bench_export.py [n_small] [n_large]`` (default 1 000 000 and 8 000 000 events). Each
export runs in a fresh child process, so its peak resident memory (``ru_maxrss``) is its own. The streaming
exporters (``simspad.io.export``, 2²⁰ events a chunk) should stay flat from the short recording to the long one;
the reference reads every column into memory and writes it in one go (h5py for DSEC, one encoder call for
EVT 3.0), as a naive exporter would. Timings are printed as a ratio too (streaming / reference).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from simspad.io.recording import RecordingWriter

_CHILD = r"""
import json, resource, sys, time
from pathlib import Path
import h5py, numpy as np
mode, fmt, rec, out = sys.argv[1:5]
t0 = time.perf_counter()
if mode == "stream":
    from simspad.io.export.dispatch import export_recording
    export_recording(rec, fmt, out)
else:
    from simspad.io.export.evt3 import Evt3Encoder
    with h5py.File(rec, "r") as h5:
        ev = {k: h5["events/" + k][()] for k in ("t", "x", "y", "p")}
    if fmt == "dsec":
        with h5py.File(out, "w") as f:
            for k in ("p", "t", "x", "y"):
                f.create_dataset("events/" + k, data=ev[k], compression="gzip", compression_opts=1, shuffle=True)
            f["ms_to_idx"] = np.searchsorted(ev["t"], np.arange(ev["t"][-1] // 1000 + 2) * 1000)
            f["t_offset"] = np.int64(0)
    else:
        Path(out).write_bytes(Evt3Encoder().encode(ev["t"], ev["x"], ev["y"], ev["p"]).tobytes())
print(json.dumps({"s": time.perf_counter() - t0, "maxrss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def write_events(path: Path, n: int, seed: int = 0) -> None:
    """``n`` random events on 346 × 260 pixels at 10 M events s⁻¹, written 2²⁰ at a time."""
    rng = np.random.default_rng(seed)
    duration_s = n / 1e7
    step = 1 << 20
    with RecordingWriter(path, dict(width=346, height=260, duration_s=duration_s, lux=1.0)) as w:
        cols = {k: w.append_dataset(f"events/{k}", (), dt, chunk_rows=step)
                for k, dt in (("t", np.int64), ("x", np.uint16), ("y", np.uint16), ("p", np.uint8))}
        for i in range(0, n, step):
            m = min(step, n - i)
            cols["t"].append(np.sort(rng.integers(i // 10, (i + m) // 10, m)))
            cols["x"].append(rng.integers(0, 346, m))
            cols["y"].append(rng.integers(0, 260, m))
            cols["p"].append(rng.integers(0, 2, m))
        n_ms = int(np.ceil(duration_s * 1e3)) + 1
        w.write_dataset("events/ms_to_idx", np.zeros(n_ms, np.uint64))  # not read by the exporters
        w.set_attrs("events", threshold_on=0.2, threshold_off=0.2)


def run(mode: str, fmt: str, rec: Path, out: Path) -> dict:
    res = subprocess.run([sys.executable, "-c", _CHILD, mode, fmt, str(rec), str(out)], capture_output=True,
                         text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    sizes = [int(a) for a in sys.argv[1:3]] or [1_000_000, 8_000_000]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        print(f"{'events':>10} {'format':>6} {'stream MiB':>11} {'reference MiB':>14} {'ratio':>6} {'time ratio':>11}")
        for n in sizes:
            rec = tmp / f"rec_{n}.h5"
            write_events(rec, n)
            for fmt, suffix in (("dsec", ".h5"), ("evt3", ".raw")):
                s = run("stream", fmt, rec, tmp / f"s{suffix}")
                r = run("reference", fmt, rec, tmp / f"r{suffix}")
                print(f"{n:>10} {fmt:>6} {s['maxrss_mib']:>11.0f} {r['maxrss_mib']:>14.0f} "
                      f"{s['maxrss_mib'] / r['maxrss_mib']:>6.2f} {s['s'] / r['s']:>11.2f}")
            rec.unlink()


if __name__ == "__main__":
    main()
