"""The SPAD group's lines of ``simspad info`` (:func:`describe_spad`, the ``describe`` of its sensor-table row)."""

from __future__ import annotations

import numpy as np

from simspad.sensors.text import format_duration_s, pixel_text

#: Binary frames read to estimate the mean detection probability (cheap: the file is not read whole).
SAMPLE_BINS = 1024
#: Attributes shown on the group's parameter line.
DESCRIBE_ATTRS = ("preset", "bin_s", "gate_s", "pixel_pitch_m", "fill_factor", "qe", "dead_time_s")


def describe_spad(rec) -> tuple[str, list[str]]:
    """Headline (binary frames and their rate, kHz) and detail lines (mean detection probability of the first
    :data:`SAMPLE_BINS` frames, median dark count rate, readout bandwidth) of ``rec``'s ``/spad``."""
    n_px = rec.width * rec.height
    sa = rec.spad.attrs
    n_bins = rec.spad.n_bins
    bin_s = float(sa["bin_s"])
    sample = min(n_bins, SAMPLE_BINS)
    p1 = float(rec.spad.counts(0, sample).sum()) / (sample * n_px) if sample else float("nan")
    dcr = rec.spad.dcr_cps
    return (f"{n_bins} binary frames ({1 / bin_s / 1e3:.4g} kHz)",
            [f"mean P(1) {p1:.4f} (first {sample} frames), DCR median {np.median(dcr):.3g} cps",
             f"bandwidth {1 / bin_s / 1e3:.4g} kHz/pixel = {1 / bin_s:.4g} bit/pixel/s "
             f"({n_px / bin_s / 8 / 2**20:.4g} MiB/s for the grid)"])


def summarize_spad(p) -> str:
    """The SPAD's parameter line of ``simspad info SPEC``: pixel, bin (and rate), gate, dark counts, dead time."""
    return (f"{pixel_text(p)}, bin {format_duration_s(p.bin_s)} ({1 / p.bin_s / 1e3:.4g} kHz), gate "
            f"{format_duration_s(p.gate_s)}, DCR median {p.dcr_median_cps:g} cps, dead time "
            f"{format_duration_s(p.dead_time_s)}")
