"""Convergence benchmark: how close each way of rendering a clip comes to a brute-force reference, for its CPU.

For each scene (its default trajectory, a short clip at a small size) it renders

* a **reference**: every keyframe path-traced at ``--ref-spp`` (seed 0), and the same again with seed 1: their
  difference is the reference's own noise (reported as the median per-pixel relative difference of the two, ÷ √2
  for one of them), and their mean is what the others are measured against;
* **brute force** at each of ``--spp`` (the path tracer, ``convergence = "off"``);
* the **irradiance cache** (``convergence = "cache"``, :mod:`simspad.render.converged`) at ``--cache-spp`` camera
  rays per pixel and ``--cache-samples`` estimates per probe point, with each keyframe schedule of
  ``--cache-interpolation`` (``linear``: every keyframe rendered; ``warp``: converged anchors, the rest
  synthesized where the warps agree, ``--warp-stride`` apart);

and reports for each its render CPU-seconds (the process's CPU time for the whole render, cache included), the
median over keyframes and pixels of the relative luminance error against the reference, and the event counts of
a noise-free event sensor (shot noise, leak and hot pixels off, the same pixel maps) at 100 and 10⁴ lx, as a
ratio to the reference's, and the error with the reference's own noise taken out (:func:`noise_corrected_error`).
A work–precision diagram (error and event ratio against CPU-seconds) is saved as a PNG. ``--work DIR`` keeps the
renders there and re-uses references found in it (the expensive part) with the CPU time they took.

Run: ``nice -n 10 python benchmarks/bench_convergence.py --scenes office --resolution 48x36 --duration 0.01``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from simspad.radiance.timeline import Timeline
from simspad.render.renderer import RenderSettings, render_sequence
# the noise-free event sensor (as `simspad simulate --sensors events --set events.shot_noise_rate_hz_at_1lux=0 --set
# events.leak_rate_hz=0 --set events.hot_pixel_fraction=0`) and its event count, shared with the warp benchmark
from bench_warp import event_counts

LUX_LEVELS = (100.0, 1e4)


def keyframe_luminance(tl: Timeline) -> np.ndarray:
    """[K, H, W] luminance of every keyframe."""
    return np.stack([tl.keyframe(i).astype(np.float64) for i in range(tl.n_keyframes)])


def median_rel_error(lum: np.ndarray, ref: np.ndarray) -> float:
    """Median over keyframes and pixels of |lum − ref| / ref (pixels where the reference is black left out)."""
    ok = ref > 0
    return float(np.median(np.abs(lum[ok] - ref[ok]) / ref[ok]))


def render_timed(scene, settings: RenderSettings, out: Path, keep: bool = False) -> tuple[Timeline, float]:
    """Render ``out``; its timeline and the process CPU time the render took, s. With ``keep`` a complete render
    already in ``out`` (from an earlier run with ``--work``) is re-used, with the CPU time it took then."""
    cpu_file = out / "bench-cpu-s.txt"
    if keep and (out / "timeline.json").is_file() and cpu_file.is_file():
        return Timeline.open(out), float(cpu_file.read_text())
    shutil.rmtree(out, ignore_errors=True)
    tic = time.process_time()
    render_sequence(scene, None, settings, out_dir=out, progress=False)
    cpu_s = time.process_time() - tic
    cpu_file.write_text(f"{cpu_s!r}\n")
    return Timeline.open(out), cpu_s


def noise_corrected_error(lum: np.ndarray, ref_lum: np.ndarray, lum0: np.ndarray, lum1: np.ndarray) -> float:
    """The median relative error with the reference's own noise taken out: sqrt(median(d²) − median(n²)), d the
    relative difference to the two-seed mean, n = (seed 0 − seed 1) / 2 its noise (the mean's σ), both relative
    to the mean; an estimate (medians of squares do not subtract exactly), 0 where the noise exceeds the error."""
    ok = ref_lum > 0
    d2 = ((lum[ok] - ref_lum[ok]) / ref_lum[ok]) ** 2
    n2 = ((lum0[ok] - lum1[ok]) / (2 * ref_lum[ok])) ** 2
    return float(np.sqrt(max(np.median(d2) - np.median(n2), 0.0)))


def measure(tl: Timeline, cpu_s: float, ref_lum: np.ndarray, ref_events: dict, ref_pair=None) -> dict:
    lum = keyframe_luminance(tl)
    row = {"cpu_s": cpu_s, "n_keyframes": int(lum.shape[0]), "median_error": median_rel_error(lum, ref_lum),
           "n_rendered": int(tl.meta["schedule"]["n_rendered_keyframes"])}
    if ref_pair is not None:
        row["median_error_noise_corrected"] = noise_corrected_error(lum, ref_lum, *ref_pair)
    for lux in LUX_LEVELS:
        on, off = event_counts(tl, lux)
        ron, roff = ref_events[lux]
        row[f"events_{lux:g}"] = [on, off]
        row[f"event_ratio_{lux:g}"] = [on / max(ron, 1), off / max(roff, 1)]
    return row


def bench_scene(name: str, base: RenderSettings, ref_spp: int, spps: list[int], cache_runs: list[dict],
                work: Path, keep: bool = False) -> dict:
    ref_tl, ref_cpu = render_timed(name, replace(base, spp=ref_spp, seed=0, interpolation="linear"),
                                   work / f"{name}-ref{ref_spp}-0", keep)
    ref2_tl, ref2_cpu = render_timed(name, replace(base, spp=ref_spp, seed=1, interpolation="linear"),
                                     work / f"{name}-ref{ref_spp}-1", keep)
    # A process's first render pays for loading Mitsuba and compiling kernels: spend that on a render not counted
    # (the references pay it otherwise, and with --work they may come from an earlier run).
    render_timed(name, replace(base, spp=1, duration_s=min(base.duration_s, 0.002), interpolation="linear"),
                 work / f"{name}-warm-up")
    lum0, lum1 = keyframe_luminance(ref_tl), keyframe_luminance(ref2_tl)
    ref_lum = 0.5 * (lum0 + lum1)
    # The mean of the two seeds is the reference: each one's noise is their difference ÷ √2, the mean's ÷ 2.
    ref_noise_one = median_rel_error(lum0, lum1) / np.sqrt(2.0)
    # Events of the reference: the seed-0 render (a timeline of the mean would need its own render directory).
    ref_events = {lux: event_counts(ref_tl, lux) for lux in LUX_LEVELS}
    ref2_events = {lux: event_counts(ref2_tl, lux) for lux in LUX_LEVELS}
    out = {"scene": name, "n_keyframes": int(lum0.shape[0]), "ref_spp": ref_spp, "ref_cpu_s": ref_cpu,
           "ref_noise_one_seed": ref_noise_one, "ref_events": {f"{k:g}": v for k, v in ref_events.items()},
           "ref_seed1_events": {f"{k:g}": v for k, v in ref2_events.items()}, "methods": {}}
    print(f"{name}: {out['n_keyframes']} keyframes; reference {ref_spp} spp: {ref_cpu:.1f} CPU-s, own noise "
          f"{100 * ref_noise_one:.2f} % (one seed), events 100 lx {ref_events[100.0]}, 1e4 lx {ref_events[1e4]} "
          f"(seed 1: {ref2_events[100.0]}, {ref2_events[1e4]})", flush=True)
    for spp in spps:
        tl, cpu = render_timed(name, replace(base, spp=spp, interpolation="linear"), work / f"{name}-bf{spp}")
        out["methods"][f"brute force {spp} spp"] = row = measure(tl, cpu, ref_lum, ref_events, (lum0, lum1))
        _print(name, f"brute force {spp} spp", row)
    for run in cache_runs:
        label = f"cache {run['spp']} spp, {run['cache_samples']} q, {run['interpolation']}"
        tl, cpu = render_timed(name, replace(base, convergence="cache", **run), work / f"{name}-cache{run['spp']}-{run['interpolation']}")
        out["methods"][label] = row = measure(tl, cpu, ref_lum, ref_events, (lum0, lum1))
        _print(name, label, row)
    return out


def _print(scene: str, label: str, row: dict) -> None:
    print(f"  {scene:<13} {label:<32} CPU {row['cpu_s']:8.1f} s  rendered {row['n_rendered']}/{row['n_keyframes']}  "
          f"median error {100 * row['median_error']:6.2f} % (noise-corrected "
          f"{100 * row['median_error_noise_corrected']:.2f} %)  "
          f"events/ref 100 lx {row['event_ratio_100'][0]:.2f}/{row['event_ratio_100'][1]:.2f}  "
          f"1e4 lx {row['event_ratio_10000'][0]:.2f}/{row['event_ratio_10000'][1]:.2f}", flush=True)


def plot(results: list[dict], path: Path) -> None:
    import matplotlib  # deferred: only for the figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: as above

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for r in results:
        bf = [(m["cpu_s"], m["median_error"], np.mean(m["event_ratio_100"] + m["event_ratio_10000"]))
              for k, m in r["methods"].items() if k.startswith("brute")]
        ca = {mode: [(m["cpu_s"], m["median_error"], np.mean(m["event_ratio_100"] + m["event_ratio_10000"]))
                     for k, m in r["methods"].items() if k.startswith("cache") and k.endswith(mode)]
              for mode in ("linear", "warp")}
        # Event ratios only where the reference has events enough to divide by (>= 20 over both lux levels).
        has_events = sum(sum(v) for v in r["ref_events"].values()) >= 20
        line, = axes[0].loglog(*zip(*[(c, e) for c, e, _ in bf]), "o-", label=f"{r['scene']} brute force")
        if has_events:
            axes[1].semilogx(*zip(*[(c, v) for c, _, v in bf]), "o-", color=line.get_color())
        for (mode, points), marker in zip(ca.items(), ("*", "D")):
            if not points:
                continue
            axes[0].loglog(*zip(*[(c, e) for c, e, _ in points]), marker, ms=12 if marker == "*" else 8,
                           color=line.get_color(), label=f"{r['scene']} cache, {mode}")
            if has_events:
                axes[1].semilogx(*zip(*[(c, v) for c, _, v in points]), marker, ms=12 if marker == "*" else 8,
                                 color=line.get_color())
    for ax in axes:
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axes[0].yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axes[0].axhline(0.03, color="k", ls=":", lw=1)
    axes[0].set_xlabel("render CPU-seconds")
    axes[0].set_ylabel("median per-pixel relative error vs reference")
    axes[1].axhspan(0.9, 1.1, color="0.9")
    axes[1].set_xlabel("render CPU-seconds")
    axes[1].set_ylabel("noise-free events ÷ reference's\n(mean of ON, OFF at 100 and 10⁴ lx)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="office")
    parser.add_argument("--resolution", default="48x36")
    parser.add_argument("--duration", type=float, default=0.01)
    parser.add_argument("--ref-spp", type=int, default=4096)
    parser.add_argument("--spp", default="16,64,256,1024", help="brute-force samples per pixel, comma-separated")
    parser.add_argument("--cache-spp", default="16", help="camera rays per pixel of the cache runs")
    parser.add_argument("--cache-samples", type=int, default=64)
    parser.add_argument("--cache-interpolation", default="linear",
                        help="keyframe schedules of the cache runs, comma-separated: linear, warp")
    parser.add_argument("--warp-stride", type=int, default=16, help="rendered keyframes at most this far apart "
                        "in the warp runs (a warp needs two strides of keyframes)")
    parser.add_argument("--work", type=Path, default=None, help="keep the renders here and re-use the "
                        "references found there (with the CPU time they took then)")
    parser.add_argument("--out", type=Path, default=Path("bench_convergence.png"))
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--plot-only", type=Path, nargs="*", default=None,
                        help="draw the figure from these --json outputs instead of measuring")
    args = parser.parse_args(argv)
    if args.plot_only:
        plot([r for path in args.plot_only for r in json.loads(path.read_text())], args.out)
        print(f"figure: {args.out}")
        return 0
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    base = RenderSettings(duration_s=args.duration, resolution=(w, h), warp_stride=args.warp_stride)
    spps = [int(s) for s in args.spp.split(",") if s]
    cache_runs = [{"spp": int(s), "cache_samples": args.cache_samples, "interpolation": mode}
                  for mode in args.cache_interpolation.split(",") if mode for s in args.cache_spp.split(",") if s]
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_convergence-"))
    work.mkdir(parents=True, exist_ok=True)
    results = []
    try:
        for name in args.scenes.split(","):
            results.append(bench_scene(name, base, args.ref_spp, spps, cache_runs, work, keep=args.work is not None))
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    plot(results, args.out)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    print(f"figure: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
