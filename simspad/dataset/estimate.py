"""What a dataset spec will cost, before anything runs: renders, CPU-hours, wall time, disk, peak memory.

Nothing here is a constant of this package: every figure is a measured unit cost on this machine scaled by the
spec's sizes.

- **Keyframes** are exact: each sequence's render is planned at its full size (:func:`layout_render`: the adaptive
  schedule from the predicted image motion), which writes nothing.
- **Render time** per keyframe: a calibration render of a few keyframes of each scene along its own trajectory,
  on one thread, at a small size and two sample counts, fitted as ``a + b·(megapixels·spp)`` (fixed part: scene
  traversal, depth pass, EXR write; variable part: path tracing).
- **Converged renders** (``convergence = "cache"``, :mod:`simspad.render.converged`) pay two costs, calibrated
  apart: the irradiance cache's build, once per render, timed on its own (64 px wide, the sequence's estimates per
  point) and scaled by ``cache_probes`` × the probe rays per view × ``cache_samples`` relative to the calibration's (:meth:`SceneRenderCost.
  cache_build_seconds`); and each keyframe's (camera rays, glossy chain, cache lookups), timed after the build
  with the cache already on disk, at the sequence's width up to 256 px and 16 and 64 camera rays, fitted as
  above. Their noise probe is
  three converged keyframes (keyframe 0 with the next seed and from each half of the cache). Converged renders
  share no keyframes across speeds (:func:`simspad.dataset.plan.shares_keyframes`), and the plan's layouts say so.
- **Simulation time**: one throughput probe of the ground truth and of each of the spec's sensors on a small
  render, measured at two durations so imports, JIT and file creation drop out (marginal costs), scaled by each
  sensor's work units from its sensor-table row (:meth:`~simspad.sensors.registry.Sensor.work_units`: Gbit of
  SPAD data, megapixel-frames, megapixel-seconds of events; megapixel-rows or -seconds for a row without a cost
  model of its own); plus a per-recording fixed part (the all-sensor probe minus its units at the marginal
  costs). The probe's pixels are repeated up to 4 × 4 towards the spec's width (:data:`PROBE_MAX_UPSAMPLE`): costs per row, per kernel call and per keyframe then weigh per pixel as
  they do at full size (64 × 48 px put them at 3–6× the cost per pixel of 256² and 512² recordings).
- **Disk**: the probe files' bytes per unit (the same marginal fit, so compression counts) and per recording;
  renders from the calibration EXRs' bytes per pixel.
- **Peak memory** per worker: the kernel's peak-RSS counter (``VmHWM``, reset through ``/proc/self/clear_refs``)
  around the calibration renders (growth between the two sample counts, scaled by pixels·spp) and the probe
  (scaled by pixels: a simulation streams in time), on top of the calibrating process's own peak.

:func:`measure_unit_costs` takes ~1 min on 2 cores for three scenes; :func:`estimate_spec` turns the costs into
the figures of one spec.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import stat
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import h5py
import numpy as np

from simspad.dataset.directory import recording_rel_path
from simspad.dataset.executors import (
    default_workers,
    job_environment,
    render_layout_of,
)
from simspad.dataset.plan import make_plan
from simspad.io.exr import LUMINANCE_CHANNEL, OBJECT_ID_CHANNEL, read_exr, write_exr
from simspad.io.geometry import GEOMETRY_BYTES_PER_PX, read_geometry, write_geometry
from simspad.io.render_dir import TIMELINE_FILE, write_timeline_json
from simspad.physics.radiometry import Optics
from simspad.render.converged import cache_block, converged_renderer, layout_convergence, probe_grid
from simspad.render.keyframe_files import make_out_dir
from simspad.render.mitsuba_env import CUDA_VARIANT, cuda_device_name, select_variant
from simspad.render.render_layout import chunk_size_for
from simspad.render.renderer import (
    load_scene,
    layout_render,
    render_keyframes,
    render_sequence,
)
from simspad.render.settings import RenderSettings
from simspad.scenes.library import resolve_scene
from simspad.sensors.recording_size import recording_bytes, recording_samples
from simspad.sensors.registry import ordered
from simspad.sensors.simulate import RecordingSettings, simulate_recording

#: Calibration render: width (px), keyframes timed per sample count (after one untimed keyframe that compiles
#: the kernels), the two sample counts whose difference separates the per-sample cost from the fixed one, and the
#: span (s) of the trajectory the keyframes are taken from.
CALIBRATION_WIDTH_PX = 64
CALIBRATION_KEYFRAMES = 2
CALIBRATION_SPP = (4, 64)  # powers of four: the stratified (multi-jittered) sampler, as renders at these counts
CALIBRATION_SPAN_S = 0.02
#: Converged calibration: its keyframes at this width and these camera-ray counts, from a cache of
#: :data:`CALIBRATION_CACHE_SAMPLES` estimates per point (its build with the sequence's estimates is timed apart,
#: at :data:`CALIBRATION_WIDTH_PX`). At 64 px and 4 rays a converged keyframe's fixed cost (kernel launches, the coarse levels'
#: lookups) hid its slope: a fit gave one scene 0 s per MP·spp and another more than path tracing; at 128 px the
#: office's fit (0.11 s per MP·spp) put a 512×512, 16-ray keyframe at 0.7 CPU-s where it takes 1.6 (a keyframe's
#: lanes fill a tile of 2²⁰ only from 256 px on, and its arrays outgrow the CPU's caches). A narrower sequence is
#: calibrated at its own width.
CONVERGED_CALIBRATION_WIDTH_PX = 256
CONVERGED_CALIBRATION_SPP = (16, 64)
CALIBRATION_CACHE_SAMPLES = 64
#: Throughput probe: size (px) and the two simulated durations (s) whose difference gives marginal costs. 40 ms
#: between them: with 16 ms, an event camera's marginal cost on 64 × 48 px (~30 ms of CPU) was within the noise of
#: the process's CPU time and came out as ≈ 0 in one estimate of five.
PROBE_SIZE_PX = (64, 48)
PROBE_DURATIONS_S = (0.01, 0.05)
#: Largest factor the probe render's pixels are repeated by (each way) towards the spec's widest sequence: 4 gives
#: 256 × 192 px, where the simulators' costs per pixel are within ~10 % of 512 × 512's, for ~10 s more probing.
PROBE_MAX_UPSAMPLE = 4
MIB = 1024**2


def _vm_hwm_bytes() -> int | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _vm_rss_bytes() -> int | None:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _reset_peak_rss() -> bool:
    """Reset the kernel's peak-RSS counter of this process (Linux ≥ 4.0); False where that is not possible."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


class _PeakRss:
    """Peak RSS above the current RSS while the ``with`` block runs (bytes; None where unmeasurable)."""

    def __enter__(self):
        self.ok = _reset_peak_rss()
        self.base = _vm_rss_bytes()
        self.bytes = None
        return self

    def __exit__(self, *exc):
        peak = _vm_hwm_bytes()
        if self.ok and peak is not None and self.base is not None:
            self.bytes = max(peak - self.base, 0)


def _probe_mrays(width: int, height: int, fields: dict) -> float:
    """Millions of probe rays per view of a converged render (``fields``: its ``renderer.convergence``)."""
    columns, rows = probe_grid(width, height, cache_block(width, fields.get("cache_width_px", width)))
    return columns * rows / 1e6


@dataclass
class SceneRenderCost:
    """Measured render cost of one scene, one thread: ``a_s + b_s·(MP·spp)`` per keyframe."""

    a_s: float
    b_s: float
    exr_bytes_per_px: float
    rss_bytes_per_mp_spp: float | None  # peak-RSS growth with the sample wavefront
    process_rss_bytes: int | None  # peak RSS of the calibrating process (imports, scene, renders)
    load_s: float = 0.0  # CPU seconds to load the scene (once per chunk of keyframes)
    #: Converged renders only: seconds of one irradiance-cache build in the calibration, and its size there
    #: (probe rays per view in millions × cache_probes × cache_samples: the irradiance estimates it makes, per
    #: million)
    cache_build_s: float = 0.0
    cache_build_units: float = 0.0

    def seconds_per_keyframe(self, megapixels: float, spp: int) -> float:
        return self.a_s + self.b_s * megapixels * spp

    def cache_build_seconds(self, probe_mrays: float, cache_probes: int, cache_samples: int) -> float:
        """Seconds of one cache build whose probe views trace ``probe_mrays`` million rays each (0 for a
        path-traced calibration): the calibration's build scaled by the estimates it makes (each vertex a probe
        ray finds is given ``cache_samples`` irradiance estimates)."""
        if self.cache_build_units <= 0:
            return 0.0
        return self.cache_build_s * probe_mrays * cache_probes * cache_samples / self.cache_build_units


@dataclass
class UnitCosts:
    """Measured unit costs on this machine (one core each)."""

    render: dict = field(default_factory=dict)  # scene name -> SceneRenderCost (path tracing)
    converged: dict = field(default_factory=dict)  # scene name -> SceneRenderCost of its converged renders
    gt_s_per_mp_frame: float = 0.0
    #: seconds and bytes per work unit of each sensor (its table row's ``work_units``: spad per Gbit, frames per
    #: MP·frame, events per MP·s, a row without a cost model per MP·row or MP·s)
    sim_s_per: dict = field(default_factory=dict)
    bytes_per: dict = field(default_factory=dict)  # also "gt": bytes per MP·frame
    sim_unit: dict = field(default_factory=dict)  # kind -> the name of its work unit
    recording_fixed_s: float = 0.0  # per recording, beyond the per-unit costs
    recording_fixed_bytes: float = 0.0
    sim_rss_bytes_per_mp: float | None = None  # peak-RSS growth of a simulation with its pixel count
    sim_process_rss_bytes: int | None = None  # peak RSS of the probing process (imports, numba, buffers)
    sim_probe_px: tuple[int, int] | None = None  # (width, height) the simulations were probed at
    calibration_s: float = 0.0
    #: Where renders run: None for CPU cores (render costs per core), else the GPU's name (costs on that GPU)
    render_gpu: str | None = None
    render_variant: str = ""


def _settings(seq, resolution, duration_s, spp, converged: bool = False) -> RenderSettings:
    """``seq``'s render settings at a probe's size, span and samples, seed 1, every keyframe rendered (linear):
    the unit costs are per rendered keyframe. Path-traced unless ``converged`` (then ``seq``'s cache settings)."""
    settings = replace(seq.render_settings(seed=1), resolution=tuple(resolution), duration_s=duration_s, spp=spp,
                       interpolation="linear")
    if converged:
        return replace(settings, cache_samples=min(settings.cache_samples, CALIBRATION_CACHE_SAMPLES))
    return replace(settings, convergence="off")


def _calibrate_scene(seq, tmp: Path, gpu: str | None = None, converged: bool = False) -> SceneRenderCost:
    """Time :data:`CALIBRATION_KEYFRAMES` keyframes of ``seq``'s scene along its trajectory at two sample counts
    (one scene load): on one CPU thread, or on the GPU ``gpu`` (its name) when the variant renders there.

    ``converged``: with an irradiance cache of ``seq``'s probe views (of :data:`CALIBRATION_CACHE_SAMPLES`
    estimates: a keyframe's cost does not depend on them), at ``seq``'s width up to
    :data:`CONVERGED_CALIBRATION_WIDTH_PX`; the keyframes are timed after its build, with the cache on disk as a
    render's later chunks find it. The build with ``seq``'s own estimates is timed apart
    (:func:`_time_cache_build`)."""
    import drjit as dr  # deferred: heavy; the variant is already set

    on_gpu = gpu is not None
    if not on_gpu:
        dr.set_thread_count(1)  # per-core cost: workers render with one thread each
    # CPU time on the CPU (a busy machine must not inflate the unit cost); wall time on a GPU, which renders while
    # the calling thread waits (the EXR write reads the image back, so each render has finished when it returns)
    clock = time.perf_counter if on_gpu else time.process_time
    # a converged keyframe's fixed part grows with its pixels (camera samples, blur, file), which a + b·MP·spp
    # cannot tell apart from a constant: calibrated at the sequence's own width up to 256 px
    w = min(CONVERGED_CALIBRATION_WIDTH_PX, int(seq.resolution[0])) if converged else CALIBRATION_WIDTH_PX
    spps = CONVERGED_CALIBRATION_SPP if converged else CALIBRATION_SPP
    h = max(1, round(w * seq.resolution[1] / seq.resolution[0]))
    span_s = min(seq.duration_s, CALIBRATION_SPAN_S)
    cpu0 = time.process_time()
    loaded = load_scene(seq.scene, seq.trajectory, w, h, spps[0])
    load_s = time.process_time() - cpu0  # every chunk of keyframes loads the scene once
    points, exr, rss, build, cache = [], [], [], (0.0, 0.0), None
    for spp in spps:
        loaded.ms.spp = spp  # mi.render takes the sample count per call; same scene, same film
        plan = layout_render(seq.scene, seq.trajectory, _settings(seq, (w, h), span_s, spp, converged),
                             loaded=loaded)
        picks = sorted({int(round(i)) for i in np.linspace(0, plan.n_keyframes - 1, CALIBRATION_KEYFRAMES + 1)})
        out = tmp / (f"cal-{spp}" if not converged else f"cal-{resolve_scene(seq.scene).name}-{spp}-cache")
        fields = layout_convergence(plan)
        if fields is not None:
            make_out_dir(out)
            if cache is not None:  # the same cache (probe rays do not depend on the camera rays): built once
                shutil.copy2(cache, out / fields["cache_file"])
            converged_renderer(plan, loaded.ms, loaded.ts, out)  # builds the cache (or reads it) into ``out``
            cache = out / fields["cache_file"]
            (out / "t").mkdir(parents=True, exist_ok=True)
            shutil.copy2(out / fields["cache_file"], out / "t" / fields["cache_file"])  # the timed keyframes' too
        render_keyframes(seq.scene, seq.trajectory, plan, picks[:1], out_dir=out, loaded=loaded)  # kernels
        timed = picks[1:] or picks[:1]
        with _PeakRss() as peak:
            cpu0 = clock()
            render_keyframes(seq.scene, seq.trajectory, plan, timed, out_dir=out / "t", loaded=loaded)
            points.append((w * h / 1e6 * spp, (clock() - cpu0) / len(timed)))
        exr.append(np.mean([(out / "t" / plan.names[i]).stat().st_size for i in timed]) / (w * h))
        rss.append(peak.bytes)
    if converged:
        build = _time_cache_build(seq, tmp, span_s, clock)
    if not on_gpu:
        dr.set_thread_count(default_workers())
    (x1, y1), (x2, y2) = points
    b = max((y2 - y1) / (x2 - x1), 0.0)
    a = max(y1 - b * x1, 0.0)
    slope = None if None in rss else max(rss[1] - rss[0], 0) / (x2 - x1)
    return SceneRenderCost(a_s=a, b_s=b, exr_bytes_per_px=float(np.mean(exr)), rss_bytes_per_mp_spp=slope,
                           process_rss_bytes=_vm_hwm_bytes(), load_s=load_s, cache_build_s=build[0],
                           cache_build_units=build[1])


def _time_cache_build(seq, tmp: Path, span_s: float, clock) -> tuple[float, float]:
    """(seconds, size) of one build of ``seq``'s irradiance cache with its own estimates per point, at the
    path-traced calibration's width (a build's cost is its estimates, whatever the image size; one from 64 estimates
    scaled ×16 overstated a 1024-estimate build 1.45×: its tracing and gathering do not scale). A build of 64
    estimates first compiles the kernels at this film size."""
    w = CALIBRATION_WIDTH_PX
    h = max(1, round(w * seq.resolution[1] / seq.resolution[0]))
    loaded = load_scene(seq.scene, seq.trajectory, w, h, CONVERGED_CALIBRATION_SPP[0])
    settings = _settings(seq, (w, h), span_s, CONVERGED_CALIBRATION_SPP[0], converged=True)
    name = resolve_scene(seq.scene).name
    for k, samples in enumerate((settings.cache_samples, seq.cache_samples)):
        plan = layout_render(seq.scene, seq.trajectory, replace(settings, cache_samples=samples), loaded=loaded)
        fields = layout_convergence(plan)
        out = tmp / f"cal-{name}-build-{k}"
        make_out_dir(out)
        cpu0 = clock()
        converged_renderer(plan, loaded.ms, loaded.ts, out)
        seconds = clock() - cpu0
    return seconds, _probe_mrays(w, h, fields) * fields["cache_probes"] * fields["cache_samples"]


def _probe_simulation(spec, seq, tmp: Path, costs: UnitCosts) -> None:
    """Marginal simulation costs of the spec's sensors on a small render of ``seq``."""

    w, h = PROBE_SIZE_PX
    half, full = PROBE_DURATIONS_S
    rdir = tmp / "probe-render"
    render_sequence(seq.scene, seq.trajectory, _settings(seq, (w, h), full, 4), out_dir=rdir, progress=False)
    widest = max(s.resolution[0] for s in spec.sequences)
    factor = int(np.clip(round(widest / w), 1, PROBE_MAX_UPSAMPLE))
    if factor > 1:
        rdir = upsample_render_dir(rdir, tmp / "probe-render-upsampled", factor)
        w, h = w * factor, h * factor
    mp = w * h / 1e6
    costs.sim_probe_px = (w, h)
    params = {k: s.params for k, s in spec.sensors.items()}
    lux = float(np.median(spec.lux))
    gt_rate_hz = spec.evaluation.rate_hz

    def run(kinds, duration_s):
        out = tmp / f"probe-{'-'.join(kinds) or 'gt'}-{duration_s}.h5"
        settings = RecordingSettings(lux=lux, sensors={k: params[k] for k in kinds}, start_s=seq.start_s,
                                     duration_s=duration_s, seed=1, stream_key=("estimate", lux),
                                     gt_rate_hz=gt_rate_hz, optics=Optics())
        cpu0 = time.process_time()  # CPU time: simulations are single-threaded, and the machine may be busy
        simulate_recording(rdir, out, settings, metadata={"created_utc": "2025-01-01T00:00:00Z"}, progress=False)
        return time.process_time() - cpu0, out

    run(list(params), half)  # imports and JIT compilation, untimed
    with _PeakRss() as peak:
        t_all, p_all = run(list(params), full)
    if peak.bytes is not None:
        costs.sim_rss_bytes_per_mp = peak.bytes / mp
    # the process before the probe (imports, numba, what the calibration renders left): the probe's own growth is
    # the per-pixel part above, and the high-water mark after it would count that growth twice
    costs.sim_process_rss_bytes = peak.base if peak.base is not None else _vm_hwm_bytes()
    gt = [run([], d) for d in (half, full)]
    gt_marginal = max(gt[1][0] - gt[0][0], 0.0)
    gt_bytes = gt[1][1].stat().st_size - gt[0][1].stat().st_size
    gt_units = mp * (full - half) * gt_rate_hz
    costs.gt_s_per_mp_frame = max(gt_marginal, 1e-9) / gt_units
    # bytes per *stored* frame: a probe's last chunk holds whole chunks' room for its few frames (25 frames take
    # 32 frames' bytes), which would inflate a full-size recording's ground truth by up to half
    stored = [_gt_stored_frames(p) for _, p in gt]
    costs.bytes_per["gt"] = max(gt_bytes, 0) / (mp * max(stored[1] - stored[0], 1))
    for row, kind_params in ordered(params):
        kind = row.name
        (t1, p1), (t2, p2) = run([kind], half), run([kind], full)
        dt = max(t2 - t1 - gt_marginal, 1e-9)
        db = max(p2.stat().st_size - p1.stat().st_size - gt_bytes, 0)
        units = row.work_units(kind_params, w, h, full) - row.work_units(kind_params, w, h, half)
        if units <= 0:  # no unit between the two durations (no frame boundary): the whole run's average instead
            units, dt, db = row.work_units(kind_params, w, h, full), max(t2 - gt[1][0], 1e-9), max(
                p2.stat().st_size - gt[1][1].stat().st_size, 0)
        if units <= 0:  # nothing of this sensor in the probe (e.g. no frame in its span): no figure to scale
            continue
        costs.sim_s_per[kind] = dt / units
        costs.bytes_per[kind] = db / units
        costs.sim_unit[kind] = row.work_unit
    # What a recording costs beyond its per-unit parts (file creation, attributes, poses, reading the render):
    # the all-sensor probe minus its units at the marginal costs.
    units_full = {row.name: row.work_units(kind_params, w, h, full) for row, kind_params in ordered(params)}
    gt_full = mp * _gt_stored_frames(p_all)
    costs.recording_fixed_s = max(t_all - costs.gt_s_per_mp_frame * gt_full - sum(
        costs.sim_s_per.get(k, 0.0) * u for k, u in units_full.items()), 0.0)
    costs.recording_fixed_bytes = max(p_all.stat().st_size - costs.bytes_per["gt"] * gt_full - sum(
        costs.bytes_per.get(k, 0.0) * u for k, u in units_full.items()), 0.0)


def upsample_render_dir(src: Path, dst: Path, factor: int) -> Path:
    """A copy of render directory ``src`` in ``dst`` with every pixel of every channel repeated ``factor`` ×
    ``factor`` times (same instants, poses and metadata): a larger render of the same content, for timing."""
    meta = json.loads((Path(src) / TIMELINE_FILE).read_text())
    names = {"r": "R", "g": "G", "b": "B", "y": LUMINANCE_CHANNEL, "z": "Z", "object_id": OBJECT_ID_CHANNEL}

    def up(a):
        return np.repeat(np.repeat(a, factor, 0), factor, 1)

    # the keyframes, the render-noise budget's probe (a recording states the budget from it) and the geometry
    # passes at the ground-truth instants
    probe = meta.get("render_noise", {}).get("probe_file")
    for rel in [kf["file"] for kf in meta["keyframes"]] + ([probe] if probe else []):
        data = read_exr(Path(src) / rel, rgb_planes=True)
        write_exr(Path(dst) / rel, {names[k]: up(a) for k, a in data.items()})
    for instant in meta.get("geometry", {}).get("instants", ()):
        depth_z, instance = read_geometry(Path(src) / instant["file"], meta["width"], meta["height"])
        (Path(dst) / instant["file"]).parent.mkdir(parents=True, exist_ok=True)
        write_geometry(Path(dst) / instant["file"], up(depth_z), up(instance))
    meta.update(width=meta["width"] * factor, height=meta["height"] * factor)
    write_timeline_json(dst, **meta)
    return Path(dst)


def _gt_stored_frames(path: Path) -> int:
    """Frames of ``/gt/flux`` that the file's chunks have room for (its frames rounded up to whole chunks)."""
    with h5py.File(path, "r") as f:  # the probe's own file: its HDF5 chunk layout, which no recording view shows
        ds = f["gt/flux"]
        rows = ds.chunks[0]
        return -(-ds.shape[0] // rows) * rows


def measure_unit_costs(spec, log=lambda msg: None) -> UnitCosts:
    """Calibrate render costs for every scene of ``spec`` and probe its sensors' simulation costs (≈ 1 min)."""

    for key, value in job_environment().items():
        os.environ.setdefault(key, value)
    variant = select_variant()
    t0 = time.perf_counter()
    costs = UnitCosts(render_variant=variant, render_gpu=(cuda_device_name() or "CUDA device")
                      if variant == CUDA_VARIANT else None)
    tmp = Path(tempfile.mkdtemp(prefix="simspad-estimate-"))
    try:
        for seq in spec.sequences:
            name = resolve_scene(seq.scene).name
            if name not in costs.render:
                where = f" on the GPU ({costs.render_gpu})" if costs.render_gpu else ""
                log(f"calibrating renders of {name}{where}")
                costs.render[name] = _calibrate_scene(seq, tmp, costs.render_gpu)
            if seq.convergence != "off" and name not in costs.converged:
                log(f"calibrating converged renders of {name} (irradiance cache, {seq.cache_samples} estimates "
                    "per point)")
                costs.converged[name] = _calibrate_scene(seq, tmp, costs.render_gpu, converged=True)
        log("probing simulation throughput")
        _probe_simulation(spec, spec.sequences[0], tmp, costs)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    costs.calibration_s = time.perf_counter() - t0
    return costs


@dataclass
class Estimate:
    """What a spec will cost on this machine (from :class:`UnitCosts`)."""

    n_renders: int
    n_keyframes: int
    n_recordings: int
    render_cpu_s: float
    sim_cpu_s: float
    longest_sim_s: float
    largest_render_cpu_s: float
    keyframe_s: list  # (seconds per keyframe on one core, keyframes) of each render
    scene_load_s: list  # (seconds to load the scene, keyframes) of each render: paid once per chunk
    disk_bytes: int
    recordings_bytes: int
    renders_bytes: int
    peak_render_rss_bytes: float | None
    peak_sim_rss_bytes: float | None
    cores: int
    plan_s: float
    n_warp_keyframes: int = 0  # keyframes of renders with warp interpolation (costed as if all were rendered)
    n_shared_keyframes: int = 0  # keyframes a faster render shares with a slower one (linked, not counted)
    n_noise_probes: int = 0  # one extra keyframe render per render (the render-noise budget), in render_cpu_s
    n_converged_renders: int = 0  # renders with an irradiance cache (convergence "cache")
    cache_build_s: float = 0.0  # their caches' builds (one per render), in render_cpu_s
    converged_keyframe_s: float = 0.0  # their keyframes after the build, in render_cpu_s
    #: None: renders run on CPU cores (``render_cpu_s`` is CPU-seconds); else the GPU's name (``render_cpu_s`` is
    #: seconds of that GPU, one render at a time per GPU)
    render_gpu: str | None = None

    @property
    def cpu_s(self) -> float:
        return self.render_cpu_s + self.sim_cpu_s

    def wall_s(self, workers: int, gpus: int = 1) -> float:
        """Wall time on ``workers`` single-core workers: renders in chunks of keyframes over all of them (at
        worst one chunk's time after the last), then the simulations (at best the longest one).

        With renders on a GPU (:attr:`render_gpu`), the renders share ``gpus`` such GPUs instead of the workers
        (a GPU renders one keyframe at a time, whatever the number of processes feeding it), and the
        simulations run on the workers' cores."""
        if self.render_gpu is not None:
            per_gpu = max(int(gpus), 1)
            chunk_tail = max((s * chunk_size_for(n, per_gpu) for s, n in self.keyframe_s), default=0.0)
            loads = sum(load * math.ceil(n / chunk_size_for(n, per_gpu)) for load, n in self.scene_load_s)
            render = (self.render_cpu_s + loads) / per_gpu + (chunk_tail if per_gpu > 1 else 0.0)
        else:
            chunk_tail = max((s * chunk_size_for(n, workers) for s, n in self.keyframe_s), default=0.0)
            loads = sum(load * math.ceil(n / chunk_size_for(n, workers)) for load, n in self.scene_load_s)
            render = (self.render_cpu_s + loads) / workers + chunk_tail
        render = render if self.render_cpu_s else 0.0
        sims = max(self.sim_cpu_s / workers, self.longest_sim_s)
        return render + sims

    def peak_memory_bytes(self, workers: int) -> float | None:
        """Peak resident memory of ``workers`` processes at once (each the larger of a render and a simulation)."""
        per = [b for b in (self.peak_render_rss_bytes, self.peak_sim_rss_bytes) if b is not None]
        return workers * max(per) if per else None


def estimate_spec(spec, costs: UnitCosts) -> Estimate:
    """Exact keyframe counts (each render planned at full size) and sizes, with ``costs`` for time and memory."""

    t0 = time.perf_counter()
    plan = make_plan(spec, "1970-01-01T00:00:00Z")
    keyframe_s, scene_load_s, render_cpu, renders_bytes, largest, render_rss = [], [], 0.0, 0, 0.0, None
    size_of, n_warp, n_shared, planned = {}, 0, 0, {}
    n_converged, build_cpu, converged_kf_cpu = 0, 0.0, 0.0
    for r in plan.renders:
        seq = r.sequence
        # Retimed (a render at speed ×k plays its trajectory k times faster); keyframes shared with the slower
        # render are linked, not rendered, and take no disk.
        rp = planned[r.rel_dir] = render_layout_of(r, planned)
        n = rp.n_keyframes - rp.n_shared
        n_shared += rp.n_shared
        name = resolve_scene(seq.scene).name
        cost = traced = costs.render[name]
        w, h = seq.resolution
        fields = layout_convergence(rp)
        build = 0.0
        if fields is not None:  # the cache's build once per render, then every keyframe at its cost after it
            cost = costs.converged[name]
            build = cost.cache_build_seconds(_probe_mrays(w, h, fields), fields["cache_probes"], fields["cache_samples"])
        per_kf = cost.seconds_per_keyframe(w * h / 1e6, seq.spp)
        keyframe_s.append((per_kf, n))
        scene_load_s.append((cost.load_s, n))
        if rp.warp is not None:
            n_warp += n
        # and its noise probe (the render-noise budget): keyframe 0 once more, path-traced; a converged render's is
        # keyframe 0 from the same cache with the next seed and from each half of the cache
        probe = 3 * per_kf if fields is not None else traced.seconds_per_keyframe(w * h / 1e6, seq.spp)
        this = build + per_kf * n + probe
        if fields is not None:
            n_converged += 1
            build_cpu += build
            converged_kf_cpu += per_kf * n
        render_cpu += this
        largest = max(largest, this)
        renders_bytes += int(cost.exr_bytes_per_px * w * h * (n + 1))
        # the geometry passes at the ground-truth instants (uncompressed float32 depth + uint16 instance per pixel)
        renders_bytes += GEOMETRY_BYTES_PER_PX * w * h * len(rp.timeline.get("geometry", {}).get("instants", ()))
        if cost.rss_bytes_per_mp_spp is not None and cost.process_rss_bytes is not None:
            render_rss = max(render_rss or 0.0,
                             cost.process_rss_bytes + cost.rss_bytes_per_mp_spp * w * h / 1e6 * seq.spp)
        size_of[r.rel_dir] = (w, h)
    plan_s = time.perf_counter() - t0
    sensors = ordered({kind: sensor.params for kind, sensor in spec.sensors.items()})
    sim_cpu, longest, rec_bytes, sim_rss = 0.0, 0.0, 0.0, None
    for rec in plan.recordings:
        w, h = size_of[rec.render_rel_dir]
        mp = w * h / 1e6
        duration_s = rec.settings.duration_s
        gt_units = mp * duration_s * rec.settings.gt_rate_hz
        t = costs.recording_fixed_s + costs.gt_s_per_mp_frame * gt_units
        b = costs.recording_fixed_bytes + costs.bytes_per.get("gt", 0.0) * gt_units
        for row, params in sensors:
            u = row.work_units(params, w, h, duration_s)
            t += costs.sim_s_per.get(row.name, 0.0) * u
            b += costs.bytes_per.get(row.name, 0.0) * u
        sim_cpu += t
        longest = max(longest, t)
        rec_bytes += b
        if costs.sim_rss_bytes_per_mp is not None and costs.sim_process_rss_bytes is not None:
            sim_rss = max(sim_rss or 0.0, costs.sim_process_rss_bytes + costs.sim_rss_bytes_per_mp * mp)
    return Estimate(n_renders=len(plan.renders), n_keyframes=sum(n for _, n in keyframe_s),
                    n_recordings=len(plan.recordings), render_cpu_s=render_cpu, sim_cpu_s=sim_cpu,
                    longest_sim_s=longest, largest_render_cpu_s=largest, keyframe_s=keyframe_s,
                    scene_load_s=scene_load_s,
                    disk_bytes=int(rec_bytes) + renders_bytes, recordings_bytes=int(rec_bytes),
                    renders_bytes=renders_bytes, peak_render_rss_bytes=render_rss, peak_sim_rss_bytes=sim_rss,
                    cores=default_workers(), plan_s=plan_s, n_warp_keyframes=n_warp,
                    n_shared_keyframes=n_shared, n_noise_probes=len(plan.renders), render_gpu=costs.render_gpu,
                    n_converged_renders=n_converged, cache_build_s=build_cpu, converged_keyframe_s=converged_kf_cpu)


def free_disk_bytes(path) -> int:
    """Free bytes on the file system that will hold ``path`` (its nearest existing ancestor)."""
    p = Path(path).expanduser().resolve()
    while not p.exists():
        p = p.parent
    return shutil.disk_usage(p).free


def total_memory_bytes() -> int | None:
    """Physical memory of this machine (bytes), None where unknown."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def format_estimate(est: Estimate, costs: UnitCosts, *, workers: int, cluster_workers=(16, 64, 256),
                    free_bytes: int | None = None) -> str:
    """The estimate as printed by ``simspad generate --estimate`` (and ``benchmarks/bench_generate.py``)."""
    def hours(s):
        return f"{s / 3600:.2f} h" if s >= 3600 else f"{s / 60:.1f} min" if s >= 60 else f"{s:.0f} s"

    def size(b):
        return f"{b / 1024**3:.2f} GiB" if b >= 1024**3 else f"{b / MIB:.1f} MiB"

    lines = [f"estimate (unit costs measured here in {costs.calibration_s:.0f} s, keyframes planned in "
             f"{est.plan_s:.0f} s):",
             f"  renders      {est.n_renders} sequence(s), {est.n_keyframes} keyframes, "
             + (f"{est.render_cpu_s / 3600:.2f} GPU-h on {est.render_gpu} ({costs.render_variant}, measured on it)"
                if est.render_gpu else f"{est.render_cpu_s / 3600:.2f} CPU-h"),
             *([f"               and {est.n_noise_probes} noise probes (one keyframe per render, three per "
                f"converged one: the render-noise budget), counted in that time"] if est.n_noise_probes else []),
             *([f"               {est.n_warp_keyframes} of them in warp renders, costed as if each were "
                f"rendered: an upper bound (how many a warp render renders depends on where its warps agree)"]
               if est.n_warp_keyframes else []),
             *([f"               plus {est.n_shared_keyframes} keyframes the faster speeds share with the slower "
                f"ones (the same poses: linked, not rendered)"] if est.n_shared_keyframes else []),
             *([f"               {est.n_converged_renders} converged render(s) (irradiance cache): cache builds "
                f"{hours(est.cache_build_s)} (one per render, × its probe rays × cache_probes × cache_samples), "
                f"their keyframes {hours(est.converged_keyframe_s)} after the build"] if est.n_converged_renders else []),
             f"  simulations  {est.n_recordings} recording(s), {est.sim_cpu_s / 3600:.2f} CPU-h (longest "
             f"{hours(est.longest_sim_s)})",
             (f"  total        {est.render_cpu_s / 3600:.2f} GPU-h + {est.sim_cpu_s / 3600:.2f} CPU-h"
              if est.render_gpu else f"  total        {est.cpu_s / 3600:.2f} CPU-h"),
             _here_line(est, workers, hours)]
    for n in cluster_workers:
        if est.render_gpu:
            lines.append(f"               {hours(est.wall_s(n, gpus=n))} on {n} workers with one {est.render_gpu} "
                         f"each (one core each for the simulations, this machine's speed)")
        else:
            lines.append(f"               {hours(est.wall_s(n))} on {n} workers (one core each, this machine's "
                         f"speed)")
    disk = f"  disk         {size(est.disk_bytes)} (recordings {size(est.recordings_bytes)}, renders " \
           f"{size(est.renders_bytes)})"
    if free_bytes is not None:
        disk += f"; {size(free_bytes)} free"
    lines.append(disk)
    peak = est.peak_memory_bytes(workers)
    if peak is not None:
        per = max(b for b in (est.peak_render_rss_bytes, est.peak_sim_rss_bytes) if b is not None)
        total = total_memory_bytes()
        lines.append(f"  peak memory  {size(peak)} ({workers} worker(s) × {size(per)})"
                     + (f"; this machine has {size(total)}" if total else ""))
    lines.append(f"  unit costs   render s/keyframe ({'the GPU' if est.render_gpu else 'one core'}): " + ", ".join(
        f"{name} {c.a_s * 1e3:.0f} ms + {c.b_s:.3g} s per MP·spp (scene load {c.load_s:.1f} s per chunk)"
        for name, c in costs.render.items()))
    if costs.converged:
        lines.append("               converged: " + ", ".join(
            f"{name} {c.a_s * 1e3:.0f} ms + {c.b_s:.3g} s per MP·spp after a cache build of "
            f"{c.cache_build_s / max(c.cache_build_units, 1e-12):.3g} s per MP·probe·estimate"
            for name, c in costs.converged.items()))
    sim = [f"{k} {v:.3g} s/{costs.sim_unit.get(k, 'unit')}" for k, v in costs.sim_s_per.items()]
    probed = f" (probed at {costs.sim_probe_px[0]}×{costs.sim_probe_px[1]} px)" if costs.sim_probe_px else ""
    lines.append("               " + ", ".join(sim + [f"gt {costs.gt_s_per_mp_frame:.3g} s/MP·frame"]) + probed)
    return "\n".join(lines)


def _here_line(est: Estimate, workers: int, hours) -> str:
    """The wall time here: ``workers`` processes share this machine's cores, so more workers than cores run no
    faster than one per core (the estimate's unit costs are one core's)."""
    cores = default_workers()
    gpu = f", renders on one {est.render_gpu}" if est.render_gpu else ""
    if workers <= cores:
        return f"  wall time    {hours(est.wall_s(workers))} here ({workers} worker(s){gpu})"
    return (f"  wall time    {hours(est.wall_s(cores))} here ({workers} workers asked, but this machine has {cores} "
            f"core(s): {workers} workers run no faster than {cores}{gpu})")


def disk_needed_bytes(spec, out_dir) -> int:
    """An upper bound of the bytes that the SPAD bits, frames and ground truth of the recordings of ``spec`` not yet
    in ``out_dir`` will take, from sizes alone (no measurement): uncompressed, as
    :func:`~simspad.sensors.recording_size.recording_bytes` counts them before each recording (a filter only shrinks
    them). Events and renders are left out (they need :func:`measure_unit_costs`). ``generate`` checks this bound
    first and measures the estimate only when the bound does not fit the free disk with room to spare."""

    params = {name: sensor.params for name, sensor in spec.sensors.items()}
    total = 0.0
    for seq in spec.sequences:
        w, h = seq.resolution
        per = recording_bytes(recording_samples(params, seq.duration_s, spec.evaluation.rate_hz), w, h)
        for k in spec.speed:  # every speed factor is a recording of its own
            for lux in spec.lux:
                if not (Path(out_dir) / recording_rel_path(seq.name, lux, k)).is_file():
                    total += per
    return int(total)


def dataset_bytes_on_disk(out_dir) -> int:
    """Bytes the recordings and renders already in ``out_dir`` take (hard-linked keyframes counted once)."""
    seen, total = set(), 0
    for sub in ("recordings", "renders"):
        root = Path(out_dir) / sub
        if not root.is_dir():
            continue
        for path in root.rglob("*"):
            try:
                st = path.lstat()
            except OSError:
                continue
            if stat.S_ISREG(st.st_mode) and (st.st_dev, st.st_ino) not in seen:
                seen.add((st.st_dev, st.st_ino))
                total += st.st_size
    return total
