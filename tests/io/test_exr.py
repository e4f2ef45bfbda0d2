"""EXR keyframes: lossless either way, ZIP only where it pays (simspad/io/exr.py)."""

from __future__ import annotations

import numpy as np
import OpenEXR

from simspad.io.exr import ZIP_MIN_SAVING, read_exr, write_exr


def _compression(path) -> object:
    return OpenEXR.File(str(path), separate_channels=True, header_only=True).header()["compression"]


def test_noisy_radiance_is_stored_uncompressed_and_flat_images_keep_zip(tmp_path):
    """Path-traced radiance (float32 noise in every mantissa) gains nothing from ZIP and is stored raw; a flat
    synthetic image shrinks and keeps ZIP. Both read back bit for bit."""
    rng = np.random.default_rng(0)
    h, w = 64, 96
    noisy = {c: rng.lognormal(0.0, 1.0, (h, w)).astype(np.float32) for c in "RGB"}
    noisy["Z"] = (2.0 + rng.random((h, w))).astype(np.float32)
    flat = {c: np.full((h, w), v, np.float32) for c, v in zip("RGB", (0.2, 0.5, 0.8))}
    flat["Z"] = np.tile(np.linspace(1.0, 3.0, w, dtype=np.float32), (h, 1))
    raw = 4 * h * w * 4
    for name, channels, expected in (("noisy", noisy, OpenEXR.NO_COMPRESSION), ("flat", flat, OpenEXR.ZIP_COMPRESSION)):
        path = write_exr(tmp_path / f"{name}.exr", channels)
        assert _compression(path) == expected, name
        back = read_exr(path)
        assert np.array_equal(back["rgb"], np.stack([channels[c] for c in "RGB"], axis=-1))
        assert np.array_equal(back["z"], channels["Z"])
    assert (tmp_path / "flat.exr").stat().st_size <= (1 - ZIP_MIN_SAVING) * raw
    assert not list(tmp_path.glob(".*tmp*"))  # the temporary written twice is renamed, not left behind
