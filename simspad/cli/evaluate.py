"""``simspad evaluate``: evaluate, print a short table and per-method timings, exit 1 when a method run failed."""

from __future__ import annotations

from pathlib import Path

import click

from simspad.analysis.preview import write_preview
from simspad.cli.simulate import parse_value
from simspad.errors import SimSpadError
from simspad.evaluate.evaluate import EvaluationFailed, evaluate
from simspad.io.names import recording_key


def summary_table(rows: list[dict]) -> str:
    """A short text table of the rows (for the terminal)."""
    lines = [f"{'method':<20} {'recording':<28} {'PSNR dB':>8} {'SSIM':>6} {'kHz/px':>9}"]
    for r in rows:
        key = recording_key(r["sequence"], r["lux"], r.get("speed_factor", 1.0))[:28]
        if r.get("error"):
            lines.append(f"{r['method'][:20]:<20} {key:<28} FAILED: {r['error'][:80]}")
        elif r["psnr_db"] != r["psnr_db"] and r.get("white_point_ph_s_m2") != r.get("white_point_ph_s_m2"):
            # no ground truth (a real capture): the scores do not exist, they are not zero
            lines.append(f"{r['method'][:20]:<20} {key:<28} {'n/a':>8} {'n/a':>6} {r['bandwidth_khz_per_pixel']:9.3f}"
                         f"  (no ground truth; MTF {r['mtf_at_0p25_cyc_px']:.3f} at 0.25, "
                         f"{r['mtf_at_0p40_cyc_px']:.3f} at 0.40 cyc/px)")
        else:
            lines.append(f"{r['method'][:20]:<20} {key:<28} {r['psnr_db']:8.2f} {r['ssim']:6.3f} "
                         f"{r['bandwidth_khz_per_pixel']:9.3f}")
    return "\n".join(lines)


def timing_table(timings: list[dict]) -> str:
    """Per-method timings (for the terminal): runs, seconds inside the method and in all, slowest first."""
    lines = [f"{'method':<20} {'runs':>5} {'method s':>9} {'total s':>9} {'s/run':>7}"]
    for t in sorted(timings, key=lambda t: -t["total_s"]):
        lines.append(f"{t['method'][:20]:<20} {t['runs']:5d} {t['method_s']:9.1f} {t['total_s']:9.1f} "
                     f"{t['total_s'] / max(t['runs'], 1):7.2f}")
    return "\n".join(lines)


def parse_method_params(items) -> dict[str, dict]:
    """``["nedi_akf.aggregate_hz=800", ...]`` → ``{"nedi_akf": {"aggregate_hz": 800}}``; values typed as
    ``--set``'s; SimSpadError naming ``--param`` on a malformed item (names and values are checked by evaluate)."""
    out: dict[str, dict] = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        method, dot, name = key.strip().partition(".")
        if not sep or not dot or not method or not name.strip():
            raise SimSpadError(f"expected METHOD.NAME=VALUE, got {item!r}", field="--param")
        out.setdefault(method, {})[name.strip()] = parse_value(value)
    return out


def preview_strip(recording: Path, out: Path) -> None:
    """A PNG strip of a recording's sensors (``simspad preview``), for recordings without ground truth."""
    out.parent.mkdir(parents=True, exist_ok=True)
    write_preview(recording, out)


def evaluate_from_cli(target, methods=None, out_dir=None, rate_hz=None, params=()) -> Path:
    """The ``simspad evaluate`` command: evaluate, print a summary and the per-method timings, raise
    EvaluationFailed if a run failed."""
    timings: list[dict] = []
    out, rows = evaluate(target, methods=methods, out_dir=out_dir, rate_hz=rate_hz, timings=timings,
                         params=parse_method_params(params), preview=preview_strip)
    click.echo(summary_table(rows))
    click.echo("")
    click.echo("timings (method s: inside the method; total s: with scoring and writing; summed over workers)")
    click.echo(timing_table(timings))
    click.echo(f"wrote {out / 'results.csv'}")
    failed = [r for r in rows if r.get("error")]
    if failed:
        raise EvaluationFailed(f"{len(failed)} of {len(rows)} method runs failed (see the error column)",
                               path=out / "results.csv", field="error")
    return out
