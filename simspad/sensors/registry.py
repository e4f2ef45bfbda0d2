"""Sensor table and dispatcher: every sensor kind by name, one :class:`Sensor` row each (docs/internals.md).

A row says everything the rest of the package asks of a sensor: its parameter dataclass and presets, its model
checks, its simulator, what it adds to the recording file (its :class:`~simspad.io.recording.layout.SensorLayout`:
datasets, attributes, read view), how many rows and bytes it stores (the size model of
:mod:`simspad.sensors.recording_size` and :mod:`simspad.dataset.limits`) and its lines in ``simspad info``.
:func:`simspad.sensors.simulate.simulate_recording`, the spec checks, the recording reader and validation and
``simspad info`` iterate over the table; none of them names a kind.

The table starts with the built-in sensors in the order their groups are written; :func:`register` adds a row
(in this process; an installed package adds rows in every process through the ``simspad.sensors`` entry-point
group, loaded when this module is imported). The recording layer (``io``, below this one) keeps the file side of
each row in :data:`~simspad.io.recording.layout.SENSOR_LAYOUTS`, so that reading a recording never needs the
simulators; :func:`register` adds the row's layout there, and its presets to :mod:`simspad.sensors.presets`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, is_dataclass

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.io.recording.layout import (
    EVENTS_LAYOUT,
    FRAMES_LAYOUT,
    SENSOR_LAYOUTS,
    SPAD_LAYOUT,
    SensorLayout,
    register_layout,
)
from simspad.sensors import events, frames, spad
from simspad.sensors.events import describe as events_describe
from simspad.sensors.events import model as events_model
from simspad.sensors.frames import describe as frames_describe
from simspad.sensors.presets import DEFAULT_PRESET, PRESETS, EventParams, FrameParams, SpadParams, register_presets
from simspad.sensors.spad import describe as spad_describe

#: One problem of a dataset spec: (field path, message).
Problem = tuple[str, str]


@dataclass(frozen=True)
class Sensor:
    """One sensor kind: everything the pipeline needs to simulate, check, store, size and describe it.

    Attributes
    ----------
    name : str
        The kind (``"spad"``): the spec's ``[sensors.<name>]`` table, ``--sensors``, the recording's group.
    params : type
        Frozen parameter dataclass (units in field names; a ``kind`` class variable equal to ``name``). The
        built-in ones check their own fields when built (:mod:`simspad.sensors.presets`), so a dataset spec, the
        CLI and the Python API share one rule and one message per field.
    presets : Mapping[str, object]
        Preset name → parameter instance.
    default_preset : str
        The preset used when none is named (a key of ``presets``).
    layout : SensorLayout
        The group it writes (datasets, attributes, read view); ``layout.name == name``.
    validate : callable
        ``validate(params, height_px)``: raise :class:`SimSpadError` naming the field for parameters that do not
        fit an image of that height (the frame camera's rolling-shutter readout); the checks that need the
        recording's size, run by ``simulate_recording`` before anything is written and on every sequence of a
        spec. Rules of a field alone belong to the parameter record.
    simulate : callable
        ``simulate(writer, flux_tl, t0_s, t1_s, params, rng, *, lux, progress) -> dict | None``: write the group
        through the :class:`~simspad.io.recording.RecordingWriter` from the photon-irradiance timeline over
        ``[t0_s, t1_s]``; return the resolved settings (``"exposure_s"`` for the frame camera) or None.
    describe : callable
        ``describe(rec) -> (headline, detail_lines)`` of an open recording holding the group (``simspad info``).
    describe_attrs : tuple of str
        The group attributes shown on its parameter line in ``simspad info``.
    rows : callable, optional
        Size model: ``rows(params, duration_s) -> float``, the rows (samples) the group stores over
        ``duration_s``; None when the scene decides it (events).
    rate_field : str, optional
        The parameter that sets the row rate (``"frame_rate_hz"``, ``"bin_s"``), named in messages; a period
        (``…_s``) is bounded by the model's own checks, a rate by :data:`~simspad.defaults.MAX_RATE_HZ`.
    row_bytes : callable, optional
        ``row_bytes(width_px, height_px) -> int``: uncompressed bytes of one row (with ``rows``).
    precheck : callable, optional
        ``precheck(flux_tl, t0_s, t1_s, params, lux)``: refuse, before anything is written, work that depends
        on the scene (the event camera's noise draws).
    spec_problems : callable, optional
        ``spec_problems(params, where, width_px, height_px, duration_s, lux_levels) -> [(field, message)]``: bounds
        of a dataset spec's sequence ``where`` beyond the model checks (the SPAD's shortest bin, the event
        camera's noise work at each lux level).
    sim_units : callable, optional
        Cost model of ``simspad generate --estimate``: ``sim_units(params, width_px, height_px, duration_s) ->
        float``, the work units a recording's simulation time and bytes scale with (the estimate measures seconds
        and bytes per unit on a probe and multiplies). None: megapixel-rows (``rows × width·height / 1e6``) with a
        size model, else megapixel-seconds (:meth:`work_units`).
    sim_unit : str
        The name of that unit in the estimate's printout (``"Gbit"``); with ``sim_units``.
    summarize : callable, optional
        ``summarize(params) -> str``: its one-line parameter summary in ``simspad info SPEC``; None: the fields.
    """

    name: str
    params: type
    presets: Mapping[str, object]
    default_preset: str
    layout: SensorLayout
    validate: Callable[[object, int], None]
    simulate: Callable[..., dict | None]
    describe: Callable[[object], tuple[str, list[str]]]
    describe_attrs: tuple[str, ...] = ()
    rows: Callable[[object, float], float] | None = None
    rate_field: str | None = None
    row_bytes: Callable[[int, int], int] | None = None
    precheck: Callable[..., None] | None = None
    spec_problems: Callable[..., list[Problem]] | None = None
    sim_units: Callable[[object, int, int, float], float] | None = None
    sim_unit: str = ""
    summarize: Callable[[object], str] | None = None

    def work_units(self, params, width_px: int, height_px: int, duration_s: float) -> float:
        """Work units of simulating ``duration_s`` of this sensor on ``width_px × height_px`` (:attr:`sim_units`,
        or the generic model: megapixel-rows with a size model, megapixel-seconds without)."""
        if self.sim_units is not None:
            return float(self.sim_units(params, width_px, height_px, duration_s))
        mp = width_px * height_px / 1e6
        if self.rows is not None:
            return self.rows(params, duration_s) * mp
        return mp * duration_s

    @property
    def work_unit(self) -> str:
        """The name of :meth:`work_units`' unit (``"Gbit"``, ``"MP·row"``, ``"MP·s"``)."""
        if self.sim_units is not None:
            return self.sim_unit
        return "MP·row" if self.rows is not None else "MP·s"


# -- the built-in rows --------------------------------------------------------------------------------------------

def _no_size_rule(params, height: int) -> None:
    """The SPAD's and the event camera's parameters fit any image size (their records checked every field)."""


def _simulate_spad(writer, flux_tl, t0, t1, params, rng, *, lux, progress):
    return spad.simulate_spad(writer, flux_tl, t0, t1, params, rng, progress)


def _simulate_frames(writer, flux_tl, t0, t1, params, rng, *, lux, progress):
    return frames.simulate_frames(writer, flux_tl, t0, t1, params, rng, progress)


def _simulate_events(writer, flux_tl, t0, t1, params, rng, *, lux, progress):
    return events.simulate_events(writer, flux_tl, t0, t1, params, rng, lux, progress)


def _spad_spec_problems(params, where, width, height, duration_s, lux_levels) -> list[Problem]:
    if params.bin_s >= defaults.MIN_SPAD_BIN_S:
        return []
    return [("sensors.spad.bin_s", f"{params.bin_s!r} s is below {defaults.MIN_SPAD_BIN_S:g} s (shorter than any "
             "SPAD's dead time)")]


def _events_spec_problems(params, where, width, height, duration_s, lux_levels) -> list[Problem]:
    out = []
    for lux in lux_levels:
        problem = events_model.noise_work_problem(params, width * height, duration_s, lux)
        if problem:
            out.append((events_model.noise_field(params, lux), f"{where}: {problem}"))
    return out


def _spad_gbit(params, width, height, duration_s) -> float:
    """Gbit of binary frames over ``duration_s``: whole gates inside it × pixels (the gate resolved as simulated)."""
    gate_s = params.bin_s if params.gate_s == "auto" else params.gate_s
    return spad.n_bins(duration_s, params.bin_s, gate_s) * width * height / 1e9


SPAD = Sensor(
    name="spad", params=SpadParams, presets=PRESETS["spad"],
    default_preset=DEFAULT_PRESET["spad"], layout=SPAD_LAYOUT,
    validate=_no_size_rule,
    simulate=_simulate_spad,
    describe=spad_describe.describe_spad, describe_attrs=spad_describe.DESCRIBE_ATTRS,
    rows=lambda params, duration_s: duration_s / params.bin_s, rate_field="bin_s",
    row_bytes=lambda width, height: height * -(-width // 8),
    spec_problems=_spad_spec_problems,
    sim_units=_spad_gbit, sim_unit="Gbit", summarize=spad_describe.summarize_spad,
)
FRAMES = Sensor(
    name="frames", params=FrameParams, presets=PRESETS["frames"],
    default_preset=DEFAULT_PRESET["frames"], layout=FRAMES_LAYOUT,
    validate=frames.validate_params,
    simulate=_simulate_frames,
    describe=frames_describe.describe_frames, describe_attrs=frames_describe.DESCRIBE_ATTRS,
    rows=lambda params, duration_s: duration_s * params.frame_rate_hz, rate_field="frame_rate_hz",
    row_bytes=lambda width, height: 2 * width * height,
    sim_units=lambda params, width, height, duration_s: int(duration_s * params.frame_rate_hz) * width * height / 1e6,
    sim_unit="MP·frame", summarize=frames_describe.summarize_frames,
)
EVENTS = Sensor(
    name="events", params=EventParams, presets=PRESETS["events"],
    default_preset=DEFAULT_PRESET["events"], layout=EVENTS_LAYOUT,
    validate=_no_size_rule,
    simulate=_simulate_events,
    describe=events_describe.describe_events, describe_attrs=events_describe.DESCRIBE_ATTRS,
    precheck=events.check_noise_work,
    spec_problems=_events_spec_problems, summarize=events_describe.summarize_events,
)

#: The built-in sensors, in the order their groups are written and listed.
BUILTIN_SENSORS: tuple[Sensor, ...] = (SPAD, FRAMES, EVENTS)

#: The table: kind → row, in registration order (the order sensors are simulated and listed).
SENSORS: dict[str, Sensor] = {}
#: Entry-point group through which an installed package adds sensors (docs/internals.md, "Adding a sensor").
ENTRY_POINT_GROUP = "simspad.sensors"
#: Plugin sensors that could not be loaded: name → the one-line reason, reported when the name is asked for.
_BROKEN_PLUGINS: dict[str, str] = {}


def register(sensor: Sensor) -> None:
    """Add ``sensor`` to the table (after the rows there), its layout to the recording layer's table and its
    presets to the preset table; registering the same row again is a no-op.

    Raises ``ValueError`` for a row that contradicts itself (layout or parameter class of another name, a default
    preset that is not one of its presets, presets not of its parameter class) or a name taken by another row.
    """
    if not isinstance(sensor, Sensor):
        raise TypeError(f"expected a simspad.sensors.registry.Sensor, got {sensor!r}")
    name = sensor.name
    if SENSORS.get(name) is sensor:
        return
    if name in SENSORS:
        raise ValueError(f"a sensor {name!r} is registered already")
    if sensor.layout.name != name:
        raise ValueError(f"sensor {name!r}: its layout is named {sensor.layout.name!r}")
    if not (isinstance(sensor.params, type) and is_dataclass(sensor.params)
            and getattr(sensor.params, "kind", None) == name):
        raise ValueError(f"sensor {name!r}: params must be a dataclass with the class variable kind = {name!r}")
    if sensor.default_preset not in sensor.presets:
        raise ValueError(f"sensor {name!r}: default preset {sensor.default_preset!r} is not one of its presets")
    if not all(type(p) is sensor.params for p in sensor.presets.values()):
        raise ValueError(f"sensor {name!r}: every preset must be a {sensor.params.__name__}")
    if (sensor.rows is None) != (sensor.row_bytes is None):
        raise ValueError(f"sensor {name!r}: rows and row_bytes go together (the size model)")
    if (sensor.sim_units is None) != (not sensor.sim_unit):
        raise ValueError(f"sensor {name!r}: sim_units and sim_unit go together (the estimate's cost model)")
    if SENSOR_LAYOUTS.get(name) is not sensor.layout:
        register_layout(sensor.layout)
    register_presets(name, sensor.presets, sensor.default_preset)
    SENSORS[name] = sensor


for _row in BUILTIN_SENSORS:
    register(_row)


def _load_plugins() -> None:
    """Register the sensors of installed packages (entry points of :data:`ENTRY_POINT_GROUP`, each a
    :class:`Sensor` row). A plugin that fails to import, is not a row, is named otherwise than its entry point or
    takes a built-in name is kept out and remembered, so that the run that asks for it gets one line naming the
    entry point, and every other run is unaffected."""
    from importlib.metadata import entry_points  # deferred: only the registry asks for plugins

    for ep in entry_points(group=ENTRY_POINT_GROUP):
        where = f"plugin sensor {ep.name!r} (entry point {ep.value!r} of group {ENTRY_POINT_GROUP!r})"
        try:
            row = ep.load()
        except Exception as exc:  # a broken plugin must not stop the built-in sensors
            _BROKEN_PLUGINS[ep.name] = f"{where} failed to load: {type(exc).__name__}: {exc}"
            continue
        if not isinstance(row, Sensor):
            _BROKEN_PLUGINS[ep.name] = f"{where} is not a simspad.sensors.registry.Sensor row"
        elif row.name != ep.name:
            _BROKEN_PLUGINS[ep.name] = f"{where}: the sensor's name is {row.name!r}; the entry point must be named so"
        elif row.name in SENSORS:
            _BROKEN_PLUGINS[ep.name] = f"{where} takes the name of a sensor registered already"
        else:
            try:
                register(row)
            except ValueError as exc:
                _BROKEN_PLUGINS[ep.name] = f"{where}: {exc}"


_load_plugins()


def get_sensor(kind: str, *, field: str = "sensors") -> Sensor:
    """The row of sensor ``kind``; :class:`SimSpadError` naming ``field`` and the known kinds otherwise (or why
    a plugin of that name could not be loaded)."""
    if kind in SENSORS:
        return SENSORS[kind]
    if kind in _BROKEN_PLUGINS:
        raise SimSpadError(_BROKEN_PLUGINS[kind], field=field)
    raise SimSpadError(f"unknown sensor {kind!r} (expected one of {', '.join(SENSORS)})", field=field)


def ordered(sensors: Mapping[str, object]) -> list[tuple[Sensor, object]]:
    """``(row, params)`` of every kind in ``sensors`` (``{kind: params}``), in table order; an unknown kind is a
    :class:`SimSpadError` naming it."""
    for kind in sensors:
        get_sensor(kind)
    return [(row, sensors[kind]) for kind, row in SENSORS.items() if kind in sensors]
