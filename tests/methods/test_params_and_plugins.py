"""Methods are open: parameters from a spec or ``--param``, validated once and recorded; third-party methods
through the ``simspad.methods`` entry-point group, run in ``simspad evaluate``'s worker processes."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from simspad.dataset.spec_validation import load_spec
from simspad.errors import SimSpadError
from simspad.methods.registry import check_method_params, get_method, method_parameters

REPO = Path(__file__).resolve().parents[2]


def test_every_builtin_method_lists_its_parameters_and_builds_with_them():
    params = method_parameters("nedi_akf")
    assert params["aggregate_hz"] is None and params["sigma_p"] == 0.005 and params["q_threshold"] is None
    assert method_parameters("qbp") == {"burst_bins": 1000, "block_bins": 100, "tile_px": 16, "hot_dcr_cps": 100.0}
    assert check_method_params("nedi_akf", {"aggregate_hz": 800, "sigma_iso": 0.01}) == \
        {"aggregate_hz": 800, "sigma_iso": 0.01}
    method = get_method("nedi_akf", aggregate_hz=800, sigma_iso=0.01)
    assert method.aggregate_hz == 800 and method.akf == {"sigma_iso": 0.01}
    assert check_method_params("qbp", {"tile_px": 8.0}) == {"tile_px": 8}  # an integral float is the int


@pytest.mark.parametrize("params, field, words", [
    ({"bogus": 1}, "params.nedi_akf.bogus", "unknown parameter"),
    ({"tile_px": 2.5}, "params.qbp.tile_px", "an integer"),
    ({"f_cut_hz": "fast"}, "params.cf.f_cut_hz", "a number"),
    ({"integrate": 1}, "params.adaptive_nedi_akf.integrate", "true or false"),
    ({"sigma_p": float("nan")}, "params.nedi_akf.sigma_p", "finite"),
])
def test_a_bad_parameter_is_one_error_naming_method_and_key(params, field, words):
    method = field.split(".")[1]
    with pytest.raises(SimSpadError) as err:
        check_method_params(method, params)
    assert err.value.field == field and words in err.value.message


def test_spec_params_are_validated_and_kept_in_the_spec_record(tmp_path):
    base = textwrap.dedent("""
        name = "p"
        lux = [10]
        [[sequences]]
        scene = "office"
        duration_s = 0.01
        resolution = [32, 24]
        spp = 1
        """)
    good = tmp_path / "good.toml"
    good.write_text(base + "[evaluation.params.nedi_akf]\naggregate_hz = 800\n")
    spec = load_spec(good)
    assert spec.evaluation.params == {"nedi_akf": {"aggregate_hz": 800}}
    assert spec.evaluation.to_dict()["params"] == {"nedi_akf": {"aggregate_hz": 800}}
    bad = tmp_path / "bad.toml"
    bad.write_text(base + "[evaluation.params.nedi_akf]\naggregate_hertz = 800\n[evaluation.params.nope]\nx = 1\n")
    with pytest.raises(SimSpadError) as err:
        load_spec(bad)
    text = str(err.value.format())
    assert "evaluation.params.nedi_akf.aggregate_hertz" in text and "evaluation.params.nope" in text


def _results(out: Path) -> list[dict]:
    with open(out / "results.csv", newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_param_on_the_command_line_reaches_the_method_and_is_recorded(simspad_cli, evaluation_dataset, tmp_path):
    out = tmp_path / "res"
    run = simspad_cli.run("evaluate", evaluation_dataset, "--methods", "ni", "--param", "ni.aggregate_hz=2000",
                          "--out", out)
    assert run.returncode == 0, run.stderr
    rows = _results(out)
    assert rows and all(json.loads(r["params"]) == {"aggregate_hz": 2000} for r in rows)
    assert json.loads((out / "results.json").read_text())["params"] == {"ni": {"aggregate_hz": 2000}}
    # 2 kHz aggregates read ≈ 5× as many values per pixel per second as the default 0.4 kHz (whole aggregates
    # over a 10 ms recording: 4 at 0.4 kHz, so the span's edges move the ratio by a few per cent)
    default = tmp_path / "default"
    assert simspad_cli.run("evaluate", evaluation_dataset, "--methods", "ni", "--out", default).returncode == 0
    ratio = float(rows[0]["bandwidth_khz_per_pixel"]) / float(_results(default)[0]["bandwidth_khz_per_pixel"])
    assert 4.5 < ratio < 5.5
    assert _results(default)[0]["params"] == ""
    bad = simspad_cli.run("evaluate", evaluation_dataset, "--methods", "ni", "--param", "ni.aggregate=1",
                          "--out", tmp_path / "bad")
    assert bad.returncode == 2 and "--param.ni.aggregate" in bad.stderr and "Traceback" not in bad.stderr
    assert not (tmp_path / "bad").exists()


PLUGIN_PYPROJECT = """
[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "simspad-toy-method"
version = "0.1"

[project.entry-points."simspad.methods"]
toy_gain = "toy_method:ToyGain"

[tool.setuptools]
py-modules = ["toy_method"]
"""

PLUGIN_MODULE = '''
"""A third-party method: the recording's own ground truth times a gain (a known input for the scores)."""
from simspad.methods import Method


class ToyGain(Method):
    name = "toy_gain"
    label = "Toy gain (GT)"
    sensors = "GT"
    full_name = "Ground truth times a constant gain"
    citation = "tests/methods/test_params_and_plugins.py"
    requires = ("gt",)
    absolute_scale = True

    def __init__(self, gain: float = 1.0):
        if not gain > 0:
            raise ValueError("gain must be > 0")
        self.gain = gain

    def _run(self, rec, times_s, tally):
        t = rec.gt.t
        for ts in times_s:
            i = int(abs(t - ts).argmin())
            yield rec.gt.flux(i) * self.gain
'''


@pytest.mark.slow
def test_an_installed_plugin_method_runs_in_evaluate_workers_and_on_the_leaderboard(
        simspad_cli, evaluation_dataset, tmp_path):
    src, site = tmp_path / "toy", tmp_path / "site"
    src.mkdir()
    (src / "pyproject.toml").write_text(PLUGIN_PYPROJECT)
    (src / "toy_method.py").write_text(PLUGIN_MODULE)
    pip = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                          "--no-index", "--target", str(site), str(src)], capture_output=True, text=True,
                         timeout=300)
    assert pip.returncode == 0, pip.stderr
    env = {"PYTHONPATH": f"{simspad_cli.env['PYTHONPATH']}:{site}"}
    runs = {}
    for gain in (1.0, 2.0):
        out = tmp_path / f"gain{gain:g}"
        run = simspad_cli.run("evaluate", evaluation_dataset, "--methods", "toy_gain,ni", "--param",
                              f"toy_gain.gain={gain}", "--out", out, env=env)
        assert run.returncode == 0, run.stderr
        runs[gain] = {r["recording"]: r for r in _results(out) if r["method"] == "toy_gain"}
    assert len(runs[1.0]) == 2  # both recordings, in the pool's worker processes
    for rec, row in runs[1.0].items():
        assert row["error"] == "" and row["label"] == "Toy gain (GT)"
        # the exact ground truth outscores the same at twice the flux on every recording
        assert float(row["psnr_db"]) > float(runs[2.0][rec]["psnr_db"]) + 3
    board = simspad_cli.run("leaderboard", tmp_path / "gain1", "--out", tmp_path / "board", env=env)
    assert board.returncode == 0, board.stderr
    assert "Ground truth times a constant gain" in (tmp_path / "board" / "leaderboard.html").read_text()
    refused = simspad_cli.run("evaluate", evaluation_dataset, "--methods", "toy_gain", "--param",
                              "toy_gain.gain=-1", "--out", tmp_path / "neg", env=env)
    assert refused.returncode == 2 and "gain must be > 0" in refused.stderr
    missing = simspad_cli.run("evaluate", evaluation_dataset, "--methods", "toy_gain", "--out", tmp_path / "no")
    assert missing.returncode == 2 and "unknown method 'toy_gain'" in missing.stderr


def test_the_method_interface_is_public_in_simspad_methods():
    import simspad.methods as api
    from simspad.methods.method import Method

    assert api.Method is Method and api.get_method("cf", f_cut_hz=1.0).alpha == pytest.approx(6.283185307)
    assert api.method_parameters("cf") == {"f_cut_hz": 0.1, "chunk_s": 0.001}
    assert set(api.__all__) >= {"Method", "Reconstruction", "Bandwidth", "register", "get_method",
                                "method_parameters", "available_methods"}
