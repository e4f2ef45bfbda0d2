"""Recording format round trip, atomic writing, validation of foreign/corrupt files."""

import hashlib

import h5py
import numpy as np
import pytest

from simspad.errors import InputError
from simspad.io.recording import RecordingWriter, open_recording


def _write(path, n_bins=300, width=13, height=5, seed=0, fail=False):
    rng = np.random.default_rng(seed)
    bits = (rng.random((n_bins, height, width)) < 0.3).astype(np.uint8)
    t_us = np.sort(rng.integers(0, 3000, 500)).astype(np.int64)
    with RecordingWriter(path, {"width": width, "height": height, "duration_s": 0.003, "lux": 10.0,
                                "scene": "x", "spec": {"a": 1}}) as w:
        app = w.append_dataset("spad/bits", (height, (width + 7) // 8), np.uint8, chunk_rows=64)
        for i in range(0, n_bins, 64):
            app.append(np.packbits(bits[i:i + 64], axis=2, bitorder="little"))
        if fail:
            raise RuntimeError("boom")
        w.write_dataset("spad/t_start", np.arange(n_bins) * 10e-6)  # every bin starts inside the 3 ms span
        w.write_dataset("spad/dcr_cps", np.full((height, width), 7.5, np.float32))
        w.set_attrs("spad", bin_s=10e-6, gate_s=1e-6, pixel_pitch_m=16.38e-6, fill_factor=0.105, qe=0.45)
        w.write_dataset("events/t", t_us)
        for k, dt in (("x", np.uint16), ("y", np.uint16), ("p", np.uint8), ("label", np.uint8)):
            w.write_dataset(f"events/{k}", rng.integers(0, 2, t_us.size).astype(dt))
        ms = np.searchsorted(t_us, np.arange(4) * 1000, side="left").astype(np.uint64)
        w.write_dataset("events/ms_to_idx", ms)
        w.set_attrs("events", threshold_on=0.3, threshold_off=0.3)
    return bits, t_us


def test_round_trip_bits_events_and_determinism(tmp_path):
    bits, t_us = _write(tmp_path / "a.h5")
    _write(tmp_path / "b.h5")
    digest = [hashlib.sha256((tmp_path / n).read_bytes()).hexdigest() for n in ("a.h5", "b.h5")]
    assert digest[0] == digest[1], "identical data must give identical bytes"
    with open_recording(tmp_path / "a.h5") as rec:
        assert rec.sensors == ("spad", "events")
        np.testing.assert_array_equal(rec.spad.bits(0, rec.spad.n_bins), bits)
        np.testing.assert_array_equal(rec.spad.counts(17, 250, chunk=50), bits[17:250].sum(0))
        again = rec.spad.counts(17, 250)  # kept from the call above: a copy the caller may change
        again += 1
        np.testing.assert_array_equal(rec.spad.counts(17, 250), bits[17:250].sum(0))
        for t0, t1 in ((0.0, 0.003), (0.0012345, 0.0021), (0.0005, 0.0005)):
            ev = rec.events.window(t0, t1)
            expected = t_us[(t_us >= t0 * 1e6 - 1e-6) & (t_us < t1 * 1e6 - 1e-6)]
            np.testing.assert_array_equal(ev["t"], expected)
        assert sum(len(c["t"]) for c in rec.events.iter_chunks(chunk=77)) == t_us.size
        assert rec.events.n_events == t_us.size and rec.events.by_index(3, 9)["label"].size == 6
        attrs = rec.spad.attrs
        attrs["bin_s"] = 0.0  # a copy: the view keeps what it read
        assert rec.spad.attrs["bin_s"] == 10e-6
        assert rec.spec == {"a": 1}


def test_failed_write_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError):
        _write(tmp_path / "c.h5", fail=True)
    assert list(tmp_path.iterdir()) == []


def test_foreign_and_corrupt_files_are_refused(tmp_path):
    with h5py.File(tmp_path / "foreign.h5", "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(InputError, match=r"foreign.h5: /.format: not a SimSPAD recording"):
        open_recording(tmp_path / "foreign.h5")
    (tmp_path / "corrupt.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    with pytest.raises(InputError, match="corrupt"):
        open_recording(tmp_path / "corrupt.h5")
    _write(tmp_path / "ok.h5")
    with h5py.File(tmp_path / "ok.h5", "a") as f:
        del f["spad/dcr_cps"]
    with pytest.raises(InputError, match=r"/spad/dcr_cps: dataset missing"):
        open_recording(tmp_path / "ok.h5")


def test_file_bytes_do_not_depend_on_how_rows_are_batched(tmp_path):
    rows = np.arange(10_000, dtype=np.int64)
    digests = set()
    for name, cuts in (("one.h5", [10_000]), ("many.h5", [1, 999, 4000, 3, 4997]), ("even.h5", [2500] * 4)):
        with RecordingWriter(tmp_path / name, {"width": 1, "height": 1, "duration_s": 1.0, "lux": 1.0}) as w:
            app = w.append_dataset("events/t", (), np.int64, chunk_rows=1024)
            i = 0
            for c in cuts:
                app.append(rows[i:i + c])
                i += c
            assert app.n == rows.size
        with h5py.File(tmp_path / name) as f:
            np.testing.assert_array_equal(f["events/t"][()], rows)
        digests.add(hashlib.sha256((tmp_path / name).read_bytes()).hexdigest())
    assert len(digests) == 1


def test_presized_dataset_is_filled_in_place_and_checks_its_length(tmp_path):
    """``n_rows``: created at its final length, the same rows whatever the batching, the same bytes; appending more
    rows than declared, or fewer by the end, is an error (and leaves no file)."""
    rows = np.arange(5000 * 3, dtype=np.uint8).reshape(5000, 3)
    digests = set()
    for name, cuts in (("one.h5", [5000]), ("many.h5", [1, 1023, 2000, 1976])):
        with RecordingWriter(tmp_path / name, {"width": 1, "height": 1, "duration_s": 1.0, "lux": 1.0}) as w:
            app = w.append_dataset("spad/bits", (3,), np.uint8, chunk_rows=512, n_rows=rows.shape[0])
            i = 0
            for c in cuts:
                app.append(rows[i:i + c])
                i += c
        with h5py.File(tmp_path / name) as f:
            np.testing.assert_array_equal(f["spad/bits"][()], rows)
            assert f["spad/bits"].maxshape[0] == rows.shape[0]
        digests.add(hashlib.sha256((tmp_path / name).read_bytes()).hexdigest())
    assert len(digests) == 1
    with pytest.raises(ValueError, match="rows appended"):
        with RecordingWriter(tmp_path / "over.h5") as w:
            w.append_dataset("spad/bits", (3,), np.uint8, chunk_rows=512, n_rows=10).append(rows[:11])
    with pytest.raises(ValueError, match="rows appended"):
        with RecordingWriter(tmp_path / "short.h5") as w:
            w.append_dataset("spad/bits", (3,), np.uint8, chunk_rows=4, n_rows=10).append(rows[:9])
    assert not (tmp_path / "over.h5").exists() and not (tmp_path / "short.h5").exists()
