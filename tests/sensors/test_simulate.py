"""`simulate_recording` and `simspad simulate`: recording layout, ground truth, determinism, bad input."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace

import numpy as np
import pytest

from simspad.cli import main
from simspad.errors import SimSpadError
from simspad.io.recording import open_recording
from simspad.io.render_dir import write_render_dir
from simspad.physics.radiometry import Optics, flux_scale
from simspad.radiance.timeline import Timeline
from simspad.sensors.presets import sensor_params
from simspad.cli.simulate import parse_overrides, parse_value
from simspad.sensors.simulate import RecordingSettings, simulate_recording

H, W = 12, 20
TIMES = np.array([0.0, 0.0013, 0.0029, 0.004])


def _frames(rng):
    base = rng.uniform(0.2, 1.0, (H, W, 3))
    return np.stack([base * (1.0 + 0.4 * np.sin(900 * t)) for t in TIMES]).astype(np.float32)


@pytest.fixture()
def render_dir(tmp_path):
    rng = np.random.default_rng(0)
    poses = np.tile(np.eye(4), (TIMES.size, 1, 1))
    poses[:, 0, 3] = np.arange(TIMES.size) * 0.1
    depth = np.broadcast_to(np.linspace(1, 2, W, dtype=np.float32), (TIMES.size, H, W))
    write_render_dir(tmp_path / "render", TIMES, _frames(rng), depth=depth, poses=poses, scene="unit",
                     trajectory="pan")
    return tmp_path / "render"


def _sensors(**spad):
    return {"spad": sensor_params("spad", None, spad),
            "frames": sensor_params("frames", None, {"frame_rate_hz": 1000.0}),
            "events": sensor_params("events")}


def test_recording_layout_and_ground_truth(render_dir, tmp_path):
    out = simulate_recording(render_dir, tmp_path / "rec.h5", RecordingSettings(
        lux=10.0, sensors=_sensors(), seed=4, stream_key=("unit", 10.0), gt_rate_hz=1000.0))
    tl = Timeline.open(render_dir)
    with open_recording(out) as rec:
        a = rec.attrs
        assert a["format"] == "simspad-recording" and a["format_version"] == 1
        for key in ("simspad_version", "scene", "trajectory", "lux", "seed", "width", "height", "duration_s", "spec",
                    "created_utc", "sequence"):
            assert key in a
        assert (a["width"], a["height"], a["lux"], a["scene"], a["trajectory"]) == (W, H, 10.0, "unit", "pan")
        assert np.isclose(a["duration_s"], 0.004)
        json.loads(a["spec"])
        assert rec.sensors == ("spad", "frames", "events")
        # SPAD
        sa = rec.spad.attrs
        assert sa["gate_s"] != "auto" and 5.75e-9 <= sa["gate_s"] <= sa["bin_s"]
        assert np.isclose(sa["pixel_area_m2"], sa["pixel_pitch_m"] ** 2) and sa["lux"] == 10.0
        n = rec.spad.n_bins
        assert n == int((0.004 - sa["gate_s"]) / sa["bin_s"]) + 1
        assert rec.h5["spad/bits"].shape == (n, H, (W + 7) // 8) and rec.h5["spad/bits"].chunks[0] >= 1
        assert np.allclose(rec.spad.t_start, np.arange(n) * sa["bin_s"])
        assert rec.spad.dcr_cps.shape == (H, W) and rec.spad.dcr_cps.dtype == np.float32
        # ground truth: instantaneous flux at 1 kHz, lux convention on the first keyframe
        assert np.allclose(rec.gt.t, [0.0, 0.001, 0.002, 0.003, 0.004])
        y0 = tl.keyframe(0)
        scale = flux_scale(float(np.mean(y0, dtype=np.float64)), 10.0, Optics())
        gt = rec.gt.flux()
        assert gt.shape == (5, H, W) and gt.dtype == np.float32
        assert np.allclose(gt[0], y0 * scale, rtol=1e-5)
        assert np.allclose(gt[2], tl.sample(0.002) * scale, rtol=1e-5)
        assert np.allclose(rec.gt.depth(1), np.linspace(1, 2, W)[None].repeat(H, 0), rtol=1e-6)
        assert np.allclose(rec.poses.t, TIMES) and rec.poses.camera_to_world.shape == (4, 4, 4)
        # the SPAD's counts follow the ground truth (same flux, same time base)
        counts = rec.spad.counts(0, n)
        q = sa["detection_area_m2"]
        g = sa["gate_s"]
        flux_tl = tl.scaled(scale)
        p_bins = np.stack([-np.expm1(-(q * flux_tl.integrate(t, t + g) + rec.spad.dcr_cps * g))
                           for t in rec.spad.t_start])
        mu, var = p_bins.sum(), (p_bins * (1 - p_bins)).sum()
        secondary = (sa["afterpulsing_probability"] + 4 * sa["crosstalk_probability"]) * mu
        assert abs(counts.sum() - mu) < 5 * np.sqrt(var) + secondary
        assert rec.frames.n_frames == 4 and rec.has("events")


def test_determinism_same_seed_same_bytes(render_dir, tmp_path):
    meta = {"created_utc": "2026-01-01T00:00:00Z"}
    settings = RecordingSettings(lux=3.0, sensors=_sensors(), seed=9, stream_key=("s", 3.0))
    a = simulate_recording(render_dir, tmp_path / "a.h5", settings, metadata=meta)
    b = simulate_recording(render_dir, tmp_path / "b.h5", settings, metadata=meta)
    c = simulate_recording(render_dir, tmp_path / "c.h5", replace(settings, seed=10), metadata=meta)
    digest = [hashlib.sha256(p.read_bytes()).hexdigest() for p in (a, b, c)]
    assert digest[0] == digest[1]
    with open_recording(a) as ra, open_recording(c) as rc:
        assert not np.array_equal(ra.h5["spad/bits"][()], rc.h5["spad/bits"][()])


def test_fixed_gate_and_sensor_subset(render_dir, tmp_path):
    settings = RecordingSettings(lux=1.0, sensors={"spad": _sensors(gate_s=1e-6)["spad"]}, start_s=0.001,
                                 duration_s=0.002)
    out = simulate_recording(render_dir, tmp_path / "s.h5", settings)
    with open_recording(out) as rec:
        assert rec.sensors == ("spad",) and rec.spad.attrs["gate_s"] == 1e-6 and not rec.spad.attrs["gate_auto"]
        assert np.isclose(rec.spad.t_start[0], 0.001) and np.isclose(rec.duration_s, 0.002)
        assert np.allclose(rec.gt.t, [0.001, 0.002, 0.003])


def test_parse_values_and_overrides():
    assert parse_value("auto") == "auto" and parse_value("true") is True and parse_value("3") == 3
    assert parse_value("1e-6") == 1e-6
    assert parse_overrides(["spad.gate_s=1e-6"], ["spad"]) == {"spad": {"gate_s": 1e-6}}
    with pytest.raises(SimSpadError, match="not in --sensors"):
        parse_overrides(["frames.exposure_s=1e-3"], ["spad"])
    with pytest.raises(SimSpadError, match="SENSOR.FIELD=VALUE"):
        parse_overrides(["gate_s"], ["spad"])


def _break(case, root):
    tl = json.loads((root / "timeline.json").read_text())
    if case == "missing_frame":
        (root / tl["keyframes"][2]["file"]).unlink()
    elif case == "non_increasing":
        tl["keyframes"][2]["t"] = tl["keyframes"][1]["t"]
        (root / "timeline.json").write_text(json.dumps(tl))
    elif case in ("nan", "negative"):
        frames = _frames(np.random.default_rng(0))
        frames[-1, 3, 4, 1] = np.nan if case == "nan" else -1.0  # last keyframe: found mid-simulation
        write_render_dir(root, TIMES, frames, scene="unit")


CLI_CASES = [
    ("missing_frame", [], "missing"),
    ("non_increasing", [], "strictly increasing"),
    ("nan", [], "NaN"),
    ("negative", [], "negative radiance"),
    (None, ["--set", "spad.no_such_field=1"], "no_such_field"),
    (None, ["--set", "spad.gate_s=1e-12"], "gate_s"),
    (None, ["--sensors", "spad,sonar"], "sonar"),
    (None, ["--lux", "0"], "--lux"),
    (None, ["--duration", "1.0"], "duration_s"),
]


@pytest.mark.parametrize("case,extra,needle", CLI_CASES)
def test_cli_bad_input_one_line_exit_2_no_file(render_dir, tmp_path, capsys, case, extra, needle):
    if case:
        _break(case, render_dir)
    out_dir = tmp_path / "out"
    argv = ["simulate", str(render_dir), "--lux", "5", "--out", str(out_dir / "rec.h5"), *extra]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("simspad: error:") and needle in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not out_dir.exists() or not any(out_dir.iterdir())


@pytest.mark.slow
def test_cli_process_writes_and_fails_cleanly(render_dir, tmp_path, simspad_cli):
    out = tmp_path / "ok.h5"
    ok = simspad_cli.run("simulate", render_dir, "--lux", "2", "--sensors", "spad", "--set", "spad.gate_s=2e-6",
                         "--out", out)
    assert ok.returncode == 0, ok.stderr
    with open_recording(out) as rec:
        assert rec.spad.attrs["gate_s"] == 2e-6
    _break("nan", render_dir)
    bad = simspad_cli.run("simulate", render_dir, "--lux", "2", "--sensors", "spad", "--out", tmp_path / "bad.h5")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and "NaN" in bad.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.h5", "render"]
