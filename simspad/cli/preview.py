"""``simspad preview``: a video (or GIF, or PNG strip) of a recording's sensors and ground truth side by side."""

from __future__ import annotations

from pathlib import Path

import click

from simspad.analysis.preview import PANEL_SENSORS, PreviewSettings, write_preview
from simspad.errors import SimSpadError
from simspad.evaluate.recordings import list_recordings
from simspad.io.atomic import check_output_path
from simspad.io.names import recording_key
from simspad.io.recording import open_recording


def preview_from_cli(target, out_path, *, kind: str = "mp4", **settings) -> list[Path]:
    """One preview for a recording (``out_path`` names the file), or one per recording of a dataset directory
    (``out_path`` is a folder; files named by recording key with ``kind``'s suffix). Prints each file written."""
    settings = PreviewSettings(**settings)
    settings.check()
    target, out_path = Path(target), Path(out_path)
    if target.is_dir():
        check_output_path(out_path, kind="dir")
        entries, _ = list_recordings(target)
        jobs = []
        for e in entries:
            with open_recording(e.path) as rec:
                key = recording_key(str(rec.attrs.get("sequence") or rec.scene or e.path.stem), float(rec.lux),
                                    float(rec.attrs.get("speed_factor", 1.0)))
            jobs.append((e.path, out_path / f"{key}.{kind}"))
    elif target.suffix.lower() in (".h5", ".hdf5") or target.exists():
        jobs = [(target, out_path)]
    else:
        raise SimSpadError("no such recording file or dataset directory", path=target)
    written = []
    for rec_path, out in jobs:
        res = write_preview(rec_path, out, settings, progress=True)
        click.echo(f"wrote {res.path}: {res.n_frames} frame(s) of {res.width_px}×{res.height_px} px, "
                   f"t = {res.times_s[0] * 1e3:.3f}–{res.times_s[-1] * 1e3:.3f} ms")
        if res.no_panel:
            click.echo(f"  no panel for {', '.join(res.no_panel)}: the preview draws the ground truth and "
                       f"{', '.join(PANEL_SENSORS)} only")
        written.append(res.path)
    return written
