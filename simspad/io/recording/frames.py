"""The conventional frames of a recording (``/frames``): raw DN and exposure intervals."""

from __future__ import annotations

import numpy as np

from simspad.io.recording.group import GroupView
from simspad.io.recording.samples import Frames


class FramesView(GroupView):
    """``/frames``: raw frames in DN, each exposed over ``[t_start, t_end)``."""

    @property
    def t_start(self) -> np.ndarray:
        """Exposure start of every frame, s."""
        return self._dataset("t_start")[()]

    @property
    def t_end(self) -> np.ndarray:
        """Exposure end of every frame, s."""
        return self._dataset("t_end")[()]

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return int(self._dataset("dn").shape[0])

    def dn(self, index=slice(None)) -> np.ndarray:
        """Raw frames in DN (uint16), ``[H,W]`` or ``[n,H,W]``."""
        return self._dataset("dn")[index]

    def items(self) -> Frames:
        """The frames as a lazy sequence of ``(t_start_s, t_end_s, dn[H,W])``."""
        return Frames(self)
