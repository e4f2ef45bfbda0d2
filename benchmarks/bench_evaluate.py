"""Evaluate throughput: today's code against a baseline revision on the same recordings, in the same session.

Both versions run ``python -m simspad.cli evaluate`` as subprocesses on the same subset of a dataset (a directory of
symbolic links to its recordings), after a warm-up run of their own on one recording so that numba caches are warm
for both; the baseline's source is exported with ``git archive``. They run in alternating rounds (``--rounds``).
Reported: wall seconds and CPU seconds (user + system of the process tree) of each run and each round's ratios,
the ratios of the fastest run of each side, and whether the two results tables agree (every column but
``runtime_s`` and the columns the baseline does not have).

Then the fresh-process warm-up of the methods: the first reconstruction of each method in a new process, with an
empty numba cache (the first run after an install) and with the cache that run left (every later run).

    python benchmarks/bench_evaluate.py DATASET [--recordings N] [--baseline REV] [--rounds K]

Skips (exit 0, with a message) when git or the baseline revision is unavailable.
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import hdf5plugin

REPO = Path(__file__).resolve().parents[1]

WARMUP_SCRIPT = r"""
import sys, time
from simspad.evaluate.protocol import evaluation_indices
from simspad.io.recording import open_recording
from simspad.methods.registry import available_methods, get_method
with open_recording(sys.argv[1]) as rec:
    times = rec.gt.t[evaluation_indices(rec.gt.t, 1000.0)][:2]
    for name in available_methods(rec):
        t0 = time.perf_counter()
        for _ in get_method(name).reconstruct(rec, times):
            pass
        print(f"{name} {time.perf_counter() - t0:.3f}", flush=True)
"""


def run_timed(cmd: list[str], env: dict, cwd: Path, ok: tuple[int, ...] = (0, 1)) -> tuple[float, float, str]:
    """(wall s, CPU s of the process tree, stdout) of one command; exits naming it if its status is not in ``ok``
    (``simspad evaluate`` exits 1 when some method runs failed: they are then reported as not comparable)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode not in ok:
        sys.exit(f"command failed ({res.returncode}): {' '.join(cmd)}\n{res.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, res.stdout


def subset(dataset: Path, n: int, dest: Path) -> list[Path]:
    """Hard links to (or, across filesystems, copies of) ``n`` recordings of ``dataset`` spread over scenes and
    light levels, in ``dest``: ``evaluate`` refuses a symbolic link leading out of the folder it reads."""
    recs = sorted(p for p in (dataset / "recordings").rglob("*.h5") if not p.name.startswith("."))
    if not recs:
        sys.exit(f"no recordings under {dataset / 'recordings'}")
    step = max(1, len(recs) // n)
    chosen = recs[::step][:n]
    dest.mkdir(parents=True)
    for p in chosen:
        try:
            os.link(p, dest / p.name)
        except OSError:  # another filesystem
            shutil.copy2(p, dest / p.name)
    return chosen


def read_rows(results_csv: Path) -> list[dict]:
    """The rows of a results.csv."""
    with open(results_csv, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def failed_runs(rows: list[dict]) -> list[str]:
    """``method/recording: error`` of every results row whose ``error`` column is set."""
    return [f"{r.get('method')}/{r.get('recording')}: {r['error'][:120]}" for r in rows if r.get("error")]


def compare(ra: list[dict], rb: list[dict]) -> str:
    """Whether two results tables agree on the columns both have, ``runtime_s`` aside; where they do not, the
    largest difference of PSNR (dB) and the columns that differ."""
    # image: the path of the comparison image, whose folder gained the speed suffix after the baseline (its two
    # speeds of a sequence shared a folder); runtime_s and mtf50_cyc_px as before
    skip = ("runtime_s", "mtf50_cyc_px", "image")
    common = [c for c in ra[0] if c in rb[0] and c not in skip] if ra and rb else []
    same = len(ra) == len(rb) and all(x[c] == y[c] for x, y in zip(ra, rb) for c in common)
    out = f"{len(ra)} rows, {len(common)} common columns {'identical' if same else 'DIFFERENT'}"
    if not same and len(ra) == len(rb):
        differing = sorted({c for x, y in zip(ra, rb) for c in common if x[c] != y[c]})
        d_psnr = [abs(float(x["psnr_db"]) - float(y["psnr_db"])) for x, y in zip(ra, rb)
                  if "psnr_db" in common and x["psnr_db"] and y["psnr_db"]]
        methods = sorted({x["method"] for x, y in zip(ra, rb) for c in common if x[c] != y[c]})
        out += (f" (columns {', '.join(differing)}; methods {', '.join(methods)}; "
                f"max |dPSNR| {max((d for d in d_psnr if d == d), default=0.0):.3g} dB)")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--recordings", type=int, default=5, help="recordings evaluated (default 5; 0: all)")
    ap.add_argument("--baseline", default="d1f88c3", help="git revision of the baseline (default d1f88c3)")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds of baseline and today (default 3)")
    args = ap.parse_args()
    if shutil.which("git") is None:
        print("skipped: git not found")
        return
    with tempfile.TemporaryDirectory(prefix="bench_evaluate_") as tmp:
        tmp = Path(tmp)
        base_src = tmp / "baseline"
        base_src.mkdir()
        archive = subprocess.run(["git", "-C", str(REPO), "archive", args.baseline, "simspad"],
                                 capture_output=True)
        if archive.returncode != 0:
            print(f"skipped: baseline revision {args.baseline} not available ({archive.stderr.decode()[:200]})")
            return
        subprocess.run(["tar", "-x", "-C", str(base_src)], input=archive.stdout, check=True)
        n = args.recordings or 10 ** 9
        chosen = subset(args.dataset, n, tmp / "subset")
        subset(args.dataset, 1, tmp / "warm")
        print(f"{len(chosen)} recordings of {args.dataset}: {', '.join(p.stem for p in chosen)}")
        envs = {}
        for name, src in (("baseline", base_src), ("today", REPO)):
            # Recordings store their SPAD bits with the Zstandard filter, which the baseline (older than that
            # default) does not register: HDF5 then loads it from hdf5plugin's folder, as any outside reader can.
            # Without it the baseline failed on every SPAD method and its "speed-up" measured less work.
            envs[name] = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(tmp / f"numba_{name}"),
                              SOURCE_DATE_EPOCH="1700000000", HDF5_PLUGIN_PATH=hdf5plugin.PLUGIN_PATH)
        cli = [sys.executable, "-m", "simspad.cli", "evaluate"]
        for name, env in envs.items():
            run_timed(cli + [str(tmp / "warm"), "--out", str(tmp / f"warm_{name}")], env, tmp)
        # Rounds of (baseline, today), each ratio taken within its round: this machine's speed drifts over tens of
        # seconds (one round measured 3.70x, the next 2.94x), and the fastest run of each side is the least
        # disturbed measure of its work.
        results = {"baseline": [], "today": []}
        timings = ""
        for r in range(args.rounds):
            for name, env in envs.items():
                wall, cpu, out = run_timed(cli + [str(tmp / "subset"), "--out", str(tmp / f"out_{name}_{r}")], env,
                                           tmp)
                results[name].append((wall, cpu))
                if name == "today" and not timings:
                    timings = out[out.find("timings"):].rstrip()
            (bw, bc), (tw, tc) = results["baseline"][-1], results["today"][-1]
            print(f"round {r + 1}: baseline wall {bw:6.1f} s CPU {bc:6.1f} s   today wall {tw:6.1f} s CPU {tc:6.1f} s"
                  f"   ratio wall {bw / tw:5.2f}x CPU {bc / tc:5.2f}x")
        print(timings)
        rows = {name: read_rows(tmp / f"out_{name}_0" / "results.csv") for name in results}
        failed = {name: failed_runs(r) for name, r in rows.items()}
        if any(failed.values()):
            print("speed-up   not comparable: method runs that failed (the two did different work): " +
                  "; ".join(f"{name} {len(f)} ({f[0]})" for name, f in failed.items() if f))
        else:
            (bw, bc), (tw, tc) = (tuple(min(col) for col in zip(*results[name])) for name in ("baseline", "today"))
            print(f"speed-up   wall {bw / tw:5.2f}x   CPU {bc / tc:5.2f}x   (fastest run of each over {args.rounds} "
                  f"round(s))")
        print("results:", compare(rows["baseline"], rows["today"]))

        rec = str(chosen[0].resolve())  # the children run in tmp: a relative dataset path would not be found there
        env = dict(os.environ, PYTHONPATH=str(REPO), NUMBA_CACHE_DIR=str(tmp / "numba_fresh"))
        for label in ("empty numba cache (first run after install)", "warm numba cache (later runs)"):
            wall, _, out = run_timed([sys.executable, "-c", WARMUP_SCRIPT, rec], env, tmp, ok=(0,))
            per = ", ".join(f"{a} {float(b):.2f}s" for a, b in (line.split() for line in out.split("\n") if line))
            print(f"fresh process, {label}: {wall:.1f} s in all; first reconstruction: {per}")


if __name__ == "__main__":
    main()
