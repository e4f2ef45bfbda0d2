"""Paths read from a results directory, manifest, timeline.json or HDF5 file stay inside their own folder/file;
the manifest's sha256 is verified by evaluate and info."""

from __future__ import annotations

import json
import re
import shutil

import h5py
import numpy as np
import pytest

from simspad.cli import main
from simspad.errors import InputError
from simspad.evaluate.recordings import list_recordings
from simspad.io.hdf5 import open_checked
from simspad.io.render_dir import read_render_dir, write_render_dir
from simspad.io.results_dir import read_csv
from simspad.io.safe_paths import confined_path


def test_confined_path_refuses_absolute_dotdot_and_link_escapes(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "ok.png").write_bytes(b"x")
    (tmp_path / "d" / "out").symlink_to(tmp_path)
    assert confined_path(tmp_path / "d", "ok.png", source="s", field="f") == tmp_path / "d" / "ok.png"
    for bad, why in (("/etc/passwd", "leaves its folder"), ("../x.png", "leaves its folder"),
                     ("a/../../x", "leaves its folder"), ("out/secret.png", "through a symbolic link"),
                     ("", "expected a relative path")):
        with pytest.raises(InputError, match=why):
            confined_path(tmp_path / "d", bad, source="s", field="f")


def test_results_csv_image_outside_the_results_dir_is_refused(tmp_path):
    (tmp_path / "results.csv").write_text("method,image\nni,../../home/user/secret.png\n")
    with pytest.raises(InputError, match=r"results\.csv: row 2: image: '\.\./\.\./home/user/secret\.png' leaves"):
        read_csv(tmp_path / "results.csv")
    (tmp_path / "results.csv").write_text("method,image\n" + "ni," + "x" * 200_000 + "\n")
    with pytest.raises(InputError, match="not a readable results CSV"):  # > 128 KiB field: one line, not a crash
        read_csv(tmp_path / "results.csv")


def test_timeline_keyframe_file_outside_the_render_dir_is_refused(tmp_path):
    meta = write_render_dir(tmp_path / "r", np.array([0.0, 0.01]), np.ones((2, 4, 6, 3), np.float32))
    doc = json.loads(meta.read_text())
    shutil.copy(tmp_path / "r" / doc["keyframes"][1]["file"], tmp_path / "elsewhere.exr")
    doc["keyframes"][1]["file"] = str(tmp_path / "elsewhere.exr")
    meta.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"keyframes\[1\]\.file: .* leaves its folder"):
        read_render_dir(tmp_path / "r")


def test_hdf5_external_and_dangling_links_are_refused(tmp_path):
    with h5py.File(tmp_path / "secret.h5", "w") as f:
        f["data"] = np.arange(3)
    for name, link, why in (("ext.h5", h5py.ExternalLink(str(tmp_path / "secret.h5"), "/data"), "external link"),
                            ("soft.h5", h5py.SoftLink("/nowhere"), "soft link")):
        with h5py.File(tmp_path / name, "w") as f:
            f.attrs["format"] = "simspad-submission"
            f.attrs["format_version"] = 1
            f.create_group("rec")["flux"] = link
        with pytest.raises(InputError, match=rf"/rec/flux: {why}"):
            open_checked(tmp_path / name, kind="submission", format="simspad-submission", format_version=1)


def test_evaluate_and_info_verify_the_manifest_sha256(evaluation_dataset, tmp_path, capsys):
    ds = tmp_path / "ds"
    shutil.copytree(evaluation_dataset, ds)
    assert len(list_recordings(ds)[0]) == 2
    assert main(["info", str(ds)]) == 0
    assert "verified    2 of 2 complete recordings match their sha256" in capsys.readouterr().out
    rec = ds / "recordings/ramp/ramp_10lx.h5"
    with h5py.File(rec, "r") as f:
        offset = f["gt/flux"].id.get_offset()
    data = bytearray(rec.read_bytes())
    data[offset + 100] ^= 0x01  # one flipped bit in /gt/flux
    rec.write_bytes(bytes(data))
    assert main(["info", str(ds)]) == 1  # a failed check is a failure (issue 33; tests/hostile)
    assert "CORRUPT     recordings/ramp/ramp_10lx.h5: sha256 differs" in capsys.readouterr().out
    assert main(["evaluate", str(ds), "--methods", "ni", "--out", str(tmp_path / "res")]) == 2
    err = capsys.readouterr().err
    assert "ramp_10lx.h5: manifest recordings[0]: sha256 differs" in err and err.count("\n") == 1
    m = json.loads((ds / "manifest.json").read_text())
    for patch, field in (({"version": 99}, "version"), ({"recordings": [dict(m["recordings"][1], path="../x.h5")]},
                                                          "recordings[0].path")):
        (ds / "manifest.json").write_text(json.dumps({**m, **patch}))
        with pytest.raises(InputError, match=rf"manifest\.json: {re.escape(field)}"):
            list_recordings(ds)


def test_one_keyframe_render_dir_says_two_are_needed(tmp_path):
    meta = write_render_dir(tmp_path / "r", np.array([0.0, 0.01]), np.ones((2, 4, 6, 3), np.float32))
    doc = json.loads(meta.read_text())
    doc["keyframes"] = doc["keyframes"][:1]
    meta.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="needs at least two"):
        read_render_dir(tmp_path / "r")


def test_nan_or_negative_depth_is_refused(tmp_path):
    from simspad.io.render_dir import read_keyframe

    for value in (np.nan, -1.0):
        depth = np.ones((2, 4, 6), np.float32)
        depth[1, 2, 3] = value
        write_render_dir(tmp_path / str(value), np.array([0.0, 0.01]), np.ones((2, 4, 6, 3), np.float32), depth=depth)
        index = read_render_dir(tmp_path / str(value))
        read_keyframe(index.files[0], 6, 4)
        with pytest.raises(InputError, match=r"depth .* at pixel \(row 2, col 3\)"):
            read_keyframe(index.files[1], 6, 4)
