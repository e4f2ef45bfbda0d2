"""Validation of a recording against docs/format.md, run by :func:`~simspad.io.recording.open_recording`.

Two passes, both before any reader, method or exporter sees the file:

1. **Structure** (no bulk data read): every attribute readable, the documented attributes of the right type and
   range (``width``/``height`` positive integers, times finite, thresholds and pitches > 0, ``bit_depth`` 1–16,
   JSON attributes parse), the required groups and datasets present with the documented dtype (byte order
   included: the numba kernels take native arrays only) and shape, and the size bounds of :mod:`simspad.defaults`
   (pixels, samples, duration; ``SIMSPAD_IGNORE_LIMITS=1`` lifts them).
2. **Values**, streamed in chunks of at most :data:`CHUNK_BYTES` (memory does not grow with the recording):
   instants finite, increasing and inside the recorded span; ground truth finite and ≥ 0; depth ≥ 0 or inf; dark
   count rates finite and ≥ 0; SPAD padding bits 0; frame DN within the ADC range; event coordinates inside the
   sensor, polarity 0/1, labels 0–3, timestamps sorted and inside the span, and ``ms_to_idx`` exactly the index
   of the first event of each millisecond (the readers find event windows through it).

A violation is one :class:`~simspad.errors.InputError` naming the file, the dataset (or attribute, as
``/group.name``) and the first bad index. A read error of the HDF5 library (a corrupt chunk, a filter this
installation lacks) becomes one too. Whatever passes can be indexed without further checks: an event's ``x``,
``y`` address a pixel of the ``height × width`` grid.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import h5py
import numpy as np

from simspad import defaults
from simspad.errors import InputError
from simspad.io.hdf5 import decode_attr
from simspad.io.recording.layout import REQUIRED_ROOT_ATTRS, SENSOR_KINDS, SENSOR_LAYOUTS

#: Most bytes of one dataset read at a time while checking values.
CHUNK_BYTES = 16 * 2**20
#: Rows of each event column (and of the ms index) read at a time: 13 MiB of columns.
EVENT_STEP = 1 << 20
#: Largest width or height: event coordinates are uint16.
MAX_SIDE_PX = 1 << 16
#: Tolerance on instants compared with the recorded span, s (the writers round µs and bin starts).
SPAN_TOL_S = 1e-9
#: Event labels of docs/format.md: 0 signal, 1 shot noise, 2 leak, 3 hot pixel.
MAX_LABEL = 3

#: dtype and rank of every dataset of the non-sensor groups; a sensor's are in its row of
#: :data:`.layout.SENSOR_LAYOUTS` (:func:`_dataset_kind`). The leading axis is the sample axis.
DATASETS = {
    "gt/t": ("float64", 1), "gt/flux": ("float32", 3), "gt/depth": ("float32", 3),
    "poses/t": ("float64", 1), "poses/camera_to_world": ("float64", 3),
}
#: Datasets a non-sensor group must hold when it is present (``/poses`` holds both of its own).
REQUIRED = {"gt": ("gt/t", "gt/flux"), "poses": ("poses/t", "poses/camera_to_world")}


def _dataset_kind(name: str) -> tuple[str, int]:
    """(dtype, rank) of the dataset ``name`` (``group/dataset``): :data:`DATASETS` or its sensor's layout row."""
    if name in DATASETS:
        return DATASETS[name]
    group, _, leaf = name.partition("/")
    return SENSOR_LAYOUTS[group].datasets[leaf]

# Attribute kinds: "pos" finite > 0, "nonneg" finite ≥ 0, "float" finite, "nonneg_or_nan" ≥ 0 or NaN (not measured),
# "unit" in (0, 1], "count" integer ≥ 0, "posint" integer ≥ 1, "str" text, "json" JSON text, "json_object" JSON
# object text, "bool" true/false (or 0/1, "true"/"false").
#: Root attributes: name → kind (the required ones: :data:`.layout.REQUIRED_ROOT_ATTRS`).
ROOT_ATTRS = {
    "width": "posint", "height": "posint", "duration_s": "pos", "lux": "pos",
    "t_start_s": "nonneg", "t_end_s": "pos", "time_origin_s": "float",
    "gt_rate_hz": "pos", "flux_scale": "pos", "speed_factor": "pos",
    "image_speed_px_s_p50": "nonneg_or_nan", "image_speed_px_s_p95": "nonneg_or_nan",
    "frame_blur_px_p95": "nonneg_or_nan", "frame_blur_exposure_s": "pos",
    "seed": "count", "simspad_version": "str", "dataset": "str",
    "sequence": "str", "scene": "str", "trajectory": "str", "sensors": "str",
    "recording_hash": "str", "created_utc": "str", "stream_key": "json",
    "optics": "json_object", "spec": "json_object",
}
#: Attributes of each non-sensor group: name → kind; a sensor group's are its layout row's ``attrs`` (those the
#: readers and methods use, and the counts; the required ones: its ``required_attrs``).
GROUP_ATTRS = {"gt": {"rate_hz": "pos"}, "poses": {}}
_EXPECT = {"pos": "a finite number > 0", "nonneg": "a finite number ≥ 0", "float": "a finite number",
           "nonneg_or_nan": "a number ≥ 0 (or NaN)", "unit": "a number in (0, 1]", "count": "an integer ≥ 0",
           "posint": "a positive integer", "str": "a string", "json": "JSON text",
           "json_object": "a JSON object (text)", "bool": "a boolean"}


def limits_lifted() -> bool:
    """True when ``SIMSPAD_IGNORE_LIMITS=1`` lifts the size bounds."""
    return os.environ.get("SIMSPAD_IGNORE_LIMITS", "") == "1"


def validate_recording(h5: h5py.File, path: Path) -> dict[str, dict]:
    """Check the open recording ``h5`` (file ``path``) against docs/format.md: structure, then values.

    Returns
    -------
    dict
        The attributes read on the way, decoded as :func:`~simspad.io.hdf5.decode_attr` does: ``"/"`` for the
        root's, then one dict per group present (the reader takes them instead of reading them again).

    Raises
    ------
    InputError
        The first violation, naming the file, the field and the first bad index.
    """
    check = _Check(h5, Path(path))
    check.structure()
    check.values()
    return check.raw


class _Check:
    """One validation run: ``structure()`` then ``values()``; ``fail`` raises the one-line error."""

    def __init__(self, h5: h5py.File, path: Path):
        self.h5 = h5
        self.path = path
        self.attrs: dict = {}
        self.group_attrs: dict[str, dict] = {}
        self.raw: dict[str, dict] = {}  # every attribute as decoded, before the checks convert the known ones
        self.ds: dict[str, h5py.Dataset] = {}  # the format's datasets present, looked up once (a lookup costs)

    def fail(self, field: str, message: str):
        raise InputError(message, path=self.path, field=field)

    # -- structure ------------------------------------------------------------------------------------------------

    def structure(self) -> None:
        self.attrs = self._read_attrs(self.h5, "/.", ROOT_ATTRS, REQUIRED_ROOT_ATTRS)
        self.width, self.height = int(self.attrs["width"]), int(self.attrs["height"])
        for key, side in (("width", self.width), ("height", self.height)):
            if not 1 <= side <= MAX_SIDE_PX:
                self.fail(f"/.{key}", f"{side} px, expected 1 … {MAX_SIDE_PX} (event coordinates are uint16)")
        self._limit("/.width", self.width * self.height, defaults.MAX_RENDER_PIXELS,
                    f"{self.width} × {self.height} pixels")
        self._span()
        self._spec()
        for group in ("gt", "poses", *SENSOR_KINDS):
            if group not in self.h5:
                continue
            if not isinstance(self.h5[group], h5py.Group):
                self.fail(f"/{group}", "expected a group, found a dataset")
            if group in SENSOR_LAYOUTS:
                row = SENSOR_LAYOUTS[group]
                table, required_attrs = row.attrs, row.required_attrs
                required = tuple(f"{group}/{d}" for d in row.required)
            else:
                table, required_attrs, required = GROUP_ATTRS[group], (), REQUIRED[group]
            self.group_attrs[group] = self._read_attrs(self.h5[group], f"/{group}.", table, required_attrs)
            for name in required:
                self._dataset(name, required=True)
        self._dataset("gt/depth", required=False)
        for kind in SENSOR_KINDS:  # the optional datasets of the sensors present (events/label)
            if kind in self.h5:
                row = SENSOR_LAYOUTS[kind]
                for leaf in row.datasets:
                    if leaf not in row.required:
                        self._dataset(f"{kind}/{leaf}", required=False)
        self._shapes()
        self._sensor_attrs()
        if "sensors" in self.attrs:
            listed = {s.strip() for s in str(self.attrs["sensors"]).split(",") if s.strip()}
            present = {g for g in SENSOR_KINDS if g in self.h5}
            # a kind this process has no row for (a plugin sensor not installed here) is taken as listed when
            # its group is there: the file is still readable, only that group is not offered
            present |= {g for g in listed - set(SENSOR_KINDS) if isinstance(self.h5.get(g), h5py.Group)}
            if listed != present:
                self.fail("/.sensors", f"lists {', '.join(sorted(listed)) or 'none'} but the file holds "
                                       f"{', '.join(sorted(present)) or 'no sensor group'}")

    def _read_attrs(self, obj, prefix: str, table: dict, required: tuple) -> dict:
        """Every attribute of ``obj`` decoded (InputError for an unreadable one), the ``table`` ones checked, the
        ``required`` ones present."""
        out = {}
        self.raw[prefix.strip("/.") or "/"] = out
        try:
            names = list(obj.attrs.keys())
        except Exception:  # noqa: BLE001 - any failure of the library to list them is a damaged file
            self.fail(prefix.rstrip("."), "attributes unreadable")
        for name in names:
            try:
                out[name] = decode_attr(obj.attrs[name])
            except Exception:  # noqa: BLE001 - an attribute type h5py cannot read (reference, opaque, bad UTF-8)
                self.fail(f"{prefix}{name}", "attribute of an unsupported type or unreadable")
        for name in required:
            if name not in out:
                self.fail(f"{prefix}{name}", "required attribute missing")
        checked = dict(out)
        for name, kind in table.items():
            if name in checked:
                checked[name] = self._attr_value(f"{prefix}{name}", checked[name], kind)
        return checked

    def _attr_value(self, field: str, value, kind: str):
        """The attribute ``value`` checked against ``kind``, as a plain Python value."""
        shown = str(value)[:60]
        if kind in ("str", "json", "json_object"):
            if not isinstance(value, str):
                self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
            if kind == "str":
                return value
            try:
                parsed = json.loads(value)
            except (ValueError, RecursionError):
                self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
            if kind == "json_object" and not isinstance(parsed, dict):
                self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
            return value
        if kind == "bool":
            if isinstance(value, bool) or (isinstance(value, int) and value in (0, 1)):
                return bool(value)
            if isinstance(value, str) and value.lower() in ("true", "false"):
                return value.lower() == "true"
            self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
        if kind in ("count", "posint"):
            if isinstance(value, float):
                if not (math.isfinite(value) and value.is_integer()):
                    self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
                value = int(value)
            if (kind == "count" and value < 0) or (kind == "posint" and value < 1):
                self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
            return value
        value = float(value)
        ok = {"pos": value > 0, "nonneg": value >= 0, "float": True, "unit": 0 < value <= 1}.get(kind)
        if kind == "nonneg_or_nan":
            ok = math.isnan(value) or (math.isfinite(value) and value >= 0)
        elif not math.isfinite(value):
            ok = False
        if not ok:
            self.fail(field, f"expected {_EXPECT[kind]}, got {shown!r}")
        return value

    def _limit(self, field: str, value: float, limit: float, what: str) -> None:
        if value > limit and not limits_lifted():
            self.fail(field, f"{what}, above the limit of {limit:g} (set SIMSPAD_IGNORE_LIMITS=1 to read it anyway)")

    def _span(self) -> None:
        """The recorded span ``[t0, t1]`` (s): ``t_start_s``/``t_end_s``, else from 0 over ``duration_s``."""
        a = self.attrs
        duration = a["duration_s"]
        self.t0 = a.get("t_start_s", 0.0)
        self.t1 = a.get("t_end_s", self.t0 + duration)
        if not self.t1 > self.t0:
            self.fail("/.t_end_s", f"{self.t1!r} s, expected after t_start_s = {self.t0!r} s")
        if abs((self.t1 - self.t0) - duration) > 1e-6 * max(1.0, duration):
            self.fail("/.duration_s", f"{duration!r} s, but t_end_s − t_start_s = {self.t1 - self.t0!r} s")
        self._limit("/.duration_s", duration, defaults.MAX_DURATION_S, f"{duration:g} s")
        if a.get("time_origin_s", 0.0) != 0.0:
            self.fail("/.time_origin_s", f"{a['time_origin_s']!r}, expected 0 (event timestamps are µs on the "
                                         "time base of /gt/t)")
        # the ms index runs from 0 to the end: bound it as a sample count
        self.n_ms = int(math.ceil(round(self.t1 * 1e3, 9))) + 1
        self._limit("/.t_end_s", self.n_ms, defaults.MAX_SAMPLES_PER_RECORDING, f"{self.t1:g} s of 1 ms index entries")

    def _spec(self) -> None:
        """The spec's ``evaluation`` table, which ``simspad evaluate`` reads from a lone recording."""
        if "spec" not in self.attrs:
            return
        ev = json.loads(self.attrs["spec"]).get("evaluation")
        if ev is None:
            return
        if not isinstance(ev, dict):
            self.fail("/.spec", "evaluation: expected a JSON object")
        rate = ev.get("rate_hz")
        if rate is not None and (isinstance(rate, bool) or not isinstance(rate, (int, float))
                                 or not 0 < rate <= defaults.MAX_RATE_HZ):
            self.fail("/.spec", f"evaluation.rate_hz: expected a number in (0, {defaults.MAX_RATE_HZ:g}] Hz, "
                                f"got {str(rate)[:40]!r}")
        methods = ev.get("methods")
        if methods is not None and (not isinstance(methods, list) or not all(isinstance(m, str) for m in methods)):
            self.fail("/.spec", "evaluation.methods: expected a list of method names")

    def _dataset(self, name: str, required: bool) -> h5py.Dataset | None:
        """The dataset ``name``, of its documented dtype and rank (None when optional and absent)."""
        if name not in self.h5:
            if required:
                self.fail(f"/{name}", "dataset missing")
            return None
        ds = self.h5[name]
        if not isinstance(ds, h5py.Dataset):
            self.fail(f"/{name}", "expected a dataset, found a group")
        dtype, rank = _dataset_kind(name)
        try:
            found = ds.dtype
        except Exception:  # noqa: BLE001 - a datatype h5py cannot map
            self.fail(f"/{name}", "unsupported datatype")
        if found != np.dtype(dtype):
            self.fail(f"/{name}", f"dtype {found.str if found.names is None else found}, expected {dtype} "
                                  "(little-endian, docs/format.md)")
        if ds.ndim != rank:
            self.fail(f"/{name}", f"shape {ds.shape}, expected {rank} dimensions")
        self._stored(ds, name)
        self.ds[name] = ds
        return ds

    def _stored(self, ds: h5py.Dataset, name: str) -> None:
        """Every byte of the dataset is in the file: HDF5 lets a small file declare a huge dataset whose missing
        chunks read as zeros, which would take hours to stream (SimSPAD's writers store every chunk)."""
        if ds.size == 0:
            return
        try:
            if ds.chunks is None:
                missing = ds.id.get_storage_size() < ds.size * ds.dtype.itemsize
            else:
                needed = int(np.prod([-(-n // c) for n, c in zip(ds.shape, ds.chunks)], dtype=np.int64))
                missing = ds.id.get_num_chunks() < needed
        except Exception:  # noqa: BLE001 - the library cannot describe its storage: a damaged file
            self.fail(f"/{name}", "storage unreadable")
        if missing:
            self.fail(f"/{name}", f"shape {ds.shape} declared but not all of its data is stored in the file")

    def _shapes(self) -> None:
        H, W = self.height, self.width
        h5 = self.h5

        def expect(name, shape, meaning):
            if name in self.ds and self.ds[name].shape != shape:
                self.fail(f"/{name}", f"shape {self.ds[name].shape}, expected {shape} ({meaning})")

        if "gt" in h5:
            n = self.ds["gt/t"].shape[0]
            if n == 0:
                self.fail("/gt/t", "no ground-truth instants")
            self._limit("/gt/t", n, defaults.MAX_SAMPLES_PER_RECORDING, f"{n} instants")
            expect("gt/flux", (n, H, W), "one frame per /gt/t instant, height × width")
            expect("gt/depth", (n, H, W), "one frame per /gt/t instant, height × width")
        if "poses" in h5:
            p = self.ds["poses/t"].shape[0]
            self._limit("/poses/t", p, defaults.MAX_SAMPLES_PER_RECORDING, f"{p} poses")
            expect("poses/camera_to_world", (p, 4, 4), "one 4×4 matrix per /poses/t instant")
        if "spad" in h5:
            m = self.ds["spad/bits"].shape[0]
            self._limit("/spad/bits", m, defaults.MAX_SAMPLES_PER_RECORDING, f"{m} binary frames")
            expect("spad/bits", (m, H, (W + 7) // 8), "binary frames × height × ceil(width / 8) bytes")
            expect("spad/t_start", (m,), "one start per binary frame")
            expect("spad/dcr_cps", (H, W), "height × width")
        if "frames" in h5:
            k = self.ds["frames/dn"].shape[0]
            self._limit("/frames/dn", k, defaults.MAX_SAMPLES_PER_RECORDING, f"{k} frames")
            expect("frames/dn", (k, H, W), "frames × height × width")
            expect("frames/t_start", (k,), "one exposure start per frame")
            expect("frames/t_end", (k,), "one exposure end per frame")
        if "events" in h5:
            e = self.ds["events/t"].shape[0]
            for name in ("x", "y", "p", "label"):
                expect(f"events/{name}", (e,), "one value per event, as /events/t")
            expect("events/ms_to_idx", (self.n_ms,), "one entry per millisecond from t = 0 to t_end_s, "
                                                       "ceil(t_end_s / 1 ms) + 1")
        for kind, row in self._generic_sensors():
            n = self.ds[f"{kind}/{row.instants}"].shape[0]
            self._limit(f"/{kind}/{row.instants}", n, defaults.MAX_SAMPLES_PER_RECORDING, f"{n} samples")
            for leaf in row.datasets:
                name = f"{kind}/{leaf}"
                if name in self.ds and self.ds[name].shape[:1] != (n,):
                    self.fail(f"/{name}", f"shape {self.ds[name].shape}, expected {n} rows (one per "
                                          f"/{kind}/{row.instants} instant)")

    def _generic_sensors(self):
        """(kind, layout row) of the sensor groups present that have no checks of their own here: those whose row
        names its ``instants``."""
        return [(k, SENSOR_LAYOUTS[k]) for k in SENSOR_KINDS
                if k in self.h5 and SENSOR_LAYOUTS[k].instants is not None]

    def _sensor_attrs(self) -> None:
        """Cross-field rules of the sensor groups' attributes and their counts against the datasets."""
        g = self.group_attrs
        if "spad" in g:
            a = g["spad"]
            if a["bin_s"] < defaults.MIN_SPAD_BIN_S:
                self.fail("/spad.bin_s", f"{a['bin_s']!r} s, shorter than {defaults.MIN_SPAD_BIN_S:g} s")
            if a["gate_s"] > a["bin_s"] * (1 + 1e-9):
                self.fail("/spad.gate_s", f"{a['gate_s']!r} s, longer than bin_s = {a['bin_s']!r} s")
            if "n_bins" in a and a["n_bins"] != self.ds["spad/bits"].shape[0]:
                self.fail("/spad.n_bins", f"{a['n_bins']}, but /spad/bits holds {self.ds['spad/bits'].shape[0]}")
        if "frames" in g:
            a = g["frames"]
            if not 1 <= a["bit_depth"] <= 16:
                self.fail("/frames.bit_depth", f"{a['bit_depth']}, expected 1 … 16 (DN are uint16)")
            if "n_frames" in a and a["n_frames"] != self.ds["frames/dn"].shape[0]:
                self.fail("/frames.n_frames", f"{a['n_frames']}, but /frames/dn holds {self.ds['frames/dn'].shape[0]}")
        if "events" in g:
            a = g["events"]
            if "n_events" in a and a["n_events"] != self.ds["events/t"].shape[0]:
                self.fail("/events.n_events", f"{a['n_events']}, but /events/t holds {self.ds['events/t'].shape[0]}")
            if a.get("ms_to_idx_origin_us", 0) != 0:
                self.fail("/events.ms_to_idx_origin_us", f"{a['ms_to_idx_origin_us']}, expected 0")
            if a.get("timestamp_unit", "us") != "us":
                self.fail("/events.timestamp_unit", f"{a['timestamp_unit']!r}, expected 'us'")

    # -- values ---------------------------------------------------------------------------------------------------

    def _blocks(self, name: str, step: int | None = None):
        """``(first_index, block)`` over dataset ``name`` along axis 0, ``step`` rows a block (default: at most
        ``CHUNK_BYTES``, whole HDF5 chunks); a read error of the library is an InputError naming the rows."""
        ds = self.ds[name]
        n = ds.shape[0]
        if step is None:
            row_bytes = max(1, ds.dtype.itemsize * int(np.prod(ds.shape[1:], dtype=np.int64)))
            step = max(1, CHUNK_BYTES // row_bytes)
            if ds.chunks:  # whole HDF5 chunks per read: each is decoded once
                step = max(ds.chunks[0], step // ds.chunks[0] * ds.chunks[0])
        for i in range(0, n, step):
            try:
                block = ds[i:i + step]
            except Exception as exc:  # noqa: BLE001 - corrupt chunk, missing filter: the library's own errors
                self.fail(f"/{name}", f"rows {i}…{min(i + step, n) - 1} unreadable ({str(exc)[:100]})")
            yield i, block

    def _first_bad(self, name: str, i0: int, bad: np.ndarray, what: str, values: np.ndarray, unit: str) -> None:
        """Fail at the first True of the 1-D ``bad`` (rows from ``i0``), naming the ``unit``, its index and value."""
        k = int(np.argmax(bad))
        self.fail(f"/{name}", f"{unit} {i0 + k}: {what} (found {values[k].item()!r})")

    def _instants(self, name: str, lo: float, hi: float, *, hi_open: bool = False) -> None:
        """A 1-D float64 dataset of instants (s): finite, strictly increasing, within ``[lo, hi]`` (``[lo, hi)``
        with ``hi_open``; both within :data:`SPAN_TOL_S`); the earliest violation is reported."""
        prev = -math.inf
        for i, t in self._blocks(name):
            before = np.concatenate(([prev], t[:-1]))
            with np.errstate(invalid="ignore"):
                checks = [(~np.isfinite(t), "not a finite time"),
                          (t <= before, "not after the previous instant"),
                          ((t < lo - SPAN_TOL_S) | ((t >= hi + SPAN_TOL_S) if hi_open else (t > hi + SPAN_TOL_S)),
                           f"outside the recorded span {lo!r} … {hi!r} s")]
            firsts = [(int(np.argmax(bad)), what) for bad, what in checks if bad.any()]
            if firsts:
                k, what = min(firsts, key=lambda f: f[0])
                self.fail(f"/{name}", f"index {i + k}: {what} (found {t[k].item()!r})")
            prev = float(t[-1]) if t.size else prev

    def _image_values(self, name: str, label: str, expected: str, bad_fn, unit: str = "frame",
                      cell: str = "pixel") -> None:
        """Every element of dataset ``name`` passes (``bad_fn`` marks the bad ones), read in blocks; else one line
        naming the first bad value, its pixel and its ``unit`` index."""
        for i, block in self._blocks(name):
            bad = bad_fn(block)
            if bad.any():
                k = tuple(int(v) for v in np.argwhere(bad)[0])
                if len(k) == 3:
                    where = f"at {cell} (row {k[1]}, col {k[2]}) of {unit} {i + k[0]}"
                else:
                    where = f"at pixel (row {k[0]}, col {k[1]})"
                self.fail(f"/{name}", f"{label} {block[k].item()!r} {where} (expected {expected})")

    def values(self) -> None:
        h5, W = self.h5, self.width
        t0, t1 = self.t0, self.t1
        if "gt" in h5:
            self._instants("gt/t", t0, t1)
            self._image_values("gt/flux", "ground-truth flux", "finite values ≥ 0",
                               lambda b: ~(np.isfinite(b) & (b >= 0)))
            if "gt/depth" in h5:
                self._image_values("gt/depth", "depth", "metres ≥ 0, or inf where no surface is hit",
                                   lambda b: ~(b >= 0))
        if "poses" in h5:
            self._instants("poses/t", -math.inf, math.inf)
            self._image_values("poses/camera_to_world", "matrix entry", "finite values", lambda b: ~np.isfinite(b),
                               unit="pose", cell="entry")
        if "spad" in h5:
            self._instants("spad/t_start", t0, t1, hi_open=True)
            bin_s = self.group_attrs["spad"]["bin_s"]
            prev = -math.inf
            for i, t in self._blocks("spad/t_start"):  # bins do not overlap: [t_start, t_start + bin_s)
                close = np.diff(np.concatenate(([prev], t))) < bin_s * (1 - 1e-6)
                if close.any():
                    k = int(np.argmax(close))
                    self.fail("/spad/t_start", f"index {i + k}: {t[k].item()!r} s starts less than bin_s = "
                                               f"{bin_s!r} s after the previous bin")
                prev = float(t[-1])
            if not np.all(np.isfinite(dcr := self.ds["spad/dcr_cps"][()]) & (dcr >= 0)):
                k = tuple(int(v) for v in np.argwhere(~(np.isfinite(dcr) & (dcr >= 0)))[0])
                self.fail("/spad/dcr_cps", f"dark count rate {dcr[k].item()!r} at pixel (row {k[0]}, col {k[1]}) "
                                           "(expected finite values ≥ 0, counts s⁻¹)")
            if W % 8:  # padding bits of the last byte of each row are 0 (docs/format.md)
                pad = np.uint8(0xFF << (W % 8) & 0xFF)
                for i, block in self._blocks("spad/bits"):
                    bad = (block[:, :, -1] & pad) != 0
                    if bad.any():
                        k = np.argwhere(bad)[0]
                        self.fail("/spad/bits", f"index {i + int(k[0])}, row {int(k[1])}: padding bits past "
                                                f"width {W} are set (expected 0)")
        if "frames" in h5:
            a = self.group_attrs["frames"]
            self._instants("frames/t_start", t0, t1, hi_open=True)
            self._instants("frames/t_end", t0, t1)
            for (i, ts), (_, te) in zip(self._blocks("frames/t_start", EVENT_STEP),
                                        self._blocks("frames/t_end", EVENT_STEP)):
                if (te <= ts).any():
                    self._first_bad("frames/t_end", i, te <= ts, "exposure ends before it starts", te, "index")
            dn_max = (1 << a["bit_depth"]) - 1
            self._image_values("frames/dn", "DN", f"≤ 2^bit_depth − 1 = {dn_max}", lambda b: b > dn_max)
        if "events" in h5:
            self._events()
        for kind, row in self._generic_sensors():
            if f"{kind}/{row.instants}" in self.ds:
                self._instants(f"{kind}/{row.instants}", t0, t1)

    def _events(self) -> None:
        """Events: columns in range, timestamps sorted inside the span, ``ms_to_idx`` exact; one pass, in chunks."""
        self.n_events = self.ds["events/t"].shape[0]
        lo_us = math.floor(round(self.t0 * 1e6, 3))
        hi_us = math.ceil(round(self.t1 * 1e6, 3))
        limits = {"x": (self.width, "x outside the sensor (expected 0 … width − 1 = {})"),
                  "y": (self.height, "y outside the sensor (expected 0 … height − 1 = {})"),
                  "p": (2, "polarity not 0 (OFF) or 1 (ON)"),
                  "label": (MAX_LABEL + 1, "label not 0 … 3")}
        step = EVENT_STEP
        columns = {k: self._blocks(f"events/{k}", step) for k in limits if f"events/{k}" in self.ds}
        prev = -(1 << 62)
        k_next = 0  # first ms boundary whose index is not yet checked
        for i, t in self._blocks("events/t", step):
            before = np.concatenate(([prev], t[:-1]))
            if (t < before).any():
                k = int(np.argmax(t < before))
                self.fail("/events/t", f"not sorted (event {i + k} at {int(t[k])} µs comes after one at "
                                       f"{int(before[k])} µs)")
            out = (t < lo_us) | (t > hi_us)
            if out.any():
                self._first_bad("events/t", i, out, f"timestamp outside the recorded span {lo_us} … {hi_us} µs", t,
                                unit="event")
            for name, (limit, what) in limits.items():
                if name in columns:
                    _, col = next(columns[name])
                    if (col >= limit).any():
                        self._first_bad(f"events/{name}", i, col >= limit, what.format(limit - 1), col, unit="event")
            if t.size:
                # the boundaries 1000·k not after this chunk's last timestamp have their first event in this chunk
                k_end = min(self.n_ms, int(t[-1]) // 1000 + 1)
                self._ms_index(k_next, k_end, lambda b, t=t, i=i: i + np.searchsorted(t, b, side="left"))
                k_next = max(k_next, k_end)
                prev = int(t[-1])
        self._ms_index(k_next, self.n_ms, lambda b: np.full(b.size, self.n_events, np.int64))

    def _ms_index(self, k0: int, k1: int, first_index) -> None:
        """``ms_to_idx[k0:k1]`` equals ``first_index(boundaries µs)``, read ``EVENT_STEP`` entries at a time."""
        ds = self.ds["events/ms_to_idx"]
        for k in range(k0, k1, EVENT_STEP):
            kb = min(k + EVENT_STEP, k1)
            try:
                found = ds[k:kb]
            except Exception as exc:  # noqa: BLE001 - corrupt chunk, missing filter
                self.fail("/events/ms_to_idx", f"rows {k}…{kb - 1} unreadable ({str(exc)[:100]})")
            expected = first_index(np.arange(k, kb, dtype=np.int64) * 1000).astype(np.uint64)
            bad = found != expected
            if bad.any():
                j = int(np.argmax(bad))
                self.fail("/events/ms_to_idx", f"index {k + j}: {int(found[j])}, expected {int(expected[j])} (the "
                                               f"first event with t ≥ {1000 * (k + j)} µs)")
