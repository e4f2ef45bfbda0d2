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

``--trajectory PATH --speed K`` renders every scene on that trajectory played ``K`` times faster
(:func:`simspad.dataset.speed.retimed`, as a spec's ``speed = [K]``). ``--few-ref-spp N`` adds a second reference
where one of every keyframe is too dear: ``--few-ref-keyframes`` keyframes spread over the clip, path-traced at
``N`` spp with seeds 0 and 1, and each method's error on those keyframes against their mean
(``median_error_few_ref``). ``--mtf`` (Siemens-star scenes) measures each keyframe's Siemens-star MTF with the
evaluation's own code: the star found in the reference's first keyframe (:func:`metrics.siemens_star_geometry`),
the MTF against a perfect print (:class:`simspad.evaluate.real_data.StarMtf`, mean over keyframes) and against the
reference's keyframes (:func:`metrics.mtf_siemens`), each as the results columns ``mtf_at_0p25_cyc_px``,
``mtf_at_0p40_cyc_px`` and ``mtf50_cyc_px`` (:func:`simspad.evaluate.protocol.star_figures`).

Run: ``nice -n 10 python benchmarks/bench_convergence.py --scenes office --resolution 48x36 --duration 0.01``;
edges: ``--scenes siemens-star --resolution 128x96 --duration 0.004 --mtf``; a fast pan: ``--scenes office
--trajectory trajectories/office_handheld_pan.toml --speed 16 --duration 0.005 --few-ref-spp 4096``.
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

from simspad.dataset.speed import retimed
from simspad.evaluate import metrics
from simspad.evaluate.protocol import star_figures
from simspad.evaluate.real_data import StarMtf
from simspad.io.exr import read_exr
from simspad.io.trajectory_files import load_trajectory
from simspad.physics.radiometry import luminance_from_planes
from simspad.radiance.timeline import Timeline
from simspad.render.renderer import RenderSettings, layout_render, render_keyframes, render_sequence
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


def render_timed(scene, settings: RenderSettings, out: Path, keep: bool = False,
                 trajectory=None) -> tuple[Timeline, float]:
    """Render ``out``; its timeline and the process CPU time the render took, s. With ``keep`` a complete render
    already in ``out`` (from an earlier run with ``--work``) is re-used, with the CPU time it took then."""
    cpu_file = out / "bench-cpu-s.txt"
    if keep and (out / "timeline.json").is_file() and cpu_file.is_file():
        return Timeline.open(out), float(cpu_file.read_text())
    if out.exists():  # only a render folder (this benchmark's, from an earlier run) is replaced
        if any(out.iterdir()) and not (cpu_file.is_file() or (out / "frames").is_dir()):
            raise SystemExit(f"{out}: exists and is not a render of this benchmark; choose another --work")
        shutil.rmtree(out)
    tic = time.process_time()
    render_sequence(scene, trajectory, settings, out_dir=out, progress=False)
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


def render_few(scene, trajectory, settings: RenderSettings, n_keyframes: int, out: Path) -> tuple[list[int], np.ndarray,
                                                                                                float]:
    """Path-trace ``n_keyframes`` keyframes spread over the clip (first and last included) of the render
    ``settings`` describe into ``out`` (files already there are re-used); (their indices, [K, H, W] luminance, the
    CPU-seconds this call took)."""
    layout = layout_render(scene, trajectory, settings)
    idx = sorted({int(round(v)) for v in np.linspace(0, layout.n_keyframes - 1, n_keyframes)})
    tic = time.process_time()
    render_keyframes(scene, trajectory, layout, idx, out_dir=out)
    cpu_s = time.process_time() - tic
    planes = [read_exr(out / layout.names[i], rgb_planes=True) for i in idx]
    lum = np.stack([luminance_from_planes(p["r"], p["g"], p["b"]).astype(np.float64) for p in planes])
    return idx, lum, cpu_s


def star_mtf(lum: np.ndarray, ref_lum: np.ndarray, geometry: tuple) -> dict:
    """Siemens-star MTF of keyframes ``lum`` [K, H, W]: against a perfect print (mean over keyframes, as the
    evaluation of a recording without ground truth) and against the reference's keyframes ``ref_lum`` (as the
    evaluation of a reconstruction against its ground truth), each as the results columns."""
    cy, cx, n, r_max = geometry
    absolute = StarMtf({"center_x_px": cx, "center_y_px": cy, "radius_px": r_max, "n_cycles": n})
    curves = []
    for img, ref in zip(lum, ref_lum):
        absolute.add(img)
        curves.append(metrics.mtf_siemens(img, ref, geometry=geometry))
    freq = curves[0][0]
    stacked = np.stack([m for _, m in curves])
    # circles where the reference shows too little of the star are NaN in every keyframe
    relative = np.array([np.nan if np.isnan(col).all() else np.nanmean(col) for col in stacked.T])
    vs_print = star_figures(absolute.result())
    # The outermost circles can lie on the star's rim (the located radius is half the frame's smaller side), where
    # the modulation is low and MTF50 reads NaN; the curve's crossing of 0.5 with those circles (below half the
    # curve's peak, at the low-frequency end) left out:
    f, m = absolute.result()
    rim = 0
    while rim < m.size and not m[rim] >= 0.5 * np.nanmax(m):
        rim += 1
    vs_print["mtf50_on_star_cyc_px"] = metrics.mtf50(f[rim:], m[rim:])
    return {"vs_print": vs_print, "vs_reference": star_figures((freq, relative))}


def measure(tl: Timeline, cpu_s: float, ref_lum: np.ndarray, ref_events: dict, ref_pair=None, few=None,
            star=None) -> dict:
    lum = keyframe_luminance(tl)
    row = {"cpu_s": cpu_s, "n_keyframes": int(lum.shape[0]), "median_error": median_rel_error(lum, ref_lum),
           "n_rendered": int(tl.meta["schedule"]["n_rendered_keyframes"])}
    if ref_pair is not None:
        row["median_error_noise_corrected"] = noise_corrected_error(lum, ref_lum, *ref_pair)
    if few is not None:
        idx, few0, few1 = few
        few_mean = 0.5 * (few0 + few1)
        row["median_error_few_ref"] = median_rel_error(lum[idx], few_mean)
        row["median_error_few_ref_noise_corrected"] = noise_corrected_error(lum[idx], few_mean, few0, few1)
    if star is not None:
        row["mtf"] = star_mtf(lum, ref_lum, star)
    for lux in LUX_LEVELS:
        on, off = event_counts(tl, lux)
        ron, roff = ref_events[lux]
        row[f"events_{lux:g}"] = [on, off]
        row[f"event_ratio_{lux:g}"] = [on / max(ron, 1), off / max(roff, 1)]
    return row


def bench_scene(name: str, base: RenderSettings, ref_spp: int, spps: list[int], cache_runs: list[dict],
                work: Path, keep: bool = False, trajectory=None, label: str | None = None, few_ref_spp: int = 0,
                few_ref_keyframes: int = 4, mtf: bool = False) -> dict:
    """Measure every method on scene ``name`` (on ``trajectory``, a TrajectorySet, or its default); ``label``
    names its renders in ``work`` and its rows (the scene's name by default)."""
    label = label or name

    def timed(settings, out, keep_it=False):
        return render_timed(name, settings, out, keep_it, trajectory)

    ref_tl, ref_cpu = timed(replace(base, spp=ref_spp, seed=0, interpolation="linear"),
                            work / f"{label}-ref{ref_spp}-0", keep)
    ref2_tl, ref2_cpu = timed(replace(base, spp=ref_spp, seed=1, interpolation="linear"),
                              work / f"{label}-ref{ref_spp}-1", keep)
    # A process's first render pays for loading Mitsuba and compiling kernels: spend that on a render not counted
    # (the references pay it otherwise, and with --work they may come from an earlier run).
    timed(replace(base, spp=1, duration_s=min(base.duration_s, 0.002), interpolation="linear"),
          work / f"{label}-warm-up")
    lum0, lum1 = keyframe_luminance(ref_tl), keyframe_luminance(ref2_tl)
    ref_lum = 0.5 * (lum0 + lum1)
    # The mean of the two seeds is the reference: each one's noise is their difference ÷ √2, the mean's ÷ 2.
    ref_noise_one = median_rel_error(lum0, lum1) / np.sqrt(2.0)
    # Events of the reference: the seed-0 render (a timeline of the mean would need its own render directory).
    ref_events = {lux: event_counts(ref_tl, lux) for lux in LUX_LEVELS}
    ref2_events = {lux: event_counts(ref2_tl, lux) for lux in LUX_LEVELS}
    out = {"scene": label, "n_keyframes": int(lum0.shape[0]), "ref_spp": ref_spp, "ref_cpu_s": ref_cpu,
           "ref_noise_one_seed": ref_noise_one, "ref_events": {f"{k:g}": v for k, v in ref_events.items()},
           "ref_seed1_events": {f"{k:g}": v for k, v in ref2_events.items()}, "methods": {}}
    print(f"{label}: {out['n_keyframes']} keyframes; reference {ref_spp} spp: {ref_cpu:.1f} CPU-s, own noise "
          f"{100 * ref_noise_one:.2f} % (one seed), events 100 lx {ref_events[100.0]}, 1e4 lx {ref_events[1e4]} "
          f"(seed 1: {ref2_events[100.0]}, {ref2_events[1e4]})", flush=True)
    few = None
    if few_ref_spp:
        pair = [render_few(name, trajectory, replace(base, spp=few_ref_spp, seed=seed, interpolation="linear"),
                           few_ref_keyframes, work / f"{label}-few{few_ref_spp}-{seed}") for seed in (0, 1)]
        few = (pair[0][0], pair[0][1], pair[1][1])
        few_noise = median_rel_error(pair[0][1], pair[1][1]) / np.sqrt(2.0)
        out["few_ref"] = {"spp": few_ref_spp, "keyframes": pair[0][0], "noise_one_seed": few_noise,
                          "ref_median_error": median_rel_error(lum0[few[0]], 0.5 * (pair[0][1] + pair[1][1]))}
        print(f"  {few_ref_spp}-spp pair on keyframes {pair[0][0]}: own noise {100 * few_noise:.2f} % (one seed); "
              f"the {ref_spp}-spp reference's seed 0 is {100 * out['few_ref']['ref_median_error']:.2f} % off it",
              flush=True)
    star = None
    if mtf:
        star = metrics.siemens_star_geometry(ref_lum[0])
        out["star_geometry"] = [float(star[0]), float(star[1]), int(star[2]), float(star[3])]
        out["ref_mtf"] = {"mean": star_mtf(ref_lum, ref_lum, star), "seed 0": star_mtf(lum0, ref_lum, star),
                          "seed 1": star_mtf(lum1, ref_lum, star)}
        for k, v in out["ref_mtf"].items():
            print(f"  reference {k:<6} MTF {_mtf_text(v)}", flush=True)
    for spp in spps:
        tl, cpu = timed(replace(base, spp=spp, interpolation="linear"), work / f"{label}-bf{spp}")
        out["methods"][f"brute force {spp} spp"] = row = measure(tl, cpu, ref_lum, ref_events, (lum0, lum1), few, star)
        _print(label, f"brute force {spp} spp", row)
    for run in cache_runs:
        method = f"cache {run['spp']} spp, {run['cache_samples']} q, {run['interpolation']}"
        tl, cpu = timed(replace(base, convergence="cache", **run),
                        work / f"{label}-cache{run['spp']}-{run['interpolation']}")
        out["methods"][method] = row = measure(tl, cpu, ref_lum, ref_events, (lum0, lum1), few, star)
        _print(label, method, row)
    return out


def _mtf_text(m: dict) -> str:
    return "  ".join(f"{kind}: " + " ".join(f"{k.replace('_cyc_px', '')} {v:.3f}" for k, v in m[kind].items())
                     for kind in ("vs_print", "vs_reference"))


def _print(scene: str, label: str, row: dict) -> None:
    print(f"  {scene:<13} {label:<32} CPU {row['cpu_s']:8.1f} s  rendered {row['n_rendered']}/{row['n_keyframes']}  "
          f"median error {100 * row['median_error']:6.2f} % (noise-corrected "
          f"{100 * row['median_error_noise_corrected']:.2f} %)  "
          f"events/ref 100 lx {row['event_ratio_100'][0]:.2f}/{row['event_ratio_100'][1]:.2f}  "
          f"1e4 lx {row['event_ratio_10000'][0]:.2f}/{row['event_ratio_10000'][1]:.2f}", flush=True)
    if "median_error_few_ref" in row:
        print(f"    against the few-keyframe pair: median error {100 * row['median_error_few_ref']:.2f} % "
              f"(noise-corrected {100 * row['median_error_few_ref_noise_corrected']:.2f} %)", flush=True)
    if "mtf" in row:
        print(f"    MTF {_mtf_text(row['mtf'])}", flush=True)


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
    parser.add_argument("--trajectory", type=Path, default=None,
                        help="a trajectory file for every scene (default: each scene's own)")
    parser.add_argument("--speed", type=float, default=1.0, help="play the trajectory this many times faster "
                        "(needs --trajectory)")
    parser.add_argument("--few-ref-spp", type=int, default=0, help="also a reference at this many spp (seeds 0 "
                        "and 1) on --few-ref-keyframes keyframes only (0: none)")
    parser.add_argument("--few-ref-keyframes", type=int, default=4)
    parser.add_argument("--mtf", action="store_true", help="the Siemens-star MTF of every method (star scenes)")
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
    if args.speed != 1.0 and args.trajectory is None:
        parser.error("--speed needs --trajectory")
    trajectory = retimed(load_trajectory(args.trajectory), args.speed) if args.trajectory else None
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
            label = name if args.speed == 1.0 else f"{name}-x{args.speed:g}"
            results.append(bench_scene(name, base, args.ref_spp, spps, cache_runs, work, keep=args.work is not None,
                                       trajectory=trajectory, label=label, few_ref_spp=args.few_ref_spp,
                                       few_ref_keyframes=args.few_ref_keyframes, mtf=args.mtf))
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
