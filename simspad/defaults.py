"""Defaults shared by the CLI, the dataset spec and the library functions: each value is named once here.

Units are in the names. Sensor defaults are the presets in :mod:`simspad.sensors.presets`; method defaults
live with each method.
"""

#: Render resolution (width, height) in pixels.
RESOLUTION_PX = (128, 96)
#: Monte Carlo samples per pixel of a render.
SPP = 16
#: Largest predicted image motion between two rendered keyframes, in pixels.
MAX_FLOW_PX = 0.5
#: Lowest keyframe rate in Hz, whatever the motion.
MIN_KEYFRAME_RATE_HZ = 1000.0
#: Rate of the ground-truth frames in a recording and of the evaluation instants, in Hz.
GT_RATE_HZ = 1000.0
#: Exposure (s) of the conventional frame whose motion blur a recording states when it has no frame camera.
FRAME_BLUR_EXPOSURE_S = 10e-3
#: Seed of renders and sensor streams when none is given.
SEED = 0
