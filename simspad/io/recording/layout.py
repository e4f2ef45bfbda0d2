"""The recording layout (docs/format.md): format name and version, and the table of sensor groups.

One HDF5 file per sequence × lux::

    /             attrs: format, format_version, width, height, duration_s, lux, scene, sequence, spec, …
    /gt           t [n] s, flux [n,H,W] ph s⁻¹ m⁻², depth [n,H,W] m (optional); with geometry passes also
                  instance [n,H,W] uint16, flow [n,H,W,2] px, flow_valid [n,H,W] uint8, velocity [n,H,W,2] px s⁻¹,
                  camera_to_world [n,4,4], object_to_world [n,K,4,4] (when objects move)
    /camera       attrs focal_px, cx_px, cy_px, x_fov_deg, y_fov_deg, …; K [3,3] px (with geometry passes)
    /poses        t [k] s, camera_to_world [k,4,4] (optional)
    /spad         bits [n,H,ceil(W/8)] uint8 (little bit order), t_start [n] s, dcr_cps [H,W]
    /frames       dn [k,H,W] uint16, t_start [k] s, t_end [k] s
    /events       t [m] int64 µs, x, y [m] uint16, p [m] uint8 (1 ON / 0 OFF), label [m] uint8 (optional),
                  ms_to_idx [ms] (index of the first event of each millisecond)

Each sensor group is one :class:`SensorLayout` row of :data:`SENSOR_LAYOUTS`: its datasets (dtype, rank), the
required ones, its attributes' kinds, and the view :class:`~simspad.io.recording.reader.Recording` exposes it
through. The rows of the three built-in sensors are here, because reading a recording (methods, captures,
exporters) must not need the simulators; a new sensor's row is defined in its folder under ``simspad/sensors/``
and added by :func:`simspad.sensors.registry.register`, which calls :func:`register_layout`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py

from simspad.io.recording.events import EventsView
from simspad.io.recording.frames import FramesView
from simspad.io.recording.group import GroupView
from simspad.io.recording.spad import SpadView

FORMAT = "simspad-recording"
FORMAT_VERSION = 1

#: Root attributes every recording has.
REQUIRED_ROOT_ATTRS = ("width", "height", "duration_s", "lux")
#: Groups that are not sensors (their views are built by the reader itself).
NON_SENSOR_GROUPS = ("gt", "camera", "poses")


@dataclass(frozen=True)
class SensorLayout:
    """What a recording holds for one sensor kind: the group ``/<name>``.

    Attributes
    ----------
    name : str
        The kind and group name (``"spad"``); also the attribute of :class:`Recording` that exposes the view.
    datasets : Mapping[str, tuple[str, int]]
        Every dataset the group may hold, by name inside the group: (little-endian dtype, rank); the leading
        axis is the sample axis.
    required : tuple of str
        The datasets (names inside the group) present whenever the group is.
    attrs : Mapping[str, str]
        Attribute name → kind checked on open (the kinds of :mod:`.validation`: ``"pos"``, ``"unit"``,
        ``"count"``, ``"str"``, …).
    required_attrs : tuple of str
        Attributes present whenever the group is.
    view : callable
        ``view(h5, path, width, height) -> GroupView``: the read view of the group.
    instants : str, optional
        For a sensor without checks of its own in :mod:`.validation`: the required float64 dataset of its sample
        instants (s),
        checked finite, increasing and inside the recorded span, every dataset of the group holding one row per
        instant. The built-in sensors leave it None: validation checks them field by field.
    """

    name: str
    datasets: Mapping[str, tuple[str, int]]
    required: tuple[str, ...]
    attrs: Mapping[str, str]
    required_attrs: tuple[str, ...]
    view: Callable[[h5py.File, Path, int, int], GroupView]
    instants: str | None = None


SPAD_LAYOUT = SensorLayout(
    name="spad",
    datasets={"bits": ("uint8", 3), "t_start": ("float64", 1), "dcr_cps": ("float32", 2)},
    required=("bits", "t_start", "dcr_cps"),
    attrs={"bin_s": "pos", "gate_s": "pos", "pixel_pitch_m": "pos",
           "fill_factor": "unit", "qe": "unit", "n_bins": "count",
           "frame_rate_hz": "pos", "detection_area_m2": "pos", "dead_time_s": "nonneg",
           "dcr_median_cps": "nonneg", "compression": "str", "gate_auto": "bool"},
    required_attrs=("bin_s", "gate_s", "pixel_pitch_m", "fill_factor", "qe"),
    view=lambda h5, path, width, height: SpadView(h5, path, width, height),
)
FRAMES_LAYOUT = SensorLayout(
    name="frames",
    datasets={"dn": ("uint16", 3), "t_start": ("float64", 1), "t_end": ("float64", 1)},
    required=("dn", "t_start", "t_end"),
    attrs={"gain_dn_per_e": "pos", "black_level_dn": "nonneg", "bit_depth": "count",
           "qe": "unit", "pixel_pitch_m": "pos", "fill_factor": "unit",
           "read_noise_e": "nonneg", "full_well_e": "pos", "exposure_s": "pos",
           "frame_rate_hz": "pos", "frame_period_s": "pos", "n_frames": "count",
           "dn_max": "count", "rgb": "bool", "rolling_shutter_line_s": "nonneg"},
    required_attrs=("gain_dn_per_e", "black_level_dn", "bit_depth", "qe", "pixel_pitch_m", "fill_factor"),
    view=lambda h5, path, width, height: FramesView(h5, path, "frames"),
)
EVENTS_LAYOUT = SensorLayout(
    name="events",
    datasets={"t": ("int64", 1), "x": ("uint16", 1), "y": ("uint16", 1), "p": ("uint8", 1),
              "label": ("uint8", 1), "ms_to_idx": ("uint64", 1)},
    required=("t", "x", "y", "p", "ms_to_idx"),
    attrs={"threshold_on": "pos", "threshold_off": "pos", "threshold_sigma": "nonneg",
           "refractory_s": "nonneg", "pixel_pitch_m": "pos", "fill_factor": "unit",
           "qe": "unit", "dark_current_e_s": "nonneg",
           "photoreceptor_cutoff_hz_max": "pos", "photoreceptor_cutoff_ref_rate_e_s": "pos",
           "n_events": "count", "ms_to_idx_origin_us": "count", "labels": "json_object",
           "timestamp_unit": "str"},
    required_attrs=("threshold_on", "threshold_off"),
    view=lambda h5, path, width, height: EventsView(h5, path),
)

#: The sensor groups by kind, in the order their groups are listed (and simulated); every layer takes the
#: kinds from here, through :data:`SENSOR_KINDS`.
SENSOR_LAYOUTS: dict[str, SensorLayout] = {row.name: row for row in (SPAD_LAYOUT, FRAMES_LAYOUT, EVENTS_LAYOUT)}


class _Kinds(Sequence):
    """The kinds of :data:`SENSOR_LAYOUTS`, in order: a read-only sequence that follows the table, so that a
    kind registered later is seen by every module that imported ``SENSOR_KINDS`` before."""

    def __getitem__(self, index):
        return tuple(SENSOR_LAYOUTS)[index]

    def __len__(self) -> int:
        return len(SENSOR_LAYOUTS)

    def __iter__(self):
        return iter(tuple(SENSOR_LAYOUTS))

    def __contains__(self, kind) -> bool:
        return kind in SENSOR_LAYOUTS

    def __repr__(self) -> str:
        return repr(tuple(SENSOR_LAYOUTS))


#: The sensor kinds, in table order (``("spad", "frames", "events")`` plus any registered since).
SENSOR_KINDS: Sequence[str] = _Kinds()

#: Reserved: a sensor's name is also an attribute of the reader's ``Recording``.
_RESERVED = frozenset(NON_SENSOR_GROUPS) | {"path", "h5", "attrs", "sensors", "width", "height", "duration_s",
                                             "lux", "scene", "sequence", "spec", "close", "has", "view"}


def register_layout(layout: SensorLayout) -> None:
    """Add the group of a new sensor kind to :data:`SENSOR_LAYOUTS` (after the existing ones).

    Raises ``ValueError`` for a name that is not a lower-case identifier, is reserved, or is taken by another
    layout (registering the same row again is a no-op).
    """
    name = layout.name
    if not (isinstance(name, str) and name.isidentifier() and name == name.lower() and not name.startswith("_")):
        raise ValueError(f"a sensor's name must be a lower-case identifier, got {name!r}")
    if name in _RESERVED:
        raise ValueError(f"{name!r} is reserved (a group or attribute of every recording)")
    if name in SENSOR_LAYOUTS:
        if SENSOR_LAYOUTS[name] is layout:
            return
        raise ValueError(f"a sensor group {name!r} is registered already")
    unknown = [d for d in layout.required if d not in layout.datasets]
    if unknown:
        raise ValueError(f"sensor group {name!r}: required datasets {unknown} not among its datasets")
    if layout.instants is not None and layout.instants not in layout.required:
        raise ValueError(f"sensor group {name!r}: its instants {layout.instants!r} must be a required dataset")
    missing_kind = [a for a in layout.required_attrs if a not in layout.attrs]
    if missing_kind:
        raise ValueError(f"sensor group {name!r}: required attributes {missing_kind} have no kind in attrs")
    SENSOR_LAYOUTS[name] = layout


#: Datasets a group must hold when the group is present, full paths (the built-in groups).
REQUIRED_DATASETS = {
    "gt": ("gt/t", "gt/flux"),
    **{k: tuple(f"{k}/{d}" for d in row.required) for k, row in SENSOR_LAYOUTS.items()},
}
#: Attributes a sensor group must carry when the group is present (the built-in groups).
REQUIRED_GROUP_ATTRS = {k: row.required_attrs for k, row in SENSOR_LAYOUTS.items()}
