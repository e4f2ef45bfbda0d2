"""Every run is bounded or refused up front (docs/trust.md, "Runs: bounded, or refused up front").

Each case was a run that went on for minutes with no output: an event camera's noise rate or step tolerance that
explodes the kernel's work, a results.csv of 20 001 rows, a manifest listing one recording 80 000 times, a Dask
scheduler address that accepts and never answers. Each is now refused with the figure, in seconds, or bounded.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from simspad import defaults
from simspad.io.render_dir import write_render_dir
from simspad.sensors.events.model import (
    leak_event_rate_hz,
    mean_shot_noise_ratio,
    noise_rates_hz,
    noise_work_problem,
)
from simspad.sensors.events.model import sensor_current_1lux_e_s, sensor_photocurrent_e_s
from simspad.sensors.presets import sensor_params

#: Seconds a refusal may take (a child process importing SimSPAD on 2 busy cores, not the minutes of the run).
REFUSAL_S = 60


@pytest.fixture()
def small_render(tmp_path) -> Path:
    rng = np.random.default_rng(1)
    times = np.array([0.0, 0.005, 0.01])
    frames = [rng.uniform(0.1, 1.0, (12, 16, 3)).astype(np.float32) for _ in times]
    return write_render_dir(tmp_path / "render", times, frames).parent


def _one_error_line(proc) -> str:
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("simspad: error: "), proc.stderr[-2000:]
    return lines[0]


# ---- the event camera's noise work and internal steps ---------------------------------------------------------

@pytest.mark.parametrize("setting, field", [
    ("events.shot_noise_rate_hz_at_1lux=1e12", "sensors.events.shot_noise_rate_hz_at_1lux"),
    ("events.hot_pixel_rate_hz=1e14", "sensors.events.hot_pixel_rate_hz"),
])
def test_simulate_refuses_noise_rates_that_explode_the_work(simspad_cli, small_render, tmp_path, setting, field):
    out = tmp_path / "rec.h5"
    start = time.monotonic()
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "spad,events", "--set", setting,
                           "--out", out)
    assert time.monotonic() - start < REFUSAL_S
    line = _one_error_line(proc)
    assert field in line and "random draws, above the limit of 1e+10" in line and "SIMSPAD_IGNORE_LIMITS" in line
    assert "192 pixels × 0.01 s" in line  # the figure: pixels × seconds × rate
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["render"]


def test_simulate_refuses_a_substep_tolerance_below_the_floor(simspad_cli, small_render, tmp_path):
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "events", "--set",
                           "events.substep_tolerance=1e-12", "--out", tmp_path / "rec.h5")
    line = _one_error_line(proc)
    assert "sensors.events.substep_tolerance" in line and "[1e-06, 0.1]" in line and "1e-12" in line
    # a floor, like MIN_MAX_FLOW_PX: lifting the size bounds does not lift it
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "events", "--set",
                           "events.substep_tolerance=1e-12", "--out", tmp_path / "rec.h5",
                           env={"SIMSPAD_IGNORE_LIMITS": "1"})
    assert "substep_tolerance" in _one_error_line(proc)


def test_simulate_at_the_default_noise_runs(simspad_cli, small_render, tmp_path):
    proc = simspad_cli.run("simulate", small_render, "--lux", "10", "--sensors", "events", "--set",
                           "events.shot_noise_rate_hz_at_1lux=1000", "--out", tmp_path / "rec.h5")
    assert proc.returncode == 0, proc.stderr[-2000:]


SPEC = """
name = "hostile"
seed = 1
output = "out"
lux = [10]
[[sequences]]
scene = "office"
duration_s = 0.03
resolution = [80, 60]
spp = 4
[sensors.events]
preset = "prophesee_gen4"
{extra}
"""


@pytest.mark.parametrize("extra, expect", [
    ("shot_noise_rate_hz_at_1lux = 1e12", "4800 pixels × 0.03 s"),
    ("substep_tolerance = 1e-12", "must be in [1e-06, 0.1]"),
])
def test_spec_with_exploding_event_work_is_refused_before_estimating(simspad_cli, tmp_path, extra, expect):
    """`generate --estimate` sat at "probing simulation throughput": the spec is now refused when it is loaded."""
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.format(extra=extra))
    for args in (("info", spec), ("generate", spec, "--estimate")):
        start = time.monotonic()
        proc = simspad_cli.run(*args)
        assert time.monotonic() - start < REFUSAL_S
        assert proc.returncode == 2 and expect in proc.stderr, proc.stderr[-2000:]
        assert "probing" not in proc.stdout + proc.stderr
    assert not (tmp_path / "out").exists()


def test_noise_work_figure_is_pixels_times_seconds_times_rate(monkeypatch):
    monkeypatch.delenv("SIMSPAD_IGNORE_LIMITS", raising=False)
    params = sensor_params("events", None, {"shot_noise_rate_hz_at_1lux": 1e9, "hot_pixel_fraction": 0.5,
                                            "hot_pixel_rate_hz": 2e8, "leak_rate_hz": 0.0})
    # at 1 lx the bound's ratio is 1: 1e9 shot + 0.5 × 2e8 hot = 1.1e9 per pixel-second
    assert noise_rates_hz(params, 1.0) == (1e9, 1e8)
    message = noise_work_problem(params, 1000, 0.5, 1.0)
    assert "5.5e+11 random draws" in message
    assert noise_work_problem(params, 10, 0.5, 1.0) is None  # 5.5e9: under the bound
    # brighter than 1 lx the mean pixel's current grows with the light: r₁·lux^−γ
    assert noise_rates_hz(params, 100.0)[0] == pytest.approx(1e9 * 100 ** -0.5)
    # leak events: half the pixels leak at least the median rate, at most once per refractory period (+1 ns)
    leaky = sensor_params("events", None, {"leak_rate_hz": 1e12, "refractory_s": 0.0, "latency_s": 0.0,
                                           "jitter_s": 0.0})
    assert leak_event_rate_hz(leaky) == pytest.approx(0.5e9)
    assert "leak ≥ 5e+08 Hz" in noise_work_problem(leaky, 100, 1.0, 1.0)
    # the default readout (50 µs latency, 100 µs refractory) caps a pixel near 7 kHz: 1e12 Hz of leak is bounded
    assert noise_work_problem(sensor_params("events", None, {"leak_rate_hz": 1e12}), 100, 1.0, 1.0) is None
    monkeypatch.setenv("SIMSPAD_IGNORE_LIMITS", "1")
    assert noise_work_problem(params, 1000, 0.5, 1.0) is None


@pytest.mark.parametrize("lux", [1e-3, 1.0, 10.0, 1e4])
def test_scene_free_noise_rate_is_a_lower_bound_of_any_scene(lux):
    """The spec's check (no render yet) never refuses more than the render's exact figure would."""
    params = sensor_params("events")
    rng = np.random.default_rng(int(lux * 1000))
    for scale in (1e10, 1e14, 1e18):  # dark to very bright scenes, photons s⁻¹ m⁻² at this lux level
        flux = scale * rng.lognormal(0.0, 1.5, (24, 32))
        current = sensor_photocurrent_e_s(flux, params)
        i1 = sensor_current_1lux_e_s(float(flux.mean()), lux, params)
        exact = mean_shot_noise_ratio(current, i1, params)
        bound = noise_rates_hz(params, lux)[0] / params.shot_noise_rate_hz_at_1lux
        assert bound <= exact * (1 + 1e-12)


def test_bounds_are_named_in_defaults():
    assert defaults.MAX_EVENT_NOISE_DRAWS == 1e10 and defaults.MIN_SUBSTEP_TOLERANCE == 1e-6


# ---- leaderboard: a results.csv of 20 001 rows -------------------------------------------------------------------

@pytest.fixture(scope="module")
def scored_results(tmp_path_factory, evaluation_dataset, simspad_cli) -> Path:
    from tests.helpers.evaluation_data import write_submission

    root = tmp_path_factory.mktemp("scored")
    sub = write_submission(root / "sub.h5", evaluation_dataset)
    proc = simspad_cli.run("score", sub, "--dataset", evaluation_dataset, "--out", root / "res")
    assert proc.returncode == 0, proc.stderr[-2000:]
    return root / "res"


def _grown_results(src: Path, dst: Path, n_rows: int, vary: str) -> Path:
    shutil.copytree(src, dst)
    with open(src / "results.csv", newline="", encoding="utf-8") as f:
        base = list(csv.DictReader(f))
    with open(dst / "results.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, list(base[0]))
        w.writeheader()
        for i in range(n_rows):
            row = dict(base[i % len(base)])
            if vary == "method":
                row["method"] = f"m{i}"
            elif vary == "scene":
                row.update(scene=f"s{i}", recording=f"recordings/s{i}.h5", image="")
            elif vary == "lux":
                row.update(lux=str(1.0 + i), recording=f"recordings/l{i}.h5", image="")
            w.writerow(row)
    return dst


@pytest.mark.parametrize("vary, figure", [("method", "20001 methods, above the 50"),
                                          ("scene", "20001 scene × speed × lux columns, above the 1000"),
                                          ("lux", "light-level × speed cells (20001 × 1), above the 400")])
def test_leaderboard_of_20001_rows_is_refused_with_the_figure(simspad_cli, scored_results, tmp_path, vary, figure):
    res = _grown_results(scored_results, tmp_path / "res", 20001, vary)
    start = time.monotonic()
    proc = simspad_cli.run("leaderboard", res, "--out", tmp_path / "board")
    assert time.monotonic() - start < REFUSAL_S
    line = _one_error_line(proc)
    assert figure in line and "SIMSPAD_IGNORE_LIMITS=1" in line and "results.csv" in line
    assert not (tmp_path / "board" / "leaderboard.html").exists()


def test_results_table_rows_are_bounded_while_reading(scored_results, tmp_path, monkeypatch):
    from simspad.errors import InputError
    from simspad.io.results_dir import read_csv

    monkeypatch.delenv("SIMSPAD_IGNORE_LIMITS", raising=False)
    monkeypatch.setattr(defaults, "MAX_RESULTS_ROWS", 100)
    res = _grown_results(scored_results, tmp_path / "res", 101, "method")
    with pytest.raises(InputError, match="more than 100 rows"):
        read_csv(res / "results.csv")
    assert len(read_csv(scored_results / "results.csv")) == 2
    monkeypatch.setenv("SIMSPAD_IGNORE_LIMITS", "1")
    assert len(read_csv(res / "results.csv")) == 101


def test_leaderboard_of_many_recordings_is_linear(simspad_cli, scored_results, tmp_path):
    """20 000 recordings of one method: choosing the image strips scanned every recording per recording (4·10⁸
    steps, minutes); now one pass."""
    res = tmp_path / "res"
    shutil.copytree(scored_results, res)
    with open(scored_results / "results.csv", newline="", encoding="utf-8") as f:
        base = list(csv.DictReader(f))
    with open(res / "results.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, list(base[0]))
        w.writeheader()
        for i in range(20000):
            row = dict(base[i % len(base)])
            row.update(method="m", recording=f"recordings/r{i}.h5", scene=f"s{i % 20}")
            w.writerow(row)
    start = time.monotonic()
    proc = simspad_cli.run("leaderboard", res, "--out", tmp_path / "board")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert time.monotonic() - start < 40  # ~8 s; 60 s before


# ---- evaluate: one recording listed 80 000 times --------------------------------------------------------------

def test_evaluate_refuses_a_manifest_listing_one_recording_twice(simspad_cli, evaluation_dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(evaluation_dataset, ds)
    manifest = json.loads((ds / "manifest.json").read_text())
    first = manifest["recordings"][0]
    twin = dict(first, path="./" + first["path"])  # the same file spelt another way
    manifest["recordings"] = [first] + [dict(first) for _ in range(79_998)] + [twin]
    (ds / "manifest.json").write_text(json.dumps(manifest))
    start = time.monotonic()
    proc = simspad_cli.run("evaluate", ds, "--methods", "ni", "--out", tmp_path / "res")
    assert time.monotonic() - start < REFUSAL_S
    line = _one_error_line(proc)
    assert "manifest.json: recordings[1].path" in line and "recordings[0] already lists" in line
    manifest["recordings"] = [first, twin]
    (ds / "manifest.json").write_text(json.dumps(manifest))
    line = _one_error_line(simspad_cli.run("evaluate", ds, "--methods", "ni", "--out", tmp_path / "res"))
    assert "recordings[1].path" in line
    assert not (tmp_path / "res").exists()


def test_evaluate_refuses_two_recordings_with_one_key(simspad_cli, evaluation_dataset, tmp_path):
    """A folder of copies: their images and reconstructions would overwrite each other."""
    folder = tmp_path / "copies"
    folder.mkdir()
    src = evaluation_dataset / "recordings" / "ramp" / "ramp_10lx.h5"
    shutil.copy(src, folder / "a.h5")
    shutil.copy(src, folder / "b.h5")
    line = _one_error_line(simspad_cli.run("evaluate", folder, "--methods", "ni", "--out", tmp_path / "res"))
    assert "b.h5" in line and "ramp_10lx" in line and "a.h5" in line


def test_evaluate_does_not_follow_a_recording_linked_out_of_its_folder(simspad_cli, evaluation_dataset, tmp_path):
    folder = tmp_path / "folder"
    folder.mkdir()
    (folder / "linked.h5").symlink_to(evaluation_dataset / "recordings" / "ramp" / "ramp_10lx.h5")
    line = _one_error_line(simspad_cli.run("evaluate", folder, "--methods", "ni", "--out", tmp_path / "res"))
    assert "linked.h5" in line and "outside" in line


# ---- Dask: a scheduler address that accepts and never answers -------------------------------------------------

@pytest.fixture()
def silent_listener():
    """A plain TCP socket on 127.0.0.1 that accepts connections and never sends a byte."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(16)
    accepted, stop = [], threading.Event()

    def accept():
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                accepted.append(server.accept()[0])
            except OSError:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}", accepted
    stop.set()
    thread.join()
    for conn in accepted:
        conn.close()
    server.close()


def test_generate_against_a_silent_scheduler_times_out_with_one_line(simspad_cli, tmp_path, silent_listener):
    address, accepted = silent_listener
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC.format(extra=""))
    start = time.monotonic()
    proc = simspad_cli.run("generate", spec, "--out", tmp_path / "out", "--executor", "dask", "--scheduler", address,
                           "--yes", env={"SIMSPAD_DASK_CONNECT_TIMEOUT_S": "2"})
    elapsed = time.monotonic() - start
    line = _one_error_line(proc)
    assert f"--scheduler: the Dask scheduler at {address} did not answer within 2 s" in line
    assert "SIMSPAD_DASK_CONNECT_TIMEOUT_S" in line
    assert accepted, "the probe never reached the listener"
    assert elapsed < REFUSAL_S, elapsed


def _free_port_below_the_ephemeral_range() -> int:
    """A free port outside the kernel's ephemeral range: a connection to a free port inside it can, rarely, be
    given that very port as its source and connect to itself (TCP self-connect), which is not a refusal."""
    try:
        low = int(open("/proc/sys/net/ipv4/ip_local_port_range").read().split()[0])
    except (OSError, ValueError, IndexError):
        low = 32768
    for port in range(low - 1, 1024, -1):
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    pytest.skip("no free port below the ephemeral range")


def test_scheduler_probe_errors(monkeypatch):
    from simspad.dataset.executors import check_scheduler_answers, dask_connect_timeout_s
    from simspad.errors import SimSpadError

    port = _free_port_below_the_ephemeral_range()  # nothing listens there: refused, not "did not answer"
    with pytest.raises(SimSpadError, match="nothing accepts connections"):
        check_scheduler_answers(f"tcp://127.0.0.1:{port}", 1.0)
    monkeypatch.delenv("SIMSPAD_DASK_CONNECT_TIMEOUT_S", raising=False)
    assert dask_connect_timeout_s() == defaults.DASK_CONNECT_TIMEOUT_S
    monkeypatch.setenv("SIMSPAD_DASK_CONNECT_TIMEOUT_S", "0.5")
    assert dask_connect_timeout_s() == 0.5
    for bad in ("soon", "-1", "nan", "inf"):
        monkeypatch.setenv("SIMSPAD_DASK_CONNECT_TIMEOUT_S", bad)
        with pytest.raises(SimSpadError, match="SIMSPAD_DASK_CONNECT_TIMEOUT_S"):
            dask_connect_timeout_s()
