"""Rendering benchmark: adaptive keyframes + linear interpolation versus brute-force renders.

Measures, on a short fast pan (a burst of yaw, plus a slight translation) over a textured scene:

1. interpolation accuracy: the timeline's interpolated luminance against brute-force renders at random
   intermediate instants, as relative RMSE (÷ mean luminance), for several ``max_flow_px``, with the render count
   of each, for the adaptive schedule and for a uniform schedule with the same number of renders (the naive
   reference); and the reduction against one render per 10.24 µs SPAD bin at the defaults;
2. kernel reuse: Dr.Jit kernels new to the process while rendering the first frame and all later frames;
3. llvm versus scalar time per frame, each measured in its own subprocess (the variant is per process).

Writes the error-versus-render-count plot (PNG). Run: ``python benchmarks/bench_render.py [--out PNG]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.ndimage import gaussian_filter
from scipy.spatial.transform import Rotation

from simspad import defaults
from simspad.io.exr import write_exr
from simspad.motion.trajectory import Trajectory, TrajectorySet, look_at
from simspad.physics.radiometry import luminance_from_rgb
from simspad.radiance.timeline import Timeline
from simspad.render.flow import camera_poses, object_poses
from simspad.render.mitsuba_scene import MitsubaScene
from simspad.render.renderer import RenderSettings, render_sequence, select_variant
from simspad.render.schedule import brute_force_keyframes, focal_length_px
from simspad.scenes.library import resolve_scene
from simspad.sensors.presets import SpadParams

HERE = Path(__file__).resolve().parent
FOV_DEG = 45.0
DURATION_S = 0.04
PEAK_FLOW_PX_S = 1000.0  # the pan's peak image speed at the image border
SPEED_PROFILE_POWER = 6  # yaw rate ∝ sin^6(πt/T): a burst in the middle third
DEFAULT_MAX_FLOW_PX = defaults.MAX_FLOW_PX
DEFAULT_MIN_RATE_HZ = defaults.MIN_KEYFRAME_RATE_HZ


def natural_texture(size: int, rng) -> np.ndarray:
    """Zero-mean, unit-variance noise with the 1/f amplitude spectrum of natural images."""
    f = np.hypot(*np.meshgrid(np.fft.fftfreq(size), np.fft.fftfreq(size), indexing="ij"))
    spectrum = np.fft.fft2(rng.standard_normal((size, size))) / np.maximum(f, 1.0 / size)
    tex = np.real(np.fft.ifft2(spectrum))
    return (tex - tex.mean()) / tex.std()


def write_scene(folder: Path, texture: str = "natural") -> Path:
    """A textured wall with three checkered boxes in front of it.

    ``texture="natural"``: 1/f noise plus sharp-edged tiles on wall and boxes; ``"fine"``: adds white-ish detail
    at the texel scale (about 0.6 px here); ``"checker"``: high-contrast point-sampled checks on the boxes.
    """
    rng = np.random.default_rng(7)
    size = 1024
    tex = natural_texture(size, rng)
    if texture in ("fine", "checker"):
        fine = gaussian_filter(rng.standard_normal((size, size)), 1.5, mode="wrap")
        tex = tex + 0.6 * fine / fine.std()
    tiles = ((np.arange(size)[:, None] // 128 + np.arange(size)[None, :] // 128) % 2).astype(float)
    albedo = np.clip(0.35 + 0.1 * tex + 0.2 * (tiles - 0.5), 0.02, 0.95).astype(np.float32)
    if texture == "checker":  # sharp, high-contrast checks on the boxes: the hardest case for interpolation
        box_bsdf = ('<texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.1"/>'
                    '<rgb name="color1" value="0.7"/><transform name="to_uv"><scale value="4"/></transform></texture>')
    else:
        box_bsdf = ('<texture type="bitmap" name="reflectance"><string name="filename" value="wall.exr"/>'
                    '<boolean name="raw" value="true"/></texture>')
    folder.mkdir(parents=True, exist_ok=True)
    write_exr(folder / "wall.exr", {"R": albedo, "G": albedo * 0.9, "B": albedo * 0.8})
    boxes = "\n".join(
        f'<shape type="cube" id="box{i}"><transform name="to_world"><scale value="{s}"/>'
        f'<translate x="{x}" y="{y}" z="{z}"/></transform><bsdf type="diffuse">{box_bsdf}</bsdf>'
        f'</shape>' for i, (x, y, z, s) in enumerate(((-0.6, -0.2, 0.8, 0.15), (0.5, 0.3, 1.2, 0.2),
                                                      (1.4, -0.3, 0.5, 0.25))))
    (folder / "scene.xml").write_text(f"""<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective" id="camera">
    <float name="fov" value="{FOV_DEG}"/>
    <transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="0.3"/></emitter>
  <shape type="rectangle" id="light">
    <transform name="to_world"><scale value="1.5"/><rotate x="1" angle="180"/><translate x="1" y="2" z="4"/></transform>
    <emitter type="area"><rgb name="radiance" value="4.0"/></emitter>
  </shape>
  <shape type="rectangle" id="wall">
    <transform name="to_world"><scale x="6" y="4"/></transform>
    <bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="wall.exr"/>
      <boolean name="raw" value="true"/></texture></bsdf>
  </shape>
  {boxes}
</scene>
""")
    return folder


def pan_trajectory(width: int):
    """A burst pan: yaw rate ∝ sin⁶(πt/T) (nearly still for the first and last third), peaking at PEAK_FLOW_PX_S at
    the image border, plus a slight translation for parallax between wall and boxes."""
    focal = focal_length_px(FOV_DEG, width)
    x_border = 0.5 * width / focal
    peak_rad_s = PEAK_FLOW_PX_S / (focal * (1 + x_border**2))
    t = np.linspace(0.0, DURATION_S, 2001)
    angle = cumulative_trapezoid(peak_rad_s * np.sin(np.pi * t / DURATION_S) ** SPEED_PROFILE_POWER, t, initial=0.0)
    base = look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    rot = Rotation.from_rotvec(angle[:, None] * np.array([0.0, 1.0, 0.0])) * Rotation.from_matrix(base[:3, :3])
    pos = base[:3, 3] + np.outer(t, [0.5, 0.0, 0.0])
    return TrajectorySet(camera=Trajectory(t, pos, rot.as_quat(), source="bench pan"), objects={},
                         source="bench pan")


def rel_rmse(tl, refs: dict[float, np.ndarray]) -> float:
    err = [np.mean((tl.sample(t).astype(np.float64) - y) ** 2) for t, y in refs.items()]
    mean = np.mean([y.mean() for y in refs.values()])
    return float(math.sqrt(np.mean(err)) / mean)


def uniform_timeline(scene, ts, n: int, res, spp, out: Path):
    """The naive reference: n keyframes evenly spaced, rendered with the same renderer."""
    # min_rate with a huge max_flow forces exactly evenly spaced keyframes.
    rate = (n - 1) / DURATION_S * (1 + 1e-9)
    render_sequence(scene, ts, RenderSettings(duration_s=DURATION_S, resolution=res, spp=spp, max_flow_px=1e9,
                                              min_rate_hz=rate), out_dir=out, progress=False)
    return Timeline.open(out)


def reference_frames(scene, ts, instants, res, spp, seed=0) -> dict[float, np.ndarray]:
    """Brute-force renders (luminance) at the given instants, same sensor, sampler and seed as the keyframes."""
    ms = MitsubaScene(resolve_scene(scene), ts, res[0], res[1], spp)
    refs = {}
    poses = camera_poses(ts, ms.rest_camera_to_world, np.asarray(instants))
    for t, pose in zip(instants, poses):
        ms.set_pose(pose, object_poses(ts, t))
        refs[float(t)] = luminance_from_rgb(ms.render_radiance(seed)).astype(np.float64)
    return refs


def time_per_frame(variant: str, scene: Path, res, spp: int, n: int = 6) -> dict:
    """Render n keyframes in a fresh subprocess with ``variant``; return its timing summary."""
    code = (
        "import json, sys, tempfile; from simspad.render.renderer import RenderSettings, render_sequence;"
        f"s = render_sequence({str(scene)!r}, None, RenderSettings(duration_s={(n - 1) * 1e-3}, "
        f"resolution={tuple(res)!r}, spp={spp}, min_rate_hz=1000.0), out_dir=tempfile.mkdtemp(), progress=False);"
        "print(json.dumps({'variant': s.variant, 'times': s.frame_times_s}))"
    )
    env = dict(os.environ, SIMSPAD_MITSUBA_VARIANT=variant)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return json.loads([line for line in out.stdout.splitlines() if line.startswith("{")][-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=HERE / "results" / "bench_render.png", help="plot (PNG)")
    parser.add_argument("--resolution", default="128x96")
    parser.add_argument("--spp", type=int, default=64)
    parser.add_argument("--texture", choices=("natural", "fine", "checker"), default="natural")
    parser.add_argument("--references", type=int, default=32, help="brute-force reference instants")
    args = parser.parse_args(argv)
    res = tuple(int(v) for v in args.resolution.split("x"))

    variant = select_variant()
    work = Path(tempfile.mkdtemp(prefix="bench_render-"))
    scene = write_scene(work / "scene", args.texture)
    ts = pan_trajectory(res[0])
    spad_bin_s = SpadParams().bin_s
    n_bins = brute_force_keyframes(DURATION_S, spad_bin_s)
    print(f"scene: {args.texture}-textured wall + 3 boxes, {res[0]}x{res[1]}, {args.spp} spp, variant {variant}")
    print(f"motion: {DURATION_S * 1e3:g} ms yaw pan, speed ∝ sin^{SPEED_PROFILE_POWER}(πt/T), peak {PEAK_FLOW_PX_S:g} "
          "px/s at the image border")

    # Defaults (max_flow 0.5 px, min rate 1 kHz) first, so the kernel count is that of a fresh process.
    s = render_sequence(scene, ts, RenderSettings(duration_s=DURATION_S, resolution=res, spp=args.spp,
                                                  max_flow_px=DEFAULT_MAX_FLOW_PX, min_rate_hz=DEFAULT_MIN_RATE_HZ),
                        out_dir=work / "default", progress=False)

    rng = np.random.default_rng(1)
    instants = np.sort(rng.uniform(0.0, DURATION_S, args.references))
    tic = time.perf_counter()
    refs = reference_frames(scene, ts, instants, res, args.spp)
    ref_s = (time.perf_counter() - tic) / len(instants)
    print(f"brute force: {len(refs)} reference renders at random instants, {ref_s * 1e3:.1f} ms each")
    other_seed = reference_frames(scene, ts, instants[:8], res, args.spp, seed=1)
    noise = math.sqrt(np.mean([np.mean((other_seed[t] - refs[t]) ** 2) for t in other_seed]) / 2)
    noise /= np.mean([refs[t].mean() for t in other_seed])
    print(f"Monte Carlo noise of one render (seed 0 vs seed 1, /sqrt 2): {noise * 100:.2f} % of mean luminance")

    default_rmse = rel_rmse(Timeline.open(work / "default"), refs)
    print(f"\ndefaults (max_flow {DEFAULT_MAX_FLOW_PX} px, min rate {DEFAULT_MIN_RATE_HZ:g} Hz): "
          f"{s.n_keyframes} renders vs {n_bins} (one per {spad_bin_s * 1e6:g} µs bin) -> "
          f"{n_bins / s.n_keyframes:.1f}x fewer; "
          f"interpolation RMSE {default_rmse * 100:.3f} % of mean luminance")
    if s.compiled_first_frame >= 0:
        print(f"kernels new to the process: {s.compiled_first_frame} while rendering the first frame, "
              f"{s.compiled_after_first} over the {s.n_rendered - 1} later frames")

    # Sweep max_flow (min rate low so that motion alone sets the schedule), against uniform spacing.
    rows = []
    print(f"\n{'max_flow_px':>11} {'renders a/u':>8} {'adaptive RMSE %':>16} {'uniform RMSE %':>15} {'uniform/adaptive':>17}")
    for flow in (0.25, 0.5, 1.0, 2.0):
        sa = render_sequence(scene, ts, RenderSettings(duration_s=DURATION_S, resolution=res, spp=args.spp,
                                                       max_flow_px=flow, min_rate_hz=50.0), out_dir=work / f"a{flow}",
                             progress=False)
        ea = rel_rmse(Timeline.open(work / f"a{flow}"), refs)
        tu = uniform_timeline(scene, ts, sa.n_keyframes, res, args.spp, work / f"u{flow}")
        eu = rel_rmse(tu, refs)
        rows.append((flow, sa.n_keyframes, ea, eu))
        counts = f"{sa.n_keyframes}/{tu.n_keyframes}"
        print(f"{flow:>11g} {counts:>8} {ea * 100:>16.3f} {eu * 100:>15.3f} {eu / ea:>17.2f}")

    # llvm versus scalar, each in a fresh process.
    print("\ntime per frame (radiance + depth pass), each variant in its own process:")
    timing = {}
    for v in ("llvm_ad_rgb", "scalar_rgb"):
        try:
            r = time_per_frame(v, scene, res, args.spp)
        except subprocess.CalledProcessError as exc:
            print(f"  {v}: failed ({exc.stderr.strip().splitlines()[-1] if exc.stderr else exc})")
            continue
        if r["variant"] != v:
            print(f"  {v}: not available (got {r['variant']})")
            continue
        timing[v] = r["times"]
        print(f"  {v:<12} first {r['times'][0] * 1e3:8.1f} ms, median of the rest "
              f"{np.median(r['times'][1:]) * 1e3:8.1f} ms")
    if len(timing) == 2:
        ratio = np.median(timing["scalar_rgb"][1:]) / np.median(timing["llvm_ad_rgb"][1:])
        print(f"  scalar / llvm time per frame: {ratio:.1f}x")

    import matplotlib  # deferred: heavy, and only the plot needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(figsize=(6, 4))
    n = [r[1] for r in rows]
    ax.loglog(n, [r[2] * 100 for r in rows], "o-", label="adaptive schedule")
    ax.loglog(n, [r[3] * 100 for r in rows], "s--", label="uniform, same render count")
    for flow, k, ea, _ in rows:
        ax.annotate(f"{flow:g} px", (k, ea * 100), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.axhline(1.0, color="grey", lw=0.8, ls=":")
    ax.scatter([s.n_keyframes], [default_rmse * 100], marker="*", s=120, color="k", zorder=5,
               label=f"defaults ({n_bins / s.n_keyframes:.0f}x fewer than per-bin)")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        axis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel(f"keyframes rendered ({DURATION_S * 1e3:g} ms; one per SPAD bin = {n_bins})")
    ax.set_ylabel("interpolation RMSE, % of mean luminance")
    ax.set_title(f"Adaptive keyframes on a fast pan ({res[0]}x{res[1]}, {args.spp} spp)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    print(f"\nwrote {args.out}")
    goal = n_bins / s.n_keyframes >= 50 and default_rmse <= 0.01
    print(f"goal (>= 50x fewer renders and RMSE <= 1 % at the defaults): {'met' if goal else 'NOT met'}")
    shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
