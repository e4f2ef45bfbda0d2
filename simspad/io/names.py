"""How numbers appear in SimSPAD's names: recording keys, file names, render folders.

One rule for every number in a name: an integral value prints as an integer (``10000``, ``16``), any other value
as Python's shortest round-trip ``repr`` (``0.5``, ``2.5``, ``1e-05``), so a name maps back to exactly one value
and a recording's key always equals its file name's stem.
"""

from __future__ import annotations


def number_label(x: float) -> str:
    """``x`` as it appears in names: ``1``, ``10000``, ``0.5``, ``2.5``."""
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def lux_label(lux: float) -> str:
    """The lux level as it appears in names: ``1``, ``10000``, ``0.5``."""
    return number_label(lux)


def speed_label(k: float) -> str:
    """The speed factor as it appears in names: ``8``, ``0.5``, ``2.5``."""
    return number_label(k)


def speed_suffix(k: float) -> str:
    """``""`` for k = 1 (names as without a speed axis), else ``"_x<k>"``."""
    return "" if float(k) == 1.0 else f"_x{speed_label(k)}"


def recording_key(sequence: str, lux: float, speed_factor: float = 1.0) -> str:
    """The key of a recording, its file name's stem: ``<sequence>[_x<k>]_<lux>lx``, e.g. ``office_10lx``,
    ``office_x16_10lx`` (the speed part only for a factor other than 1)."""
    return f"{sequence}{speed_suffix(speed_factor)}_{lux_label(lux)}lx"
