"""A toy sensor added through the sensor table alone: a photodiode that records the mean photon irradiance over
the whole sensor in each of its sampling periods (the proof that adding a sensor is one folder plus one row,
docs/internals.md "Adding a sensor"). Used in-process by tests/sensors/test_sensor_table.py and, copied into a
package with a ``simspad.sensors`` entry point, by its plugin test."""

from __future__ import annotations

import typing
from dataclasses import dataclass

import numpy as np

from simspad.errors import SimSpadError
from simspad.io.recording.group import GroupView
from simspad.io.recording.layout import SensorLayout
from simspad.sensors.presets import params_to_attrs
from simspad.sensors.registry import Sensor


@dataclass(frozen=True)
class PhotodiodeParams:
    """A single large photodiode covering the sensor."""

    kind: typing.ClassVar[str] = "photodiode"
    rate_hz: float = 2000.0
    """Samples per second; sample k averages the irradiance over [t0 + k/rate_hz, t0 + (k+1)/rate_hz)."""


def validate_params(params: PhotodiodeParams, height: int) -> None:
    if not params.rate_hz > 0:
        raise SimSpadError("must be > 0", field="sensors.photodiode.rate_hz")


def simulate_photodiode(writer, flux_tl, t0, t1, params, rng, *, lux, progress):
    """Write ``/photodiode``: ``t`` [n] s (period starts) and ``mean_flux`` [n] ph s⁻¹ m⁻² (the period's average
    over time and pixels)."""
    n = int((t1 - t0) * params.rate_hz)
    starts = t0 + np.arange(n) / params.rate_hz
    means = np.array([float(flux_tl.mean(a, a + 1 / params.rate_hz).mean(dtype=np.float64)) for a in starts])
    writer.write_dataset("photodiode/t", starts)
    writer.write_dataset("photodiode/mean_flux", means)
    writer.set_attrs("photodiode", **params_to_attrs(params), n_samples=n)
    return {"n_samples": n}


class PhotodiodeView(GroupView):
    """``/photodiode`` of an open recording."""

    @property
    def t(self) -> np.ndarray:
        return self._dataset("t")[()]

    @property
    def mean_flux(self) -> np.ndarray:
        return self._dataset("mean_flux")[()]


def describe_photodiode(rec) -> tuple[str, list[str]]:
    flux = rec.photodiode.mean_flux
    return f"{flux.size} samples", [f"mean {flux.mean():.4g} ph/s/m²"]


PHOTODIODE = Sensor(
    name="photodiode", params=PhotodiodeParams, presets={"basic": PhotodiodeParams()}, default_preset="basic",
    layout=SensorLayout(name="photodiode", datasets={"t": ("float64", 1), "mean_flux": ("float64", 1)},
                        required=("t", "mean_flux"), attrs={"rate_hz": "pos", "n_samples": "count"},
                        required_attrs=("rate_hz",),
                        view=lambda h5, path, width, height: PhotodiodeView(h5, path, "photodiode"),
                        instants="t"),
    validate=validate_params, simulate=simulate_photodiode,
    describe=describe_photodiode, describe_attrs=("rate_hz",),
    rows=lambda params, duration_s: duration_s * params.rate_hz, rate_field="rate_hz",
    row_bytes=lambda width, height: 16,
)
