"""``simspad export`` as a user runs it: a file out, or one line on stderr, exit 2 and nothing half-written."""

from __future__ import annotations

import h5py
import numpy as np

from tests.io.export.conftest import write_event_recording


def _events_only(tmp_path):
    return write_event_recording(tmp_path / "rec.h5", [100, 1500, 2500], [0, 1, 2], [0, 1, 0], [1, 0, 1], width=3,
                                 height=2, t_start_s=0.0, t_end_s=0.003).path


def test_export_writes_the_file(simspad_cli, tmp_path):
    rec = _events_only(tmp_path)
    res = simspad_cli.run("export", rec, "--to", "dsec", "--out", tmp_path / "dsec" / "events.h5")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"wrote {tmp_path / 'dsec' / 'events.h5'}"
    with h5py.File(tmp_path / "dsec" / "events.h5", "r") as h5:
        np.testing.assert_array_equal(h5["events/t"][()], [100, 1500, 2500])
        np.testing.assert_array_equal(h5["ms_to_idx"][()], [0, 1, 2, 3])


def test_bad_input_is_one_line_and_exit_2(simspad_cli, tmp_path):
    rec = _events_only(tmp_path)
    cases = [
        (("export", tmp_path / "missing.h5", "--to", "evt3", "--out", tmp_path / "a.raw"), "missing.h5"),
        (("export", rec, "--to", "npz", "--out", tmp_path / "out"), "no /spad, /frames or /gt group"),
        (("export", rec, "--to", "evt9", "--out", tmp_path / "a.raw"), "'evt9' is not one of"),
        (("export", rec, "--to", "evt3", "--out", tmp_path), "a directory of that name exists"),
    ]
    for args, needle in cases:
        res = simspad_cli.run(*args)
        assert res.returncode == 2, (args, res.stderr)
        assert needle in res.stderr and "Traceback" not in res.stderr
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as h5:
        h5["x"] = 1
    res = simspad_cli.run("export", foreign, "--to", "dsec", "--out", tmp_path / "b.h5")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and str(foreign) in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["foreign.h5", "rec.h5"]
