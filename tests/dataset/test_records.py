"""One record travels whole (issue 34): each field has one rule and one message, whichever way it comes in; a
sequence's render settings are mapped once; a recording task carries the settings its simulation is given; one
results row record."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from simspad.cli import main
from simspad.dataset.plan import make_plan
from simspad.dataset.spec import SequenceSpec
from simspad.dataset.spec_validation import spec_from_dict
from simspad.errors import SimSpadError, SpecError
from simspad.io.render_dir import write_render_dir
from simspad.io.results_dir import RESULT_COLUMNS, ResultRow, write_results_dir
from simspad.render.settings import RenderSettings, resolution_problem
from simspad.sensors.recording_settings import RecordingSettings, lux_problem

SPEC = {"name": "rec", "seed": 3, "lux": [10, 1000], "speed": [1, 4],
        "sequences": [{"scene": "siemens-star", "duration_s": 0.02, "resolution": [16, 12], "spp": 1}],
        "sensors": {"spad": {"preset": "swissspad2"}, "frames": {"preset": "blackfly_s"}}}


def _spec_errors(**changes) -> list[str]:
    with pytest.raises(SpecError) as info:
        spec_from_dict({**SPEC, **changes})
    return info.value.errors


@pytest.mark.parametrize("lux", [0.0, -5.0, math.nan, math.inf, 1e30, 1e-300])
def test_a_bad_lux_gets_one_message_from_the_spec_the_cli_and_the_record(lux, tmp_path, capsys):
    message = lux_problem(lux)
    assert message and "\n" not in message
    # the dataset spec: one line naming the field
    assert _spec_errors(lux=[10, lux]) == [f"<spec>: lux[1]: {message}"]
    # the recording record itself
    with pytest.raises(SimSpadError) as info:
        RecordingSettings(lux=lux, sensors={})
    assert (info.value.field, info.value.message) == ("lux", message)
    # `simspad simulate --lux`: the same words under the option's name, nothing written
    render = write_render_dir(tmp_path / "r", np.array([0.0, 0.01]), np.ones((2, 4, 6, 3), np.float32)).parent
    assert main(["simulate", str(render), "--lux", repr(lux), "--out", str(tmp_path / "o" / "a.h5")]) == 2
    assert capsys.readouterr().err == f"simspad: error: --lux: {message}\n"
    assert not (tmp_path / "o").exists()


def test_lux_of_the_wrong_type_is_named_in_the_spec():
    assert _spec_errors(lux=["bright"]) == [f"<spec>: lux[0]: {lux_problem('bright')}"]
    assert "got string 'bright' (expected an illuminance in lux > 0)" in lux_problem("bright")
    assert lux_problem(1e-6) is None and lux_problem(1e6) is None and lux_problem(np.float64(3.0)) is None


@pytest.mark.parametrize("resolution", [[32, 0], [32], [32.5, 24], [-1, 24], [True, 24]])
def test_a_bad_resolution_gets_one_message_from_the_spec_the_cli_and_the_record(resolution, tmp_path, capsys):
    message = resolution_problem(resolution)
    assert message and "two positive integers" in message
    seq = {**SPEC["sequences"][0], "resolution": resolution}
    assert _spec_errors(sequences=[seq]) == [f"<spec>: sequences[0].resolution: {message}"]
    with pytest.raises(SimSpadError) as info:
        RenderSettings(duration_s=0.01, resolution=tuple(resolution)).checked_size()
    assert (info.value.field, info.value.message) == ("resolution", resolution_problem(tuple(resolution)))
    if len(resolution) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in resolution):
        # `simspad render --resolution WxH`: refused by the record before the output folder is made
        out = tmp_path / "render"
        text = "x".join(str(v) for v in resolution)
        assert main(["render", "siemens-star", "--duration", "0.001", "--resolution", text, "--out", str(out)]) == 2
        assert capsys.readouterr().err == f"simspad: error: resolution: {resolution_problem(tuple(resolution))}\n"
        assert not out.exists()


@pytest.mark.parametrize("field, value", [("spp", 0), ("spp", 2.5), ("max_flow_px", -1.0), ("max_flow_px", 1e-9),
                                          ("min_rate_hz", math.inf), ("duration_s", 0.0), ("duration_s", "long"),
                                          ("start_s", math.nan), ("interpolation", "cubic"),
                                          ("convergence", "mesh"), ("cache_samples", 0),
                                          ("resolution", [16000, 16000])])
def test_a_bad_sequence_field_gets_the_render_settings_message(field, value):
    name = {"duration_s": "duration", "start_s": "start"}.get(field, field)
    settings = RenderSettings(**{"duration_s": 0.02, "resolution": [16, 12], "spp": 1, field: value})
    expected = [message for f, message in settings.problems() if f == name]
    assert len(expected) == 1
    assert _spec_errors(sequences=[{**SPEC["sequences"][0], field: value}]) == \
        [f"<spec>: sequences[0].{field}: {expected[0]}"]


def test_a_negative_start_is_the_specs_own_rule():
    errors = _spec_errors(sequences=[{**SPEC["sequences"][0], "start_s": -1.0}])
    assert errors == ["<spec>: sequences[0].start_s: must be ≥ 0, got -1.0 (expected a start time in seconds ≥ 0)"]
    assert RenderSettings(duration_s=0.02, start_s=-1.0).problems() == []


def test_every_field_a_sequence_shares_with_render_settings_is_carried_over():
    seq = SequenceSpec(name="s", scene="fan", trajectory=None, duration_s=0.25, start_s=0.5, resolution=(40, 30),
                       spp=7, max_flow_px=0.75, min_rate_hz=123.0, interpolation="warp", convergence="cache",
                       cache_samples=32)
    settings = seq.render_settings(seed=11, gt_rate_hz=250.0)
    shared = {f.name for f in dataclasses.fields(SequenceSpec)} & {f.name for f in dataclasses.fields(RenderSettings)}
    assert shared == {"duration_s", "start_s", "resolution", "spp", "max_flow_px", "min_rate_hz", "interpolation",
                      "convergence", "cache_samples"}
    for name in shared:
        assert getattr(settings, name) == getattr(seq, name), name
    assert (settings.seed, settings.gt_rate_hz) == (11, 250.0)
    assert settings.checked_size() == (40, 30)


def test_a_recording_task_carries_the_settings_its_file_states():
    spec = spec_from_dict(SPEC)
    plan = make_plan(spec, "2025-01-01T00:00:00Z")
    assert len(plan.recordings) == 4
    for task in plan.recordings:
        s = task.settings
        assert isinstance(s, RecordingSettings) and task.lux == s.lux
        assert s.sensors == {kind: sensor.params for kind, sensor in spec.sensors.items()}
        assert (s.start_s, s.duration_s, s.seed, s.gt_rate_hz) == (0.0, 0.02, 3, spec.evaluation.rate_hz)
        stated = json.loads(dict(task.metadata)["spec"])  # what the recording's "spec" attribute will say
        assert stated["lux"] == s.lux and tuple(stated["stream_key"]) == s.stream_key
        assert stated["optics"] == dataclasses.asdict(s.optics)
        expected_key = ("siemens-star", s.lux) if task.speed_factor == 1.0 else \
            ("siemens-star", s.lux, "speed", task.speed_factor)
        assert s.stream_key == expected_key


class _Entry:
    scene, sequence, lux, rel, speed_factor, image_speed_px_s = "fan", "fan", 10.0, "recordings/fan/a.h5", 1.0, 2.5


def test_results_rows_keep_their_columns_and_results_json_is_built_once(tmp_path):
    assert RESULT_COLUMNS == (
        "method", "label", "sensors", "scene", "sequence", "lux", "recording", "speed_factor", "image_speed_px_s",
        "psnr_db", "ssim", "mtf_at_0p25_cyc_px", "mtf_at_0p40_cyc_px", "mtf50_cyc_px", "bandwidth_khz_per_pixel",
        "bandwidth_bits_per_pixel_s", "absolute_scale", "n_frames", "runtime_s", "white_point_ph_s_m2", "image",
        "error", "params")
    row = ResultRow.for_recording("ni", _Entry(), params="")
    with pytest.raises(TypeError, match="no column 'psnr'"):
        row.update(psnr=1.0)
    row.update(psnr_db=31.5, n_frames=4)
    submitted = ResultRow.for_recording("x", _Entry(), label="X", sensors="S")
    write_results_dir(tmp_path, "score", [row, submitted], [], [], {"rate_hz": 1000.0})
    lines = (tmp_path / "results.csv").read_text().splitlines()
    assert lines[0] == ",".join(RESULT_COLUMNS)
    assert lines[1] == "ni,ni,,fan,fan,10.0,recordings/fan/a.h5,1.0,2.5,31.5,nan,nan,nan,nan,nan,nan,true,4,nan,nan,,,"
    assert lines[2].startswith("x,X,S,fan,")
    meta = json.loads((tmp_path / "results.json").read_text())
    assert (meta["format"], meta["kind"], meta["rate_hz"]) == ("simspad-results", "score", 1000.0)
    assert isinstance(meta["created_utc"], str) and meta["created_utc"].endswith("+00:00")
    assert [r["params"] for r in meta["results"]] == ["", None] and meta["results"][0]["ssim"] is None
