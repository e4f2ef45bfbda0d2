"""Plant: a yucca (three canes, each topped by a rosette of thin sword leaves) in a terracotta pot.

The pot stands on a wooden floor (y = 0) in front of a plastered back wall (z = -0.8) with a window whose right
half frames the leaves, so many thin leaf edges cross a background > 10³ times brighter than the shadowed
wall and floor. The outdoor view is an area emitter behind the window hole; a dim ceiling panel and a faint
ambient term are the only other light. Leaves are one mesh of ~100 V-folded strips with a veined texture, seen
from both sides.
"""

WINDOW_RADIANCE = 40.0
LAMP_RADIANCE = 1.5  # a dim ceiling panel so the room is not lit through the window alone
POT_CENTER = (-0.1, 0.0, -0.35)


def _canes():
    """(base, top) of each cane, metres."""
    cx, _, cz = POT_CENTER
    return [((cx - 0.02, 0.3, cz), (cx - 0.07, 0.95, cz + 0.02)),
            ((cx + 0.02, 0.3, cz + 0.01), (cx + 0.12, 1.22, cz - 0.03)),
            ((cx, 0.3, cz - 0.02), (cx - 0.01, 1.45, cz - 0.06))]


def _leaves(meshes, np):
    rng = np.random.default_rng(2024)
    parts = []
    for _, top in _canes():
        n = int(rng.integers(28, 36))
        for k in range(n):
            az = 360.0 * k / n * 2.39996 + rng.normal(0, 10)  # golden-angle phyllotaxis
            el = rng.uniform(-10, 80)
            length = rng.uniform(0.3, 0.5)
            parts.append(meshes.leaf(np.asarray(top) + rng.normal(0, 0.01, 3), az, el, length,
                                     rng.uniform(0.025, 0.04), droop=rng.uniform(0.1, 0.45),
                                     twist_deg=rng.uniform(-40, 40), fold=0.25, stations=16))
    return meshes.merge(parts)


def build() -> dict:
    import numpy as np

    from simspad.scenes.assets import build as b
    from simspad.scenes.assets import meshes, textures

    # Mitsuba puts a bitmap's first row at v = 0, the bottom of a rectangle: images are flipped to read upright.
    wall = b.diffuse(b.texture(textures.plaster((256, 256), colour=(0.80, 0.74, 0.62), seed=61, amount=0.3),
                               (3, 2)))
    floor = b.diffuse(b.texture(textures.wood((256, 512), light=(0.60, 0.48, 0.34), dark=(0.34, 0.24, 0.15),
                                              seed=67), (2, 3)))
    bark = b.diffuse(b.texture(textures.plaster((256, 64), colour=(0.42, 0.32, 0.20), seed=71, amount=0.7),
                               (1, 3)))
    frame = b.diffuse((0.85, 0.85, 0.82))
    leaf_v, leaf_f, leaf_uv = _leaves(meshes, np)
    leaves = b.mesh("leaves", leaf_v, leaf_f, b.twosided(b.diffuse(b.texture(textures.leaf_texture()))),
                    uv=leaf_uv)
    profile = [(0.12, 0.0), (0.135, 0.1), (0.15, 0.22), (0.165, 0.29), (0.175, 0.30), (0.175, 0.33),
               (0.16, 0.33), (0.155, 0.30)]
    pot_v, pot_f, pot_uv = meshes.lathe(profile, segments=64, center=POT_CENTER)
    pot = b.mesh("pot", pot_v, pot_f, b.twosided(b.diffuse(b.texture(textures.terracotta()))), uv=pot_uv,
                 smooth_normals=True)
    soil = textures.plaster((128, 128), colour=(0.16, 0.11, 0.07), seed=73, amount=0.6)
    canes = {f"cane_{i}": b.cylinder(p0, p1, 0.022 - 0.003 * i, bark) for i, (p0, p1) in enumerate(_canes())}

    wx0, wx1, wy0, wy1 = -0.05, 1.05, 0.7, 2.1  # window hole in the back wall
    cx, cy = (wx0 + wx1) / 2, (wy0 + wy1) / 2
    back = {
        "wall_left": b.rect(((-1.8 + wx0) / 2, 1.3, -0.8), (wx0 + 1.8, 2.6), wall),
        "wall_right": b.rect(((wx1 + 1.8) / 2, 1.3, -0.8), (1.8 - wx1, 2.6), wall),
        "wall_below": b.rect((cx, wy0 / 2, -0.8), (wx1 - wx0, wy0), wall),
        "wall_above": b.rect((cx, (wy1 + 2.6) / 2, -0.8), (wx1 - wx0, 2.6 - wy1), wall),
        "outdoor": b.rect((cx, cy, -1.1), (2.0, 2.0),
                          emitter=b.area(b.texture(textures.outdoor_view(seed=83)[::-1] * WINDOW_RADIANCE))),
        "mullion": b.box((cx, cy, -0.8), (0.04, wy1 - wy0, 0.05), frame),
        "transom": b.box((cx, cy + 0.3, -0.8), (wx1 - wx0, 0.04, 0.05), frame),
        "frame_l": b.box((wx0, cy, -0.8), (0.05, wy1 - wy0 + 0.05, 0.1), frame),
        "frame_r": b.box((wx1, cy, -0.8), (0.05, wy1 - wy0 + 0.05, 0.1), frame),
        "frame_t": b.box((cx, wy1, -0.8), (wx1 - wx0 + 0.05, 0.05, 0.1), frame),
        "sill": b.box((cx, wy0 - 0.02, -0.74), (wx1 - wx0 + 0.12, 0.04, 0.16), frame),
    }
    return b.scene({
        "camera": b.camera(origin=(0.2, 1.0, 1.95), target=(0.12, 0.88, -0.5), fov_deg=55.0),
        "leaves": leaves,
        "pot": pot,
        "soil": b.disk((POT_CENTER[0], 0.31, POT_CENTER[2]), 0.158, b.diffuse(b.texture(soil)),
                       rotate=(((1.0, 0.0, 0.0), -90.0),)),
        **canes,
        **back,
        "floor": b.rect((0.0, 0.0, 0.4), (3.6, 2.4), floor, rotate=(((1.0, 0.0, 0.0), -90.0),)),
        "left_wall": b.rect((-1.8, 1.3, 0.4), (2.4, 2.6), wall, rotate=(((0.0, 1.0, 0.0), 90.0),)),
        "ceiling": b.rect((0.0, 2.6, 0.4), (3.6, 2.4), b.diffuse(0.7), rotate=(((1.0, 0.0, 0.0), 90.0),)),
        "ceiling_lamp": b.rect((0.0, 2.58, 0.6), (0.5, 0.5), b.diffuse(0.8), rotate=(((1.0, 0.0, 0.0), 90.0),),
                               emitter=b.area(LAMP_RADIANCE)),
        "ambient": {"type": "constant", "radiance": b.rgb(0.01)},
    }, max_depth=5)
