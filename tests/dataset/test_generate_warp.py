"""``interpolation = "warp"`` in a dataset spec: the render is spread over workers in two phases (anchors and
the noise probe, then runs of segments between anchors) and gives the bytes of a one-process render."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from simspad.dataset.executors import ExecutorConfig
from simspad.dataset.generate import generate
from simspad.dataset.spec_validation import load_spec
from simspad.errors import SpecError
from simspad.io.hashing import file_sha256
from simspad.render.renderer import RenderSettings, render_sequence

pytestmark = pytest.mark.slow  # generates datasets

SPEC = """
name = "warped"
seed = 3
output = "unused"
lux = [100]

[[sequences]]
name = "fan"
scene = "fan"
duration_s = 0.04
resolution = [32, 24]
spp = 4
interpolation = "{interpolation}"

[sensors.spad]
preset = "swissspad2"
"""


def _render_dir(out: Path) -> Path:
    (render,) = (out / "renders").iterdir()
    return render


def _frames(render: Path) -> dict[str, str]:
    meta = json.loads((render / "timeline.json").read_text())
    return {kf["file"]: file_sha256(render / kf["file"]) for kf in meta["keyframes"]}


def test_warp_render_in_generate_is_chunk_independent(tmp_path):
    spec = tmp_path / "warped.toml"
    spec.write_text(SPEC.format(interpolation="warp"))
    outs = {}
    for workers in (1, 2):
        outs[workers] = tmp_path / f"w{workers}"
        res = generate(load_spec(spec), outs[workers], ExecutorConfig("local", workers=workers), progress=False)
        assert not res.failed
    renders = {w: _render_dir(o) for w, o in outs.items()}
    meta = json.loads((renders[2] / "timeline.json").read_text())
    sources = [kf["source"] for kf in meta["keyframes"]]
    assert meta["schedule"]["interpolation"] == "warp" and "warp" in sources and "render" in sources
    assert meta["schedule"]["n_rendered_keyframes"] == sources.count("render") < len(sources)
    assert meta["schedule"]["warp"]["n_warped"] == sources.count("warp")
    # One worker or two (other chunks): the same keyframes, byte for byte, and the same timeline.
    assert _frames(renders[1]) == _frames(renders[2])
    assert (renders[1] / "timeline.json").read_bytes() == (renders[2] / "timeline.json").read_bytes()
    # The same as `simspad render --interpolation warp` in one process with the render's own settings.
    r = meta["renderer"]
    settings = RenderSettings(duration_s=meta["duration_s"], start_s=meta["start_s"], resolution=(32, 24),
                              spp=r["spp"], seed=r["seed"], max_flow_px=r["max_flow_px"],
                              min_rate_hz=r["min_rate_hz"], interpolation="warp")
    single = tmp_path / "single"
    render_sequence("fan", None, settings, out_dir=single, progress=False)
    assert _frames(single) == _frames(renders[2])
    single_meta = json.loads((single / "timeline.json").read_text())
    assert single_meta["keyframes"] == meta["keyframes"]
    # Resumed after losing half of its synthesized keyframes and its timeline: the same bytes again.
    before = _frames(single)
    for kf in single_meta["keyframes"][1::2]:
        if kf["source"] == "warp":
            (single / kf["file"]).unlink()
    (single / "timeline.json").unlink()
    render_sequence("fan", None, settings, out_dir=single, progress=False)
    assert _frames(single) == before
    assert single_meta["schedule"]["warp"] == meta["schedule"]["warp"]  # (generate adds the SPAD-bin comparison)
    # A linear spec renders every keyframe (and its hash, hence its render directory, is the one it always had).
    spec.write_text(SPEC.format(interpolation="linear"))
    lin = tmp_path / "linear"
    generate(load_spec(spec), lin, ExecutorConfig("local", workers=2), progress=False)
    lin_meta = json.loads((_render_dir(lin) / "timeline.json").read_text())
    assert {kf["source"] for kf in lin_meta["keyframes"]} == {"render"}
    assert _render_dir(lin).name != renders[2].name


def test_bad_interpolation_is_named(tmp_path):
    spec = tmp_path / "bad.toml"
    spec.write_text(SPEC.format(interpolation="cubic"))
    with pytest.raises(SpecError, match=r"sequences\[0\]\.interpolation"):
        load_spec(spec)
