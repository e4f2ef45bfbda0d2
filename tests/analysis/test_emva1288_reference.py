"""EMVA's own reference implementation recovers the frame camera's parameters from SimSPAD flat fields.

The frame sensor (``sensors/frames``, preset ``blackfly_s``) records a flat, uniformly lit scene whose irradiance
steps through a photon-transfer series (EMVA 1288 4.0, "variation of irradiation" at one exposure time): darks,
then 2 frames at each of 60 irradiance levels up to 2 % past the full well, and 16-frame stacks in the dark and at
half saturation for the spatial nonuniformities. The frames are read back from the recording, written as 16-bit
TIFFs with an EMVA 1288 descriptor file, and processed by EMVA's ``emva1288`` package (PyPI) in a virtual
environment of its own (its pins may clash with SimSPAD's), in a child process: tests/analysis/emva1288_process.py.

The environment is made once in ``~/.cache/simspad-emva`` (``$SIMSPAD_EMVA_VENV`` overrides) and reused; the test
is skipped, saying so, only when the package index cannot be reached.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile

from simspad.io.recording import RecordingWriter, open_recording
from simspad.radiance.timeline import Timeline
from simspad.sensors import frames
from simspad.sensors.presets import sensor_params

pytestmark = pytest.mark.slow

SHAPE = (128, 128)
EXPOSURE_S = 1e-3
FRAME_RATE_HZ = 100.0
N_LEVELS = 60
N_SPATIAL = 16
PROCESS_SCRIPT = Path(__file__).with_name("emva1288_process.py")
#: pip's words for an index it cannot reach (the only reason to skip).
OFFLINE_MARKERS = ("NewConnectionError", "Failed to establish a new connection", "Temporary failure in name",
                   "Network is unreachable", "Max retries exceeded", "No matching distribution found for emva1288",
                   "Could not find a version that satisfies the requirement emva1288", "ProxyError")


def _emva_python() -> Path:
    """The Python of a virtual environment holding ``emva1288`` (made on first use; skip when offline)."""
    venv = Path(os.environ.get("SIMSPAD_EMVA_VENV") or Path.home() / ".cache" / "simspad-emva")
    python, done, making = venv / "bin" / "python", venv / ".simspad-emva-installed", venv / ".simspad-emva-making"
    if done.exists() and python.exists():
        return python
    if venv.exists() and not making.exists():  # not made by this test: used if it holds emva1288, never deleted
        usable = python.exists() and subprocess.run([str(python), "-c", "import emva1288"],
                                                    capture_output=True).returncode == 0
        if usable:
            return python
        raise AssertionError(f"{venv} exists but is not an environment with emva1288; remove it or set "
                             f"SIMSPAD_EMVA_VENV to another folder")
    if venv.exists():  # half made by an interrupted run of this test: made again
        shutil.rmtree(venv)
    venv.mkdir(parents=True)
    making.write_text("being made by tests/analysis/test_emva1288_reference.py\n")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, capture_output=True, timeout=300)
    # emva1288 1.0.2 calls np.asfarray, which NumPy 2 removed, and does not pin NumPy itself
    r = subprocess.run([str(python), "-m", "pip", "install", "--disable-pip-version-check", "emva1288",
                        "numpy<2"],
                       capture_output=True, text=True, timeout=900)
    if r.returncode != 0:
        log = r.stdout + r.stderr
        if any(m in log for m in OFFLINE_MARKERS):
            pytest.skip(f"the package index is unreachable, so EMVA's emva1288 cannot be installed: "
                        f"{log.strip().splitlines()[-1]}")
        raise AssertionError(f"pip install emva1288 failed:\n{log[-3000:]}")
    done.write_text("emva1288 installed\n")
    making.unlink()
    return python


def _staircase(levels_ph_s_m2: list[float], n_frames: list[int]) -> tuple[Timeline, list[slice]]:
    """A flat scene holding each irradiance for its frames: keyframes at the plateau's first frame start and
    5 ms before the next plateau (after the last exposure of this one ends), so no exposure sees a transition."""
    times, values, slices, f = [], [], [], 0
    for level, n in zip(levels_ph_s_m2, n_frames):
        times += [f / FRAME_RATE_HZ, (f + n) / FRAME_RATE_HZ - 5e-3]
        values += [level, level]
        slices.append(slice(f, f + n))
        f += n
    times[-1] = f / FRAME_RATE_HZ
    keyframes = np.stack([np.full(SHAPE, v, np.float32) for v in values])
    return Timeline.from_arrays(np.asarray(times), keyframes), slices


def _simulate_series(tmp_path: Path, params) -> tuple[np.ndarray, list[slice], np.ndarray]:
    """Frames (DN) of the whole series, each plateau's frames, and the photons per pixel of each plateau."""
    area_m2 = params.pixel_pitch_m ** 2  # EMVA's photons fall on the pixel's area; the fill factor is in η
    full_p = params.full_well_e / (params.qe * params.fill_factor)
    # dense near saturation (0.4 % of the full well apart), ending 2 % past it: the reference code takes the
    # saturation point as the last local maximum of the temporal variance searching back from the brightest
    # level, so a long clipped tail (variance flat at the dark level, its noise making local maxima) would stop
    # its search there
    mu_p = np.concatenate([np.linspace(0.0, 0.9 * full_p, N_LEVELS // 2 + 1)[1:],
                           np.linspace(0.9 * full_p, 1.02 * full_p, N_LEVELS - N_LEVELS // 2 + 1)[1:]])
    half_p = 0.5 * full_p
    # plateaus: the dark stack, the bright levels, the stack at half saturation
    irradiance = [0.0, *(mu_p / (EXPOSURE_S * area_m2)), half_p / (EXPOSURE_S * area_m2)]
    n_frames = [N_SPATIAL, *([2] * N_LEVELS), N_SPATIAL]
    timeline, slices = _staircase(irradiance, n_frames)
    # photons per pixel as the sensor sees them (the keyframes are float32)
    photons = np.array([float(np.float32(e)) for e in irradiance]) * EXPOSURE_S * area_m2
    t1 = sum(n_frames) / FRAME_RATE_HZ
    with RecordingWriter(tmp_path / "ptc.h5", {"width": SHAPE[1], "height": SHAPE[0], "duration_s": t1,
                                               "lux": 1.0}) as w:
        frames.simulate_frames(w, timeline, 0.0, t1, params, np.random.default_rng(2024))
    with open_recording(tmp_path / "ptc.h5") as rec:
        dn = rec.frames.dn()
        np.testing.assert_allclose(rec.frames.t_end - rec.frames.t_start, EXPOSURE_S)
    assert dn.shape[0] == sum(n_frames)
    return dn, slices, photons


def _write_descriptor(root: Path, params, dn: np.ndarray, slices: list[slice], photons: np.ndarray) -> Path:
    """16-bit TIFFs and the EMVA 1288 descriptor file (exposure in ns, photons per pixel) listing them."""
    (root / "img").mkdir()
    names = []
    for k, frame in enumerate(dn):
        names.append(f"img/f{k:04d}.tif")
        tifffile.imwrite(root / names[-1], frame.astype(np.uint16))
    exposure_ns = f"{EXPOSURE_S * 1e9:.1f}"
    lines = ["v 3", f"n {params.bit_depth} {SHAPE[1]} {SHAPE[0]}"]
    dark, spatial_bright = slices[0], slices[-1]
    lines.append(f"d {exposure_ns}")  # temporal dark: a pair
    lines += [f"i {names[k]}" for k in range(dark.start, dark.start + 2)]
    for s, p in zip(slices[1:-1], photons[1:-1]):
        lines.append(f"b {exposure_ns} {p:.6f}")
        lines += [f"i {names[k]}" for k in range(s.start, s.stop)]
    lines.append(f"d {exposure_ns}")  # spatial: the dark stack and the stack at half saturation
    lines += [f"i {names[k]}" for k in range(dark.start, dark.stop)]
    lines.append(f"b {exposure_ns} {photons[-1]:.6f}")
    lines += [f"i {names[k]}" for k in range(spatial_bright.start, spatial_bright.stop)]
    descriptor = root / "descriptor.txt"
    descriptor.write_text("\n".join(lines) + "\n")
    return descriptor


def test_emva1288_package_recovers_the_frame_preset(tmp_path):
    params = sensor_params("frames", "blackfly_s", {"exposure_s": EXPOSURE_S, "frame_rate_hz": FRAME_RATE_HZ})
    python = _emva_python()
    dn, slices, photons = _simulate_series(tmp_path, params)
    descriptor = _write_descriptor(tmp_path, params, dn, slices, photons)
    r = subprocess.run([str(python), str(PROCESS_SCRIPT), str(descriptor)], capture_output=True, text=True,
                       timeout=600, cwd=tmp_path, env={"PATH": os.environ.get("PATH", ""), "HOME": str(Path.home())})
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    print("emva1288 results:", res)  # the measured values, for the record (pytest -s)
    assert res["n_points"] == N_LEVELS
    # tolerances: seeds 1, 7, 99 and 2024 agree with the preset within 0.6 % (K, η, σ_d, PRNU) and 3.3 % (DSNU,
    # 0.5 e⁻ under 2.8 e⁻ of read noise), the saturation capacity at 0.957–0.970 of the full well
    # K: from 2-frame variances of 16 k pixels at the ~40 levels of the linear range
    assert res["K"] == pytest.approx(params.gain_dn_per_e, rel=0.02)
    # η·fill (EMVA's η includes the fill factor): R / K, both fitted
    assert res["QE"] / 100 == pytest.approx(params.qe * params.fill_factor, rel=0.02)
    # σ_d: the read noise and the dark current's shot noise over the exposure (3 e⁻/s × 1 ms: 0.003 e⁻²)
    assert res["sigma_d"] == pytest.approx(np.hypot(params.read_noise_e, np.sqrt(params.dark_current_e_s
                                                                                  * EXPOSURE_S)), rel=0.03)
    # saturation: EMVA takes the level of maximum temporal variance, which a hard full-well clip puts 3–5 %
    # below the full well (pixels of high PRNU gain and shot noise clip first; tests/sensors/test_presets.py)
    assert 0.93 * params.full_well_e < res["u_e_sat"] < 0.99 * params.full_well_e
    # fixed pattern: the preset's DSNU (0.5 e⁻) and PRNU (1 %) from the 16-frame stacks
    assert res["DSNU1288"] == pytest.approx(params.dsnu_e, rel=0.10)
    assert res["PRNU1288"] / 100 == pytest.approx(params.prnu, rel=0.05)
