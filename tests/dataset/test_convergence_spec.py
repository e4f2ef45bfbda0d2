"""``convergence = "cache"`` in a dataset spec (issue 35 goal 1's knob): checked by the render settings' rule,
carried into the render, hashed only when not "off", stated by the render's timeline.json and every recording,
shown by ``simspad info``; a converged sequence's faster speeds share no keyframes."""

from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest

from simspad.dataset.executors import ExecutorConfig
from simspad.dataset.generate import generate
from simspad.dataset.plan import make_plan
from simspad.dataset.spec import SequenceSpec
from simspad.dataset.spec_hashing import spec_hash
from simspad.dataset.spec_validation import load_spec, spec_from_dict
from simspad.errors import SimSpadError, SpecError
from simspad.io.manifest import read_manifest
from simspad.io.render_dir import write_render_dir
from simspad.render.renderer import RenderSettings, layout_render
from simspad.sensors.presets import sensor_params
from simspad.sensors.recording_settings import RecordingSettings
from simspad.sensors.simulate import simulate_recording

SPEC = {"name": "conv", "seed": 3, "lux": [100], "speed": [1, 2],
        "sequences": [{"scene": "siemens-star", "duration_s": 0.004, "resolution": [24, 16], "spp": 1}],
        "sensors": {"events": {"preset": "prophesee_gen4"}}}


def _with(**fields) -> dict:
    return {**SPEC, "sequences": [{**SPEC["sequences"][0], **fields}]}


def test_a_spec_without_the_fields_keeps_its_hash():
    """A path-traced sequence's dict (what its hashes cover) has no convergence keys, whatever cache_samples says:
    specs written before the fields existed keep their spec, render and recording hashes."""
    plain = spec_from_dict(SPEC)
    off = spec_from_dict(_with(convergence="off", cache_samples=8))
    assert "convergence" not in plain.sequences[0].to_dict() and "cache_samples" not in plain.sequences[0].to_dict()
    assert spec_hash(off) == spec_hash(plain)
    hashes = [[r.render_hash for r in make_plan(s, "x").renders] for s in (off, plain)]
    assert hashes[0] == hashes[1]
    cache = spec_from_dict(_with(convergence="cache", cache_samples=8))
    cache16 = spec_from_dict(_with(convergence="cache", cache_samples=16))
    assert cache.sequences[0].to_dict()["convergence"] == "cache"
    assert len({spec_hash(plain), spec_hash(cache), spec_hash(cache16)}) == 3


def test_the_fields_are_carried_into_the_render_settings():
    seq = SequenceSpec(name="s", scene="fan", trajectory=None, duration_s=0.01, convergence="cache",
                       cache_samples=32)
    settings = seq.render_settings(seed=1)
    assert (settings.convergence, settings.cache_samples) == ("cache", 32)
    shared = {f.name for f in dataclasses.fields(SequenceSpec)} & {f.name for f in dataclasses.fields(RenderSettings)}
    assert {"convergence", "cache_samples"} <= shared


@pytest.mark.parametrize("field, value", [("convergence", "mesh"), ("convergence", 1), ("cache_samples", 0),
                                          ("cache_samples", 2.5), ("cache_samples", True),
                                          ("cache_samples", 70000)])
def test_a_bad_value_is_refused_with_one_line_naming_file_and_field(field, value, tmp_path, simspad_cli):
    name = {"convergence": "convergence", "cache_samples": "cache_samples"}[field]
    expected = [m for f, m in RenderSettings(duration_s=0.004, **{field: value}).problems() if f == name]
    assert len(expected) == 1
    path = tmp_path / "bad.toml"
    path.write_text(f"""name = "bad"
lux = [100]
[[sequences]]
scene = "siemens-star"
duration_s = 0.004
resolution = [24, 16]
{field} = {json.dumps(value)}
""")
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert info.value.errors == [f"{path}: sequences[0].{field}: {expected[0]}"]
    res = simspad_cli.run("info", str(path))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert f"{path}: sequences[0].{field}: {expected[0]}" in res.stderr


def test_a_converged_render_neither_shares_nor_lends_keyframes():
    """The plan gives a converged sequence's faster speed no prefix, and the renderer refuses one either way."""
    plan = make_plan(spec_from_dict(_with(convergence="cache", cache_samples=8)), "x")
    assert [r.prefix for r in plan.renders] == [None, None]
    plain = make_plan(spec_from_dict(SPEC), "x")
    assert plain.renders[1].prefix is plain.renders[0]  # (path-traced: the faster one shares, as before)
    base = RenderSettings(duration_s=0.002, resolution=(24, 16), spp=1)
    off = layout_render("siemens-star", None, base)
    cache = layout_render("siemens-star", None, dataclasses.replace(base, convergence="cache", cache_samples=8))
    longer = dataclasses.replace(base, duration_s=0.004)
    for prefix, settings in ((off, dataclasses.replace(longer, convergence="cache", cache_samples=8)),
                             (cache, longer)):
        with pytest.raises(SimSpadError, match="own irradiance cache"):
            layout_render("siemens-star", None, settings, prefix=prefix)


@pytest.mark.slow
def test_a_converged_spec_is_generated_and_every_recording_states_it(tmp_path, simspad_cli):
    """End to end, a real converged render at 24×16 px: timeline.json and each recording state the mode and knobs,
    ``simspad info`` shows them for the spec and the recording."""
    spec_path = tmp_path / "conv.toml"
    spec_path.write_text(f"""name = "conv"
seed = 3
lux = [100]
speed = [1, 2]
[[sequences]]
name = "star"
scene = "siemens-star"
duration_s = 0.002
resolution = [24, 16]
spp = 1
convergence = "cache"
cache_samples = 4
[sensors.events]
preset = "prophesee_gen4"
[evaluation]
rate_hz = 1000
""")
    out = tmp_path / "out"
    res = generate(load_spec(spec_path), out, ExecutorConfig("local", workers=1), progress=False,
                   created_utc="2025-01-01T00:00:00Z")
    assert not res.failed
    m = read_manifest(out)
    assert len(m["renders"]) == 2 and len(m["recordings"]) == 2
    for r in m["renders"]:
        meta = json.loads((out / r["path"] / "timeline.json").read_text())
        conv = meta["renderer"]["convergence"]
        assert (conv["mode"], conv["cache_samples"]) == ("cache", 4)
        assert (out / r["path"] / conv["cache_file"]).is_file()
        assert "shared_keyframes" not in meta["schedule"]
    for e in m["recordings"]:
        with h5py.File(out / e["path"], "r") as f:
            stated = json.loads(f.attrs["render_convergence"])
            assert (stated["mode"], stated["cache_samples"]) == ("cache", 4)
            assert json.loads(f.attrs["spec"])["sequence"]["convergence"] == "cache"
    info = simspad_cli.run("info", str(out / m["recordings"][0]["path"]))
    assert info.returncode == 0 and "convergence cache: 4 irradiance estimates per cache point" in info.stdout
    info = simspad_cli.run("info", str(spec_path))
    assert info.returncode == 0 and "convergence cache (4 estimates per cache point)" in info.stdout


def test_a_path_traced_recording_has_no_convergence_attribute(tmp_path):
    """Recordings of path-traced renders keep their attributes (and bytes): no ``render_convergence``."""
    write_render_dir(tmp_path / "r", [0.0, 0.01], np.full((2, 4, 6), 0.5, np.float32))
    out = simulate_recording(tmp_path / "r", tmp_path / "rec.h5",
                             RecordingSettings(lux=100.0, sensors={"events": sensor_params("events")}))
    with h5py.File(out, "r") as f:
        assert "render_convergence" not in f.attrs


def test_a_converged_render_builds_its_cache_once_in_the_layout_job(tmp_path):
    """``simspad generate`` lays a render out in one job, then spreads its keyframes over workers: the layout job
    builds the irradiance cache, so no chunk in another worker finds it missing and builds its own."""
    from simspad.dataset.executors import job_environment, run_render_layout, run_render_chunk
    from simspad.dataset.jobs import LayoutResult

    spec = spec_from_dict(_with(convergence="cache", cache_samples=4), source_path=tmp_path / "conv.toml")
    task = make_plan(spec, tmp_path).renders[0]
    res = run_render_layout(task, str(tmp_path), job_environment())
    assert isinstance(res, LayoutResult), res
    final = tmp_path / task.rel_dir
    cache_file = final / res.layout.timeline["renderer"]["convergence"]["cache_file"]
    assert cache_file.is_file()  # before any keyframe is rendered
    assert not any((final / name).is_file() for name in res.layout.names)
    built = cache_file.stat().st_mtime_ns
    run_render_chunk(task, res.layout, (0, 1), str(tmp_path), job_environment())
    assert cache_file.stat().st_mtime_ns == built  # the chunk read it
    assert all((final / name).is_file() for name in res.layout.names[:2])
