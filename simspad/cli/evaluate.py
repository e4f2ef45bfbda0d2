"""``simspad evaluate``: evaluate, print a short table, exit 1 when a method run failed."""

from __future__ import annotations

from pathlib import Path

import click

from simspad.evaluate.evaluate import EvaluationFailed, evaluate
from simspad.io.results_dir import recording_key


def summary_table(rows: list[dict]) -> str:
    """A short text table of the rows (for the terminal)."""
    lines = [f"{'method':<20} {'recording':<28} {'PSNR dB':>8} {'SSIM':>6} {'kHz/px':>9}"]
    for r in rows:
        key = recording_key(r["sequence"], r["lux"])[:28]
        if r.get("error"):
            lines.append(f"{r['method'][:20]:<20} {key:<28} FAILED: {r['error'][:80]}")
        else:
            lines.append(f"{r['method'][:20]:<20} {key:<28} {r['psnr_db']:8.2f} {r['ssim']:6.3f} "
                         f"{r['bandwidth_khz_per_pixel']:9.3f}")
    return "\n".join(lines)


def evaluate_from_cli(target, methods=None, out_dir=None, rate_hz=None) -> Path:
    """The ``simspad evaluate`` command: evaluate, print a summary, raise EvaluationFailed if a run failed."""
    out, rows = evaluate(target, methods=methods, out_dir=out_dir, rate_hz=rate_hz)
    click.echo(summary_table(rows))
    click.echo(f"wrote {out / 'results.csv'}")
    failed = [r for r in rows if r.get("error")]
    if failed:
        raise EvaluationFailed(f"{len(failed)} of {len(rows)} method runs failed (see the error column)",
                               path=out / "results.csv", field="error")
    return out
