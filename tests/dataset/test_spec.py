"""Dataset specs: a good spec loads into typed objects; every kind of bad spec is refused, one line per error."""

from __future__ import annotations

import shutil
import textwrap
from pathlib import Path

import pytest

from simspad.bundled import TRAJECTORIES_DIR
from simspad.cli import main
from simspad.dataset.spec import DatasetSpec, EvaluationSpec, default_spec_path
from simspad.dataset.spec_hashing import sequence_hash, spec_hash
from simspad.dataset.spec_validation import load_spec
from simspad.errors import SpecError
from simspad.sensors.presets import EventParams, FrameParams, SpadParams

SCENE_XML = """<scene version="3.0.0">
  <sensor type="perspective" id="cam"><float name="fov" value="40"/></sensor>
  <shape type="sphere"><bsdf type="diffuse"/></shape>
</scene>
"""

TRAJ_CSV = "t,tx,ty,tz,qx,qy,qz,qw\n0,0,0,3,0,1,0,0\n1,0.1,0,3,0,1,0,0\n"


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A folder holding a user scene and a trajectory; the current directory is elsewhere."""
    (tmp_path / "specs" / "myscene").mkdir(parents=True)
    (tmp_path / "specs" / "myscene" / "scene.xml").write_text(SCENE_XML)
    (tmp_path / "specs" / "dolly.csv").write_text(TRAJ_CSV)
    (tmp_path / "specs" / "broken.csv").write_text(TRAJ_CSV.replace("1,0.1,0,3", "0,0.1,0,3"))
    (tmp_path / "cwd").mkdir()
    monkeypatch.chdir(tmp_path / "cwd")
    return tmp_path


GOOD = """
name = "unit"
seed = 7
output = "out/unit"
lux = [1, 10.5, 1e4]

[[sequences]]
scene = "myscene"
trajectory = "dolly.csv"
duration_s = 0.02
resolution = [32, 24]
spp = 4

[[sequences]]
name = "second"
scene = "myscene"
trajectory = "example_pan.csv"     # not beside the spec: found in the bundled trajectories/
duration_s = 0.5
start_s = 0.1
resolution = [16, 12]
spp = 2
max_flow_px = 0.25

[sensors.spad]
preset = "swissspad2"
gate_s = 1e-6
dcr_median_cps = 20

[sensors.frames]
exposure_s = 0.002

[evaluation]
rate_hz = 500
methods = ["ni", "nedi_akf"]
"""


def _write(workdir: Path, text: str, name: str = "spec.toml") -> Path:
    p = workdir / "specs" / name
    p.write_text(textwrap.dedent(text))
    return p


def test_good_spec_loads_into_typed_objects(workdir):
    spec = load_spec(_write(workdir, GOOD))
    assert isinstance(spec, DatasetSpec)
    assert spec.name == "unit" and spec.seed == 7
    assert spec.output == workdir / "cwd" / "out" / "unit"  # relative to the current directory
    assert spec.lux == (1.0, 10.5, 1e4) and all(isinstance(x, float) for x in spec.lux)
    first, second = spec.sequences
    assert first.name == "myscene"  # defaults to the scene name
    assert Path(first.scene) == workdir / "specs" / "myscene"
    assert Path(first.trajectory) == workdir / "specs" / "dolly.csv"
    assert first.resolution == (32, 24) and first.spp == 4 and first.duration_s == 0.02 and first.start_s == 0.0
    assert first.max_flow_px == 0.5 and first.min_rate_hz == 1000.0
    assert Path(second.trajectory) == TRAJECTORIES_DIR / "example_pan.csv"
    assert second.max_flow_px == 0.25 and second.start_s == 0.1
    assert set(spec.sensors) == {"spad", "frames"}
    spad = spec.sensors["spad"]
    assert isinstance(spad.params, SpadParams) and spad.preset == "swissspad2"
    assert spad.params.gate_s == 1e-6 and spad.params.dcr_median_cps == 20.0
    assert spad.overrides == {"gate_s": 1e-6, "dcr_median_cps": 20}
    assert isinstance(spec.sensors["frames"].params, FrameParams)
    assert spec.sensors["frames"].preset == "blackfly_s" and spec.sensors["frames"].params.exposure_s == 0.002
    assert spec.evaluation == EvaluationSpec(rate_hz=500.0, methods=("ni", "nedi_akf"))
    assert spec.source_path == (workdir / "specs" / "spec.toml").resolve()
    assert spec.raw["sequences"][1]["name"] == "second"


def test_static_trajectory_covers_any_duration(workdir):
    (workdir / "specs" / "still.toml").write_text(
        '[camera]\ngenerator = "static_pose"\nposition = [0, 0, 3]\nduration_s = 1.0\n')
    spec = load_spec(_write(workdir, GOOD.replace('"dolly.csv"', '"still.toml"').replace("duration_s = 0.02",
                                                                                          "duration_s = 3.0")))
    assert spec.sequences[0].duration_s == 3.0


def test_sensors_default_to_all_three_presets(workdir):
    text = GOOD.split("[sensors.spad]")[0]
    spec = load_spec(_write(workdir, text))
    assert {k: type(s.params) for k, s in spec.sensors.items()} == {
        "spad": SpadParams, "frames": FrameParams, "events": EventParams}
    assert spec.evaluation == EvaluationSpec()


def test_spec_hash_is_stable_and_tracks_content(workdir):
    a = load_spec(_write(workdir, GOOD))
    b = load_spec(_write(workdir, GOOD.replace('output = "out/unit"', 'output = "elsewhere"'), "b.toml"))
    c = load_spec(_write(workdir, GOOD.replace("seed = 7", "seed = 8"), "c.toml"))
    assert len(spec_hash(a)) == 64
    assert spec_hash(a) == spec_hash(b)  # the output folder does not change the data
    assert spec_hash(a) != spec_hash(c)
    assert spec_hash({"b": 1, "a": [1, 2]}) == spec_hash({"a": [1, 2], "b": 1})
    moved = workdir / "moved"
    shutil.copytree(workdir / "specs", moved)
    assert spec_hash(load_spec(moved / "spec.toml")) == spec_hash(a)  # paths are hashed by content
    s0 = a.sequences[0]
    render_hash = sequence_hash(s0)
    assert render_hash == sequence_hash(c.sequences[0])  # the seed does not change the render
    assert sequence_hash(s0, a) != sequence_hash(s0, c)  # but it changes the recordings
    (workdir / "specs" / "dolly.csv").write_text(TRAJ_CSV.replace("0.1,0,3", "0.2,0,3"))
    assert sequence_hash(s0) != render_hash  # trajectory content, not its path, is hashed


def test_default_spec_is_valid():
    spec = load_spec(default_spec_path())
    assert default_spec_path().name == "mini.toml"
    assert spec.name == "mini" and spec.lux == (1.0, 100.0, 10000.0)
    assert len(spec.speed) >= 2 and spec.speed[0] == 1.0  # the regime: as written and much faster
    assert [s.scene for s in spec.sequences] == ["office", "piano", "plant", "siemens-star", "fan"]
    assert set(spec.sensors) == {"spad", "frames", "events"}
    # The embedded default must stay laptop-sized: small grids and tens of milliseconds.
    assert all(max(s.resolution) <= 128 and s.duration_s <= 0.1 for s in spec.sequences)


# Each bad case: (spec text replacing part of GOOD, expected field paths, a fragment of the message).
BAD = {
    "toml_syntax": (GOOD.replace("spp = 4\n", "spp = 4\nbroken = = 2\n"), ["line 13"], "TOML syntax error"),
    "wrong_type": (GOOD.replace("seed = 7", 'seed = "seven"'), ["seed"], "must be an integer in [0, 2**64)"),
    "lux_not_positive": (GOOD.replace("lux = [1, 10.5, 1e4]", "lux = [1, 0, -5]"), ["lux[1]", "lux[2]"], "> 0"),
    "lux_wrong_type": (GOOD.replace("lux = [1, 10.5, 1e4]", 'lux = ["bright"]'), ["lux[0]"], "expected"),
    "unknown_sensor_kind": (GOOD.replace("[sensors.frames]", "[sensors.lidar]"), ["sensors.lidar"],
                            "unknown sensor kind 'lidar'"),
    "unknown_preset": (GOOD.replace('preset = "swissspad2"', 'preset = "spad512"'), ["sensors.spad.preset"],
                       "unknown spad preset 'spad512'"),
    "unknown_sensor_field": (GOOD.replace("gate_s = 1e-6", "gate_ns = 10"), ["sensors.spad.gate_ns"],
                             "unknown spad parameter 'gate_ns'"),
    "sensor_field_type": (GOOD.replace("exposure_s = 0.002", 'exposure_s = "long"'), ["sensors.frames.exposure_s"],
                          "exposure_s: must be a number or 'auto', got 'long'"),
    "spad_compression": (GOOD.replace("gate_s = 1e-6", 'gate_s = 1e-6\ncompression = "lz4"'),
                         ["sensors.spad.compression"], "compression: must be one of 'none', 'gzip', 'zstd'"),
    "missing_scene": (GOOD.replace('scene = "myscene"\ntrajectory = "dolly.csv"',
                                   'scene = "no-such-scene"\ntrajectory = "dolly.csv"'),
                      ["sequences[0].scene"], "unknown scene 'no-such-scene'"),
    "trajectory_not_found": (GOOD.replace('"dolly.csv"', '"nowhere.csv"'), ["sequences[0].trajectory"],
                             "not found"),
    "trajectory_malformed": (GOOD.replace('"dolly.csv"', '"broken.csv"'), ["sequences[0].trajectory"],
                             "broken.csv: line 3: "),
    "beyond_trajectory_end": (GOOD.replace("duration_s = 0.02", "duration_s = 1.5"), ["sequences[0].duration_s"],
                              "covers 0–1 s"),
    "duration_not_positive": (GOOD.replace("duration_s = 0.02", "duration_s = 0"), ["sequences[0].duration_s"],
                              "> 0"),
    "duration_missing": (GOOD.replace("duration_s = 0.02\n", ""), ["sequences[0].duration_s"], "missing"),
    "resolution_one_value": (GOOD.replace("[32, 24]", "[32]"), ["sequences[0].resolution"], "two positive"),
    "resolution_not_positive": (GOOD.replace("[32, 24]", "[32, 0]"), ["sequences[0].resolution"], "two positive"),
    "resolution_float": (GOOD.replace("[32, 24]", "[32.5, 24]"), ["sequences[0].resolution"], "integers"),
    "spp_not_positive": (GOOD.replace("spp = 4", "spp = -1"), ["sequences[0].spp"], "integer > 0"),
    "duplicate_names": (GOOD.replace('name = "second"', 'name = "myscene"'), ["sequences[1].name"], "duplicate"),
    "bad_sequence_name": (GOOD.replace('name = "second"', 'name = "a/b c"'), ["sequences[1].name"], "names files"),
    "unknown_top_level_key": (GOOD.replace("seed = 7", "seed = 7\nsed = 8"), ["sed"], "unknown top-level key"),
    "unknown_sequence_key": (GOOD.replace("spp = 2", "spp = 2\nfps = 30"), ["sequences[1].fps"], "unknown key"),
    "no_sequences": (GOOD.split("[[sequences]]")[0], ["sequences"], "missing"),
    "evaluation_rate": (GOOD.replace("rate_hz = 500", "rate_hz = -500"), ["evaluation.rate_hz"], "> 0"),
    "unknown_method": (GOOD.replace('"nedi_akf"]', '"magic"]'), ["evaluation.methods[1]"], "unknown method"),
    # Resource bounds and cross-field rules (issue 14): refused by `simspad info`, before any render.
    "resolution_huge": (GOOD.replace("[32, 24]", "[16000, 16000]"), ["sequences[0].resolution"], "GiB of memory"),
    "spp_huge": (GOOD.replace("spp = 4", "spp = 9223372036854775807"), ["sequences[0].spp"], "limit of 65536"),
    "max_flow_tiny": (GOOD.replace("max_flow_px = 0.25", "max_flow_px = 1e-12"), ["sequences[1].max_flow_px"],
                      "≥ 0.01 px"),
    "lux_out_of_range": (GOOD.replace("lux = [1, 10.5, 1e4]", "lux = [1e30, 1e-300]"), ["lux[0]", "lux[1]"],
                         "outside 1e-06–1e+06 lx"),
    "bit_depth_64": (GOOD.replace("exposure_s = 0.002", "exposure_s = 0.002\nbit_depth = 64"),
                     ["sensors.frames.bit_depth"], "between 1 and 16"),
    "bin_s_femto": (GOOD.replace("gate_s = 1e-6", "gate_s = \"auto\"\nbin_s = 1e-15\nmin_gate_s = 1e-16"),
                    ["sensors.spad.bin_s", "sensors.spad.bin_s", "sensors.spad.bin_s"], "dead time"),
    "frame_rate_giga": (GOOD.replace("exposure_s = 0.002", "exposure_s = \"auto\"\nframe_rate_hz = 1e9"),
                        ["sensors.frames.frame_rate_hz"], "above the limit of 1e+06 Hz"),
    "shorter_than_a_frame": (GOOD.replace("exposure_s = 0.002", "exposure_s = 0.002\nframe_rate_hz = 10"),
                             ["sequences[0].duration_s"], "shorter than one period of sensors.frames.frame_rate_hz"),
    "dataset_name_escapes": (GOOD.replace('name = "unit"', 'name = "../../evil"'), ["name"], "names the output"),
    "dataset_name_too_long": (GOOD.replace('name = "unit"', f'name = "{"a" * 300}"'), ["name"], "up to 100"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_spec_is_refused_naming_file_and_field(workdir, case, capsys):
    text, fields, fragment = BAD[case]
    path = _write(workdir, text)
    with pytest.raises(SpecError) as info:
        load_spec(path)
    errors = info.value.errors
    assert len(errors) == len(fields), errors
    for line, field in zip(errors, fields):
        assert line.startswith(f"{path}: {field}: "), line
        assert "\n" not in line
    assert fragment in "\n".join(errors)
    # Through the CLI: exit 2, one line per error, no traceback.
    assert main(["info", str(path)]) == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and captured.out == ""
    assert f"{path}: {path}" not in captured.err
    assert captured.err.rstrip("\n").count("\n") + 1 == len(fields)
    for field in fields:
        assert f"{path}: {field}: " in captured.err


def test_all_errors_are_collected(workdir):
    text = (GOOD.replace("seed = 7", "seed = -1").replace("lux = [1, 10.5, 1e4]", "lux = [0]")
            .replace("spp = 4", "spp = 0").replace("[sensors.frames]", "[sensors.radar]"))
    with pytest.raises(SpecError) as info:
        load_spec(_write(workdir, text))
    fields = [line.split(": ")[1] for line in info.value.errors]
    assert fields == ["seed", "lux[0]", "sequences[0].spp", "sensors.radar"]


def test_missing_spec_file(tmp_path, capsys):
    assert main(["info", str(tmp_path / "none.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "none.toml" in err


def test_bad_spec_via_console_script(workdir, simspad_cli):
    path = _write(workdir, BAD["lux_not_positive"][0])
    proc = simspad_cli.run("info", path)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 2 and all(str(path) in line for line in lines)


def test_info_summarises_a_spec(workdir, capsys):
    path = _write(workdir, GOOD)
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    for fragment in ("unit", "1, 10.5, 10000", "myscene", "second", "32×24 px", "4 spp", "spad: preset swissspad2",
                     "gate 1 µs", "frames: preset blackfly_s", "exposure 2 ms", "500 Hz", "ni, nedi_akf"):
        assert fragment in out, fragment
