"""One record travels whole (issue 34): each field has one rule and one message, whichever way it comes in; a
sequence's render settings are mapped once; a recording task carries the settings its simulation is given; one
results row record."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from simspad.cli import main
from simspad.defaults import duration_problem, gt_rate_problem, seed_problem
from simspad.dataset.plan import make_plan
from simspad.dataset.spec import SequenceSpec
from simspad.dataset.spec_validation import spec_from_dict
from simspad.errors import SimSpadError, SpecError
from simspad.evaluate.recordings import RecordingEntry
from simspad.io.render_dir import write_render_dir
from simspad.io.results_dir import RESULT_COLUMNS, ResultRow, write_results_dir
from simspad.render.settings import RenderSettings, resolution_problem
from simspad.sensors.recording_settings import RecordingSettings, lux_problem
from simspad.sensors.registry import SENSORS

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


def _render_dir(tmp_path):
    return write_render_dir(tmp_path / "r", np.array([0.0, 0.01]), np.ones((2, 4, 6, 3), np.float32)).parent


def _simulate(tmp_path, *options) -> tuple[int, Path]:
    out = tmp_path / "o" / "a.h5"
    return main(["simulate", str(_render_dir(tmp_path)), "--lux", "10", *options, "--out", str(out)]), out.parent


def _one_message_everywhere(tmp_path, capsys, message, *, render_field, render_kwargs, record_field,
                            record_kwargs, option, value, render_option=None):
    """The spec's error, the render and recording records' problem, ``simspad simulate OPTION`` (and, given
    ``render_option``, ``simspad render OPTION``) all state ``message``; the commands write nothing."""
    assert (render_field, message) in RenderSettings(**render_kwargs).problems()
    with pytest.raises(SimSpadError) as info:
        RecordingSettings(lux=10.0, sensors={}, **record_kwargs)
    assert (info.value.field, info.value.message) == (record_field, message)
    code, written = _simulate(tmp_path, option, value)
    assert code == 2 and capsys.readouterr().err == f"simspad: error: {option}: {message}\n"
    assert not written.exists()
    if render_option is not None:
        out = tmp_path / "render"
        assert main(["render", "siemens-star", "--duration", "0.001", render_option, value, "--out", str(out)]) == 2
        assert capsys.readouterr().err == f"simspad: error: {render_field}: {message}\n"
        assert not out.exists()


@pytest.mark.parametrize("rate", [0.0, -1.0, math.nan, math.inf])
def test_a_bad_ground_truth_rate_gets_one_message_from_the_spec_the_cli_and_the_records(rate, tmp_path, capsys):
    message = gt_rate_problem(rate)
    assert message and "\n" not in message
    assert _spec_errors(evaluation={"rate_hz": rate}) == [f"<spec>: evaluation.rate_hz: {message}"]
    # `simspad simulate --gt-rate` and `simspad render --gt-rate`: the same words, nothing written
    _one_message_everywhere(tmp_path, capsys, message, render_field="gt_rate_hz",
                            render_kwargs={"duration_s": 0.01, "gt_rate_hz": rate}, record_field="gt_rate_hz",
                            record_kwargs={"gt_rate_hz": rate}, option="--gt-rate", value=repr(rate),
                            render_option="--gt-rate")


def test_a_rate_of_the_wrong_type_is_named_in_the_spec():
    assert _spec_errors(evaluation={"rate_hz": "fast"}) == [f"<spec>: evaluation.rate_hz: {gt_rate_problem('fast')}"]
    assert gt_rate_problem(1e-3) is None and gt_rate_problem(np.float64(250.0)) is None


@pytest.mark.parametrize("seed", [-1, 2**64, 2**70])
def test_a_bad_seed_gets_one_message_from_the_spec_the_cli_and_the_records(seed, tmp_path, capsys):
    message = seed_problem(seed)
    assert message == f"must be an integer in [0, 2**64), got {seed!r}"
    # the spec used to accept any seed ≥ 0; one past 2**64 failed only when its first render started
    assert _spec_errors(seed=seed) == [f"<spec>: seed: {message}"]
    _one_message_everywhere(tmp_path, capsys, message, render_field="seed",
                            render_kwargs={"duration_s": 0.01, "seed": seed}, record_field="seed",
                            record_kwargs={"seed": seed}, option="--seed", value=str(seed), render_option="--seed")


def test_the_seed_rule_takes_every_uint64_and_nothing_else():
    for good in (0, 2**64 - 1, np.uint64(2**64 - 1)):
        assert seed_problem(good) is None
        RecordingSettings(lux=10.0, sensors={}, seed=good)
    assert spec_from_dict({**SPEC, "seed": 2**64 - 1}).seed == 2**64 - 1
    for bad in ("seven", True, 1.0):
        assert _spec_errors(seed=bad) == [f"<spec>: seed: {seed_problem(bad)}"]
    RecordingSettings(lux=10.0, sensors={}, seed=np.random.SeedSequence(5))  # a SeedSequence is its own check


@pytest.mark.parametrize("duration", [0.0, -1.0, math.nan, math.inf])
def test_a_bad_duration_gets_one_message_from_the_spec_the_cli_and_the_records(duration, tmp_path, capsys):
    message = duration_problem(duration)
    seq = {**SPEC["sequences"][0], "duration_s": duration}
    assert _spec_errors(sequences=[seq]) == [f"<spec>: sequences[0].duration_s: {message}"]
    # `simspad simulate --duration`: refused with the rule's words before the output folder is made
    _one_message_everywhere(tmp_path, capsys, message, render_field="duration",
                            render_kwargs={"duration_s": duration}, record_field="duration_s",
                            record_kwargs={"duration_s": duration}, option="--duration", value=repr(duration))


_BAD_PARAMS = [("spad", "qe", -1.0), ("spad", "qe", 2.0), ("spad", "dead_time_s", math.inf),
               ("spad", "compression", "lz4"), ("spad", "gate_s", 1.0), ("spad", "min_gate_s", 1.0),
               ("frames", "exposure_s", 0.5), ("frames", "bit_depth", 12.5), ("frames", "rgb", "yes please"),
               ("events", "substep_tolerance", 1e-12), ("events", "dark_current_e_s", -3.0),
               ("events", "hot_pixel_fraction", 1.5)]


@pytest.mark.parametrize("kind, field, value", _BAD_PARAMS)
def test_a_bad_sensor_parameter_gets_one_message_from_the_spec_the_cli_and_the_record(kind, field, value,
                                                                                      tmp_path, capsys):
    # the parameter record itself, built directly (the Python API)
    with pytest.raises(SimSpadError) as info:
        SENSORS[kind].params(**{field: value})
    where, message = info.value.field, info.value.message
    assert where == f"sensors.{kind}.{field}" and "\n" not in message and repr(value) in message
    # the dataset spec: one line naming the field, with the record's words
    assert _spec_errors(sensors={kind: {field: value}}) == [f"<spec>: {where}: {message}"]
    # `simspad simulate --set`: the same line, before the output folder is made
    code, written = _simulate(tmp_path, "--sensors", kind, "--set", f"{kind}.{field}={value}")
    assert code == 2 and capsys.readouterr().err == f"simspad: error: {where}: {message}\n"
    assert not written.exists()


def test_the_sensor_models_trust_the_record_and_keep_only_the_size_rule(tmp_path):
    # a good record passes every row's size check; the rolling-shutter readout is refused at the size that breaks it
    for row in SENSORS.values():
        if row.name in ("spad", "frames", "events"):
            row.validate(row.presets[row.default_preset], 4096)
    slow = SENSORS["frames"].params(rolling_shutter_line_s=1e-4)  # 10 ms frame period: 100 rows fit, 101 do not
    SENSORS["frames"].validate(slow, 100)
    with pytest.raises(SimSpadError) as info:
        SENSORS["frames"].validate(slow, 102)
    assert info.value.field == "sensors.frames.rolling_shutter_line_s"
    # a spec whose sequence is too tall for it is refused up front, naming the field once
    errors = _spec_errors(sensors={"frames": {"rolling_shutter_line_s": 1e-4}},
                          sequences=[{**SPEC["sequences"][0], "resolution": [16, 120]}])
    with pytest.raises(SimSpadError) as tall:
        SENSORS["frames"].validate(slow, 120)
    assert errors == [f"<spec>: sensors.frames.rolling_shutter_line_s: {tall.value.message}"]
    # and so is `simspad simulate` on a render that tall, before anything is written
    render = write_render_dir(tmp_path / "tall", np.array([0.0, 0.01]), np.ones((2, 120, 4, 3), np.float32)).parent
    out = tmp_path / "o" / "a.h5"
    assert main(["simulate", str(render), "--lux", "10", "--sensors", "frames", "--set",
                 "frames.rolling_shutter_line_s=1e-4", "--out", str(out)]) == 2
    assert not out.exists()


def test_results_json_lists_recordings_with_one_builder():
    entry = RecordingEntry(path=Path("/d/recordings/fan/a.h5"), rel="recordings/fan/a.h5", sequence="fan",
                           scene="fan", lux=10.0, key="fan/10lx", speed_factor=2.0, image_speed_px_s=3.5,
                           about={"trajectory": "fan.toml"})
    base = {"recording": "recordings/fan/a.h5", "key": "fan/10lx", "sequence": "fan", "scene": "fan", "lux": 10.0,
            "speed_factor": 2.0, "image_speed_px_s": 3.5, "trajectory": "fan.toml"}
    assert entry.summary() == base  # `simspad score`
    assert entry.summary(ground_truth=False, preview="previews/fan-10lx.png") == \
        {**base, "ground_truth": False, "preview": "previews/fan-10lx.png"}  # `simspad evaluate`


def test_results_json_created_utc_honours_source_date_epoch(tmp_path, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    for name in ("a", "b"):
        write_results_dir(tmp_path / name, "score", [], [], [], {"rate_hz": 1000.0})
    a, b = ((tmp_path / name / "results.json").read_bytes() for name in ("a", "b"))
    assert a == b and json.loads(a)["created_utc"] == "2023-11-14T22:13:20+00:00"
    monkeypatch.delenv("SOURCE_DATE_EPOCH")
    write_results_dir(tmp_path / "c", "score", [], [], [], {})
    assert json.loads((tmp_path / "c" / "results.json").read_text())["created_utc"].endswith("+00:00")
