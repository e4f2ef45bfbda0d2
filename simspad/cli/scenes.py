"""``simspad scenes``: list the built-in scenes; optionally render them all into one contact sheet."""

from __future__ import annotations

from pathlib import Path

import click

from simspad.bundled import bundled_relative
from simspad.io.atomic import PNG_MAGIC, check_output_file, starts_with
from simspad.render.contact_sheet import write_contact_sheet
from simspad.scenes.library import list_scenes


def scenes_from_cli(contact_sheet: Path | None = None) -> None:
    """``simspad scenes``: print the built-in scenes; optionally render all of them into one contact sheet."""
    if contact_sheet is not None:
        check_output_file(contact_sheet, field="--contact-sheet", recognise=starts_with(PNG_MAGIC),
                          what="a PNG image")  # before minutes of rendering
    scenes = list_scenes()
    width = max((len(s.name) for s in scenes), default=4)
    trajs = [_display_path(s.default_trajectory) if s.default_trajectory else "-" for s in scenes]
    traj_width = max((len(t) for t in trajs), default=1)
    for s, traj in zip(scenes, trajs):
        objs = f"  [animated: {', '.join(s.objects)}]" if s.objects else ""
        click.echo(f"{s.name:<{width}}  {traj:<{traj_width}}  {s.description}{objs}")
    if contact_sheet is not None:
        path = write_contact_sheet(Path(contact_sheet), scenes)
        click.echo(f"wrote {path}")


def _display_path(path: Path) -> str:
    """A bundled trajectory as ``trajectories/<file>`` (what ``--trajectory`` accepts), any other path as it is."""
    return bundled_relative(path) or str(path)
