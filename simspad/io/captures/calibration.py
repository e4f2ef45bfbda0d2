"""The calibration file of ``simspad import`` (docs/format.md section 9): a TOML file describing a rig's captures.

It names each sensor's capture file and its format, the sensor's size, clock offset and response (SPAD bin
width, gate, detection efficiency and dark counts; frame gain, black level and exposure; event contrast
thresholds and noise figures), the homography of each sensor onto the common reference grid, and optionally a
Siemens-star region that evaluation measures an MTF on. :func:`load_calibration` checks every field (type,
range, that the files exist) and refuses unknown keys, so a typo is one line naming the file and the field.
Relative paths are relative to the calibration file.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simspad.errors import InputError

#: Event capture formats, by the suffix that selects them when ``format`` is not given.
EVENT_FORMATS = {".raw": "evt3", ".h5": "dsec", ".hdf5": "dsec", ".aedat4": "aedat4", ".npy": "npy"}
#: SPAD capture formats, by suffix.
SPAD_FORMATS = {".npy": "npy", ".npz": "npz", ".bin": "bin"}
#: Frame capture formats, by suffix (a folder is a PNG folder).
FRAME_FORMATS = {".tif": "tiff", ".tiff": "tiff", "": "png"}


@dataclass(frozen=True)
class SensorCalibration:
    """What every sensor table shares.

    Attributes
    ----------
    kind : str
        "spad", "frames" or "events".
    path : Path
        The capture (file or folder), absolute.
    format : str
        The capture's format (see the ``*_FORMATS`` tables).
    width, height : int or None
        Sensor size, px (None: taken from the capture).
    time_offset_s : float
        Added to the sensor's timestamps to put them on the rig's common clock, s.
    homography : ndarray [3, 3] or None
        Maps sensor pixel coordinates (x, y, 1) to reference-grid coordinates; None: identity (the sensor is the
        reference grid), or given by ``options["pose"]`` (``K``, ``R``, ``t``, ``d``: see
        :func:`simspad.captures.geometry.pose_homography`).
    attrs : dict
        The sensor's response parameters, stored as the group's attributes (units in the names).
    options : dict
        Format options (bit order, packed axis, timestamps file, …).
    """

    kind: str
    path: Path
    format: str
    width: int | None
    height: int | None
    time_offset_s: float
    homography: np.ndarray | None
    attrs: dict
    options: dict = field(default_factory=dict)


@dataclass(frozen=True)
class StarRegion:
    """A Siemens star on the reference grid: centre (x, y) and outer radius, px; spokes (cycles) if known."""

    center_x_px: float
    center_y_px: float
    radius_px: float
    n_cycles: int | None
    contrast: float


@dataclass(frozen=True)
class Calibration:
    """A validated calibration file (see the module docstring and docs/format.md section 9)."""

    path: Path
    text: str
    name: str
    scene: str
    lux: float
    t_start_s: float | None
    duration_s: float | None
    rate_hz: float
    width: int
    height: int
    valid_mask: Path | None
    star: StarRegion | None
    sensors: dict[str, SensorCalibration]
    reference_intrinsics: np.ndarray | None = None
    """K of the reference camera, px (for sensors given by a pose)."""


class _Table:
    """One TOML table being read: typed getters that name the file and the field on a bad value."""

    def __init__(self, path: Path, name: str, raw):
        self.path, self.name = path, name
        if not isinstance(raw, dict):
            raise InputError(f"expected a table, got {type(raw).__name__}", path=path, field=name)
        self.raw = dict(raw)
        self.used: set[str] = set()

    def _where(self, key: str) -> str:
        return f"{self.name}.{key}" if self.name else key

    def error(self, key: str, message: str) -> InputError:
        return InputError(message, path=self.path, field=self._where(key))

    def has(self, key: str) -> bool:
        return key in self.raw

    def get(self, key: str, default=None):
        self.used.add(key)
        return self.raw.get(key, default)

    def number(self, key: str, default=None, *, positive=False, non_negative=False, required=False, unit=""):
        v = self.get(key)
        if v is None:
            if required:
                raise self.error(key, f"required ({unit})" if unit else "required")
            return default
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.error(key, f"expected a finite number{' in ' + unit if unit else ''}, got {v!r}")
        if positive and not v > 0:
            raise self.error(key, f"must be > 0, got {v!r}")
        if non_negative and v < 0:
            raise self.error(key, f"must be ≥ 0, got {v!r}")
        return float(v)

    def integer(self, key: str, default=None, *, required=False, minimum=1):
        v = self.get(key)
        if v is None:
            if required:
                raise self.error(key, "required")
            return default
        if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
            raise self.error(key, f"expected an integer ≥ {minimum}, got {v!r}")
        return int(v)

    def string(self, key: str, default=None, *, choices=None, required=False):
        v = self.get(key)
        if v is None:
            if required:
                raise self.error(key, "required")
            return default
        if not isinstance(v, str):
            raise self.error(key, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(key, f"expected one of {', '.join(map(repr, choices))}, got {v!r}")
        return v

    def file(self, key: str, *, required=False, directory_ok=False) -> Path | None:
        v = self.string(key, required=required)
        if v is None:
            return None
        p = Path(v).expanduser()
        p = p if p.is_absolute() else self.path.parent / p
        if not (p.is_file() or (directory_ok and p.is_dir())):
            raise self.error(key, f"no such {'file or folder' if directory_ok else 'file'}: {p}")
        return p

    def matrix3(self, key: str, *, what: str = "homography", normalise: bool = True) -> np.ndarray | None:
        v = self.get(key)
        if v is None:
            return None
        try:
            m = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            m = None
        if m is None or m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise self.error(key, f"expected a 3×3 array of finite numbers (rows of the {what})")
        if abs(np.linalg.det(m)) < 1e-12:
            raise self.error(key, f"the {what} is singular (determinant 0)")
        return m / m[2, 2] if normalise and m[2, 2] != 0 else m

    def vector3(self, key: str) -> np.ndarray | None:
        v = self.get(key)
        if v is None:
            return None
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            a = None
        if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
            raise self.error(key, "expected [x, y, z] in metres")
        return a

    def finish(self) -> None:
        unknown = sorted(set(self.raw) - self.used)
        if unknown:
            raise self.error(unknown[0], "unknown key (see docs/format.md, section 9)")


#: Response parameters each sensor table accepts (stored as attributes of its group), with their constraints.
_SPAD_PARAMS = {"pixel_pitch_m": "positive", "fill_factor": "positive", "qe": "positive",
                "dead_time_s": "non_negative", "afterpulsing_probability": "non_negative",
                "crosstalk_probability": "non_negative"}
_FRAME_PARAMS = {"pixel_pitch_m": "positive", "fill_factor": "positive", "qe": "positive",
                 "gain_dn_per_e": "positive", "black_level_dn": "non_negative", "read_noise_e": "non_negative",
                 "full_well_e": "positive", "dark_current_e_s": "non_negative"}
_EVENT_PARAMS = {"threshold_on": "positive", "threshold_off": "positive", "threshold_sigma": "non_negative",
                 "refractory_s": "non_negative", "pixel_pitch_m": "positive", "fill_factor": "positive",
                 "qe": "positive", "dark_current_e_s": "non_negative",
                 "photoreceptor_cutoff_hz_max": "positive", "photoreceptor_cutoff_ref_rate_e_s": "positive",
                 "shot_noise_rate_hz_at_1lux": "non_negative", "leak_rate_hz": "non_negative",
                 "hot_pixel_fraction": "non_negative", "latency_s": "non_negative", "jitter_s": "non_negative"}
_REQUIRED = {"spad": ("pixel_pitch_m", "fill_factor", "qe"),
             "frames": ("pixel_pitch_m", "qe", "gain_dn_per_e", "black_level_dn", "read_noise_e", "full_well_e"),
             "events": ("threshold_on",)}


def _params(t: _Table, table: dict[str, str], required: tuple[str, ...]) -> dict:
    out = {}
    for key, rule in table.items():
        v = t.number(key, required=key in required, positive=rule == "positive",
                     non_negative=rule == "non_negative")
        if v is not None:
            out[key] = v
    return out


def _format(t: _Table, path: Path, formats: dict[str, str]) -> str:
    fmt = t.string("format", choices=sorted(set(formats.values())))
    if fmt is None:
        suffix = "" if path.is_dir() else path.suffix.lower()
        fmt = formats.get(suffix)
        if fmt is None:
            raise t.error("format", f"cannot tell the format from the name {path.name!r}: give format = one of "
                                    f"{', '.join(sorted(set(formats.values())))}")
    return fmt


def _sensor_common(t: _Table, kind: str, formats: dict[str, str]):
    path = t.file("path", required=True, directory_ok=kind == "frames")
    fmt = _format(t, path, formats)
    width = t.integer("width")
    height = t.integer("height")
    offset = t.number("time_offset_s", 0.0, unit="s")
    return path, fmt, width, height, offset, t.matrix3("homography"), _pose(t)


#: The fields of a sensor's pose relative to the reference camera (the alternative to a homography).
POSE_FIELDS = ("intrinsics", "rotation", "translation_m", "plane_distance_m")


def _pose(t: _Table) -> dict | None:
    """The sensor's intrinsics K, rotation R and translation t onto the reference camera and the distance of the
    scene plane, when given (all four; the reference's intrinsics come from ``[reference]``)."""
    given = [k for k in POSE_FIELDS if t.has(k)]
    if not given:
        return None
    if t.has("homography"):
        raise t.error(given[0], "give either a homography or a pose (intrinsics, rotation, translation_m, "
                                "plane_distance_m), not both")
    missing = [k for k in POSE_FIELDS if k not in given]
    if missing:
        raise t.error(missing[0], f"a pose needs all of {', '.join(POSE_FIELDS)}")
    rot = t.matrix3("rotation", what="rotation", normalise=False)
    if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise t.error("rotation", "not a rotation matrix (R·Rᵀ must be the identity, det R = +1)")
    return {"K": t.matrix3("intrinsics", what="intrinsic matrix", normalise=False), "R": rot,
            "t": t.vector3("translation_m"),
            "d": t.number("plane_distance_m", positive=True, required=True, unit="m")}


def _spad(t: _Table) -> SensorCalibration:
    path, fmt, width, height, offset, hom, pose = _sensor_common(t, "spad", SPAD_FORMATS)
    attrs = _params(t, _SPAD_PARAMS, _REQUIRED["spad"])
    bin_s = t.number("bin_s", required=fmt != "npz", positive=True, unit="s")
    gate_s = t.number("gate_s", positive=True, unit="s")
    if bin_s is not None and gate_s is not None and gate_s > bin_s * (1 + 1e-9):
        raise t.error("gate_s", f"the gate ({gate_s} s) is longer than the bin ({bin_s} s)")
    opts = {"pose": pose, "bin_s": bin_s, "gate_s": gate_s,
            "t_start_s": t.number("t_start_s", unit="s"),
            "bit_order": t.string("bit_order", "big" if fmt == "npy" else "little", choices=("little", "big")),
            "bitpack_dim": t.integer("bitpack_dim", 2, minimum=1),
            "frame_header_bytes": t.integer("frame_header_bytes", 0, minimum=0),
            "dcr_cps": t.number("dcr_cps", non_negative=True, unit="counts/s"),
            "dcr_map": t.file("dcr_map"),
            "dark_capture": t.file("dark_capture")}
    if opts["bitpack_dim"] not in (1, 2):
        raise t.error("bitpack_dim", f"expected 1 (rows packed) or 2 (columns packed), got {opts['bitpack_dim']}")
    if fmt == "bin" and (width is None or height is None):
        raise t.error("width" if width is None else "height", "required for a raw .bin stream (the frame size)")
    given = [k for k in ("dcr_cps", "dcr_map", "dark_capture") if opts[k] is not None]
    if len(given) > 1:
        raise t.error(given[1], f"give one of dcr_cps, dcr_map, dark_capture (also got {given[0]})")
    return SensorCalibration("spad", path, fmt, width, height, offset, hom, attrs, opts)


#: Frame response fields an EMVA 1288 flat/dark capture set measures (given values win over measured ones).
EMVA_MEASURED = ("gain_dn_per_e", "read_noise_e", "full_well_e", "black_level_dn")


def _emva(t: _Table) -> dict | None:
    if not t.has("emva"):
        return None
    e = _Table(t.path, "frames.emva", t.get("emva"))
    flats = e.get("flats")
    if not isinstance(flats, list) or len(flats) < 3 or not all(isinstance(f, str) for f in flats):
        raise e.error("flats", "expected a list of at least 3 flat-field captures (TIFF stacks or image folders), "
                               "at increasing illumination up to saturation")
    resolved = []
    for i, f in enumerate(flats):
        p = Path(f).expanduser()
        p = p if p.is_absolute() else t.path.parent / p
        if not (p.is_file() or p.is_dir()):
            raise e.error(f"flats[{i}]", f"no such file or folder: {p}")
        resolved.append(p)
    out = {"flats": resolved, "dark": e.file("dark", required=True, directory_ok=True)}
    e.finish()
    return out


def _frames(t: _Table) -> SensorCalibration:
    path, fmt, width, height, offset, hom, pose = _sensor_common(t, "frames", FRAME_FORMATS)
    emva = _emva(t)
    required = _REQUIRED["frames"] if emva is None else tuple(k for k in _REQUIRED["frames"]
                                                               if k not in EMVA_MEASURED)
    attrs = _params(t, _FRAME_PARAMS, required)
    bit_depth = t.integer("bit_depth", required=True)
    if bit_depth > 16:
        raise t.error("bit_depth", f"at most 16 bits (frames are stored as uint16), got {bit_depth}")
    attrs["bit_depth"] = bit_depth
    attrs.setdefault("fill_factor", 1.0)
    opts = {"pose": pose, "emva": emva, "timestamps": t.file("timestamps"),
            "frame_rate_hz": t.number("frame_rate_hz", positive=True, unit="Hz"),
            "exposure_s": t.number("exposure_s", positive=True, unit="s"),
            "t_start_s": t.number("t_start_s", 0.0, unit="s")}
    if opts["timestamps"] is None:
        default_csv = (path if path.is_dir() else path.parent) / "timestamps.csv"
        if default_csv.is_file():
            opts["timestamps"] = default_csv
        elif opts["frame_rate_hz"] is None or opts["exposure_s"] is None:
            raise t.error("timestamps", "give a timestamps file (columns t_start_s, t_end_s) or frame_rate_hz "
                                        "and exposure_s")
    return SensorCalibration("frames", path, fmt, width, height, offset, hom, attrs, opts)


def _events(t: _Table) -> SensorCalibration:
    path, fmt, width, height, offset, hom, pose = _sensor_common(t, "events", EVENT_FORMATS)
    attrs = _params(t, _EVENT_PARAMS, _REQUIRED["events"])
    attrs.setdefault("threshold_off", attrs["threshold_on"])
    attrs.setdefault("threshold_sigma", 0.0)
    if fmt == "npy" and (width is None or height is None):
        raise t.error("width" if width is None else "height", "required for a structured .npy event array")
    return SensorCalibration("events", path, fmt, width, height, offset, hom, attrs, {"pose": pose})


def load_calibration(path: str | Path) -> Calibration:
    """Read and check a calibration TOML file.

    Raises
    ------
    InputError
        Naming the file and the first field at fault (unknown key, wrong type, out of range, missing file).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("no such calibration file", path=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the calibration file ({exc})", path=path) from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML ({exc})", path=path) from None
    top = _Table(path, "", raw)
    cap = _Table(path, "capture", top.get("capture", {}))
    name = cap.string("name", path.stem)
    scene = cap.string("scene", name)
    lux = cap.number("lux", required=True, non_negative=True, unit="lx")
    t_start_s = cap.number("t_start_s", unit="s")
    duration_s = cap.number("duration_s", positive=True, unit="s")
    rate_hz = cap.number("rate_hz", 1000.0, positive=True, unit="Hz")
    cap.finish()

    sensors: dict[str, SensorCalibration] = {}
    for kind, reader in (("spad", _spad), ("frames", _frames), ("events", _events)):
        if top.has(kind):
            t = _Table(path, kind, top.get(kind))
            sensors[kind] = reader(t)
            t.finish()
    if not sensors:
        raise InputError("no sensor table: give at least one of [spad], [frames], [events]", path=path,
                         field="spad")

    ref = _Table(path, "reference", top.get("reference", {}))
    first = next(iter(sensors.values()))
    width = ref.integer("width", first.width)
    height = ref.integer("height", first.height)
    valid_mask = ref.file("valid_mask")
    k_ref = ref.matrix3("intrinsics", what="intrinsic matrix", normalise=False)
    ref.finish()
    if k_ref is None and any(sc.options.get("pose") for sc in sensors.values()):
        raise InputError("a sensor pose needs the reference camera's intrinsics", path=path,
                         field="reference.intrinsics")

    star = None
    if top.has("star"):
        st = _Table(path, "star", top.get("star"))
        centre = st.get("center_px")
        if (not isinstance(centre, list) or len(centre) != 2
                or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in centre)):
            raise st.error("center_px", "expected [x, y] in reference-grid pixels")
        radius = st.number("radius_px", required=True, positive=True, unit="px")
        n_cycles = st.integer("n_cycles", minimum=2)
        contrast = st.number("contrast", 1.0, positive=True)
        if contrast > 1:
            raise st.error("contrast", f"a Michelson contrast lies in (0, 1], got {contrast}")
        st.finish()
        star = StarRegion(float(centre[0]), float(centre[1]), radius, n_cycles, contrast)
    top.finish()
    return Calibration(path, text, name, scene, lux, t_start_s, duration_s, rate_hz, width, height,
                       valid_mask, star, sensors, k_ref)
