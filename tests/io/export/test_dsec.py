"""DSEC export, read back by DSEC's own EventSlicer and by tonic's DSEC loader."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from simspad.errors import InputError
from simspad.io.export.dispatch import export_recording
from tests.io.export.conftest import write_event_recording
from tests.io.export.dsec_eventslicer import EventSlicer


def _select(src, t0_us, t1_us):
    keep = (src.t >= t0_us) & (src.t < t1_us)
    return {"t": src.t[keep], "x": src.x[keep], "y": src.y[keep], "p": src.p[keep]}


def test_dsec_eventslicer_returns_every_window_exactly(event_source, tmp_path):
    out = export_recording(event_source.path, "dsec", tmp_path / "events.h5", chunk_events=7_777)
    rng = np.random.default_rng(1)
    with h5py.File(out, "r") as h5:
        assert h5["t_offset"][()] == 12_000 and h5["events/p"].dtype == np.uint8
        slicer = EventSlicer(h5)
        assert slicer.get_start_time_us() == 12_000
        assert slicer.get_final_time_us() == event_source.t[-1]
        n_checked = 0
        for _ in range(400):
            a = int(rng.integers(12_000, 52_000))
            b = a + int(rng.integers(1, 6_000))
            got = slicer.get_events(a, b)
            if b - 12_000 > 1000 * (h5["ms_to_idx"].shape[0] - 1):
                assert got is None  # past the index: EventSlicer declines rather than guess
                continue
            want = _select(event_source, a, b)
            for k in ("t", "x", "y", "p"):
                np.testing.assert_array_equal(got[k], want[k], err_msg=f"window [{a}, {b}) field {k}")
            n_checked += 1
    assert n_checked > 300


def test_tonic_dsec_loader_reads_the_export(event_source, tmp_path, monkeypatch):
    tonic = pytest.importorskip("tonic")
    import imageio.plugins.freeimage

    # tonic's DSEC constructor fetches the FreeImage library (for 16-bit flow PNGs, not events) from the network;
    # nothing may be downloaded in tests, and reading events does not need it.
    monkeypatch.setattr(imageio.plugins.freeimage, "download", lambda *a, **k: None)
    recording = "thun_00_a"  # tonic accepts only DSEC's own sequence names
    target = tmp_path / "DSEC" / recording / "events_left" / "events.h5"
    export_recording(event_source.path, "dsec", target)
    data, _ = tonic.datasets.DSEC(str(tmp_path), split=recording, data_selection="events_left")[0]
    events = data[0]["events_left"]
    np.testing.assert_array_equal(events["t"], event_source.t)  # tonic adds t_offset back
    np.testing.assert_array_equal(events["x"], event_source.x)
    np.testing.assert_array_equal(events["y"], event_source.y)
    np.testing.assert_array_equal(events["p"], event_source.p.astype(bool))
    k = np.arange(data[0]["ms_to_idx"].size)
    np.testing.assert_array_equal(data[0]["ms_to_idx"],
                                  np.searchsorted(event_source.t - 12_000, 1000 * k, side="left"))


def test_unsorted_events_are_refused_and_nothing_is_left(tmp_path):
    src = write_event_recording(tmp_path / "rec.h5", [5, 9, 7], [0, 1, 2], [0, 0, 0], [1, 0, 1], width=4,
                                height=2, t_start_s=0.0, t_end_s=0.001)
    with pytest.raises(InputError, match=r"/events/t.*not sorted \(event 2"):
        export_recording(src.path, "dsec", tmp_path / "out" / "events.h5")
    assert not (tmp_path / "out").exists() or list((tmp_path / "out").iterdir()) == []  # refused on open
