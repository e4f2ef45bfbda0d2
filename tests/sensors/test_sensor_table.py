"""The sensor table (simspad/sensors/registry.py): the built-in rows, and a toy sensor registered through the table
alone (tests/helpers/toy_sensor.py, no other module edited) simulated on a real Mitsuba render, sized, validated,
read back and described."""

from __future__ import annotations

import re
import subprocess
import sys

import h5py
import numpy as np
import pytest

from simspad.cli.app import main
from simspad.cli.describe import describe_recording
from simspad.errors import InputError, SimSpadError
from simspad.io.recording import SENSOR_KINDS, open_recording
from simspad.io.recording import layout
from simspad.physics.radiometry import Optics
from simspad.radiance.timeline import Timeline
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.sensors import presets, registry
from simspad.sensors.presets import sensor_params
from simspad.sensors.recording_size import recording_samples
from simspad.sensors.simulate import RecordingSettings, simulate_recording
from tests.helpers import toy_sensor

W, H, DURATION_S, LUX = 24, 16, 0.004, 50.0


def test_the_builtin_rows_are_the_tables_every_layer_reads():
    assert tuple(registry.SENSORS) == tuple(SENSOR_KINDS) == ("spad", "frames", "events")
    for kind, row in registry.SENSORS.items():
        assert row.layout is layout.SENSOR_LAYOUTS[kind] and row.presets is presets.PRESETS[kind]
        assert type(sensor_params(kind)) is row.params and row.default_preset == presets.DEFAULT_PRESET[kind]
    with pytest.raises(SimSpadError, match="unknown sensor 'lidar'.*spad, frames, events"):
        registry.get_sensor("lidar")
    with pytest.raises(ValueError, match="registered already"):
        registry.register(registry.Sensor(**{**registry.SPAD.__dict__, "describe_attrs": ()}))


@pytest.fixture()
def photodiode():
    """The toy row registered for one test, then removed from every table register() wrote into."""
    registry.register(toy_sensor.PHOTODIODE)
    try:
        yield toy_sensor.PHOTODIODE
    finally:
        for table in (registry.SENSORS, layout.SENSOR_LAYOUTS, presets.PRESETS, presets.DEFAULT_PRESET):
            table.pop("photodiode", None)


@pytest.fixture(scope="module")
def render_dir(tmp_path_factory):
    """A real render: the rotating Siemens star at 24 × 16 px over 4 ms."""
    out = tmp_path_factory.mktemp("toy_sensor") / "star"
    render_sequence("siemens-star", None, RenderSettings(duration_s=DURATION_S, resolution=(W, H), spp=2, seed=1),
                    out_dir=out, progress=False)
    return out


def test_a_toy_sensor_registered_through_the_table_runs_end_to_end(photodiode, render_dir, tmp_path, capsys):
    assert "photodiode" in SENSOR_KINDS  # the name every layer imported before is live
    params = sensor_params("photodiode", None, {"rate_hz": 1500.0})
    assert params == toy_sensor.PhotodiodeParams(rate_hz=1500.0)
    out = simulate_recording(render_dir, tmp_path / "toy.h5", RecordingSettings(
        lux=LUX, sensors={"photodiode": params, "frames": sensor_params("frames", None, {"frame_rate_hz": 1000.0})},
        seed=3, stream_key=("star", LUX), gt_rate_hz=1000.0))

    flux_tl = Timeline.open(render_dir).photon_flux(LUX, Optics())
    t0, t1 = flux_tl.t_start, flux_tl.t_end
    n = int((t1 - t0) * 1500.0)
    with open_recording(out) as rec:
        assert rec.sensors == ("frames", "photodiode") and rec.attrs["sensors"] == "frames,photodiode"
        assert rec.view("photodiode") is rec.photodiode
        np.testing.assert_allclose(rec.photodiode.t, t0 + np.arange(n) / 1500.0, rtol=0, atol=1e-15)
        expected = [flux_tl.mean(a, a + 1 / 1500.0).mean(dtype=np.float64) for a in rec.photodiode.t]
        np.testing.assert_array_equal(rec.photodiode.mean_flux, expected)
        # the star turns, but the sensor's mean irradiance is that of the ground truth's frames
        gt_mean = np.mean([rec.gt.flux(i).mean(dtype=np.float64) for i in range(len(rec.gt.t))])
        assert rec.photodiode.mean_flux.mean() == pytest.approx(gt_mean, rel=0.02)
        a = rec.photodiode.attrs
        assert (a["rate_hz"], a["n_samples"], a["lux"]) == (1500.0, n, LUX)  # the common attrs written by simulate
    text = describe_recording(out)
    assert f"    photodiode {n} samples, " in text and "rate_hz=1500" in text
    assert main(["simulate", "--help"]) == 0  # the options' help is the table's, toy included
    help_text = " ".join(capsys.readouterr().out.split())
    assert "sensor kinds, of: spad, frames, events, photodiode. [default: spad,frames,events]" in help_text
    assert "photodiode basic" in help_text

    # the size model: rows counted before simulating, a unit slip refused with the figure
    assert recording_samples({"photodiode": params}, 2.0, 1000.0) == {"gt": 2000.0, "photodiode": 3000.0}
    with pytest.raises(SimSpadError, match="photodiode rows"):
        simulate_recording(render_dir, tmp_path / "big.h5", RecordingSettings(
            lux=LUX, sensors={"photodiode": toy_sensor.PhotodiodeParams(rate_hz=1e14)}))
    assert not (tmp_path / "big.h5").exists()
    with pytest.raises(SimSpadError, match="must be > 0") as bad:
        simulate_recording(render_dir, tmp_path / "bad.h5", RecordingSettings(
            lux=LUX, sensors={"photodiode": toy_sensor.PhotodiodeParams(rate_hz=-1.0)}))
    assert bad.value.field == "sensors.photodiode.rate_hz"

    # the layout row drives validation: instants out of order are refused, naming the dataset
    broken = tmp_path / "broken.h5"
    broken.write_bytes(out.read_bytes())
    with h5py.File(broken, "r+") as f:
        f["photodiode/t"][0] = f["photodiode/t"][1]
    with pytest.raises(InputError, match="photodiode/t.*index 1: not after the previous instant"):
        open_recording(broken)


TOY_SPEC = """
name = "toy"
seed = 1
lux = [50]

[[sequences]]
name = "star"
scene = "siemens-star"
duration_s = {duration_s}
resolution = [{w}, {h}]
spp = 2

[sensors.photodiode]
rate_hz = {rate_hz}
[sensors.frames]
preset = "blackfly_s"
frame_rate_hz = 1000.0

[evaluation]
rate_hz = 1000
"""


def _toy_spec(path, rate_hz=1500.0):
    path.write_text(TOY_SPEC.format(duration_s=DURATION_S, w=W, h=H, rate_hz=rate_hz))
    return path


@pytest.mark.slow
def test_the_estimate_costs_a_toy_sensor_from_its_row(photodiode, tmp_path):
    """`generate --estimate`'s cost model comes from the table: the toy (no cost model of its own) is probed and
    costed per megapixel-row of its size model, and its rate moves the estimate by exactly those rows."""
    from simspad.cli.describe_spec import describe_spec
    from simspad.cli.generate import _measured_estimate
    from simspad.dataset.estimate import estimate_spec, format_estimate
    from simspad.dataset.spec_validation import load_spec

    spec = load_spec(_toy_spec(tmp_path / "toy.toml"))
    summary = describe_spec(tmp_path / "toy.toml")  # `simspad info SPEC`: each row's line, the toy's fields
    assert f"      {registry.FRAMES.summarize(spec.sensors['frames'].params)}\n" in summary
    assert "    photodiode: preset basic (overrides: rate_hz=1500.0)\n      rate_hz 1500.0\n" in summary
    est, costs = _measured_estimate(spec)
    assert costs.sim_s_per["photodiode"] > 0 and costs.bytes_per["photodiode"] > 0
    assert costs.sim_unit == {"frames": "MP·frame", "photodiode": "MP·row"}
    assert re.search(r"photodiode \S+ s/MP·row", format_estimate(est, costs, workers=1))
    # ten times the rate: ten times the rows, each at the probed cost (time and bytes)
    faster = estimate_spec(load_spec(_toy_spec(tmp_path / "fast.toml", rate_hz=15000.0)), costs)
    rows = DURATION_S * (15000.0 - 1500.0) * W * H / 1e6
    assert faster.sim_cpu_s - est.sim_cpu_s == pytest.approx(costs.sim_s_per["photodiode"] * rows, rel=1e-9)
    assert faster.recordings_bytes - est.recordings_bytes == pytest.approx(
        costs.bytes_per["photodiode"] * rows, abs=1)


def test_a_toy_recording_is_readable_where_the_toy_is_not_installed(photodiode, render_dir, tmp_path, child_env,
                                                                     simspad_cli):
    out = simulate_recording(render_dir, tmp_path / "toy.h5", RecordingSettings(
        lux=LUX, sensors={"photodiode": toy_sensor.PhotodiodeParams()}))
    # the preview has no panel for it: it draws the ground truth and says so in one line
    png = tmp_path / "toy.png"
    preview = simspad_cli.run("preview", out, "--kind", "png", "--out", png)
    assert preview.returncode == 0, preview.stderr
    assert "  no panel for photodiode: the preview draws the ground truth and spad, frames, events only" \
        in preview.stdout and png.is_file()
    code = ("import sys; from simspad.io.recording import open_recording\n"
            "with open_recording(sys.argv[1]) as rec: print(rec.sensors, rec.attrs['sensors'], rec.gt.t.size)")
    run = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, timeout=120,
                         env=child_env)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["()", "photodiode", "5"]


PLUGIN_PYPROJECT = """
[build-system]
requires = ["setuptools"]
build-backend = "setuptools.build_meta"

[project]
name = "simspad-toy-photodiode"
version = "0.1"

[project.entry-points."simspad.sensors"]
photodiode = "toy_photodiode:PHOTODIODE"

[tool.setuptools]
py-modules = ["toy_photodiode"]
"""


@pytest.mark.slow
def test_an_installed_plugin_sensor_runs_through_the_command_line(simspad_cli, render_dir, tmp_path):
    src, site = tmp_path / "toy", tmp_path / "site"
    src.mkdir()
    (src / "pyproject.toml").write_text(PLUGIN_PYPROJECT)
    (src / "toy_photodiode.py").write_text(open(toy_sensor.__file__).read())
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                          "--no-index", "--target", str(site), str(src)], capture_output=True, text=True,
                         timeout=300)
    assert pip.returncode == 0, pip.stderr
    env = {"PYTHONPATH": f"{simspad_cli.env['PYTHONPATH']}:{site}"}
    out = tmp_path / "toy.h5"
    run = simspad_cli.run("simulate", render_dir, "--lux", LUX, "--sensors", "photodiode,spad", "--set",
                          "photodiode.rate_hz=1500", "--out", out, env=env)
    assert run.returncode == 0, run.stderr
    with h5py.File(out, "r") as f:
        assert {"gt", "spad", "photodiode"} <= set(f)
        assert f.attrs["sensors"] == "spad,photodiode" and f["photodiode"].attrs["rate_hz"] == 1500.0
    info = simspad_cli.run("info", out, env=env)
    assert info.returncode == 0, info.stderr
    assert re.search(r"\n    photodiode \d+ samples, .*\n +rate_hz=1500\n +mean ", info.stdout), info.stdout
    refused = simspad_cli.run("simulate", render_dir, "--lux", LUX, "--sensors", "photodiode", "--set",
                              "photodiode.rate_hz=-2", "--out", tmp_path / "neg.h5", env=env)
    assert refused.returncode == 2 and "rate_hz" in refused.stderr and not (tmp_path / "neg.h5").exists()
    unknown = simspad_cli.run("simulate", render_dir, "--lux", LUX, "--sensors", "photodiode", "--out",
                              tmp_path / "no.h5")
    assert unknown.returncode == 2 and "unknown sensor 'photodiode'" in unknown.stderr
    estimate = simspad_cli.run("generate", _toy_spec(tmp_path / "toy.toml"), "--estimate", "--out",
                               tmp_path / "toy-dataset", env=env)
    assert estimate.returncode == 0, estimate.stderr
    assert re.search(r"photodiode \S+ s/MP·row", estimate.stdout), estimate.stdout
    assert not (tmp_path / "toy-dataset").exists()
