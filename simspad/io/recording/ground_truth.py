"""The ground truth of a recording: sharp photon irradiance (``/gt``) and camera poses (``/poses``)."""

from __future__ import annotations

import numpy as np

from simspad.io.recording.group import GroupView
from simspad.io.recording.samples import GroundTruth


class GroundTruthView(GroupView):
    """``/gt``: the sharp irradiance the methods are scored against, at the instants ``t``."""

    @property
    def t(self) -> np.ndarray:
        """Ground-truth instants, s."""
        return self._dataset("t")[()]

    def flux(self, index=slice(None)) -> np.ndarray:
        """Sharp photon irradiance at the sensor plane, photons s⁻¹ m⁻² (``[H,W]`` or ``[n,H,W]``)."""
        return self._dataset("flux")[index]

    def depth(self, index=slice(None)) -> np.ndarray | None:
        """Depth, m (``[H,W]`` or ``[n,H,W]``); None when the render had none."""
        return self._h5["gt/depth"][index] if "gt/depth" in self._h5 else None

    def items(self) -> GroundTruth:
        """The ground truth as a lazy sequence of ``(t_s, flux[H,W], depth[H,W] or None)``."""
        return GroundTruth(self)


class PosesView(GroupView):
    """``/poses``: the camera-to-world matrices (Mitsuba convention) at the instants ``t``; None when absent."""

    @property
    def t(self) -> np.ndarray | None:
        """Pose instants, s."""
        return self._optional("t")

    @property
    def camera_to_world(self) -> np.ndarray | None:
        """``[k,4,4]`` camera-to-world matrices."""
        return self._optional("camera_to_world")
