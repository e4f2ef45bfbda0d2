"""SPAD simulation throughput against a naive NumPy reference (HDF5 write included), storage filters, warm-up
and streaming memory.

Run: ``python benchmarks/bench_spad.py [--size 512] [--duration-ms 10] [--quick]``

1. Throughput: a 512×512 textured scene whose brightness varies in time (keyframes every 1 ms, as the renderer's
   minimum rate), scaled so that the mean detection probability per bin spans ~0.1 % … ~90 % (over the run's
   pixels and bins, dark counts included: the fraction of ones in the recording). For each level, SimSPAD
   (:func:`simspad.sensors.spad.simulate_spad` into a real recording through
   :class:`~simspad.io.recording.RecordingWriter`, afterpulsing and crosstalk on) and a naive reference (one
   uniform number per pixel per bin compared with the exact per-bin probability, packed in NumPy and written to
   an uncompressed HDF5 dataset with h5py, then flushed to the disk as SimSPAD's recordings are) produce the same
   bins in the same process, in 3 rounds of one naive run beside SimSPAD's runs (the ratio is taken within each
   round: the machine's speed drifts over seconds). Printed: Gbit/s of each (process CPU time, file written and
   closed; SimSPAD's the median of 5 runs) in the median round, the ratio of each round, and the real-time
   factor against the SwissSPAD2 (512×512 at 97.7 kHz = 25.6 Gbit/s). SimSPAD runs twice per level: storing
   its bits uncompressed (``compression = "none"``, as the reference does) and with the default Zstandard
   filter (the same bits; its CPU time and file size are printed beside).
2. Storage filters: the packed bits of one streamed chunk at P(1) = 0.001 and 0.05 written with each candidate
   HDF5 filter (SimSPAD's choices none, gzip and zstd; lzf, gzip with byte shuffle, LZ4, and Blosc2 with
   bit-shuffle from ``hdf5plugin``): size, write and read speed.
3. Warm-up: a fresh Python process imports the simulator and runs a tiny chunk (numba's on-disk cache).
4. Streaming memory: :func:`simspad.sensors.spad.simulate_spad` writes real HDF5 recordings of 1× and 4× the
   duration in fresh subprocesses; their peak resident memory (``ru_maxrss``) and the traced NumPy peak
   (``tracemalloc``) must not grow with the duration.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import h5py
import hdf5plugin
import numpy as np

from simspad.io.atomic import fsync_file
from simspad.io.compression import SPAD_COMPRESSIONS
from simspad.io.recording import RecordingWriter
from simspad.physics.spad_statistics import detection_probability
from simspad.radiance.timeline import Timeline
from simspad.sensors.presets import SpadParams
from simspad.sensors.spad import SpadChunker, chunk_bins, h5_chunk_bins, pack_bits, simulate_spad
from simspad.sensors.spad.model import dcr_map

SWISSSPAD2_GBIT_S = 512 * 512 / 10.24e-6 / 1e9  # 25.6
#: SimSPAD runs per level (median CPU time kept; same seed, so the same bytes each time): its ~0.1–0.5 s runs
#: swing by ±30 % on a shared machine, and 5 runs give a steadier median than 3.
FAST_REPEATS = 5
#: Rounds per level, each a naive run and SimSPAD's runs beside it (see :func:`throughput`).
ROUNDS = 3


def texture(size: int, rng: np.random.Generator) -> np.ndarray:
    """A smooth scene with ~2 decades of contrast (log-normal blobs), mean 1."""
    from scipy.ndimage import gaussian_filter

    log_y = gaussian_filter(rng.standard_normal((size, size)), size / 32) * 1.0
    y = np.exp(log_y / log_y.std())
    return (y / y.mean()).astype(np.float32)


def scene(size: int, duration_s: float, mean_probability: float, params: SpadParams, seed: int = 0,
          dcr_cps: np.ndarray | None = None) -> Timeline:
    """Keyframes every 1 ms; brightness modulated ±30 % in time; scaled to the requested mean probability.

    Without ``dcr_cps``: mean P(1) over pixels of the unmodulated scene, signal only. With the recording's dark
    count map ``dcr_cps`` (counts s⁻¹, [size, size]): the fraction of ones the recording will hold, i.e. P(1)
    averaged over pixels and over the run's bins (modulation included, as the timeline interpolates it between
    keyframes) with dark counts included; a level at or below the dark counts' own floor is refused.
    """
    rng = np.random.default_rng(seed)
    base = texture(size, rng)
    times = np.arange(0.0, duration_s + 1e-3, 1e-3)
    modulation = 1.0 + 0.3 * np.sin(2 * np.pi * 37.0 * times)
    q, gate = params.detection_area_m2, params.gate_s
    relative = base.astype(np.float64).ravel()[None, :]  # [instants, pixels], flux per unit of the scale below
    dark = 0.0
    if dcr_cps is not None:
        # 8 instants spread over the run stand for its bins: P(1) is smooth in the modulation, so the mean over 8
        # is within ~0.1 % of the mean over every bin
        instants = (np.arange(8) + 0.5) / 8 * duration_s
        relative = relative * np.interp(instants, times, modulation)[:, None]
        dark = np.asarray(dcr_cps, dtype=np.float64).ravel()
        floor = dark_probability(dcr_cps, params)
        if mean_probability <= floor:
            raise ValueError(f"mean P(1) = {mean_probability:g} is at or below the dark counts' own {floor:.2g}")
    # find the flux scale (photons s⁻¹ m⁻² per unit of the texture) giving that mean P(1) (monotone: bisection)
    lo, hi = 1e-9 / (q * gate), 1e6 / (q * gate)
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        if np.mean(detection_probability(relative * mid, q, gate, dark)) < mean_probability:
            lo = mid
        else:
            hi = mid
    frames = (base[None] * modulation[:, None, None] * lo).astype(np.float32)
    return Timeline.from_arrays(times, frames)


def dark_probability(dcr_cps: np.ndarray, params: SpadParams) -> float:
    """Mean P(1) per bin over the pixels from the dark counts alone."""
    return float(np.mean(detection_probability(0.0, params.detection_area_m2, params.gate_s, dcr_cps)))


def naive_runs(tl: Timeline, t0: float, bin_s: float, gate: float, k0: int, m: int):
    """Yield (j0, n, ya, yb, w0, dw): runs of bins whose gates lie in one linear piece of ``tl`` (images ya, yb at
    its ends, weight w0 at the first gate's middle, dw per bin), or one straddling bin (ya = yb = its exact mean)."""
    t_first = t0 + k0 * bin_s
    t_last_end = t0 + (k0 + m - 1) * bin_s + gate
    pieces = list(tl.segments(t_first, t_last_end))
    if not pieces:  # a single keyframe: constant in time
        y = tl.sample(t_first)
        yield 0, m, y, y, 0.0, 0.0
        return
    tol = 1e-6 * gate
    starts = t0 + (k0 + np.arange(m)) * bin_s
    ta = np.array([p[0] for p in pieces])
    tb = np.array([p[1] for p in pieces])
    idx = np.clip(np.searchsorted(ta, starts + tol, side="right") - 1, 0, len(pieces) - 1)
    inside = starts + gate <= tb[idx] + tol
    j = 0
    while j < m:
        i = idx[j]
        if not inside[j]:
            y = _gate_mean(pieces, float(starts[j]), gate)
            yield j, 1, y, y, 0.0, 0.0
            j += 1
            continue
        e = j + 1
        while e < m and inside[e] and idx[e] == i:
            e += 1
        a, b, ya, yb = pieces[i]
        span = b - a
        yield j, e - j, ya, yb, float((starts[j] + 0.5 * gate - a) / span), float(bin_s / span)
        j = e


def _gate_mean(pieces, t: float, gate: float) -> np.ndarray:
    """Exact mean over the gate ``[t, t + gate]``: each overlapped piece weighted by its share, at its middle."""
    total = None
    for a, b, ya, yb in pieces:
        lo, hi = max(t, a), min(t + gate, b)
        if hi <= lo:
            continue
        w = (0.5 * (lo + hi) - a) / (b - a)
        term = ya * np.float32((hi - lo) * (1.0 - w) / gate) + yb * np.float32((hi - lo) * w / gate)
        total = term if total is None else total + term
    return total


def naive_chunk(chunker: SpadChunker, k0: int, m: int, rng: np.random.Generator, batch: int = 16) -> np.ndarray:
    """One uniform per pixel per bin, compared with the exact per-bin probability (same linear pieces)."""
    H, W = chunker.tl.height, chunker.tl.width
    out = np.empty((m, H, (W + 7) // 8), np.uint8)
    dcr_g = chunker.dcr.astype(np.float64) * chunker.gate_s
    for j0, n, ya, yb, w0, dw in naive_runs(chunker.tl, chunker.t0, chunker.bin_s, chunker.gate_s, k0, m):
        ya64, d64 = ya.astype(np.float64), yb.astype(np.float64) - ya
        for b in range(0, n, batch):
            j = np.arange(b, min(b + batch, n))
            lam = chunker.q_gate * (ya64[None] + d64[None] * (w0 + dw * j)[:, None, None]) + dcr_g[None]
            p = -np.expm1(-lam)
            out[j0 + b : j0 + b + j.size] = pack_bits(rng.random(p.shape) < p)
    return out


def count_ones(packed: np.ndarray) -> int:
    return int(np.bitwise_count(packed).sum(dtype=np.int64))


def fraction_of_ones(path: str, name: str, width: int) -> float:
    """Fraction of ones over a whole bit-packed dataset [bins, H, ceil(W/8)] (its padding bits are zeros)."""
    with h5py.File(path, "r") as f:
        ds = f[name]
        ones = sum(count_ones(ds[k0:k0 + 256]) for k0 in range(0, ds.shape[0], 256))
        return ones / (ds.shape[0] * ds.shape[1] * width)


def _remove(path: str) -> None:
    """Delete a previous round's output before a timed write. Replacing or truncating a 32 MB file frees its
    pages inside the timed region (≈ 2 ms of process CPU time per file here, 4 % of a SimSPAD run at P(1) = 0.001),
    which a run writing new files never pays."""
    with contextlib.suppress(FileNotFoundError):
        os.remove(path)


def _simspad_to_h5(tl: Timeline, duration_s: float, params: SpadParams, path: str) -> float:
    """CPU seconds of :func:`simulate_spad` writing a complete recording (closed and renamed)."""
    size = tl.width
    _remove(path)
    c = time.process_time()
    with RecordingWriter(path, {"width": size, "height": tl.height, "duration_s": duration_s, "lux": 1.0}) as w:
        simulate_spad(w, tl, 0.0, duration_s, params, np.random.default_rng(1))
    return time.process_time() - c


def _median_simspad_s(tl: Timeline, duration_s: float, params: SpadParams, path: str) -> float:
    """Median CPU seconds of :data:`FAST_REPEATS` runs of :func:`_simspad_to_h5` (a new file each; the first is
    kept as ``path``). A ~0.1–1 s run is short enough that a burst of other work on a shared machine can double
    one, while the naive reference's ~10 s averages it out."""
    stem = path.removesuffix(".h5")
    seconds = [_simspad_to_h5(tl, duration_s, params, f"{stem}_{i}.h5") for i in range(FAST_REPEATS)]
    os.replace(f"{stem}_0.h5", path)
    return float(np.median(seconds))


def _naive_to_h5(tl: Timeline, n: int, params: SpadParams, dcr: np.ndarray, path: str) -> float:
    """CPU seconds of the naive reference writing its packed bits to an uncompressed HDF5 dataset."""
    size = tl.width
    m = chunk_bins(size, size)
    ref = SpadChunker(tl, 0.0, n, params, dcr, np.random.default_rng(2))
    rng = np.random.default_rng(3)
    _remove(path)
    c = time.process_time()
    with h5py.File(path, "w") as f:
        ds = f.create_dataset("bits", (n, tl.height, (size + 7) // 8), np.uint8,
                              chunks=(h5_chunk_bins(tl.height, size), tl.height, (size + 7) // 8))
        for k0 in range(0, n, m):
            ref_buf = naive_chunk(ref, k0, min(m, n - k0), rng)
            ds[k0 : k0 + ref_buf.shape[0]] = ref_buf
    # flushed to the disk like SimSPAD's recordings: otherwise the kernel writes these 32 MB back while the next
    # level's SimSPAD runs are timed, and their CPU time swung by up to 1.3× with it
    fsync_file(path)
    return time.process_time() - c


def throughput(size: int, duration_ms: float, levels: list[float]) -> list[dict]:
    params = SpadParams(gate_s=10.24e-6, compression="none")
    zstd = dataclasses.replace(params, compression="zstd")
    duration_s = duration_ms * 1e-3
    # simulate_spad draws its dark count map first from its generator (seed 1 in _simspad_to_h5): the same map
    # here lets each level be the fraction of ones the recording holds, dark counts included
    dcr = dcr_map((size, size), params, np.random.default_rng(1))
    p_dark = dark_probability(dcr, params)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        _simspad_to_h5(scene(32, 0.002, 0.1, params), 0.002, params, f"{tmp}/warm.h5")  # numba cache load
        for level in levels:
            tl = scene(size, duration_s, level, params, dcr_cps=dcr)
            path = f"{tmp}/simspad_{level}.h5"
            # Rounds of (SimSPAD ×5, Zstandard ×5, naive ×1), each ratio taken within its round: this machine's
            # speed drifts over seconds (SimSPAD's median alone moved 165 -> 240 ms at P(1) = 0.05 between runs of
            # the bench), and a ratio of runs seconds apart kept that drift. The median round is printed.
            rounds = []
            for r in range(ROUNDS):
                c_fast = _median_simspad_s(tl, duration_s, params, path)
                c_zstd = _median_simspad_s(tl, duration_s, zstd, f"{tmp}/zstd_{level}.h5")
                if r == 0:  # the same seed every round: the same bins and dark count map
                    with h5py.File(path, "r") as f:
                        n = f["spad/bits"].shape[0]
                        if not np.array_equal(f["spad/dcr_cps"][()], dcr):
                            raise RuntimeError("simulate_spad no longer draws its dark count map first: update "
                                               "throughput()")
                c_naive = _naive_to_h5(tl, n, params, dcr, f"{tmp}/naive_{level}.h5")
                rounds.append((c_naive / c_fast, c_fast, c_zstd, c_naive))
            speedups = sorted(r[0] for r in rounds)
            _, c_fast, c_zstd, c_naive = sorted(rounds)[len(rounds) // 2]
            mb_zstd = os.path.getsize(f"{tmp}/zstd_{level}.h5") / 2**20
            bits = n * size * size
            # CPU time of this process: on a shared machine wall time also counts other people's jobs
            gbit_fast, gbit_naive = bits / c_fast / 1e9, bits / c_naive / 1e9
            rows.append(dict(level=level, p_dark=p_dark, p_fast=fraction_of_ones(path, "spad/bits", size),
                             p_naive=fraction_of_ones(f"{tmp}/naive_{level}.h5", "bits", size), gbit_fast=gbit_fast,
                             gbit_naive=gbit_naive, speedup=c_naive / c_fast, rtf=gbit_fast / SWISSSPAD2_GBIT_S,
                             mb_fast=os.path.getsize(path) / 2**20, speedup_zstd=c_naive / c_zstd,
                             mb_zstd=mb_zstd, speedup_rounds=speedups))
    return rows


# ------------------------------------------------------------------------------------------------ storage filters
def filter_candidates() -> list[tuple[str, dict]]:
    """HDF5 filters to compare: SimSPAD's choices (``compression = ...``) and other candidates."""
    rows = [(f"{name} (SimSPAD)", dict(kwargs)) for name, kwargs in SPAD_COMPRESSIONS.items()]
    rows += [("lzf", {"compression": "lzf"}),
             ("gzip 4 + shuffle", {"compression": "gzip", "compression_opts": 4, "shuffle": True}),
             ("lz4", dict(hdf5plugin.LZ4()))]
    for cname in ("lz4", "zstd"):
        rows.append((f"blosc2 {cname} + bitshuffle",
                     dict(hdf5plugin.Blosc2(cname=cname, clevel=5, filters=hdf5plugin.Blosc2.BITSHUFFLE))))
    return rows


def filters(size: int, levels: list[float]) -> list[dict]:
    """Write one streamed chunk of packed bits per level with each filter; size, write and read speed."""
    params = SpadParams(gate_s=10.24e-6)
    m = chunk_bins(size, size)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        # one untimed write of a chunk's size first: the first 16 MB written in a process pays for fresh page-cache
        # pages, and the first candidate timed ('none') ran at 0.15-0.55x the speed it had at the next level
        with h5py.File(f"{tmp}/warm.h5", "w") as f:
            f.create_dataset("bits", data=np.ones((m, size, (size + 7) // 8), np.uint8))
        _remove(f"{tmp}/warm.h5")
        for level in levels:
            tl = scene(size, m * params.bin_s + 2e-3, level, params)
            packed = SpadChunker(tl, 0.0, m, params, np.full((size, size), 7.5, np.float32),
                                 np.random.default_rng(4)).chunk(0, m)
            for name, kwargs in filter_candidates():
                path = f"{tmp}/f.h5"
                _remove(path)
                c = time.process_time()
                with h5py.File(path, "w") as f:
                    f.create_dataset("bits", data=packed, chunks=(h5_chunk_bins(size, size), *packed.shape[1:]),
                                     **kwargs)
                c_write = time.process_time() - c
                c = time.process_time()
                with h5py.File(path, "r") as f:
                    back = f["bits"][()]
                c_read = time.process_time() - c
                assert np.array_equal(back, packed)
                mb = packed.nbytes / 2**20
                out.append(dict(level=level, filter=name, ratio=packed.nbytes / os.path.getsize(path),
                                file_mb=os.path.getsize(path) / 2**20, write_mb_s=mb / c_write,
                                read_mb_s=mb / c_read))
    return out


def warm_up_seconds() -> float:
    """Wall seconds of a fresh process importing the simulator and running one tiny chunk (numba cache hit)."""
    code = ("import time; t = time.perf_counter(); import numpy as np; "
            "from simspad.radiance.timeline import Timeline; from simspad.sensors.presets import SpadParams; "
            "from simspad.sensors.spad import SpadChunker; "
            "tl = Timeline.from_arrays([0.0, 1e-3], np.full((2, 16, 16), 1e15, np.float32)); "
            "SpadChunker(tl, 0.0, 50, SpadParams(gate_s=10.24e-6), np.zeros((16, 16), np.float32), "
            "np.random.default_rng(0)).chunk(0, 50); print(time.perf_counter() - t)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(res.stdout.strip().splitlines()[-1])


def lux_for_probability(p: float, params: SpadParams) -> float:
    """Mid-grey scene illuminance giving mean P(1) = p per 10.24 µs bin with the presets at f/2 (docs/sensors.md)."""
    from simspad.physics.radiometry import flux_scale

    rate = -math.log1p(-p) / params.bin_s
    return rate / (flux_scale(1.0, 1.0) * params.detection_area_m2)


# ------------------------------------------------------------------------------------------------ streaming memory
def _stream_child(size: int, duration_s: float, level: float, out: str) -> None:
    from simspad.io.recording import RecordingWriter
    from simspad.sensors.spad import simulate_spad

    params = SpadParams(gate_s=10.24e-6)
    tl = scene(size, duration_s, level, params)
    tracemalloc.start()
    t = time.perf_counter()
    with RecordingWriter(out, {"width": size, "height": size, "duration_s": duration_s, "lux": 1.0}) as w:
        attrs = simulate_spad(w, tl, 0.0, duration_s, params, np.random.default_rng(0))
    elapsed = time.perf_counter() - t
    _, peak = tracemalloc.get_traced_memory()
    print(json.dumps({"n_bins": attrs["n_bins"], "seconds": elapsed, "traced_peak_mb": peak / 2**20,
                      "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "file_mb": os.path.getsize(out) / 2**20}))


def streaming(size: int, durations: list[float], level: float) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for d in durations:
            out = str(Path(tmp) / f"s{d}.h5")
            res = subprocess.run([sys.executable, __file__, "--_child", str(size), str(d), str(level), out],
                                 capture_output=True, text=True, check=True)
            row = json.loads(res.stdout.strip().splitlines()[-1])
            row["duration_s"] = d
            rows.append(row)
            os.unlink(out)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--duration-ms", type=float, default=10.0)
    ap.add_argument("--quick", action="store_true", help="fewer levels, shorter streams")
    ap.add_argument("--_child", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args._child:
        size, d, level, out = args._child
        _stream_child(int(size), float(d), float(level), out)
        return
    levels = [0.001, 0.01, 0.05, 0.9] if args.quick else [0.001, 0.003, 0.01, 0.03, 0.05, 0.1, 0.3, 0.6, 0.9]
    params = SpadParams(gate_s=10.24e-6)
    print(f"SPAD throughput, {args.size}x{args.size}, {args.duration_ms:g} ms of 10.24 µs bins (gate = bin), "
          f"keyframes every 1 ms, ±30 % temporal modulation; afterpulsing/crosstalk on in SimSPAD, off in naive; "
          f"both write a complete HDF5 file")
    print("target P(1): mean detection probability per bin over the run (pixels and bins, modulation and dark counts "
          "included: the fraction of ones the recording should hold); P SimSPAD / P naive: the fraction of ones "
          "each file holds (SimSPAD also adds afterpulses and crosstalk)")
    print(f"{'target P(1)':>11} {'~lux':>8} {'P SimSPAD':>9} {'P naive':>8} {'SimSPAD Gbit/s':>15} "
          f"{'naive Gbit/s':>13} {'speed-up':>9} {'× real time':>12} {'file MB':>8} {'zstd speed-up':>14} "
          f"{'zstd MB':>8}  speed-up of each round")
    rows = throughput(args.size, args.duration_ms, levels)
    for r in rows:
        print(f"{r['level']:11.3f} {lux_for_probability(r['level'] - r['p_dark'], params):8.3g} {r['p_fast']:9.4f} "
              f"{r['p_naive']:8.4f} {r['gbit_fast']:15.2f} {r['gbit_naive']:13.3f} {r['speedup']:8.1f}× "
              f"{r['rtf']:12.3f} {r['mb_fast']:8.1f} {r['speedup_zstd']:13.1f}× {r['mb_zstd']:8.1f}  "
              + ", ".join(f"{x:.1f}×" for x in r["speedup_rounds"]))
    print(f"(Gbit/s from process CPU time, single thread, HDF5 write and close included on both sides; real-time "
          f"factor against SwissSPAD2 {SWISSSPAD2_GBIT_S:.1f} Gbit/s; ~lux = mid-grey scene illuminance for that "
          f"mean P(1) less the dark counts' own {rows[0]['p_dark']:.2g}, at f/2; speed-up and file MB: SimSPAD "
          f"storing uncompressed like the reference; zstd: with its default filter, same bits; each level runs "
          f"{ROUNDS} rounds of SimSPAD ×{FAST_REPEATS} (median) beside one naive run, and shows its median round)")
    print(f"\nStorage filters: one streamed chunk of packed bits ({chunk_bins(args.size, args.size)} bins of "
          f"{args.size}x{args.size}), HDF5 chunks of {h5_chunk_bins(args.size, args.size)} bins")
    print(f"{'P(1)':>6} {'filter':>26} {'file MB':>8} {'ratio':>7} {'write MB/s':>11} {'read MB/s':>10}")
    rows = filters(args.size, [0.001, 0.05])
    for r in rows:
        print(f"{r['level']:6.3f} {r['filter']:>26} {r['file_mb']:8.2f} {r['ratio']:6.1f}× {r['write_mb_s']:11.0f} "
              f"{r['read_mb_s']:10.0f}")
    print("(MB/s of uncompressed packed bits per CPU second)")
    for level in sorted({r["level"] for r in rows}):
        at = [r for r in rows if r["level"] == level]
        fast, small = max(at, key=lambda r: r["write_mb_s"]), max(at, key=lambda r: r["ratio"])
        print(f"P(1) = {level:g}: fastest write '{fast['filter']}' ({fast['write_mb_s']:.0f} MB/s, "
              f"{fast['ratio']:.1f}×), smallest '{small['filter']}' ({small['ratio']:.1f}×, "
              f"{small['write_mb_s']:.0f} MB/s)")
    print(f"\nWarm-up of a fresh process (import + first chunk, numba cache): {warm_up_seconds():.2f} s wall")
    size = 256
    durations = [0.05, 0.2] if args.quick else [0.1, 0.4]
    print(f"\nStreaming simulate_spad → HDF5, {size}x{size}, mean P(1) = 0.05, durations {durations} s")
    print(f"{'duration s':>10} {'bins':>7} {'file MB':>8} {'seconds':>8} {'Gbit/s':>7} {'traced peak MB':>15} "
          f"{'max RSS MB':>11}")
    for r in streaming(size, durations, 0.05):
        gbit = r["n_bins"] * size * size / r["seconds"] / 1e9
        print(f"{r['duration_s']:10.2f} {r['n_bins']:7d} {r['file_mb']:8.1f} {r['seconds']:8.2f} {gbit:7.2f} "
              f"{r['traced_peak_mb']:15.1f} {r['maxrss_mb']:11.1f}")


if __name__ == "__main__":
    main()
