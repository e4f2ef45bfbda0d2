"""The path tracer's stratified sampler is unbiased where the light comes from deep bounces.

Mitsuba 3.9's low-discrepancy sampler (``ldsampler``) renders the office's dim, indirectly lit half 2–3 % too
bright at every sample count (docs/rendering.md, "Samples per pixel"); SimSPAD's :func:`sampler_for` must give
the independent sampler's mean there. The dim half is chosen on a separate render, so the selection does not
pick the reference's own low noise.
"""

import numpy as np
import pytest

from simspad.render.mitsuba_env import select_variant
from simspad.render.mitsuba_scene import sampler_for
from simspad.render.renderer import load_scene

W, H, SPP = 32, 24, 1024


def _render(ms, sampler: str, spp: int, seed: int) -> np.ndarray:
    mi = ms.mi
    sensor = mi.load_dict({
        "type": "perspective", "fov": ms.x_fov_deg, "fov_axis": "x", "near_clip": ms.near_clip_m,
        "far_clip": ms.far_clip_m, "to_world": mi.ScalarTransform4f(ms.rest_camera_to_world),
        "film": {"type": "hdrfilm", "width": W, "height": H, "pixel_format": "rgb", "rfilter": {"type": "box"}},
        "sampler": {"type": sampler, "sample_count": spp}})
    return np.array(mi.render(ms.scene, sensor=sensor, seed=seed, spp=spp), dtype=np.float64)[..., :3].mean(-1)


@pytest.fixture(scope="module")
def office():
    """(the office scene, its dim half, the independent reference's sum of two seeds)."""
    select_variant()
    ms = load_scene("office", None, W, H, SPP).ms
    chooser = _render(ms, "independent", 256, 99)
    return ms, chooser < np.median(chooser), _render(ms, "independent", SPP, 1) + _render(ms, "independent", SPP, 2)


@pytest.mark.slow
def test_the_stratified_sampler_agrees_with_independent_samples_in_indirect_light(office):
    office, dim, reference = office
    ours = _render(office, sampler_for(SPP), SPP, 3) + _render(office, sampler_for(SPP), SPP, 4)
    # Measured: multijitter +0.3 / +1.1 % on two seeds, ldsampler +2.9 / +3.0 %, independent -0.6 / +0.7 %; the
    # reference pair's own noise on this sum is about 0.4 %.
    ratio = ours[dim].sum() / reference[dim].sum()
    assert abs(ratio - 1.0) < 0.015, (sampler_for(SPP), ratio)
    assert sampler_for(SPP) != "ldsampler"


@pytest.mark.slow
def test_the_low_discrepancy_sampler_is_the_biased_one(office):
    # The same measurement on Mitsuba's low-discrepancy sampler fails the bound: the test above can fail.
    office, dim, reference = office
    ld = _render(office, "ldsampler", SPP, 3) + _render(office, "ldsampler", SPP, 4)
    assert ld[dim].sum() / reference[dim].sum() - 1.0 > 0.015
