"""Every exporter: the same recording gives the same bytes, and an unknown format is one clear error."""

from __future__ import annotations

import hashlib

import pytest

from simspad.errors import SimSpadError
from simspad.io.export import FORMATS
from simspad.io.export.dispatch import export_recording


@pytest.mark.parametrize("fmt", ["dsec", "evt3", "aedat4"])
def test_same_recording_same_bytes(event_source, tmp_path, fmt):
    if fmt == "aedat4":
        pytest.importorskip("dv_processing")
    a = export_recording(event_source.path, fmt, tmp_path / "a" / "out", chunk_events=20_000)
    b = export_recording(event_source.path, fmt, tmp_path / "b" / "out", chunk_events=50_000)
    assert hashlib.sha256(a.read_bytes()).digest() == hashlib.sha256(b.read_bytes()).digest()


def test_unknown_format_names_the_choices(event_source, tmp_path):
    with pytest.raises(SimSpadError, match="--to.*'mp4'.*" + ", ".join(FORMATS)):
        export_recording(event_source.path, "mp4", tmp_path / "x")
