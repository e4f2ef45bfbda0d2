"""Small real recordings, datasets and submissions for the evaluation tests (issue 8).

Recordings are written with the project's RecordingWriter; SPAD bits are drawn from the gated binary model of
docs/sensors.md with the SwissSPAD2 preset (simspad.sensors.spad), so the methods see physically consistent data.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from simspad.io.hashing import file_sha256
from simspad.io.recording import RecordingWriter
from simspad.physics.spad_statistics import detection_probability
from simspad.sensors.presets import sensor_params
from simspad.sensors.spad import spad_attrs

H, W = 24, 32
GT_RATE_HZ = 2000.0
DURATION_S = 0.01


def pattern(h: int = H, w: int = W, level: float = 1.0) -> np.ndarray:
    """A static test image (ph s⁻¹ m⁻²): a horizontal ramp with a bright disc and a dark bar."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    img = 0.15 + 0.7 * xx / (w - 1)
    img[(yy - h / 2) ** 2 + (xx - w / 3) ** 2 < (h / 5) ** 2] = 1.0
    img[:, int(0.75 * w):int(0.8 * w)] = 0.05
    return (img * level).astype(np.float32)


def write_recording(path: Path, *, sequence: str = "ramp", scene: str = "ramp", lux: float = 10.0,
                    level: float = 3e15, with_spad: bool = True, seed: int = 0, gt=None) -> Path:
    """A static-scene recording: ground truth at 2 kHz over 10 ms and (optionally) SPAD bits of that flux."""
    n_gt = int(round(DURATION_S * GT_RATE_HZ)) + 1
    gt_t = np.arange(n_gt) / GT_RATE_HZ
    flux = pattern(level=level) if gt is None else np.asarray(gt, np.float32)
    h, w = flux.shape
    with RecordingWriter(path, {"width": w, "height": h, "duration_s": DURATION_S, "lux": lux, "scene": scene,
                                "sequence": sequence, "seed": seed, "spec": {}}) as wr:
        wr.write_dataset("gt/t", gt_t)
        wr.write_dataset("gt/flux", np.repeat(flux[None], n_gt, axis=0))
        if with_spad:
            p = sensor_params("spad", overrides={"gate_s": 2e-6})
            bin_s, gate_s = p.bin_s, 2e-6
            n_bins = int(DURATION_S / bin_s) + 1
            q = p.pixel_pitch_m ** 2 * p.fill_factor * p.qe
            dcr = np.full((h, w), p.dcr_median_cps, np.float32)
            prob = detection_probability(flux, q, gate_s, dcr)
            rng = np.random.default_rng(seed)
            bits = (rng.random((n_bins, h, w)) < prob).astype(np.uint8)
            wr.write_dataset("spad/bits", np.packbits(bits, axis=2, bitorder="little"))
            wr.write_dataset("spad/t_start", np.arange(n_bins) * bin_s)
            wr.write_dataset("spad/dcr_cps", dcr)
            wr.set_attrs("spad", **spad_attrs(p, gate_s, n_bins, 0.0))
    return path


def write_dataset(root: Path, luxes=(10.0, 100.0), sequences=("ramp",), incomplete: bool = True) -> Path:
    """A dataset directory with a manifest; an extra 'failed' entry checks that non-complete ones are skipped."""
    recs = []
    for seq in sequences:
        for lux in luxes:
            rel = f"recordings/{seq}/{seq}_{lux:g}lx.h5"
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            write_recording(root / rel, sequence=seq, scene=seq, lux=lux, level=3e15 * (lux / 10.0) ** 0.6,
                            seed=int(lux))
            recs.append({"sequence": seq, "scene": seq, "lux": lux, "path": rel, "size": (root / rel).stat().st_size,
                         "sha256": file_sha256(root / rel), "status": "complete"})
    if incomplete:
        recs.append({"sequence": "ghost", "scene": "ghost", "lux": 1.0, "path": "recordings/ghost/ghost_1lx.h5",
                     "size": 0, "sha256": "", "status": "failed"})
    (root / "manifest.json").write_text(json.dumps({"format": "simspad-dataset", "version": 1, "name": "eval",
                                                    "spec": {"evaluation": {"rate_hz": 1000.0}},
                                                    "spec_hash": "x", "seed": 0, "recordings": recs}))
    return root


def gt_of(path: Path, rate_hz: float = 1000.0):
    """(t, flux) of the ground truth at the evaluation instants (every other 2 kHz instant)."""
    with h5py.File(path, "r") as f:
        t = f["gt/t"][()]
        flux = f["gt/flux"][()]
    step = int(round(GT_RATE_HZ / rate_hz))
    return t[::step], flux[::step]


def write_submission(path: Path, dataset: Path, *, method: str = "ext", transform=None, attrs: dict | None = None,
                     groups: dict | None = None) -> Path:
    """A submission of (optionally transformed) ground truth for every complete recording of ``dataset``."""
    manifest = json.loads((dataset / "manifest.json").read_text())
    base = {"format": "simspad-submission", "method": method, "label": f"{method} (X)", "sensors": "S",
            "absolute_scale": True, "bandwidth_khz_per_pixel": 0.5, "bandwidth_bits_per_pixel_s": 4000.0}
    base.update(attrs or {})
    with h5py.File(path, "w") as f:
        for k, v in base.items():
            if v is not None:
                f.attrs[k] = v
        if groups is None:
            for r in manifest["recordings"]:
                if r["status"] != "complete":
                    continue
                t, flux = gt_of(dataset / r["path"])
                flux = flux if transform is None else transform(flux)
                g = f.create_group(f"{r['sequence']}_{r['lux']:g}lx")
                g.create_dataset("t", data=t)
                g.create_dataset("flux", data=flux)
        else:
            for name, members in groups.items():
                g = f.create_group(name)
                for k, v in members.items():
                    g.create_dataset(k, data=v)
    return path
