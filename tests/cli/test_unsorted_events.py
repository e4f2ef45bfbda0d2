"""A recording whose events go back in time is refused by `evaluate` and `export` with one line (issue 14)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from simspad.io.recording import Recording, open_recording, validation
from simspad.errors import InputError
from tests.helpers.synthetic_recordings import write_recording


@pytest.fixture
def unsorted_recording(tmp_path):
    path = tmp_path / "rec.h5"
    write_recording(path, lambda t: np.full((12, 16), 1e3 * (1.0 + 50.0 * t)), spad=False, frames=False)
    with h5py.File(path, "r+") as f:
        t = f["events/t"][()]
        assert t.size > 10 and np.all(np.diff(t) >= 0)
        i = t.size - 3  # late in the stream: a check of the first window alone would not see it
        t[i] = t[0] - 1 if t[0] > 0 else -1
        f["events/t"][...] = t
    return path, i


def test_time_order_is_checked_chunk_by_chunk(unsorted_recording, monkeypatch):
    path, i = unsorted_recording
    with pytest.raises(InputError, match=rf"/events/t: not sorted \(event {i} at "):
        open_recording(path)  # validation on open, in chunks
    monkeypatch.setattr(validation, "EVENT_STEP", 7)
    with pytest.raises(InputError, match=rf"/events/t: not sorted \(event {i} at "):
        open_recording(path)  # the disorder inside a chunk or at a chunk boundary
    # The readers' own checks, on a file opened without validation (a Recording built by hand)
    with Recording(path, h5py.File(path, "r")) as rec:
        for chunk in (2, 7, 1 << 20):
            with pytest.raises(InputError, match=rf"/events/t: not sorted \(event {i} at "):
                rec.events.check_time_order(chunk)
            with pytest.raises(InputError, match=rf"/events/t: not sorted \(event {i} at "):
                list(rec.events.iter_chunks(chunk))


@pytest.mark.parametrize("command", ["evaluate", "export"])
def test_unsorted_events_are_refused_by_the_cli(unsorted_recording, tmp_path, simspad_cli, command):
    path, i = unsorted_recording
    out = tmp_path / "out"
    args = (["evaluate", path, "--methods", "cf", "--out", out] if command == "evaluate"
            else ["export", path, "--to", "evt3", "--out", tmp_path / "rec.raw"])
    proc = simspad_cli.run(*args)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert f"rec.h5: /events/t: not sorted (event {i} at" in proc.stderr, proc.stderr
