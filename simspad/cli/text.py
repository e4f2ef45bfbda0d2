"""Text building blocks of the command summaries: byte sizes, durations and the per-recording table."""

from __future__ import annotations

from typing import Callable

from simspad.sensors.text import format_duration_s  # noqa: F401  (the cli summaries format durations so)


def format_bytes(n) -> str:
    """``n`` bytes in binary units (``"512 B"``, ``"1.5 MiB"``); ``"-"`` for None."""
    if n is None:
        return "-"
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"


def recording_table(recordings: list[dict], last_column: str, last_value: Callable[[dict], str]) -> list[str]:
    """One aligned line per manifest recording entry (sequence, speed, lux, status, size, simulate time, last
    column), after a header line; text columns left-aligned, numbers right-aligned, trailing blanks stripped."""
    rows = [("sequence", "speed", "lux", "status", "size", "simulate", last_column)]
    for e in recordings:
        t = (e.get("timings") or {}).get("simulate_s")
        rows.append((e["sequence"], f"×{float(e.get('speed_factor', 1.0)):g}", f"{e['lux']:g}", e["status"],
                     format_bytes(e.get("size")), "-" if t is None else f"{t:.1f} s", last_value(e)))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  ".join(c.ljust(w) if i in (0, 3, 6) else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
            .rstrip() for r in rows]
