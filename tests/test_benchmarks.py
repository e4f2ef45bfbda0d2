"""Benchmarks that drive the package's own task types still run against them.

A benchmark that builds its own stand-in of a package type drifts silently: bench_render_chunks.py once stopped at
"plan failed: AttributeError" after the render task gained a field, and nothing ran it. The heavy measurements stay
in benchmarks/; here each such script runs at a size that takes seconds.
"""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.mark.slow
def test_bench_render_chunks_renders_one_sequence_on_one_and_two_workers_with_the_same_bytes(child_env):
    res = subprocess.run([sys.executable, str(BENCHMARKS / "bench_render_chunks.py"), "--resolution", "24", "18",
                          "--spp", "1", "--duration", "0.004", "--workers", "1", "2"],
                         capture_output=True, text=True, timeout=300, env=child_env)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    lines = re.findall(r"(\d+) worker\(s\):.*for (\d+) keyframes.*bytes (\w+)", res.stdout)
    assert [(w, b) for w, _, b in lines] == [("1", "identical"), ("2", "identical")], res.stdout
    assert int(lines[0][1]) >= 2


@pytest.mark.slow
def test_bench_evaluate_times_both_revisions_and_each_methods_first_reconstruction(child_env, evaluation_dataset):
    # The dataset is named relative to the working directory, as a user types it: the warm-up children run
    # elsewhere, and once printed an empty list of first reconstructions ("no such recording file" went unread).
    if subprocess.run(["git", "-C", str(BENCHMARKS.parent), "rev-parse", "HEAD"], capture_output=True).returncode:
        pytest.skip("not a git checkout: the benchmark's baseline comes from git")
    res = subprocess.run([sys.executable, str(BENCHMARKS / "bench_evaluate.py"), evaluation_dataset.name,
                          "--recordings", "0", "--baseline", "HEAD", "--rounds", "1"],
                         capture_output=True, text=True, timeout=600, env=child_env, cwd=evaluation_dataset.parent)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert re.search(r"speed-up +wall +[\d.]+x +CPU +[\d.]+x", res.stdout), res.stdout
    assert "columns identical" in res.stdout, res.stdout
    firsts = re.findall(r"fresh process, .*: [\d.]+ s in all; first reconstruction: (.*)", res.stdout)
    assert len(firsts) == 2, res.stdout
    for listed in firsts:
        methods = dict(re.findall(r"(\w+) ([\d.]+)s", listed))
        assert {"ni", "qbp"} <= methods.keys(), res.stdout  # the SPAD-only methods (these recordings have no events)


@pytest.mark.slow
def test_bench_akf_times_the_kernel_against_the_vectorised_reference_and_they_agree(child_env):
    res = subprocess.run([sys.executable, str(BENCHMARKS / "bench_akf.py"), "20000"], capture_output=True, text=True,
                         timeout=300, env=child_env)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]  # it asserts agreement before timing
    assert re.search(r"NumPy vectorised : +20,000 events .*states agree to 1e-12", res.stdout), res.stdout
    assert re.search(r"speed-up +: +[\d.]+x wall", res.stdout), res.stdout


@pytest.mark.slow
def test_bench_nedi_times_the_solver_against_the_vectorised_reference_and_they_agree(child_env):
    res = subprocess.run([sys.executable, str(BENCHMARKS / "bench_nedi.py"), "24"], capture_output=True, text=True,
                         timeout=300, env=child_env)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert re.search(r"SciPy vectorised : +576 px .*agree to 1e-9", res.stdout), res.stdout


@pytest.mark.slow
def test_bench_convergence_measures_brute_force_and_the_cache_against_a_reference(child_env, tmp_path):
    out, table = tmp_path / "wp.png", tmp_path / "wp.json"
    res = subprocess.run([sys.executable, str(BENCHMARKS / "bench_convergence.py"), "--scenes", "siemens-star",
                          "--resolution", "16x12", "--duration", "0.002", "--ref-spp", "64", "--spp", "16",
                          "--cache-spp", "4", "--cache-samples", "16", "--out", str(out), "--json", str(table),
                          "--trajectory", str(BENCHMARKS.parent / "trajectories" / "siemens-star.toml"), "--speed", "2",
                          "--few-ref-spp", "32", "--few-ref-keyframes", "2", "--mtf"],
                         capture_output=True, text=True, timeout=600, env=child_env)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    (result,) = json.loads(table.read_text())
    assert result["scene"] == "siemens-star-x2"
    assert set(result["methods"]) == {"brute force 16 spp", "cache 4 spp, 16 q, linear"}
    assert result["few_ref"]["spp"] == 32 and result["few_ref"]["keyframes"][0] == 0
    assert len(result["few_ref"]["keyframes"]) == 2 and result["ref_mtf"]["mean"]["vs_reference"]
    for row in result["methods"].values():
        assert row["cpu_s"] > 0 and 0 < row["median_error"] < 1 and len(row["event_ratio_100"]) == 2
        assert 0 < row["median_error_few_ref"] < 1 and set(row["mtf"]) == {"vs_print", "vs_reference"}
    assert out.stat().st_size > 10_000


def test_bench_convergence_star_mtf_is_one_against_itself_and_falls_with_blur(monkeypatch):
    # The --mtf columns of bench_convergence on a drawn star (24 cycles, 128x96): a render identical to the
    # reference scores 1 against it, a blurred one (Gaussian, sigma 1 px) far less, against the print too.
    from scipy.ndimage import gaussian_filter

    from simspad.evaluate import metrics

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from bench_convergence import star_mtf  # deferred: a script of benchmarks/, importable only from there

    y, x = np.mgrid[0:96, 0:128].astype(float)
    r, theta = np.hypot(y - 47.5, x - 63.5), np.arctan2(y - 47.5, x - 63.5)
    sharp = np.where(r < 45, 0.05 + 0.75 * (np.sin(24 * theta) > 0), 0.4)
    blurred = gaussian_filter(sharp, 1.0)
    geometry = metrics.siemens_star_geometry(sharp)
    assert geometry[2] == 24 and abs(geometry[0] - 47.5) < 1 and abs(geometry[1] - 63.5) < 1
    same, blur = star_mtf(sharp[None], sharp[None], geometry), star_mtf(blurred[None], sharp[None], geometry)
    assert same["vs_reference"]["mtf_at_0p25_cyc_px"] == pytest.approx(1.0)
    assert same["vs_reference"]["mtf_at_0p40_cyc_px"] == pytest.approx(1.0)
    assert blur["vs_reference"]["mtf_at_0p25_cyc_px"] < 0.5 and blur["vs_reference"]["mtf_at_0p40_cyc_px"] < 0.1
    assert 0.1 < blur["vs_reference"]["mtf50_cyc_px"] < 0.25
    for f in ("mtf_at_0p25_cyc_px", "mtf_at_0p40_cyc_px"):
        assert blur["vs_print"][f] < 0.5 * same["vs_print"][f]


@pytest.mark.slow
def test_bench_cache_lookup_times_the_kernel_against_the_numpy_lookup_and_they_agree(child_env):
    res = subprocess.run([sys.executable, str(BENCHMARKS / "bench_cache_lookup.py"), "--resolution", "24x18",
                          "--spp", "4", "--cache-samples", "4", "--rounds", "1", "--scenes", "office"],
                         capture_output=True, text=True, timeout=300, env=child_env)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert re.search(r"^office +\d+\.\d+ +\d+\.\d+ +\d+\.\d+x +\d+\.\d+ +\d\.\de-\d\d$", res.stdout, re.M), res.stdout
