"""The ground truth of a recording: sharp photon irradiance (``/gt``), its geometry (instance masks, motion field,
poses and the camera's intrinsics, when the render had geometry passes) and the keyframes' camera poses
(``/poses``)."""

from __future__ import annotations

import json

import numpy as np

from simspad.errors import InputError
from simspad.io.recording.group import GroupView
from simspad.motion.motion_field import flow_validity, motion_field, relative_motion
from simspad.motion.pinhole import PinholeCamera
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

    @property
    def has_geometry(self) -> bool:
        """Whether the recording carries instance masks, the motion field and the camera model."""
        return "gt/flow" in self._h5

    def instance(self, index=slice(None)) -> np.ndarray:
        """Instance id of the scene object seen at each pixel centre (uint16, 0: nothing; ``[H,W]`` or ``[n,H,W]``)."""
        return self._dataset("instance")[index]

    @property
    def instance_names(self) -> list[str]:
        """Scene object name of each instance id (entry 0, nothing hit, is ``""``)."""
        return json.loads(self._dataset("instance").attrs["names"])

    def flow(self, index=slice(None)) -> np.ndarray:
        """Forward motion field over the next ground-truth interval, px (``[H,W,2]`` or ``[n,H,W,2]``: x right, y
        down; NaN where undefined)."""
        return self._dataset("flow")[index]

    def flow_valid(self, index=slice(None)) -> np.ndarray:
        """Where the flow lands on the same visible surface inside the image (bool, ``[H,W]`` or ``[n,H,W]``)."""
        return self._dataset("flow_valid")[index].astype(bool)

    def velocity(self, index=slice(None)) -> np.ndarray:
        """Instantaneous image velocity, px s⁻¹ (``[H,W,2]`` or ``[n,H,W,2]``: x right, y down)."""
        return self._dataset("velocity")[index]

    @property
    def camera_to_world(self) -> np.ndarray:
        """``[n,4,4]`` camera pose at each ground-truth instant (Mitsuba convention)."""
        return self._dataset("camera_to_world")[()]

    @property
    def object_names(self) -> list[str]:
        """The animated objects, in the order of :attr:`object_to_world`'s axis 1 (empty when none)."""
        return json.loads(self._h5["gt/object_to_world"].attrs["objects"]) if "gt/object_to_world" in self._h5 else []

    @property
    def object_to_world(self) -> np.ndarray | None:
        """``[n,K,4,4]`` pose of each animated object at each ground-truth instant; None when none moves."""
        return self._optional("object_to_world")

    @property
    def camera(self) -> dict | None:
        """The camera model (``/camera``): its attributes (``focal_px``, ``cx_px``, ``cy_px``, ``x_fov_deg``, …)
        and ``K`` (3×3, px); None when the recording has none."""
        if "camera" not in self._h5:
            return None
        out = {k: (v.item() if hasattr(v, "item") else v) for k, v in self._h5["camera"].attrs.items()}
        out["K"] = self._h5["camera/K"][()]
        return out

    def flow_between(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Exact forward motion field from ground-truth instant ``i`` to instant ``j`` (any later instant, e.g. the
        end of an event window), from the recording's depth, instances, poses and intrinsics.

        Returns
        -------
        flow : ndarray [H, W, 2] float32
            Displacement, px (x right, y down); NaN where undefined.
        valid : ndarray [H, W] bool
            Where the moved point is the surface seen at ``j`` inside the image (as ``/gt/flow_valid``).
        """
        cam = self.camera
        if cam is None:
            raise InputError("the recording has no camera model (/camera): its render had no geometry passes",
                             path=self._path, field="camera")
        camera = PinholeCamera(int(cam["width"]), int(cam["height"]), float(cam["focal_px"]))
        c2w = self._dataset("camera_to_world")
        depth, inst = self._dataset("depth")[i], self._dataset("instance")[i]
        names = self.instance_names
        objects = self.object_to_world
        moves = {names.index(n): relative_motion(objects[i, k], objects[j, k])
                 for k, n in enumerate(self.object_names)}
        flow, moved_depth = motion_field(camera, depth, inst, c2w[i], c2w[j], moves)
        valid = flow_validity(camera, flow, moved_depth, inst, self._dataset("depth")[j], self._dataset("instance")[j])
        return flow.astype(np.float32), valid

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
