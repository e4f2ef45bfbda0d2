"""Resource bounds and cross-field rules of a dataset spec, checked by ``simspad info SPEC`` before any work.

Per-field checks live with the records (:mod:`simspad.dataset.spec_validation` runs them; a sequence's render
fields and their bounds are :meth:`simspad.render.settings.RenderSettings.problems`, a lux level
:func:`simspad.sensors.recording_settings.lux_problem`); this module adds what needs several fields or a bound
with a figure: every sensor's model checks at the sequence's size
(the same ones the simulators run, so nothing fails after rendering), the event camera's noise
work (:func:`simspad.sensors.events.model.noise_work_problem`, a lower bound whatever the scene), and the number
of frames, SPAD bins and ground-truth instants of each recording (at least one, at most
:data:`~simspad.defaults.MAX_SAMPLES_PER_RECORDING`).
"""

from __future__ import annotations

from simspad import defaults
from simspad.errors import SimSpadError
from simspad.render.settings import limits_ignored
from simspad.sensors.events import model as events_model
from simspad.sensors.frames import model as frames_model
from simspad.sensors.spad import model as spad_model

def spec_limit_problems(spec) -> list[tuple[str, str]]:
    """(field path, message) for every bound or cross-field rule ``spec`` breaks (empty: fine)."""
    out: list[tuple[str, str]] = []
    for kind, checker in (("spad", spad_model.validate_params), ("events", events_model.validate_params)):
        if kind in spec.sensors:
            out += _model_problems(checker, spec.sensors[kind].params)
    spad = spec.sensors.get("spad")
    if spad is not None and not spad.params.bin_s >= defaults.MIN_SPAD_BIN_S:
        out.append(("sensors.spad.bin_s", f"{spad.params.bin_s!r} s is below {defaults.MIN_SPAD_BIN_S:g} s (shorter "
                    "than any SPAD's dead time)"))
    for i, seq in enumerate(spec.sequences):
        where = f"sequences[{i}]"
        w, h = seq.resolution
        if "frames" in spec.sensors:
            out += _model_problems(frames_model.validate_params, spec.sensors["frames"].params, h)
        out += _count_problems(spec, seq, where)
        if "events" in spec.sensors:
            params = spec.sensors["events"].params
            for lux in spec.lux:
                problem = events_model.noise_work_problem(params, w * h, seq.duration_s, lux)
                if problem:
                    out.append((events_model.noise_field(params, lux), f"{where}: {problem}"))
    return list(dict.fromkeys(out))  # a sensor problem found for every sequence is reported once


def _model_problems(checker, *args) -> list[tuple[str, str]]:
    try:
        checker(*args)
    except SimSpadError as exc:
        return [(exc.field or "sensors", exc.message)]
    except ValueError as exc:
        return [("sensors", str(exc))]
    return []


def _count_problems(spec, seq, where: str) -> list[tuple[str, str]]:
    """At least one sample of every stream the recording holds; at most MAX_SAMPLES_PER_RECORDING of each."""
    out = []
    rates = {"evaluation.rate_hz": spec.evaluation.rate_hz, "ground-truth rate": defaults.GT_RATE_HZ}
    if "frames" in spec.sensors:
        rates["sensors.frames.frame_rate_hz"] = spec.sensors["frames"].params.frame_rate_hz
    if "spad" in spec.sensors:
        rates["sensors.spad.bin_s"] = 1.0 / spec.sensors["spad"].params.bin_s
    for name, rate_hz in rates.items():
        if not name.endswith("bin_s") and rate_hz > defaults.MAX_RATE_HZ and not limits_ignored():
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
