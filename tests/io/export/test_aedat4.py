"""AEDAT 4 export through dv-processing, read back by dv-processing's own recording reader."""

from __future__ import annotations

import numpy as np
import pytest

from simspad.io.export.dispatch import export_recording


def test_dv_processing_reads_back_every_event(event_source, tmp_path):
    dv = pytest.importorskip("dv_processing")
    out = export_recording(event_source.path, "aedat4", tmp_path / "rec.aedat4", chunk_events=25_000)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left behind
    rec = dv.io.MonoCameraRecording(str(out))
    assert rec.getCameraName() == "SimSPAD"
    assert tuple(rec.getEventResolution()) == (346, 260)
    batches = []
    while (batch := rec.getNextEventBatch()) is not None:
        batches.append(batch.numpy())
    events = np.concatenate(batches)
    np.testing.assert_array_equal(events["timestamp"], event_source.t)
    np.testing.assert_array_equal(events["x"], event_source.x)
    np.testing.assert_array_equal(events["y"], event_source.y)
    np.testing.assert_array_equal(events["polarity"], event_source.p)
