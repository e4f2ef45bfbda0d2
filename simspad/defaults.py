"""Defaults shared by the CLI, the dataset spec and the library functions: each value is named once here.

Units are in the names. Sensor defaults are the presets in :mod:`simspad.sensors.presets`; method defaults
live with each method. The rules of the values that records of different layers carry (the seed, checked by
:func:`seed_problem`, a duration, by :func:`duration_problem`, and the ground-truth rate, by
:func:`gt_rate_problem`) are here too, beside their defaults, so that the renderer's and the sensors' records,
the dataset spec and the CLI give one message for each.
"""

import math
import numbers

#: Render resolution (width, height) in pixels.
RESOLUTION_PX = (128, 96)
#: Monte Carlo samples per pixel of a path-traced render (``convergence = "off"``).
SPP = 16
#: Camera rays per pixel of a converged render (``simspad render`` with no quality flag): 64 below
#: :data:`FEW_CAMERA_RAYS_FROM_PX` wide, :data:`FEW_CAMERA_RAYS` from there (:func:`camera_rays`). The rays average
#: texture, cached light and glossy chains over a pixel's footprint, so their noise falls as pixels shrink: 16 rays
#: leave the office and plant 3.5-4.0 % off a 4096-spp pair at 48×36 px (64: 2.9-3.0 %), but 1.8-2.7 % at 256 px
#: and 2.1 % at 512 px (office, plant, piano; docs/rendering.md, fifth round).
CAMERA_RAYS = 64
FEW_CAMERA_RAYS = 16
FEW_CAMERA_RAYS_FROM_PX = 256


def camera_rays(width: int) -> int:
    """Default camera rays per pixel of a converged render ``width`` pixels wide (:data:`CAMERA_RAYS`)."""
    return FEW_CAMERA_RAYS if width >= FEW_CAMERA_RAYS_FROM_PX else CAMERA_RAYS


#: Largest predicted image motion between two rendered keyframes, in pixels.
MAX_FLOW_PX = 0.5
#: Lowest keyframe rate in Hz, whatever the motion.
MIN_KEYFRAME_RATE_HZ = 1000.0
#: Rate of the ground-truth frames in a recording and of the evaluation instants, in Hz.
GT_RATE_HZ = 1000.0
#: Exposure (s) of the conventional frame whose motion blur a recording states when it has no frame camera.
FRAME_BLUR_EXPOSURE_S = 10e-3
#: Seed of renders and sensor streams when none is given.
SEED = 0
#: Seeds are integers in [0, SEED_LIMIT): a render seed is a uint64 (Mitsuba's sampler).
SEED_LIMIT = 2**64


def seed_problem(seed) -> str | None:
    """What is wrong with a seed, or None: the one rule for a dataset spec's ``seed``, ``--seed``,
    :class:`~simspad.render.settings.RenderSettings` and
    :class:`~simspad.sensors.recording_settings.RecordingSettings` (an integer in [0, 2**64))."""
    if isinstance(seed, numbers.Integral) and not isinstance(seed, bool) and 0 <= seed < SEED_LIMIT:
        return None
    return f"must be an integer in [0, 2**64), got {seed!r}"


def duration_problem(duration_s) -> str | None:
    """What is wrong with a duration in seconds, or None: the one rule for a sequence's ``duration_s``,
    ``--duration``, :class:`~simspad.render.settings.RenderSettings` and
    :class:`~simspad.sensors.recording_settings.RecordingSettings` (a finite number > 0; the bound
    :data:`MAX_DURATION_S` is a render's limit)."""
    if isinstance(duration_s, numbers.Real) and not isinstance(duration_s, bool) and math.isfinite(duration_s) \
            and duration_s > 0:
        return None
    return f"must be a number of seconds > 0, got {duration_s!r}"


def gt_rate_problem(rate_hz) -> str | None:
    """What is wrong with a ground-truth (evaluation) rate in Hz, or None: the one rule for a dataset spec's
    ``evaluation.rate_hz``, ``--gt-rate``, :class:`~simspad.render.settings.RenderSettings` and
    :class:`~simspad.sensors.recording_settings.RecordingSettings` (a finite number > 0; the bound
    :data:`MAX_RATE_HZ` and the samples per recording are the spec's limits, with the duration)."""
    if isinstance(rate_hz, numbers.Real) and not isinstance(rate_hz, bool) and math.isfinite(rate_hz) \
            and rate_hz > 0:
        return None
    return f"must be a finite number of Hz > 0, got {rate_hz!r}"

# Resource bounds: values past these are typos or unit slips (µs written as s), refused before any work with the
# figure; SIMSPAD_IGNORE_LIMITS=1 lifts the size bounds for a machine that can take them.
#: Largest render (width × height) in pixels: 4096 × 4096; a 16000² film alone needs ~15 GB.
MAX_RENDER_PIXELS = 4096 * 4096
#: Bytes of memory per rendered pixel (Mitsuba film RGBA + depth AOV in float32, developed copies, EXR buffers).
RENDER_BYTES_PER_PIXEL = 64
#: Largest Monte Carlo samples per pixel.
MAX_SPP = 65536
#: Smallest max_flow_px: below 0.01 px the interpolation error is far under any sensor's noise.
MIN_MAX_FLOW_PX = 0.01
#: Most keyframes one render may schedule (each is one EXR of the render size).
MAX_KEYFRAMES = 200_000
#: Most samples a motion generator may tabulate (duration × its sampling rate).
MAX_GENERATOR_SAMPLES = 2_000_000
#: Longest sequence in seconds (SPAD bins of 10 µs: 1e8 bins in 1000 s).
MAX_DURATION_S = 1000.0
#: Lux levels accepted: 1e-6 lx (far below a moonless overcast night) to 1e6 lx (about 10× direct sunlight).
LUX_RANGE = (1e-6, 1e6)
#: Most frames, SPAD bins or ground-truth instants one recording may hold.
MAX_SAMPLES_PER_RECORDING = 100_000_000
#: Shortest SPAD bin in seconds (1 ns: shorter than any SPAD's dead time).
MIN_SPAD_BIN_S = 1e-9
#: Highest frame, evaluation or ground-truth rate in Hz (1 MHz: the fastest high-speed cameras).
MAX_RATE_HZ = 1e6
#: Largest |time| (s) and |position| (m) of a trajectory keyframe: beyond, a unit slip or garbage (±1e308).
MAX_TRAJECTORY_TIME_S = 1e10  # TUM files carry Unix times (~1.7e9 s)
MAX_TRAJECTORY_POSITION_M = 1e6
#: Most noise-process draws (shot-noise and hot-pixel hazards) an event simulation may take: pixels × seconds ×
#: noise rate per pixel. Each costs ~20 ns of one core even while the pixel is blind (the refractory period caps
#: the events, not the draws), so 1e10 is ~3 min of CPU; the defaults draw ~1 per pixel-second.
MAX_EVENT_NOISE_DRAWS = 1e10
#: Smallest event ``substep_tolerance`` (a floor, kept under SIMSPAD_IGNORE_LIMITS): each tenfold cut costs ~3×
#: the internal steps, and crossings have converged at 1e-5 (benchmarks/bench_events.py's reference); 1e-6 is
#: already ~100× the default's steps, 1e-12 would be ~10⁵×.
MIN_SUBSTEP_TOLERANCE = 1e-6
#: Most rows of a results.csv the leaderboard reads (methods × recordings; reading and merging take ~0.3 ms a row).
MAX_RESULTS_ROWS = 200_000
#: Most methods one leaderboard shows: each is a line of every plot and a heatmap panel (~0.5 s of CPU each).
MAX_LEADERBOARD_METHODS = 50
#: Most table columns (scene × speed × lux) and light-level × speed cells of one leaderboard's regime map.
MAX_LEADERBOARD_COLUMNS = 1000
MAX_LEADERBOARD_REGIME_CELLS = 400
#: Seconds `generate --executor dask --scheduler ADDRESS` waits for the scheduler to answer (connection and
#: handshake); the environment variable SIMSPAD_DASK_CONNECT_TIMEOUT_S overrides it.
DASK_CONNECT_TIMEOUT_S = 15.0
