"""Inputs validated on open, beyond the fuzz catalogue: memory flat in the recording's length, saved
reconstructions read back, sensor sizes an export format cannot hold (issue 33)."""

from __future__ import annotations

import tracemalloc

import h5py
import numpy as np
import pytest

from simspad.errors import InputError
from simspad.io.export.dispatch import export_recording
from simspad.io.reconstructions import ReconstructionSink, open_reconstruction
from simspad.io.recording import RecordingWriter, open_recording, validation
from tests.io.export.conftest import write_event_recording


def test_validation_memory_does_not_grow_with_the_events(tmp_path, monkeypatch):
    n = 1 << 22  # 4 Mi events: 54 MiB of columns
    t = np.sort(np.random.default_rng(0).integers(0, 1_000_000, n)).astype(np.int64)
    src = write_event_recording(tmp_path / "big.h5", t, t % 640, t % 480, t % 2, width=640, height=480,
                                t_start_s=0.0, t_end_s=1.0)
    monkeypatch.setattr(validation, "EVENT_STEP", 1 << 16)  # 0.85 MiB of columns a step
    tracemalloc.start()
    try:
        with open_recording(src.path) as rec:
            assert rec.events.n_events == n
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 8 * 2**20, f"validation peaked at {peak / 2**20:.1f} MiB for 54 MiB of events"


def test_saved_reconstruction_reads_back_and_damage_is_one_line(tmp_path):
    path = tmp_path / "r.h5"
    frames = np.random.default_rng(1).random((5, 4, 6)).astype(np.float32)
    sink = ReconstructionSink(path, np.arange(5) * 1e-3, (4, 6), {"method": "ni", "recording": "a.h5",
                                                                   "units": "photons s-1 m-2"})
    for i, f in enumerate(frames):
        sink(i, f)
    sink.close()
    with open_reconstruction(path) as rec:
        assert (rec.method, rec.shape) == ("ni", (4, 6))
        assert np.array_equal(np.concatenate([b for _, b in rec.frames(2)]), frames)
    for damage, fragment in [
        (lambda f: f.attrs.__setitem__("method", 3), "/.method: expected a string"),
        (lambda f: f["flux"].__setitem__((3, 2, 1), np.nan), "/flux: flux nan at pixel (row 2, col 1) of frame 3"),
        (lambda f: f["t"].__setitem__(2, 0.0), "/t: index 2:"),
        (lambda f: (f.__delitem__("t"), f.create_dataset("t", data=np.arange(5, dtype=np.float32))), "/t: dtype <f4"),
        (lambda f: (f.__delitem__("t"), f.create_dataset("t", data=np.arange(4.0))), "/flux: 5 frames but 4"),
    ]:
        bad = tmp_path / "bad.h5"
        bad.write_bytes(path.read_bytes())
        with h5py.File(bad, "r+") as f:
            damage(f)
        with pytest.raises(InputError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
            open_reconstruction(bad)


@pytest.mark.parametrize("fmt, fragment", [("evt3", "EVT 3.0 addresses are 11-bit"),
                                           ("aedat4", "AEDAT 4 event addresses are int16")])
def test_sensor_wider_than_the_format_is_refused(tmp_path, fmt, fragment):
    pytest.importorskip("dv_processing") if fmt == "aedat4" else None
    src = write_event_recording(tmp_path / "wide.h5", [10, 20], [39_999, 35_000], [0, 0], [1, 0], width=40_000,
                                height=1, t_start_s=0.0, t_end_s=0.001)
    out = tmp_path / f"out.{fmt}"
    with pytest.raises(InputError, match=fragment):
        export_recording(src.path, fmt, out)
    assert not out.exists()
    # DSEC stores uint16 addresses: the same recording exports
    assert export_recording(src.path, "dsec", tmp_path / "events.h5").is_file()


@pytest.mark.parametrize("method", ["cf", "akf_fe", "edi"])
def test_event_methods_refuse_an_event_outside_the_sensor_without_validation(tmp_path, method):
    # A Recording built by hand skips the validation on open; the event reader in front of the kernels still
    # refuses x = width (before, its pixel index y·W + x landed on the next row's pixel, or past the array).
    from simspad.io.recording import Recording
    from simspad.methods.registry import get_method
    from tests.helpers.synthetic_recordings import write_recording

    path = tmp_path / "rec.h5"
    write_recording(path, lambda t: np.full((6, 8), 1e3 * (1.0 + 80.0 * t)) * (1 + np.arange(8)[None] / 8),
                    shape=(6, 8), spad=False)
    with h5py.File(path, "r+") as f:
        x = f["events/x"][()]
        assert x.size > 10
        x[x.size // 2] = 8
        f["events/x"][...] = x
    with Recording(path, h5py.File(path, "r")) as rec:
        times = rec.gt.t[1:]
        with pytest.raises(InputError, match=r"/events/x: event at .* x = 8 outside the sensor \(expected < 8\)"):
            list(get_method(method).reconstruct(rec, times))


def test_a_file_is_validated_once_until_it_changes(tmp_path, monkeypatch):
    from simspad.io.recording import reader

    calls = []
    monkeypatch.setattr(reader, "validate_recording", lambda h5, path: calls.append(path) or {})
    src = write_event_recording(tmp_path / "a.h5", [5, 9], [0, 1], [0, 0], [1, 0], width=4, height=2,
                                t_start_s=0.0, t_end_s=0.001)
    for _ in range(2):  # just written: file times tick coarsely, so it is validated at every open
        open_recording(src.path).close()
    assert len(calls) == 2
    monkeypatch.setattr(reader, "_SETTLED_S", -1.0)  # as if it had been left alone long enough
    for _ in range(3):
        open_recording(src.path).close()
    assert len(calls) == 3  # one more validation, then remembered
    copy = tmp_path / "b.h5"
    copy.write_bytes(src.path.read_bytes())
    copy.replace(src.path)  # replaced under the same name: another inode
    open_recording(src.path).close()
    assert len(calls) == 4
