"""``--interpolation warp``: render sparse keyframes and synthesize those between by reprojection.

Three modules, lowest first: :mod:`~simspad.render.warp.synthesis` (one keyframe from its two rendered neighbours,
and how far the two warps disagree), :mod:`~simspad.render.warp.schedule` (which keyframes to render and which to
synthesize, over a :class:`~simspad.render.warp.schedule.KeyframeSource`), and
:mod:`~simspad.render.warp.rendering` (the Mitsuba side: that source for a loaded scene, the noise probe, and what
a chunk of a render reports to the dataset driver). Nothing is imported here, so importing one module does not
load the others.
"""
