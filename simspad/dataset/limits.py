"""Resource bounds and cross-field rules of a dataset spec, checked by ``simspad info SPEC`` before any work.

Per-field checks live with the records (:mod:`simspad.dataset.spec_validation` runs them; a sequence's render
fields and their bounds are :meth:`simspad.render.settings.RenderSettings.problems`, a lux level
:func:`simspad.sensors.recording_settings.lux_problem`); this module adds what needs several fields or a bound
with a figure: every sensor's rule at the sequence's size (its table row's ``validate(params, height)``, the
one :func:`~simspad.sensors.simulate.simulate_recording` runs, so nothing fails after rendering; each parameter's
own rule is its record's, checked when the spec built it) and its own bounds (its sensor-table row's ``spec_problems``: the SPAD's shortest bin, the
event camera's noise work, a lower bound whatever the scene), and the number of rows of every sensor stream with a
size model (frames, SPAD bins) and of ground-truth instants of each recording (at least one, at most
:data:`~simspad.defaults.MAX_SAMPLES_PER_RECORDING`).
"""

from __future__ import annotations

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.render.settings import limits_ignored
from simspad.sensors.registry import ordered


def spec_limit_problems(spec) -> list[tuple[str, str]]:
    """(field path, message) for every bound or cross-field rule ``spec`` breaks (empty: fine)."""
    out: list[tuple[str, str]] = []
    sensors = ordered({kind: s.params for kind, s in spec.sensors.items()})
    for i, seq in enumerate(spec.sequences):
        where = f"sequences[{i}]"
        w, h = seq.resolution
        for row, params in sensors:  # each sensor's model checks at this size, then its own bounds
            out += _model_problems(row.validate, params, h)
            if row.spec_problems is not None:
                out += row.spec_problems(params, where, w, h, seq.duration_s, tuple(spec.lux))
        out += _count_problems(spec, seq, where, sensors)
    return list(dict.fromkeys(out))  # a sensor problem found for every sequence is reported once


def _model_problems(checker, *args) -> list[tuple[str, str]]:
    try:
        checker(*args)
    except SimSpadError as exc:
        return [(exc.field or "sensors", exc.message)]
    except ValueError as exc:
        return [("sensors", str(exc))]
    return []


def _count_problems(spec, seq, where: str, sensors) -> list[tuple[str, str]]:
    """At least one sample of every stream the recording holds; at most MAX_SAMPLES_PER_RECORDING of each (the
    sensors' rows per second from their table rows' size model; ``sensors``: (row, params) in table order)."""
    out = []
    rates = {"evaluation.rate_hz": spec.evaluation.rate_hz, "ground-truth rate": defaults.GT_RATE_HZ}
    for row, params in sensors:
        if row.rows is not None:
            rates[f"sensors.{row.name}.{row.rate_field}"] = row.rows(params, 1.0)
    for name, rate_hz in rates.items():
        # a period (bin_s) is bounded by its model's check, a rate by MAX_RATE_HZ
        if not name.endswith("_s") and rate_hz > defaults.MAX_RATE_HZ and not limits_ignored():
            out.append((name, f"{rate_hz:.3g} Hz is above the limit of {defaults.MAX_RATE_HZ:.3g} Hz (set "
                        "SIMSPAD_IGNORE_LIMITS=1 to try anyway)"))
            continue
        n = seq.duration_s * rate_hz
        if n < 1:
            out.append((f"{where}.duration_s", f"{seq.duration_s:g} s is shorter than one period of {name} "
                        f"({1 / rate_hz:g} s): the recording would hold no sample of it"))
        elif n > defaults.MAX_SAMPLES_PER_RECORDING and not limits_ignored():
            out.append((name, f"{seq.duration_s:g} s of {where} at {rate_hz:.3g} Hz is {n:.3g} samples per "
                        f"recording; the limit is {defaults.MAX_SAMPLES_PER_RECORDING:.3g} (set "
                        "SIMSPAD_IGNORE_LIMITS=1 to try anyway)"))
    return out
