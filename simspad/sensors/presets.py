"""Sensor presets: dataclasses carrying the published parameters of the reference paper's cameras.

Every field is overridable from a dataset spec (``[sensors.<kind>]`` table) or the CLI. Field names carry
units. ``"auto"`` exposure settings are resolved from the first keyframe's flux (docs/sensors.md, exposure control).

Sources: SwissSPAD2 — Ulku et al., IEEE JSTQE 2019; Blackfly S BFS-U3-16S2 (Sony IMX273) — FLIR EMVA 1288
report; Prophesee Gen4 (Sony IMX636) — Finateu et al., ISSCC 2020 and the reference paper (Muglikar et al.).
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass
from typing import Literal, Union

from simspad.io.compression import SPAD_COMPRESSIONS
from simspad.io.recording import SENSOR_KINDS
from simspad.physics.radiometry import detection_area_m2

Auto = Literal["auto"]
#: The SPAD stream's storage filters, by name (:data:`simspad.io.compression.SPAD_COMPRESSIONS`).
SpadCompression = Literal[tuple(SPAD_COMPRESSIONS)]


class _PixelArea:
    """The detection area of a preset's pixel, from its ``pixel_pitch_m``, ``fill_factor`` and ``qe`` fields."""

    @property
    def detection_area_m2(self) -> float:
        """``q = pixel_pitch_m²·fill_factor·qe`` (m²): detections s⁻¹ per photon s⁻¹ m⁻² (radiometry)."""
        return detection_area_m2(float(self.pixel_pitch_m), float(self.fill_factor), float(self.qe))


@dataclass(frozen=True)
class SpadParams(_PixelArea):
    """SwissSPAD2-class gated binary SPAD array."""

    kind: typing.ClassVar[str] = "spad"
    pixel_pitch_m: float = 16.38e-6
    fill_factor: float = 0.105
    qe: float = 0.45
    """Photon detection probability, spectrally weighted (≈ 0.5 peak at 520 nm, lower to blue and NIR)."""
    bin_s: float = 10.24e-6
    """Binary frame period (97.7 kHz)."""
    gate_s: Union[float, Auto] = "auto"
    """Gate (exposure) within each bin: 5.75 ns ≤ gate_s ≤ bin_s, or ``"auto"``."""
    min_gate_s: float = 5.75e-9
    auto_max_probability: float = 0.9
    """``auto`` gate: longest gate keeping the 99th-percentile detection probability per bin at or below this."""
    auto_percentile: float = 99.0
    """Percentile of the first keyframe's pixels that the ``auto`` gate keeps at or below ``auto_max_probability``."""
    dcr_median_cps: float = 7.5
    dcr_log_sigma: float = 0.9
    """Log-normal spatial spread (σ of ln DCR) of the ordinary pixels."""
    hot_pixel_fraction: float = 0.02
    hot_pixel_dcr_cps: float = 2000.0
    """Median DCR of hot pixels (log-normal with the same σ)."""
    dead_time_s: float = 100e-9
    afterpulsing_probability: float = 0.001
    """Probability that a detection triggers a spurious detection in the next bin."""
    crosstalk_probability: float = 0.001
    """Probability that a detection triggers each of the 4-neighbours in the same bin (total ≈ 4×)."""
    compression: SpadCompression = "zstd"
    """Storage filter of the packed bits (``/spad/bits``): ``"zstd"`` (Zstandard level 1; 6–10× smaller on the
    bundled 512 × 512 office at its auto gate, readable with h5py after ``import hdf5plugin``), ``"gzip"`` (level 1;
    read by any HDF5 reader) or ``"none"`` (fastest; one bit per pixel and bin). The bits are the same whichever is
    chosen (:mod:`simspad.io.compression`)."""


@dataclass(frozen=True)
class FrameParams(_PixelArea):
    """Blackfly S (Sony IMX273) conventional global-shutter camera, EMVA 1288 model."""

    kind: typing.ClassVar[str] = "frames"
    pixel_pitch_m: float = 3.45e-6
    fill_factor: float = 1.0
    """Microlensed: the effective area loss is folded into ``qe``."""
    qe: float = 0.65
    """Quantum efficiency η, spectrally weighted (≈ 0.65–0.70 at 525 nm)."""
    gain_dn_per_e: float = 0.38
    """System gain K (DN per electron). The report's measured quantity is the saturation capacity (full well,
    10.5 ke⁻); K is chosen so that the 12-bit range above the black level covers it:
    K ≤ (4095 − 40 DN)/10 500 e⁻ = 0.386. 0.38 puts the full well at 4030 DN, 65 DN (≈ 60 σ of read noise)
    below the ADC clip, so saturation in the output is the full well, as in the camera (0.39 clipped in the ADC
    at 10 397 e⁻ and hid it)."""
    read_noise_e: float = 2.8
    full_well_e: float = 10500.0
    bit_depth: int = 12
    black_level_dn: float = 40.0
    dark_current_e_s: float = 3.0
    dsnu_e: float = 0.5
    """Dark-signal non-uniformity, rms electrons (fixed pattern)."""
    prnu: float = 0.01
    """Photo-response non-uniformity, relative rms (fixed pattern)."""
    frame_rate_hz: float = 100.0
    exposure_s: Union[float, Auto] = "auto"
    max_exposure_s: float = 10e-3
    """Upper bound of the ``auto`` exposure (motion-blur budget)."""
    auto_max_fill: float = 0.8
    """``auto`` exposure: 99th-percentile signal at or below this fraction of the full well."""
    rolling_shutter_line_s: float = 0.0
    """Line delay of a rolling shutter (0 = global shutter, as the IMX273)."""
    rgb: bool = False
    """Bayer RGGB colour filter array instead of monochrome."""


@dataclass(frozen=True)
class EventParams(_PixelArea):
    """Prophesee Gen4 (Sony IMX636) event camera."""

    kind: typing.ClassVar[str] = "events"
    pixel_pitch_m: float = 4.86e-6
    fill_factor: float = 0.77
    qe: float = 0.5
    threshold_on: float = 0.3
    threshold_off: float = 0.3
    threshold_sigma: float = 0.03
    """Per-pixel threshold mismatch (fixed pattern, Gaussian σ in log units)."""
    threshold_min: float = 0.01
    """Thresholds are clamped here: never ≤ 0."""
    refractory_s: float = 100e-6
    photoreceptor_cutoff_hz_max: float = 3000.0
    """Photoreceptor bandwidth in bright light; it falls in proportion to photocurrent in dim light."""
    photoreceptor_cutoff_ref_rate_e_s: float = 1e6
    """Photo-electron rate at which the cutoff reaches half of its maximum."""
    dark_current_e_s: float = 30.0
    """Junction leakage: adds to the photocurrent, sets the log floor."""
    shot_noise_rate_hz_at_1lux: float = 1.0
    """Shot-noise event rate of a pixel seeing the scene's mean luminance at 1 lx (ON + OFF)."""
    shot_noise_current_exponent: float = 0.5
    """Rate ∝ (photocurrent + dark current)^−exponent: 0.5 = relative shot-noise amplitude 1/sqrt(I)."""
    leak_rate_hz: float = 0.1
    leak_rate_log_sigma: float = 0.3
    hot_pixel_fraction: float = 1e-4
    hot_pixel_rate_hz: float = 200.0
    latency_s: float = 50e-6
    """Fixed readout latency added to every event's timestamp."""
    jitter_s: float = 10e-6
    """Gaussian timing jitter (σ) of the readout (the latency plus jitter is never negative)."""
    substep_tolerance: float = 0.01
    """Internal time step accuracy: within a step the photoreceptor output is interpolated linearly, within this
    fraction of the pixel's smaller threshold of its exact path (sets crossing-time accuracy)."""


#: Presets by kind: name → parameters. The built-in sensors' are here, beside their classes (their models import
#: the classes from this module); a sensor added to the table (:func:`simspad.sensors.registry.register`) brings
#: its own, added by :func:`register_presets`.
PRESETS: dict[str, dict[str, object]] = {
    "spad": {"swissspad2": SpadParams()},
    "frames": {"blackfly_s": FrameParams()},
    "events": {"prophesee_gen4": EventParams()},
}

#: The preset of each kind used when none is named.
DEFAULT_PRESET = {"spad": "swissspad2", "frames": "blackfly_s", "events": "prophesee_gen4"}


def register_presets(kind: str, presets, default: str) -> None:
    """Add the presets of a new sensor ``kind`` (called by :func:`simspad.sensors.registry.register`; the
    built-in kinds' tables are the ones above, so registering them again changes nothing)."""
    if PRESETS.get(kind) is presets and DEFAULT_PRESET.get(kind) == default:
        return
    if kind in PRESETS:
        raise ValueError(f"presets of sensor {kind!r} are registered already")
    PRESETS[kind] = dict(presets)
    DEFAULT_PRESET[kind] = default


def sensor_params(kind: str, preset: str | None = None, overrides: dict | None = None):
    """Build the parameter dataclass of a sensor ``kind`` from a preset and overrides.

    Raises ``ValueError`` (with a message naming the field) on an unknown kind, preset or field, or a value of
    the wrong type; callers attach the file name.
    """
    if kind not in SENSOR_KINDS or kind not in PRESETS:
        raise ValueError(f"unknown sensor {kind!r} (expected one of {', '.join(SENSOR_KINDS)})")
    preset = preset or DEFAULT_PRESET[kind]
    if preset not in PRESETS[kind]:
        raise ValueError(f"unknown {kind} preset {preset!r} (expected one of {', '.join(PRESETS[kind])})")
    base = PRESETS[kind][preset]
    overrides = dict(overrides or {})
    fields = {f.name: f for f in dataclasses.fields(base)}
    hints = typing.get_type_hints(type(base))
    clean = {}
    for name, value in overrides.items():
        if name not in fields:
            raise ValueError(f"unknown {kind} parameter {name!r} (expected one of {', '.join(fields)})")
        clean[name] = _coerce(name, value, hints[name])
    return dataclasses.replace(base, **clean)


def _coerce(name: str, value, hint):
    allowed = typing.get_args(hint) if typing.get_origin(hint) is Union else (hint,)
    if value == "auto" and Auto in allowed:
        return value
    choices = [c for a in allowed if typing.get_origin(a) is Literal and a is not Auto for c in typing.get_args(a)]
    if choices:
        if value in choices:
            return value
        raise ValueError(f"{name} must be one of {', '.join(repr(c) for c in choices)}, got {value!r}")
    if bool in allowed:
        if isinstance(value, bool):
            return value
        raise ValueError(f"{name} must be true or false, got {value!r}")
    if int in allowed and isinstance(value, int) and not isinstance(value, bool):
        return value
    if float in allowed and isinstance(value, (int, float)) and not isinstance(value, bool):
        if not value == value or value in (float("inf"), float("-inf")):
            raise ValueError(f"{name} must be finite, got {value!r}")
        if value < 0:
            raise ValueError(f"{name} must be ≥ 0, got {value!r}")
        return float(value)
    expected = " or ".join("'auto'" if a is Auto else a.__name__ for a in allowed)
    raise ValueError(f"{name} must be {expected}, got {value!r}")


def params_to_attrs(params) -> dict:
    """Flatten a parameter dataclass into HDF5-storable attrs (``auto`` stays a string)."""
    return {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
