"""The sRGB transfer curve (IEC 61966-2-1), in both directions.

Linear values are what the renderer and the sensors use; encoded values are for display (metrics, contact
sheets) and for authoring colours that look as named. Relative luminance of linear RGB is
:func:`simspad.physics.radiometry.luminance_from_rgb`.
"""

from __future__ import annotations

import numpy as np

#: Linear value below which the curve is a straight line, and that line's slope.
SRGB_LINEAR_BREAK = 0.0031308
SRGB_LINEAR_SLOPE = 12.92
#: Encoded value at the same break (= SRGB_LINEAR_BREAK · SRGB_LINEAR_SLOPE, rounded as the standard does).
SRGB_ENCODED_BREAK = 0.04045


def srgb_encode(v) -> np.ndarray:
    """sRGB-encode linear values in [0, 1]; float32 out."""
    v = np.asarray(v, dtype=np.float32)
    return np.where(v <= SRGB_LINEAR_BREAK, SRGB_LINEAR_SLOPE * v,
                    1.055 * np.power(np.maximum(v, SRGB_LINEAR_BREAK), 1 / 2.4) - 0.055).astype(np.float32)


def srgb_decode(c) -> np.ndarray:
    """Linear values of sRGB-encoded values in [0, 1]; float64 out."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= SRGB_ENCODED_BREAK, c / SRGB_LINEAR_SLOPE, ((c + 0.055) / 1.055) ** 2.4)
