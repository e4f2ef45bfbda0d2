"""The default dataset is in the regime SimSPAD exists for: at its fastest speed a 10 ms conventional frame is
blurred by ≥ 10 px on every sequence, measured on real renders the way `generate` measures its recordings."""

from __future__ import annotations

import pytest

from simspad.dataset.spec import default_spec_path
from simspad.dataset.spec_validation import load_spec
from simspad.dataset.speed import sequence_trajectories
from simspad.render.image_motion import measure_image_motion
from simspad.render.renderer import render_sequence
from simspad.render.settings import RenderSettings

SPEC = load_spec(default_spec_path())
FRAME_EXPOSURE_S = 0.01
SPAN_S = 0.012  # one exposure and a little: enough to measure, and 2.5× cheaper than the 30 ms sequences


@pytest.mark.parametrize("seq", SPEC.sequences, ids=[s.name for s in SPEC.sequences])
def test_fastest_speed_blurs_a_10ms_frame_by_10px(seq, tmp_path):
    k = max(SPEC.speed)
    # 1 spp and a coarse schedule: image motion comes from depth and poses, not from the pixel values. A coarse
    # schedule measures chords of curved paths, so it can only under-estimate the blur.
    settings = RenderSettings(duration_s=min(seq.duration_s, SPAN_S), start_s=seq.start_s,
                              resolution=seq.resolution, spp=1, max_flow_px=8.0, min_rate_hz=100.0, seed=0)
    out = tmp_path / "render"
    render_sequence(seq.scene, sequence_trajectories(seq.scene, seq.trajectory, k), settings, out_dir=out,
                    progress=False)
    motion = measure_image_motion(out, exposure_s=FRAME_EXPOSURE_S)
    assert motion.frame_blur_px_p95 >= 10.0, (seq.name, motion)
