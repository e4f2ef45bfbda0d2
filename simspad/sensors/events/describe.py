"""The event camera's lines of ``simspad info`` (:func:`describe_events`, the ``describe`` of its sensor-table
row). Event rates are per pixel of the simulation grid; an event is 32 bits of readout (docs/methods.md)."""

from __future__ import annotations

import numpy as np

from simspad.sensors.text import format_duration_s, pixel_text

#: Attributes shown on the group's parameter line.
DESCRIBE_ATTRS = ("preset", "threshold_on", "threshold_off", "threshold_sigma", "refractory_s", "pixel_pitch_m")


def describe_events(rec) -> tuple[str, list[str]]:
    """Headline (events, ev/s, ev/pixel/s, ON share) and detail lines (label shares, readout bandwidth) of
    ``rec``'s ``/events``."""
    n_px, dur = rec.width * rec.height, rec.duration_s
    n = rec.events.n_events
    rate_px = n / (n_px * dur) if dur > 0 else float("nan")
    labels = ""
    if n and "events/label" in rec.h5:
        counts = np.zeros(4, np.int64)
        step = 1 << 22
        ds = rec.h5["events/label"]
        for i in range(0, n, step):
            counts += np.bincount(np.minimum(ds[i : i + step], 3), minlength=4)[:4]
        labels = ", ".join(f"{name} {c / n:.1%}" for name, c in zip(("signal", "shot", "leak", "hot"), counts))
    on = ""
    if n:
        p = rec.h5["events/p"][: min(n, 1 << 22)]
        on = f", ON {p.mean():.1%}"
    return (f"{n} events ({n / dur if dur > 0 else float('nan'):.4g} ev/s, {rate_px:.4g} ev/pixel/s{on})",
            [*([f"labels: {labels}"] if labels else []),
             f"bandwidth {rate_px / 1e3:.4g} kHz/pixel = {rate_px * 32:.4g} bit/pixel/s (32 bit/event)"])


def summarize_events(p) -> str:
    """The event camera's parameter line of ``simspad info SPEC``: pixel, thresholds, refractory, latency."""
    return (f"{pixel_text(p)}, thresholds +{p.threshold_on:g}/−{p.threshold_off:g} (σ {p.threshold_sigma:g}), "
            f"refractory {format_duration_s(p.refractory_s)}, latency {format_duration_s(p.latency_s)}")
