"""Text shared by the sensors' summary lines (``simspad info``): durations in the unit that reads best and the
pixel line every built-in sensor starts its parameter summary with."""

from __future__ import annotations


def format_duration_s(x) -> str:
    """A duration in seconds with the unit that reads best (``"10 ms"``, ``"1.5 µs"``); text (``"auto"``) as is."""
    if isinstance(x, str):
        return x
    x = float(x)
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("ns", 1e-9)):
        if abs(x) >= scale:
            return f"{x / scale:.4g} {unit}"
    return f"{x:g} s"


def pixel_text(p) -> str:
    """``pitch … µm, fill …, QE …`` of parameters ``p`` with ``pixel_pitch_m``, ``fill_factor`` and ``qe``."""
    return f"pitch {p.pixel_pitch_m * 1e6:.4g} µm, fill {p.fill_factor:.3g}, QE {p.qe:.3g}"
