"""Warp benchmark: motion-compensated keyframe synthesis (``--interpolation warp``) against rendering every keyframe
of the linear schedule (``--interpolation linear``, the naive reference), in the same process.

For every built-in scene (its default trajectory) and for a fast pan with parallax (bench_render.py's textured
wall + boxes, a yaw burst plus translation) it measures

1. Mitsuba renders per sequence: keyframes rendered (plus the noise-probe render every render makes: the
   render-noise budget's, and the warp schedule's reference; and the blocks rendered into synthesized keyframes
   where the warps disagree, counted by their pixel samples as a fraction of a whole render), the warp schedule's 1-spp depth + id passes (one per synthesized keyframe) and
   its emission passes (one per keyframe, the emission layer), and the whole render work (``cost``: every pass in
   whole renders, at the price of each kind of pass measured on the scene's first keyframe; the goal is judged
   on it); the wall-time columns say what everything cost;
2. accuracy: relative RMSE of the timeline's luminance at random instants against converged renders
   (``--ref-spp`` samples, same pose), so Monte Carlo noise counts;
3. events: ON and OFF counts of the event simulator (its own noise sources off, the same pixel maps) on both
   timelines; frozen screen-space noise that warping moved would show up as extra events. With
   ``--events-spp N`` also those of an all-render timeline at N spp: how many of the linear timeline's events
   are Monte Carlo noise (under camera motion the fixed-seed noise does not stay frozen).

With ``--plain`` each scene also runs warp without its emission layer (``warp_emission=False``: every pixel
warped, emitters included). On the pan it also sweeps the linear schedule's ``max_flow_px`` and the warp stride, and plots error against render
count for both (PNG). Run: ``python benchmarks/bench_warp.py [--out PNG]``.
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from simspad import defaults
from simspad.io.trajectory_files import load_trajectory
from simspad.physics.radiometry import luminance_from_rgb
from simspad.radiance.timeline import Timeline
from simspad.render.flow import camera_poses, object_poses
from simspad.render.mitsuba_scene import MitsubaScene
from simspad.render.renderer import RenderSettings, render_sequence, select_variant
from simspad.scenes.library import builtin_scene_names, resolve_scene
from simspad.sensors.events.model import (
    draw_pixel_maps,
    sensor_current_1lux_e_s,
    sensor_photocurrent_e_s,
)
from simspad.sensors.events.simulator import EventSimulator, iter_knot_chunks
from simspad.sensors.presets import EventParams

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_render

HERE = Path(__file__).resolve().parent
LUX = 1000.0
#: Event camera with its own noise sources off: only radiance changes make events.
QUIET_EVENTS = replace(EventParams(), shot_noise_rate_hz_at_1lux=0.0, leak_rate_hz=0.0, hot_pixel_fraction=0.0)
NOISE_PROBE_RENDERS = 1  # render_noise_probe() in render/warp/rendering.py (keyframe 0 again, next seed), every render


def converged(scene, ts, instants, res, spp) -> dict[float, np.ndarray]:
    """Luminance at ``instants`` rendered with ``spp`` samples (the converged reference)."""
    ms = MitsubaScene(resolve_scene(scene), ts, res[0], res[1], spp)
    poses = camera_poses(ts, ms.rest_camera_to_world, np.asarray(instants))
    out = {}
    for t, pose in zip(instants, poses):
        ms.set_pose(pose, object_poses(ts, t))
        out[float(t)] = luminance_from_rgb(ms.render_radiance(0)).astype(np.float64)
    return out


def rel_rmse(tl: Timeline, refs: dict) -> float:
    err = [np.mean((tl.sample(t).astype(np.float64) - y) ** 2) for t, y in refs.items()]
    return float(math.sqrt(np.mean(err)) / np.mean([y.mean() for y in refs.values()]))


def event_counts(tl: Timeline, lux: float = LUX) -> tuple[int, int]:
    """(ON, OFF) events of the quiet (noise-free) event camera over the whole timeline at ``lux``."""
    flux = tl.photon_flux(lux)
    params = QUIET_EVENTS
    maps = draw_pixel_maps(params, (tl.height, tl.width), np.random.default_rng(0))
    current_1lux = sensor_current_1lux_e_s(float(np.mean(flux.keyframe(0))), lux, params)
    sim = EventSimulator(params, (tl.height, tl.width), sensor_photocurrent_e_s(flux.sample(tl.t_start), params).ravel(),
                         tl.t_start, current_1lux, maps)
    on = off = 0
    batches = (sim.advance(knot_t, knot_current) for knot_t, knot_current in
               iter_knot_chunks(flux, tl.t_start, tl.t_end, params))
    for batch in (*batches, sim.finish()):
        on += int(np.count_nonzero(batch.polarity == 1))
        off += int(np.count_nonzero(batch.polarity == 0))
    return on, off


def pass_costs(scene, ts, settings: RenderSettings, repeat: int = 3) -> tuple[float, float]:
    """Wall time of a 1-spp depth + id pass and of an emission pass, each ÷ that of a radiance render of the same
    keyframe (keyframe 0, median of ``repeat``, after one untimed round of each): what they cost in renders."""
    ms = MitsubaScene(resolve_scene(scene), ts, settings.resolution[0], settings.resolution[1], settings.spp)
    ms.set_pose(camera_poses(ts, ms.rest_camera_to_world, np.array([0.0]))[0], object_poses(ts, 0.0))
    passes = (lambda: ms.render_radiance(0), lambda: ms.render_depth_ids(0), lambda: ms.render_emission(0))
    times = [[], [], []]
    for k in range(repeat + 1):
        for f, out in zip(passes, times):
            tic = time.perf_counter()
            f()
            if k:
                out.append(time.perf_counter() - tic)
    full, geo, emis = (float(np.median(t)) for t in times)
    return geo / full, emis / full


def run(scene, ts, settings: RenderSettings, out: Path, with_geometry: bool = False):
    """Render ``out``; returns the timeline, its radiance renders (noise probes included), the wall time (s) and,
    with ``with_geometry``, the depth + id passes of its synthesized keyframes and its emission passes."""
    tic = time.perf_counter()
    s = render_sequence(scene, ts, settings, out_dir=out, progress=False)
    tl = Timeline.open(out)
    warp = tl.meta["schedule"].get("warp", {})
    # Blocks rendered into synthesized keyframes count by their pixel samples, as a fraction of a whole render.
    # Every render renders one noise probe (the render-noise budget's; the warp schedule judges its warps against
    # it too), linear and warp alike.
    n = s.n_keyframes - s.n_warped + NOISE_PROBE_RENDERS + float(warp.get("patch_renders", 0.0))
    if with_geometry:
        return (tl, n, time.perf_counter() - tic, int(warp.get("n_geometry_passes", 0)),
                int(warp.get("n_emission_passes", 0)))
    return tl, n, time.perf_counter() - tic


def compare(name, scene, ts, settings, work: Path, instants, ref_spp, events_spp: int = 0,
            plain: bool = False) -> dict:
    """One scene: linear (every keyframe rendered) against warp, same settings otherwise; with ``events_spp``
    also the events of an all-render timeline at that many spp (how many of the linear count are noise); with
    ``plain`` also warp without its emission layer (every pixel warped)."""
    c_geo, c_emis = pass_costs(scene, ts, settings)
    tl_lin, n_lin, s_lin = run(scene, ts, replace(settings, interpolation="linear"), work / f"{name}-linear")
    refs = converged(scene, ts, instants, settings.resolution, ref_spp)
    e_lin, ev_lin = rel_rmse(tl_lin, refs), event_counts(tl_lin)
    variants = [("warp", True)] + ([("warp-plain", False)] if plain else [])
    for label, layer in variants:
        tl_warp, n_warp, s_warp, geo, emis = run(scene, ts, replace(settings, interpolation="warp",
                                                                    warp_emission=layer),
                                                 work / f"{name}-{label}", with_geometry=True)
        e_warp, ev_warp = rel_rmse(tl_warp, refs), event_counts(tl_warp)
        d_on = (ev_warp[0] - ev_lin[0]) / max(ev_lin[0], 1)
        d_off = (ev_warp[1] - ev_lin[1]) / max(ev_lin[1], 1)
        # every pass in whole renders, at its measured cost: what the schedule really spends
        cost = n_warp + geo * c_geo + emis * c_emis
        tag = name if label == "warp" else f"{name} (plain)"
        print(f"{tag:<13} {tl_lin.n_keyframes:>4} {n_lin:>6} {n_warp:>6.1f} {geo:>5} {emis:>5} {cost:>6.1f} "
              f"{n_lin / n_warp:>6.1f}x {n_lin / cost:>6.1f}x "
              f"{e_lin * 100:>8.2f} {e_warp * 100:>8.2f} {e_warp / e_lin:>6.2f} "
              f"{ev_lin[0]:>8} {ev_warp[0]:>8} {d_on * 100:>+6.1f}% {ev_lin[1]:>8} {ev_warp[1]:>8} "
              f"{d_off * 100:>+6.1f}% {s_lin:>6.1f} {s_warp:>6.1f}", flush=True)
        if label == "warp":
            out = {"renders_linear": n_lin, "renders_warp": n_warp, "cost_warp": cost, "err_linear": e_lin,
                   "err_warp": e_warp, "events_linear": ev_lin, "events_warp": ev_warp, "geometry_passes": geo,
                   "emission_passes": emis}
    if events_spp:
        tl_hi, _, _ = run(scene, ts, replace(settings, interpolation="linear", spp=events_spp),
                          work / f"{name}-linear-{events_spp}")
        ev_hi = event_counts(tl_hi)
        print(f"{'':<13} all-render timeline at {events_spp} spp: ON {ev_hi[0]}, OFF {ev_hi[1]} "
              f"({settings.spp}-spp linear has {ev_lin[0] / max(ev_hi[0], 1):.2f}x / {ev_lin[1] / max(ev_hi[1], 1):.2f}x "
              f"as many, warp {ev_warp[0] / max(ev_hi[0], 1):.2f}x / {ev_warp[1] / max(ev_hi[1], 1):.2f}x)", flush=True)
        out["events_hi"] = ev_hi
    return out


HEADER = (f"{'scene':<13} {'kf':>4} {'r.lin':>6} {'r.warp':>6} {'geo':>5} {'emis':>5} {'cost':>6} {'fewer':>7} "
          f"{'cheaper':>7} {'err.lin%':>8} "
          f"{'err.warp%':>8} {'ratio':>6} {'ON lin':>8} {'ON warp':>8} {'dON':>7} {'OFF lin':>8} {'OFF warp':>8} "
          f"{'dOFF':>7} {'t.lin':>6} {'t.warp':>6}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=HERE / "results" / "bench_warp.png", help="plot (PNG)")
    parser.add_argument("--resolution", default="64x48")
    parser.add_argument("--spp", type=int, default=defaults.SPP)
    parser.add_argument("--duration", type=float, default=0.048, help="seconds of each built-in scene")
    parser.add_argument("--ref-spp", type=int, default=1024)
    parser.add_argument("--instants", type=int, default=8, help="random instants per sequence")
    parser.add_argument("--scenes", default=",".join(builtin_scene_names()))
    parser.add_argument("--skip-pan", action="store_true")
    parser.add_argument("--plain", action="store_true", help="also run warp without its emission layer")
    parser.add_argument("--events-spp", type=int, default=0,
                        help="also count the events of an all-render timeline at this many spp (0: off)")
    args = parser.parse_args(argv)
    res = tuple(int(v) for v in args.resolution.split("x"))
    variant = select_variant()
    work = Path(tempfile.mkdtemp(prefix="bench_warp-"))
    rng = np.random.default_rng(1)
    print(f"{res[0]}x{res[1]}, {args.spp} spp, variant {variant}, references {args.ref_spp} spp at "
          f"{args.instants} random instants; renders (r.) are radiance renders, the warp schedule's include its "
          f"{NOISE_PROBE_RENDERS} noise-probe renders; geo: its 1-spp depth + id passes (t.: wall time of each "
          "schedule, s); events: quiet event camera (no shot noise, leak or hot pixels) at "
          f"{LUX:g} lx\n")
    print(HEADER)
    results = {}
    base = RenderSettings(duration_s=args.duration, resolution=res, spp=args.spp)
    for name in [s for s in args.scenes.split(",") if s]:
        instants = np.sort(rng.uniform(0.0, args.duration, args.instants))
        ts = load_trajectory(resolve_scene(name).default_trajectory)
        results[name] = compare(name, name, ts, base, work, instants, args.ref_spp, args.events_spp, args.plain)

    rows_lin, rows_warp = [], []
    if not args.skip_pan:
        pan_res = (96, 72)
        scene = bench_render.write_scene(work / "pan-scene")
        ts = bench_render.pan_trajectory(pan_res[0])
        dur = bench_render.DURATION_S
        instants = np.sort(rng.uniform(0.0, dur, 2 * args.instants))
        pan = RenderSettings(duration_s=dur, resolution=pan_res, spp=64)
        print(f"\nfast pan with parallax ({dur * 1e3:g} ms, peak {bench_render.PEAK_FLOW_PX_S:g} px/s, "
              f"{pan_res[0]}x{pan_res[1]}, 64 spp):")
        print(HEADER)
        results["pan"] = compare("pan", scene, ts, pan, work, instants, args.ref_spp)
        refs = converged(scene, ts, instants, pan_res, args.ref_spp)
        print(f"\n{'schedule':<26} {'renders':>7} {'err %':>7}")
        for flow in (0.25, 0.5, 1.0, 2.0):
            tl, n, _ = run(scene, ts, replace(pan, interpolation="linear", max_flow_px=flow), work / f"lin{flow}")
            rows_lin.append((n, rel_rmse(tl, refs), f"{flow:g} px"))
            print(f"{'linear, max_flow ' + str(flow):<26} {n:>7} {rows_lin[-1][1] * 100:>7.2f}", flush=True)
        for stride in (4, 8, 16, 32):
            tl, n, _ = run(scene, ts, replace(pan, interpolation="warp", warp_stride=stride), work / f"warp{stride}")
            rows_warp.append((n, rel_rmse(tl, refs), f"stride {stride}"))
            print(f"{'warp, stride ' + str(stride):<26} {n:>7} {rows_warp[-1][1] * 100:>7.2f}", flush=True)

    print("\nsummary (linear default schedule vs warp default):")
    ok_all = True
    for name, r in results.items():
        fewer = r["renders_linear"] / r["renders_warp"]
        # the goal is judged on the whole cost: depth + id and emission passes count at their measured price
        cheaper = r["renders_linear"] / r.get("cost_warp", r["renders_warp"])
        ev_ok = all(abs(w - l) <= 0.02 * max(l, 1) for l, w in zip(r["events_linear"], r["events_warp"]))
        acc_ok = r["err_warp"] <= r["err_linear"]
        ok_all &= cheaper >= 8 and acc_ok and ev_ok
        print(f"  {name:<13} {fewer:5.1f}x fewer radiance renders, {cheaper:5.1f}x less render work; error "
              f"warp/linear {r['err_warp'] / r['err_linear']:.2f} ({'ok' if acc_ok else 'LARGER'}); events within "
              f"2 %: {'yes' if ev_ok else 'NO'}")
    print(f"goal (>= 8x less render work, error no larger, events within 2 %, every sequence): "
          f"{'met' if ok_all else 'NOT met'}")

    if rows_lin:
        import matplotlib  # deferred: heavy, and only the plot needs it

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        for rows, style, label in ((rows_lin, "s--", "linear: every keyframe rendered (max_flow sweep)"),
                                   (rows_warp, "o-", "warp: sparse renders + reprojection (stride sweep)")):
            ax.loglog([r[0] for r in rows], [r[1] * 100 for r in rows], style, label=label)
            for n, e, tag in rows:
                ax.annotate(tag, (n, e * 100), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.set_xlabel("Mitsuba renders per sequence")
        ax.set_ylabel(f"RMSE vs {args.ref_spp}-spp renders at random instants, % of mean")
        ax.set_title("Fast pan with parallax (96x72, 64 spp)")
        ax.legend(fontsize=7)
        fig.tight_layout()
        args.out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.out, dpi=120)
        print(f"wrote {args.out}")
    shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
