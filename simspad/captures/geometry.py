"""Putting each sensor on the reference grid: homographies applied to events, binary frames and images.

A sensor's homography is given in the calibration, or derived from its pose (intrinsics K, rotation R,
translation t onto the reference camera and the distance of the scene plane) by :func:`pose_homography`.

A sensor's homography ``Hs`` (3×3) maps its pixel coordinates to the reference grid's:
``(u, v, w)ᵀ = Hs·(x, y, 1)ᵀ``, reference pixel ``(u/w, v/w)``; pixel (x, y) is the centre of column x, row y.

- **Events** are moved forward: each event's coordinates are mapped and rounded to the nearest reference pixel
  (``numpy.rint``: half to even); events landing outside the grid or outside the valid region are dropped.
  Several sensor pixels can land on one reference pixel (a sensor finer than the grid) and some reference pixels
  receive none (a coarser one): the event methods see the stream as if the sensor had the grid's pixels.
- **Binary SPAD frames** are resampled backwards, nearest neighbour: reference pixel (u, v) takes the bit of the
  sensor pixel nearest to ``Hs⁻¹·(u, v, 1)`` (a bit stays a bit; interpolating would invent probabilities).
- **Conventional frames** are resampled backwards bilinearly (scipy's ``map_coordinates``, order 1), DN rounded
  to the nearest integer.

The valid region is where every sensor sees the reference pixel (its back-mapped centre lies inside the sensor,
within half a pixel of the outermost centres), intersected with an optional mask image. Pixels outside it hold
0 in SPAD bits and frames, and no events.

Coordinates are computed with element-wise products and sums, and the inverse by the adjugate, not BLAS or
LAPACK, so the same calibration gives the same mapping on every CPU (docs/internals.md, Determinism).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates



def pose_homography(k_sensor: np.ndarray, rotation: np.ndarray, translation_m: np.ndarray, plane_distance_m: float,
                    k_reference: np.ndarray) -> np.ndarray:
    """The homography from the sensor's pixels to the reference camera's induced by a scene plane.

    A point X in the sensor camera's frame is ``R·X + t`` in the reference camera's; on the plane ``nᵀX = d`` with
    n = (0, 0, 1) (facing the sensor, at distance d along its optical axis) that is ``(R + t·nᵀ/d)·X``, so pixels
    map by ``H = K_ref·(R + t·nᵀ/d)·K_sensor⁻¹`` (Hartley & Zisserman, eq. 13.2), normalised to H[2, 2] = 1.
    """
    plane = np.zeros((3, 3))
    plane[:, 2] = np.asarray(translation_m, np.float64) / plane_distance_m  # t·nᵀ/d with n = (0, 0, 1)
    h = matmul3(matmul3(k_reference, rotation + plane), inverse3(k_sensor))
    return h / h[2, 2]


def matmul3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a·b`` of 3×3 matrices as element-wise products summed in a fixed order: the same bits on every CPU
    (a BLAS product's rounding depends on the kernel the CPU selects; docs/internals.md, Determinism)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a[:, 0, None] * b[0] + a[:, 1, None] * b[1] + a[:, 2, None] * b[2]


def inverse3(m: np.ndarray) -> np.ndarray:
    """Inverse of a 3×3 matrix by its adjugate (no LAPACK, for the same reason as :func:`matmul3`)."""
    m = np.asarray(m, np.float64)
    cof = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            r = [k for k in range(3) if k != i]
            c = [k for k in range(3) if k != j]
            cof[i, j] = (-1) ** (i + j) * (m[r[0], c[0]] * m[r[1], c[1]] - m[r[0], c[1]] * m[r[1], c[0]])
    det = m[0, 0] * cof[0, 0] + m[0, 1] * cof[0, 1] + m[0, 2] * cof[0, 2]
    return cof.T / det

def apply_homography(h: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map coordinates ``(x, y)`` (float64 arrays) by the homography ``h``; returns ``(u, v)``."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    w = h[2, 0] * x + h[2, 1] * y + h[2, 2]
    return (h[0, 0] * x + h[0, 1] * y + h[0, 2]) / w, (h[1, 0] * x + h[1, 1] * y + h[1, 2]) / w


def is_identity(h: np.ndarray | None) -> bool:
    return h is None or bool(np.array_equal(h, np.eye(3)))


class SensorWarp:
    """The mapping of one sensor of ``sensor_shape`` (H, W) onto the reference grid ``ref_shape`` (H, W).

    Attributes
    ----------
    identity : bool
        The sensor is the reference grid (no resampling: data pass through unchanged).
    sees : ndarray [H_ref, W_ref] bool
        Reference pixels whose back-mapped centre lies on the sensor.
    """

    def __init__(self, homography: np.ndarray | None, sensor_shape: tuple[int, int], ref_shape: tuple[int, int]):
        self.h = np.eye(3) if homography is None else np.asarray(homography, np.float64)
        self.sensor_shape = tuple(sensor_shape)
        self.ref_shape = tuple(ref_shape)
        self.identity = is_identity(homography) and self.sensor_shape == self.ref_shape
        Hr, Wr = self.ref_shape
        Hs, Ws = self.sensor_shape
        v, u = np.mgrid[0:Hr, 0:Wr]
        sx, sy = apply_homography(inverse3(self.h), u.ravel(), v.ravel())
        self.src_x = sx.reshape(Hr, Wr)
        self.src_y = sy.reshape(Hr, Wr)
        self.sees = ((self.src_x >= -0.5) & (self.src_x <= Ws - 0.5) & (self.src_y >= -0.5)
                     & (self.src_y <= Hs - 0.5))
        self._nx = np.clip(np.rint(self.src_x), 0, Ws - 1).astype(np.int64)
        self._ny = np.clip(np.rint(self.src_y), 0, Hs - 1).astype(np.int64)

    def nearest(self, img: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Resample ``img`` ([..., H_s, W_s]) to the grid by nearest neighbour; 0 outside ``valid``."""
        if self.identity:
            return np.where(valid, img, 0).astype(img.dtype, copy=False)
        out = img[..., self._ny, self._nx]
        return np.where(valid, out, 0).astype(img.dtype, copy=False)

    def bilinear(self, img: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Resample one image [H_s, W_s] to the grid bilinearly; 0 outside ``valid``."""
        if self.identity:
            return np.where(valid, img, 0).astype(img.dtype, copy=False)
        out = map_coordinates(np.asarray(img, np.float64), [self.src_y, self.src_x], order=1, mode="nearest")
        return np.where(valid, out, 0.0)

    def events(self, x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference-grid ``(x, y)`` of events at sensor pixels ``(x, y)`` and the mask of those kept."""
        if self.identity:
            keep = valid[y, x]
            return x, y, keep
        u, v = apply_homography(self.h, x, y)
        ui, vi = np.rint(u), np.rint(v)
        Hr, Wr = self.ref_shape
        inside = (ui >= 0) & (ui < Wr) & (vi >= 0) & (vi < Hr)
        ui = np.where(inside, ui, 0).astype(np.int64)
        vi = np.where(inside, vi, 0).astype(np.int64)
        keep = inside & valid[vi, ui]
        return ui, vi, keep
