"""Converged keyframes: the irradiance cache looked up inside a Dr.Jit kernel against the numpy lookup.

For each scene (its default trajectory, one keyframe in the middle of a short clip) it builds an irradiance cache
from two probe views (the first and last keyframes), then renders the middle keyframe with
:meth:`simspad.render.converged.ConvergedRenderer.render` twice per round, alternating:

* **kernel**: the finest level looked up on every lane of the chain inside Dr.Jit (what SimSPAD does), numpy only
  for the vertices it leaves without light;
* **numpy**: every vertex read back and looked up by :meth:`IrradianceCache.lookup` (sorted keys, binary search,
  the same trilinear weights), which is what a keyframe did before.

It reports each one's CPU time (``process_time``: Dr.Jit's threads included), their ratio, a path-traced keyframe
at the same samples per pixel for scale, and the largest relative difference between the two images (float32
rounding only). Run: ``python benchmarks/bench_cache_lookup.py --resolution 128x96 --spp 64``.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from simspad.render import converged as cv
from simspad.render.flow import object_poses
from simspad.render.renderer import RenderSettings, layout_render, load_scene


def _numpy_only(self, cache, lane, poses):
    q, ok = _KERNEL(self, cache, lane, poses)
    return q, ok & False  # no lane found in the kernel: every vertex goes to the numpy lookup


_KERNEL = cv.ConvergedRenderer._lookup_lanes


def bench_scene(scene: str, w: int, h: int, spp: int, q_samples: int, rounds: int) -> dict:
    loaded = load_scene(scene, None, w, h, spp)
    ms, ts = loaded.ms, loaded.ts
    layout = layout_render(scene, None, RenderSettings(duration_s=0.02, resolution=(w, h), spp=spp), loaded=loaded)
    pose = lambda i: (np.asarray(layout.camera_to_world[i]), object_poses(ts, layout.times_s[i]))  # noqa: E731
    cr = cv.ConvergedRenderer(ms, spp)
    cache = cv.build_cache(cr, [pose(0), pose(layout.n_keyframes - 1)], 0, q_samples, 2.0)
    camera_to_world, objects = pose(layout.n_keyframes // 2)
    ms.set_pose(camera_to_world, objects)
    times = {"kernel": [], "numpy": [], "path": []}
    images = {}
    for mode in ("kernel", "numpy"):  # warm-up: kernels compiled, the open table built
        cv.ConvergedRenderer._lookup_lanes = _KERNEL if mode == "kernel" else _numpy_only
        images[mode] = cr.render(cache, 0, objects)
    ms.render_radiance(0)
    try:
        for _ in range(rounds):
            for mode in ("kernel", "numpy"):
                cv.ConvergedRenderer._lookup_lanes = _KERNEL if mode == "kernel" else _numpy_only
                tic = time.process_time()
                cr.render(cache, 0, objects)
                times[mode].append(time.process_time() - tic)
            tic = time.process_time()
            ms.render_radiance(0)
            times["path"].append(time.process_time() - tic)
    finally:
        cv.ConvergedRenderer._lookup_lanes = _KERNEL
    ref = images["numpy"]
    diff = float(np.max(np.abs(images["kernel"] - ref) / np.maximum(ref, 1e-6 * ref.max())))
    med = {k: float(np.median(v)) for k, v in times.items()}
    return {"scene": scene, **{f"{k}_cpu_s": v for k, v in med.items()}, "speedup": med["numpy"] / med["kernel"],
            "max_rel_diff": diff}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="office,plant,piano,fan,siemens-star")
    parser.add_argument("--resolution", default="128x96")
    parser.add_argument("--spp", type=int, default=64, help="camera rays per pixel (and the path tracer's spp)")
    parser.add_argument("--cache-samples", type=int, default=64, help="estimates per probe point (the build is "
                        "not timed; fewer than a render's default keep the benchmark short)")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    print(f"{'scene':14s} {'kernel':>9s} {'numpy':>9s} {'ratio':>6s} {'path-traced':>12s} {'max rel diff':>13s}"
          f"   (CPU-s per keyframe, {w}x{h}, {args.spp} rays / spp, median of {args.rounds})")
    for scene in args.scenes.split(","):
        r = bench_scene(scene, w, h, args.spp, args.cache_samples, args.rounds)
        print(f"{scene:14s} {r['kernel_cpu_s']:9.3f} {r['numpy_cpu_s']:9.3f} {r['speedup']:5.2f}x "
              f"{r['path_cpu_s']:12.3f} {r['max_rel_diff']:13.1e}")
        if not r["max_rel_diff"] < 1e-4:
            print(f"{scene}: the kernel and numpy lookups disagree", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
