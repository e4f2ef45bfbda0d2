"""Mitsuba backends: which variant is chosen for what is available (CUDA, LLVM, neither, forced), the scalar
fallback rendering every built-in scene with LLVM's statistics, the sample count honoured as asked, and Mitsuba's
log kept plain and out of SimSPAD's messages.

There is no CUDA device on the machines these tests were written on: the CUDA path is covered by the selection
tests (:func:`choose_variant` is a pure function of :class:`Backends`), not by a render on a GPU.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from simspad.errors import SimSpadError
from simspad.radiance.timeline import Timeline
from simspad.render.mitsuba_env import (
    CUDA_VARIANT,
    LLVM_VARIANT,
    SCALAR_VARIANT,
    VARIANT_ENV,
    Backends,
    choose_variant,
    plain_log_line,
    probe_cuda,
)
from simspad.render.mitsuba_scene import honoured_spp, sampler_for
from simspad.render.renderer import RenderSettings, render_sequence, select_variant
from simspad.scenes.library import builtin_scene_names

GPU = Backends(cuda_device="NVIDIA H200", cuda_problem=None, llvm=True, llvm_problem=None)
CPU = Backends(cuda_device=None, cuda_problem="Dr.Jit found no CUDA driver or device", llvm=True, llvm_problem=None)
BARE = Backends(cuda_device=None, cuda_problem="Dr.Jit found no CUDA driver or device", llvm=False,
                llvm_problem="no libLLVM found (set DRJIT_LIBLLVM_PATH)")
GPU_NO_LLVM = Backends(cuda_device="NVIDIA H200", cuda_problem=None, llvm=False, llvm_problem="no libLLVM found")
LUMA = np.array([0.2126, 0.7152, 0.0722])


@pytest.mark.parametrize("backends, variant", [(GPU, CUDA_VARIANT), (GPU_NO_LLVM, CUDA_VARIANT),
                                               (CPU, LLVM_VARIANT), (BARE, SCALAR_VARIANT)])
def test_the_fastest_available_backend_is_chosen(backends, variant):
    chosen, notice = choose_variant(None, backends)
    assert chosen == variant
    if variant == SCALAR_VARIANT:  # the fallback says so, and why
        assert notice == f"rendering with {SCALAR_VARIANT} (slower): {BARE.llvm_problem}"
    else:
        assert notice is None


@pytest.mark.parametrize("forced", [CUDA_VARIANT, LLVM_VARIANT, SCALAR_VARIANT])
def test_a_forced_variant_wins_over_what_is_available(forced):
    assert choose_variant(forced, GPU) == (forced, None)


@pytest.mark.parametrize("forced, backends, words", [
    (CUDA_VARIANT, CPU, "no CUDA device here (Dr.Jit found no CUDA driver or device)"),
    (CUDA_VARIANT, BARE, "no CUDA device here"),
    (LLVM_VARIANT, BARE, "no libLLVM found"),
    (LLVM_VARIANT, GPU_NO_LLVM, "no libLLVM found"),
    ("cuda_ad_spectral", GPU, "unknown Mitsuba variant 'cuda_ad_spectral'"),
])
def test_a_forced_backend_that_does_not_work_here_is_refused(forced, backends, words):
    with pytest.raises(SimSpadError, match=re.escape(words)) as err:
        choose_variant(forced, backends)
    assert err.value.field == VARIANT_ENV


def test_forcing_cuda_without_a_gpu_is_one_line_and_exit_2(simspad_cli, tmp_path):
    if probe_cuda()[0] is not None:
        pytest.skip("a CUDA device is present: the forced variant works here")
    proc = simspad_cli.run("render", "siemens-star", "--duration", "0.001", "--resolution", "16x12", "--spp", "1",
                           "--out", tmp_path / "r", env={VARIANT_ENV: CUDA_VARIANT})
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines() == [
        f"simspad: error: {VARIANT_ENV}: {CUDA_VARIANT} is forced but there is no CUDA device here "
        "(Dr.Jit found no CUDA driver or device)"]
    assert not (tmp_path / "r").exists()


def test_mitsuba_log_lines_are_plain():
    coloured = "\x1b[31m2026-11-28 13:23:36 WARN  [LowDiscrepancySampler] Sample count should be square and " \
               "power of two, rounding to 4\n\x1b[0m"
    assert plain_log_line("warning", coloured) == ("simspad: mitsuba: warning: [LowDiscrepancySampler] Sample "
                                                   "count should be square and power of two, rounding to 4")


def test_a_real_mitsuba_warning_comes_out_plain_and_once(child_env):
    # A low-discrepancy sampler asked for 1 sample warns (and rounds to 4): loaded twice, the warning shows once.
    code = ("from simspad.render.mitsuba_env import select_variant; select_variant(); import mitsuba as mi\n"
            "for _ in range(2): mi.load_dict({'type': 'ldsampler', 'sample_count': 1})\n")
    proc = subprocess.run([sys.executable, "-c", code], env=child_env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "mitsuba" in line]
    assert lines == ["simspad: mitsuba: warning: [LowDiscrepancySampler] Sample count should be square and power "
                     "of two, rounding to 4"]
    assert "\x1b" not in proc.stderr


def test_every_sample_count_is_rendered_as_asked():
    select_variant()
    import mitsuba as mi  # deferred: after the variant is set

    for spp in range(1, 70):
        sensor = mi.load_dict({"type": "perspective", "film": {"type": "hdrfilm", "width": 4, "height": 4},
                               "sampler": {"type": sampler_for(spp), "sample_count": spp}})
        assert honoured_spp(sensor) == spp, (spp, sampler_for(spp))
    # the default and the paper's spp are stratified (multi-jittered), not Mitsuba's biased low-discrepancy sampler
    assert [sampler_for(n) for n in (1, 2, 4, 8, 16, 64, 256)] == [
        "independent", "independent", "multijitter", "independent", "multijitter", "multijitter", "multijitter"]


def test_one_spp_renders_one_sample_without_mitsuba_noise_on_stderr(simspad_cli, tmp_path):
    proc = simspad_cli.run("render", "siemens-star", "--duration", "0.001", "--resolution", "16x12", "--spp", "1",
                           "--out", tmp_path / "r")
    assert proc.returncode == 0, proc.stderr
    renderer = json.loads((tmp_path / "r" / "timeline.json").read_text())["renderer"]
    assert (renderer["spp"], renderer["sampler"]) == (1, "independent")
    assert "rounding" not in proc.stderr and "\x1b[" not in proc.stderr


# ------------------------------------------------------------------------------------------- scalar fallback
SIZE, SPP = (32, 24), 64
BLOCK_PX = 8


def _block_luminance(render_dir) -> np.ndarray:
    y = Timeline.open(render_dir).rgb_keyframe(0) @ LUMA
    h, w = y.shape
    return y.reshape(h // BLOCK_PX, BLOCK_PX, w // BLOCK_PX, BLOCK_PX).mean(axis=(1, 3))


def _cli_args(scene, out):
    return ("render", scene, "--duration", "0.001", "--resolution", f"{SIZE[0]}x{SIZE[1]}", "--spp", str(SPP),
            "--max-flow", "1e6", "--min-rate", "1000", "--out", out)


@pytest.mark.slow
@pytest.mark.parametrize("scene", sorted(builtin_scene_names()))
def test_scalar_fallback_renders_every_builtin_scene_with_llvms_statistics(simspad_cli, tmp_path, scene):
    """Without libLLVM (``DRJIT_LIBLLVM_PATH=/nonexistent``) every built-in scene renders with ``scalar_rgb``, says so
    once, and keyframe 0 agrees with LLVM's (32×24 px, 64 spp): image mean luminance within 3 %, and its 8×8 px
    blocks' mean absolute log ratio to LLVM's within the larger of 5 % and 1.5× that of two LLVM seeds. The two
    variants draw different random numbers, so only statistics can agree (measured with multi-jittered samples:
    0.9–1.4× the seeds' spread on every scene, e.g. office 6.7 % against 7.5 %, plant 3.8 % against 3.6 %)."""
    if select_variant() != LLVM_VARIANT:
        pytest.skip("no LLVM backend here to compare with")
    proc = simspad_cli.run(*_cli_args(scene, tmp_path / "scalar"), env={"DRJIT_LIBLLVM_PATH": "/nonexistent"})
    assert proc.returncode == 0, proc.stderr
    notices = [line for line in proc.stderr.splitlines() if line.startswith("simspad: notice:")]
    assert notices == [f"simspad: notice: rendering with {SCALAR_VARIANT} (slower): the LLVM backend failed "
                       "(Dr.Jit cannot use /nonexistent)"]
    meta = json.loads((tmp_path / "scalar" / "timeline.json").read_text())
    assert meta["renderer"]["variant"] == SCALAR_VARIANT and len(meta["keyframes"]) == 2
    llvm = []
    for seed in (0, 1):
        render_sequence(scene, None, RenderSettings(duration_s=1e-3, resolution=SIZE, spp=SPP, max_flow_px=1e6,
                                                    min_rate_hz=1e3, seed=seed),
                        out_dir=tmp_path / f"llvm{seed}", progress=False)
        llvm.append(_block_luminance(tmp_path / f"llvm{seed}"))
    scalar = _block_luminance(tmp_path / "scalar")
    assert np.all(np.isfinite(scalar)) and scalar.min() >= 0
    assert abs(scalar.mean() / llvm[0].mean() - 1) < 0.03, (scalar.mean(), llvm[0].mean())
    # Over the 12 blocks, not the worst one: the largest of 12 noisy ratios is itself too noisy a statistic.
    seed_spread = float(np.abs(np.log(llvm[1] / llvm[0])).mean())
    spread = float(np.abs(np.log(scalar / llvm[0])).mean())
    assert spread <= max(0.05, 1.5 * seed_spread), (spread, seed_spread)


# ------------------------------------------------------------------------------------- the estimate's workers
def _estimate(render_gpu=None):
    from simspad.dataset.estimate import Estimate  # deferred: only these tests need the dataset layer

    return Estimate(n_renders=2, n_keyframes=36000, n_recordings=10, render_cpu_s=36000.0, sim_cpu_s=3600.0,
                    longest_sim_s=100.0, largest_render_cpu_s=18000.0, keyframe_s=[(1.0, 18000), (1.0, 18000)],
                    scene_load_s=[(0.5, 18000), (0.5, 18000)], disk_bytes=1, recordings_bytes=1, renders_bytes=0,
                    peak_render_rss_bytes=None, peak_sim_rss_bytes=None, cores=2, plan_s=1.0, n_noise_probes=2,
                    render_gpu=render_gpu)


def test_the_estimate_puts_renders_on_the_gpu_and_simulations_on_the_cores():
    from simspad.dataset.estimate import UnitCosts, format_estimate  # deferred: as above

    cpu, gpu = _estimate(), _estimate("NVIDIA H200")
    sims_2, sims_64 = max(3600 / 2, 100.0), max(3600 / 64, 100.0)
    # on the CPU the renders spread over the workers; on one GPU they take its time whatever the workers
    assert cpu.wall_s(64) < cpu.wall_s(2) / 20
    assert gpu.wall_s(2) - sims_2 == pytest.approx(gpu.wall_s(64) - sims_64)
    # every keyframe on the GPU, plus a scene load per chunk of (at most 64) keyframes
    assert gpu.wall_s(64) - sims_64 == pytest.approx(36000.0 + 2 * 0.5 * math.ceil(18000 / 64), rel=1e-9)
    assert gpu.wall_s(64, gpus=64) < gpu.wall_s(64) / 20  # a GPU per worker: they spread again
    costs = UnitCosts(render_gpu="NVIDIA H200", render_variant=CUDA_VARIANT)
    text = format_estimate(gpu, costs, workers=2, cluster_workers=(64,))
    assert "10.00 GPU-h on NVIDIA H200 (cuda_ad_rgb, measured on it)" in text
    assert "total        10.00 GPU-h + 1.00 CPU-h" in text
    assert "here (2 worker(s), renders on one NVIDIA H200)" in text
    assert "on 64 workers with one NVIDIA H200 each" in text and "render s/keyframe (the GPU)" in text
    assert "and 2 noise probes" in text
    assert "GPU" not in format_estimate(cpu, UnitCosts(render_variant=LLVM_VARIANT), workers=2)
