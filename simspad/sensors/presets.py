"""Sensor presets: dataclasses carrying the published parameters of the reference paper's cameras.

Every field is overridable from a dataset spec (``[sensors.<kind>]`` table) or the CLI. Field names carry
units. ``"auto"`` exposure settings are resolved from the first keyframe's flux (docs/sensors.md, exposure control).

A parameter record checks itself when it is built (:meth:`_CheckedParams.problems`: each field's type, finiteness
and range, then the rules between fields such as a fixed gate within ``[min_gate_s, bin_s]``), raising one
:class:`~simspad.errors.SimSpadError` naming ``sensors.<kind>.<field>``; so a dataset spec's ``[sensors.*]``
tables, ``simspad simulate --set`` and the Python API meet one rule with one message, and the models and the
simulators trust the record. Only what needs a recording's size stays with the sensor table's ``validate``
(the frame camera's rolling-shutter readout against its frame period, :mod:`simspad.sensors.registry`).

Sources: SwissSPAD2 — Ulku et al., IEEE JSTQE 2019; Blackfly S BFS-U3-16S2 (Sony IMX273) — FLIR EMVA 1288
report; Prophesee Gen4 (Sony IMX636) — Finateu et al., ISSCC 2020 and the reference paper (Muglikar et al.).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import typing
from dataclasses import dataclass
from typing import Literal, Union

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.io.compression import SPAD_COMPRESSIONS
from simspad.io.recording import SENSOR_KINDS
from simspad.physics.radiometry import detection_area_m2

Auto = Literal["auto"]
#: The SPAD stream's storage filters, by name (:data:`simspad.io.compression.SPAD_COMPRESSIONS`).
SpadCompression = Literal[tuple(SPAD_COMPRESSIONS)]


#: A field's range rule: (holds(value), what the value must be).
_Rule = tuple[typing.Callable[[object], bool], str]


def _positive() -> _Rule:
    return (lambda v: v > 0, "must be > 0")


def _fraction(lo_open: bool, hi_open: bool) -> _Rule:
    text = f"must be in {'(' if lo_open else '['}0, 1{')' if hi_open else ']'}"
    return (lambda v: (v > 0 if lo_open else v >= 0) and (v < 1 if hi_open else v <= 1), text)


class _CheckedParams:
    """A sensor's parameter record that checks itself on construction (and on :func:`dataclasses.replace`).

    Subclasses list their range rules in ``_RULES`` (field → :data:`_Rule`; a number field without one must be
    ≥ 0) and the rules between fields in :meth:`_cross_problems`.
    """

    kind: typing.ClassVar[str]
    _RULES: typing.ClassVar[dict[str, _Rule]] = {}

    def __post_init__(self):
        for field_name, message in self.problems():
            raise SimSpadError(message, field=f"sensors.{self.kind}.{field_name}")

    def problems(self) -> list[tuple[str, str]]:
        """(field, message) for every field that breaks its rule (empty: fine): type, finite, range, then the
        rules between fields once every field is fine."""
        out = [(f.name, problem) for f in dataclasses.fields(self)
               if (problem := self.field_problem(f.name, getattr(self, f.name))) is not None]
        return out or self._cross_problems()

    @classmethod
    def field_problem(cls, name: str, value) -> str | None:
        """What is wrong with ``value`` for the field ``name`` on its own (type, finite, range), or None; the
        rules between fields are :meth:`problems`'."""
        problem = _type_problem(value, typing.get_type_hints(cls)[name])
        if problem is None and _is_number(value):
            holds, text = cls._RULES.get(name, (lambda v: v >= 0, "must be ≥ 0"))
            if not holds(value):
                problem = text
        return None if problem is None else f"{problem}, got {value!r}"

    def _cross_problems(self) -> list[tuple[str, str]]:
        return []


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _type_problem(value, hint) -> str | None:
    """What the value must be when its type does not fit the field's annotation (or it is not finite), else None."""
    allowed = typing.get_args(hint) if typing.get_origin(hint) is Union else (hint,)
    if value == "auto" and Auto in allowed:
        return None
    choices = [c for a in allowed if typing.get_origin(a) is Literal and a is not Auto for c in typing.get_args(a)]
    if choices:
        return None if value in choices else f"must be one of {', '.join(repr(c) for c in choices)}"
    if bool in allowed:
        return None if isinstance(value, bool) else "must be true or false"
    if int in allowed and isinstance(value, numbers.Integral) and not isinstance(value, bool):
        return None
    if float in allowed and _is_number(value):
        return None if math.isfinite(value) else "must be finite"
    return "must be " + " or ".join({"Auto": "'auto'", "float": "a number", "int": "an integer"}.get(
        getattr(a, "__name__", "Auto"), "'auto'") for a in allowed)


class _PixelArea:
    """The detection area of a preset's pixel, from its ``pixel_pitch_m``, ``fill_factor`` and ``qe`` fields."""

    @property
    def detection_area_m2(self) -> float:
        """``q = pixel_pitch_m²·fill_factor·qe`` (m²): detections s⁻¹ per photon s⁻¹ m⁻² (radiometry)."""
        return detection_area_m2(float(self.pixel_pitch_m), float(self.fill_factor), float(self.qe))


#: The pixel's rules, shared by every kind.
_PIXEL_RULES: dict[str, _Rule] = {"pixel_pitch_m": _positive(), "fill_factor": _fraction(True, False),
                                  "qe": _fraction(True, False)}


@dataclass(frozen=True)
class SpadParams(_PixelArea, _CheckedParams):
    """SwissSPAD2-class gated binary SPAD array."""

    kind: typing.ClassVar[str] = "spad"
    _RULES: typing.ClassVar[dict[str, _Rule]] = {
        **_PIXEL_RULES, "bin_s": _positive(), "min_gate_s": _positive(),
        "auto_max_probability": (lambda v: 0 < v < 1, "must be in (0, 1)"),
        "auto_percentile": (lambda v: 0 <= v <= 100, "must be in [0, 100]"),
        "hot_pixel_fraction": _fraction(False, False), "afterpulsing_probability": _fraction(False, True),
        "crosstalk_probability": _fraction(False, True)}
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

    def _cross_problems(self) -> list[tuple[str, str]]:
        if self.min_gate_s > self.bin_s:
            return [("min_gate_s", f"must be in (0, bin_s], got {self.min_gate_s!r}")]
        if self.gate_s != "auto" and not (self.min_gate_s * (1 - 1e-9) <= self.gate_s <= self.bin_s * (1 + 1e-9)):
            return [("gate_s", f"gate {self.gate_s:g} s must lie in [min_gate_s = {self.min_gate_s:g}, "
                               f"bin_s = {self.bin_s:g}] s (or be 'auto')")]
        return []


@dataclass(frozen=True)
class FrameParams(_PixelArea, _CheckedParams):
    """Blackfly S (Sony IMX273) conventional global-shutter camera, EMVA 1288 model."""

    kind: typing.ClassVar[str] = "frames"
    _RULES: typing.ClassVar[dict[str, _Rule]] = {
        **_PIXEL_RULES, "frame_rate_hz": _positive(), "max_exposure_s": _positive(),
        "bit_depth": (lambda v: 1 <= v <= 16, "must be between 1 and 16 (uint16 output)"),
        "gain_dn_per_e": _positive(), "full_well_e": _positive(), "auto_max_fill": _fraction(True, False),
        "exposure_s": (lambda v: v > 0, "must be > 0 s or 'auto'")}
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

    def _cross_problems(self) -> list[tuple[str, str]]:
        period_s = 1.0 / self.frame_rate_hz
        if self.exposure_s != "auto" and self.exposure_s > period_s * (1 + 1e-9):
            return [("exposure_s", f"{self.exposure_s!r} s is longer than the frame period 1/frame_rate_hz = "
                                   f"{period_s!r} s")]
        return []


@dataclass(frozen=True)
class EventParams(_PixelArea, _CheckedParams):
    """Prophesee Gen4 (Sony IMX636) event camera."""

    kind: typing.ClassVar[str] = "events"
    _RULES: typing.ClassVar[dict[str, _Rule]] = {
        **_PIXEL_RULES, "threshold_on": _positive(), "threshold_off": _positive(),
        "threshold_min": (lambda v: v > 0, "must be > 0 (thresholds may never reach 0)"),
        "photoreceptor_cutoff_hz_max": _positive(), "hot_pixel_fraction": _fraction(False, False),
        "substep_tolerance": (lambda v: defaults.MIN_SUBSTEP_TOLERANCE <= v <= 0.1,
                              f"must be in [{defaults.MIN_SUBSTEP_TOLERANCE:g}, 0.1] (each tenfold cut costs ~3× "
                              "the internal steps; crossings have converged at 1e-5)")}
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

    Raises ``ValueError`` (naming it) on an unknown kind, preset or field; a value the record refuses raises the
    record's own :class:`~simspad.errors.SimSpadError` naming ``sensors.<kind>.<field>``
    (:meth:`_CheckedParams.problems`). Callers attach the file name.
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
        clean[name] = _as_float(value, hints[name])
    return dataclasses.replace(base, **clean)


def override_problem(kind: str, name: str, value) -> str | None:
    """What is wrong with overriding the field ``name`` of a ``kind`` preset with ``value`` on its own (an unknown
    field, or the record's rule of that field), or None. ``kind`` must be a known sensor."""
    cls = type(PRESETS[kind][DEFAULT_PRESET[kind]])
    fields = [f.name for f in dataclasses.fields(cls)]
    if name not in fields:
        return f"unknown {kind} parameter {name!r} (expected one of {', '.join(fields)})"
    check = getattr(cls, "field_problem", None)  # a sensor registered with a plain dataclass checks in validate
    return None if check is None else check(name, _as_float(value, typing.get_type_hints(cls)[name]))


def _as_float(value, hint):
    """An integer given for a number field, as a float (``qe = 1`` in TOML); anything else as it is: the record
    checks it."""
    allowed = typing.get_args(hint) if typing.get_origin(hint) is Union else (hint,)
    if float in allowed and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def params_to_attrs(params) -> dict:
    """Flatten a parameter dataclass into HDF5-storable attrs (``auto`` stays a string)."""
    return {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
