"""``generate --estimate`` of a converged spec (``convergence = "cache"``): the irradiance cache's build is a
fixed cost per render, apart from its keyframes' cost, and a converged render's faster speeds share no keyframes.
Checked against real ``generate`` runs of a tiny spec (real renders, real worker processes)."""

from __future__ import annotations

import contextlib
import os
import resource

import pytest

from simspad.dataset.estimate import estimate_spec, format_estimate, measure_unit_costs
from simspad.dataset.executors import ExecutorConfig
from simspad.dataset.generate import generate
from simspad.dataset.spec_validation import spec_from_dict
from simspad.io.manifest import read_manifest

#: A spec whose converged cost is mostly the cache's build (64 × 48 px × 4 probe views × 1024 estimates, ≈ 5 s per
#: render on one core) and whose keyframes are cheap (4 spp): spreading the build over the keyframes instead of
#: paying it once per render would be many times off.
SPEC = {"name": "conv-estimate", "seed": 3, "lux": [100], "speed": [1, 2],
        "sequences": [{"scene": "siemens-star", "duration_s": 0.01, "resolution": [64, 48], "spp": 4,
                       "convergence": "cache", "cache_samples": 1024}],
        "sensors": {"events": {"preset": "prophesee_gen4"}}}
#: The tolerance of the path-traced estimate's test (tests/dataset/test_generate.py): a factor 1.5.
TOLERANCE = 1.5


@contextlib.contextmanager
def _one_core():
    """This process and the workers it starts on one core: one worker, one render thread, as the unit costs are."""
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(before)})
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def _generate_cpu_s(spec, out) -> float:
    """CPU seconds of the worker processes of a real ``generate`` of ``spec`` into ``out`` (one worker)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    with _one_core():
        generate(spec, out, ExecutorConfig("local", workers=1), progress=False, created_utc="2025-01-01T00:00:00Z")
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime)


@pytest.mark.slow
def test_the_estimate_of_a_converged_spec_matches_a_real_generate(tmp_path):
    """What a converged spec costs beyond the same spec path-traced, estimated and measured, agree within the
    path-traced estimate test's factor 1.5 (the workers' start, imports and scene loads, which no estimate
    counts, are the same in both runs and drop out of the difference); exact keyframe counts, none shared."""
    converged = spec_from_dict(SPEC)
    traced = spec_from_dict({**SPEC, "sequences": [{**SPEC["sequences"][0], "convergence": "off"}]})
    costs = measure_unit_costs(converged)
    cost = costs.converged["siemens-star"]
    assert cost.cache_build_s > 0 and cost.cache_build_units > 0 and cost.b_s > 0
    assert costs.render["siemens-star"].cache_build_s == 0  # the path-traced calibration (the noise probes)
    est, est_traced = estimate_spec(converged, costs), estimate_spec(traced, costs)
    real = _generate_cpu_s(converged, tmp_path / "cache")
    real_traced = _generate_cpu_s(traced, tmp_path / "off")

    renders = read_manifest(tmp_path / "cache")["renders"]
    assert est.n_keyframes == sum(r["n_keyframes"] for r in renders) and est.n_shared_keyframes == 0
    assert est_traced.n_shared_keyframes > 0  # (the path-traced twin's speed 2 does share)
    assert est.n_converged_renders == 2 and est_traced.n_converged_renders == 0
    extra, extra_real = est.cpu_s - est_traced.cpu_s, real - real_traced
    assert extra_real / TOLERANCE < extra < extra_real * TOLERANCE, (extra, extra_real, real, real_traced)
    # one build per render, sized by its probe rays (64 × 48: one per pixel), probe views and estimates, from the
    # calibration's (64 × 48, the sequence's 1024 estimates)
    assert cost.cache_build_units == pytest.approx(64 * 48 * 4 * 1024 / 1e6)
    build = cost.cache_build_s * (64 * 48 * 4 * 1024 / 1e6) / cost.cache_build_units
    assert est.cache_build_s == pytest.approx(2 * build)
    # and each render's noise probe: three converged keyframes (keyframe 0 with the next seed, from each half cache)
    assert est.render_cpu_s == pytest.approx(est.cache_build_s + est.converged_keyframe_s + sum(
        3 * cost.seconds_per_keyframe(64 * 48 / 1e6, 4) for _ in range(2)))


    text = format_estimate(est, costs, workers=1)
    assert "2 converged render(s) (irradiance cache): cache builds" in text and "converged: siemens-star" in text
    assert "converged" not in format_estimate(est_traced, costs, workers=1).split("unit costs")[0]
