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
                          "--cache-spp", "4", "--cache-samples", "16", "--out", str(out), "--json", str(table)],
                         capture_output=True, text=True, timeout=600, env=child_env)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    (result,) = json.loads(table.read_text())
    assert set(result["methods"]) == {"brute force 16 spp", "cache 4 spp, 16 q, linear"}
    for row in result["methods"].values():
        assert row["cpu_s"] > 0 and 0 < row["median_error"] < 1 and len(row["event_ratio_100"]) == 2
    assert out.stat().st_size > 10_000
