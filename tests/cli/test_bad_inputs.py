"""Bad inputs that used to end in `internal error` (exit 1) or were accepted silently: now one line, exit 2."""

from __future__ import annotations

import os

import numpy as np
import pytest

from simspad.cli import main
from simspad.io.render_dir import write_render_dir


@pytest.fixture
def files(tmp_path):
    render = write_render_dir(tmp_path / "render", np.array([0.0, 0.01]), np.ones((2, 4, 6, 3), np.float32)).parent
    (tmp_path / "isdir").mkdir()
    (tmp_path / "nested.json").write_text("[" * 100_000 + "]" * 100_000)
    (tmp_path / "huge.csv").write_text("t,tx,ty,tz,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n1,1e308,0,0,0,0,0,1\n")
    (tmp_path / "late.toml").write_text("[camera]\nkeyframes = [{t = 0, position = [0,0,0], quaternion_xyzw = "
                                        "[0,0,0,1]}, {t = 1e300, position = [0,0,0], quaternion_xyzw = [0,0,0,1]}]\n")
    (tmp_path / "underscore.tum").write_text("0 0 0 0 0 0 0 1\n1_0 0 0 0 0 0 0 1\n")
    os.mkfifo(tmp_path / "fifo")
    return tmp_path, render


CASES = {
    "min_rate_inf": (["render", "siemens-star", "--duration", "0.001", "--min-rate", "inf", "--out", "{t}/r"],
                     "min_rate_hz"),
    "seed_negative": (["simulate", "{r}", "--lux", "10", "--seed", "-1", "--out", "{t}/a.h5"], "--seed"),
    "out_is_a_directory": (["simulate", "{r}", "--lux", "10", "--out", "{t}/isdir"], "is a directory"),
    "out_is_a_fifo": (["snr", "--out", "{t}/fifo"], "is a FIFO"),
    "out_name_too_long": (["snr", "--out", "{t}/" + "a" * 300 + ".png"], "File name too long"),
    "nested_json": (["info", "{t}/nested.json"], "nested too deeply"),
    "position_1e308": (["info", "{t}/huge.csv"], "position beyond"),
    "time_1e300": (["info", "{t}/late.toml"], "t beyond"),
    "tum_digit_separator": (["info", "{t}/underscore.tum"], "'1_0' is not a number"),
    "set_overflow": (["simulate", "{r}", "--lux", "10", "--set", "frames.bit_depth=99999999999999999999",
                      "--out", "{t}/b.h5"], "bit_depth"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_line_exit_2(files, case, capsys):
    tmp, render = files
    argv, fragment = CASES[case]
    assert main([a.format(t=tmp, r=render) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("simspad: error: ") and err.count("\n") == 1 and fragment in err, err
    assert not [p for p in tmp.rglob(".*tmp-*")], "a temporary file was left behind"


def test_malformed_source_date_epoch_is_one_line(tmp_path, simspad_cli):
    proc = simspad_cli.run("info", "mini", env={"SOURCE_DATE_EPOCH": "abc"})
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0 and "SOURCE_DATE_EPOCH" in proc.stderr


def test_keyframe_times_in_microseconds_are_refused_before_writing(tmp_path, capsys):
    # 0 … 33 000 "s" (µs written as seconds): 3.2e9 SPAD bins; before, 4.2 GB were written in 60 s.
    render = write_render_dir(tmp_path / "r", np.array([0.0, 33_000.0]), np.ones((2, 4, 6, 3), np.float32)).parent
    assert main(["simulate", str(render), "--lux", "10", "--out", str(tmp_path / "o" / "a.h5")]) == 2
    err = capsys.readouterr().err
    assert "spad rows, above the limit of 1e+08 (keyframe times in µs written as seconds?" in err
    assert not (tmp_path / "o").exists() or not list((tmp_path / "o").iterdir())
    assert main(["simulate", str(render), "--lux", "1e30", "--out", str(tmp_path / "o" / "a.h5")]) == 2
    assert "outside 1e-06–1e+06 lx" in capsys.readouterr().err


@pytest.mark.parametrize("damage, fragment", [
    ("width_text", "/.width: expected a positive integer, got 'abc'"),
    ("lux_array", "/.lux: expected a finite number"),
    ("group_for_dataset", "/gt/flux: expected a dataset, found a group"),
    ("nan_gt", "/gt/flux: ground-truth flux nan at pixel (row 0, col 0) of frame 0"),
])
def test_damaged_recording_is_one_line(tmp_path, capsys, damage, fragment):
    import h5py

    from tests.helpers.evaluation_data import write_recording

    path = tmp_path / "rec.h5"
    write_recording(path, sequence="s", scene="s", lux=10.0, level=3e15, seed=1)
    with h5py.File(path, "r+") as f:
        if damage == "width_text":
            f.attrs["width"] = "abc"
        elif damage == "lux_array":
            f.attrs["lux"] = np.array([1.0, 2.0])
        elif damage == "group_for_dataset":
            del f["gt/flux"]
            f.create_group("gt/flux")
        else:
            flux = f["gt/flux"][()]
            flux[0, 0, 0] = np.nan
            f["gt/flux"][...] = flux
    assert main(["evaluate", str(path), "--methods", "ni", "--out", str(tmp_path / "res")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err, err
