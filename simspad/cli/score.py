"""``simspad score``: score a submission, print a short table and what the submission left out."""

from __future__ import annotations

import json
from pathlib import Path

import click

from simspad.cli.evaluate import summary_table
from simspad.evaluate.score import score


def score_from_cli(submission, dataset_dir, out_dir=None) -> Path:
    """The ``simspad score`` command."""
    out, rows = score(submission, dataset_dir, out_dir)
    click.echo(summary_table(rows))
    missing = json.loads((out / "results.json").read_text(encoding="utf-8")).get("missing_recordings", [])
    click.echo(f"scored {len(rows)} recording(s)" + (f"; {len(missing)} of the dataset not in the submission"
                                                    if missing else "") + f"; wrote {out / 'results.csv'}")
    return out
