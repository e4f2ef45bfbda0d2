"""EVT 3.0 export, read back by three independent decoders: expelliarmus, evt3 and faery."""

from __future__ import annotations

import numpy as np
import pytest

from simspad.errors import InputError
from simspad.io.export.dispatch import export_recording
from tests.io.export.conftest import write_event_recording

T_OFFSET_US = 12_000  # event_source starts at 12.3 ms: timestamps are written from the whole ms below


def test_expelliarmus_reads_every_address_polarity_and_the_low_time_bits(event_source, tmp_path):
    expelliarmus = pytest.importorskip("expelliarmus")
    out = export_recording(event_source.path, "evt3", tmp_path / "rec.raw", chunk_events=9_999)
    arr = expelliarmus.Wizard(encoding="evt3").read(out)
    assert arr.size == event_source.t.size
    np.testing.assert_array_equal(arr["x"], event_source.x)
    np.testing.assert_array_equal(arr["y"], event_source.y)
    np.testing.assert_array_equal(arr["p"], event_source.p)
    # expelliarmus 1.1 adds a spurious 4096 µs carry whenever TIME_LOW decreases (its issue #19), so of its
    # timestamps only the 12 low bits are right; the decoders below check the full timestamps.
    np.testing.assert_array_equal(arr["t"] & 0xFFF, (event_source.t - T_OFFSET_US) & 0xFFF)


@pytest.mark.parametrize("reader", ["evt3", "faery"])
def test_spec_decoders_read_every_event_exactly(event_source, tmp_path, reader):
    pytest.importorskip(reader)
    out = export_recording(event_source.path, "evt3", tmp_path / "rec.raw", chunk_events=9_999)
    t, x, y, p, size = _decode(reader, out)
    assert size == (346, 260)
    np.testing.assert_array_equal(t + T_OFFSET_US, event_source.t)
    np.testing.assert_array_equal(x, event_source.x)
    np.testing.assert_array_equal(y, event_source.y)
    np.testing.assert_array_equal(p, event_source.p)


def test_timestamps_survive_24_bit_wraps_and_long_gaps(tmp_path):
    """Over 16.8 s the 24-bit time field wraps; a 40 s gap needs extra TIME_HIGH words for a reader to count the
    wraps. Every event sits at TIME_LOW = 100, where expelliarmus decodes full timestamps exactly."""
    expelliarmus = pytest.importorskip("expelliarmus")
    high = np.array([0, 1, 2, 2, 4095, 4096, 4097, 9000, 9000 + 10_000, 30_000])  # × 4096 µs, up to 123 s
    t_us = high * 4096 + 100
    src = write_event_recording(tmp_path / "rec.h5", t_us, np.arange(10), np.arange(10) % 3, np.arange(10) % 2,
                                width=16, height=4, t_start_s=0.0, t_end_s=123.0)
    out = export_recording(src.path, "evt3", tmp_path / "rec.raw")
    arr = expelliarmus.Wizard(encoding="evt3").read(out)
    np.testing.assert_array_equal(arr["t"], t_us)
    np.testing.assert_array_equal(arr["x"], np.arange(10))


def test_addresses_beyond_11_bits_are_refused(tmp_path):
    src = write_event_recording(tmp_path / "rec.h5", [1], [0], [0], [1], width=4096, height=2, t_start_s=0.0,
                                t_end_s=0.001)
    with pytest.raises(InputError, match=r"/\.width.*11-bit"):
        export_recording(src.path, "evt3", tmp_path / "rec.raw")
    assert not (tmp_path / "rec.raw").exists()


def _decode(reader, path):
    if reader == "evt3":
        import evt3

        ev = evt3.decode_file(str(path))
        return (np.asarray(ev.t), np.asarray(ev.x), np.asarray(ev.y), np.asarray(ev.p),
                (ev.sensor_width, ev.sensor_height))
    import faery

    stream = faery.events_stream_from_file(path)
    arr = np.concatenate(list(stream))
    return arr["t"], arr["x"], arr["y"], arr["p"].astype(np.uint8), tuple(stream.dimensions())
