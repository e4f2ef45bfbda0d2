"""The frame camera's lines of ``simspad info`` (:func:`describe_frames`, the ``describe`` of its sensor-table
row)."""

from __future__ import annotations

from simspad.sensors.text import format_duration_s, pixel_text

#: Attributes shown on the group's parameter line.
DESCRIBE_ATTRS = ("preset", "exposure_s", "gain_dn_per_e", "read_noise_e", "full_well_e", "bit_depth", "qe",
                  "pixel_pitch_m")


def describe_frames(rec) -> tuple[str, list[str]]:
    """Headline (frames and their rate, fps) and detail lines (first frame's mean DN, readout bandwidth) of
    ``rec``'s ``/frames``."""
    fa = rec.frames.attrs
    k = rec.frames.n_frames
    t0 = rec.frames.t_start
    rate = float(fa.get("frame_rate_hz", (k - 1) / (t0[-1] - t0[0]) if k > 1 and t0[-1] > t0[0] else 0.0))
    bits = int(fa.get("bit_depth", 16))
    mean_dn = float(rec.frames.dn(0).mean()) if k else float("nan")
    return (f"{k} frames at {rate:.4g} fps",
            [f"first frame mean {mean_dn:.1f} DN",
             f"bandwidth {rate / 1e3:.4g} kHz/pixel = {rate * bits:.4g} bit/pixel/s"])


def summarize_frames(p) -> str:
    """The frame camera's parameter line of ``simspad info SPEC``: pixel, rate, exposure, gain, noise, range."""
    return (f"{pixel_text(p)}, {p.frame_rate_hz:g} fps, exposure {format_duration_s(p.exposure_s)}, K "
            f"{p.gain_dn_per_e:g} DN/e⁻, read noise {p.read_noise_e:g} e⁻, full well {p.full_well_e:g} e⁻, "
            f"{p.bit_depth} bit")
