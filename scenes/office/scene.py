"""Office: a desk against the back wall of a dim room, lit by a bright window beside it, the monitor and a dim
ceiling panel.

Room: floor y = 0, back wall z = -1, side walls x = ±1.6, ceiling y = 2.6 (metres). The window (a hole in the
back wall, left of the desk) shows an outdoor view as an area emitter behind the glass plane, > 10³ brighter than
the shadow under the desk. On the desk: a monitor showing code (emissive), a keyboard of 54 individual keys
(one mesh), a mouse, standing books with printed spines and one lying book; a patterned rug on a plank floor.
The camera stands at (0.3, 1.15, 1.35) looking at the desk; its default trajectory is hand-held tremor.
"""

WINDOW_RADIANCE = 40.0  # relative radiance of the outdoor view (the room's diffuse walls are ~0.01–0.3)
SCREEN_RADIANCE = 1.5
LAMP_RADIANCE = 2.0  # a dim ceiling panel: keeps the interior from being lit by one small opening only
KEY_PITCH_M = 0.019


def _keyboard(b, meshes, np):
    rows = [14, 14, 13, 12]
    centers = []
    for r, n in enumerate(rows):
        x0 = -0.5 * (n - 1) * KEY_PITCH_M + 0.004 * r
        for k in range(n):
            centers.append((x0 + k * KEY_PITCH_M, 0.789, -0.43 + r * KEY_PITCH_M))
    centers.append((0.0, 0.789, -0.43 + 4 * KEY_PITCH_M))  # space bar
    sizes = np.full((len(centers), 3), (0.016, 0.01, 0.016))
    sizes[-1] = (0.11, 0.01, 0.016)
    v, f, uv = meshes.boxes(centers, sizes)
    return b.mesh("keys", v, f, b.glossy((0.55, 0.55, 0.56), roughness=0.3), uv=uv)


def build() -> dict:
    import numpy as np

    from simspad.scenes.assets import build as b
    from simspad.scenes.assets import meshes, textures

    # Mitsuba puts a bitmap's first row at v = 0, the bottom of a rectangle: images are flipped to read upright.
    rx = ((1.0, 0.0, 0.0), -90.0)  # rectangle facing +Y (floor-like)
    wood = b.diffuse(b.texture(textures.wood((256, 512), seed=7), (1, 1)))
    floor = b.diffuse(b.texture(textures.wood((256, 512), light=(0.55, 0.45, 0.35), dark=(0.30, 0.22, 0.15),
                                              seed=19), (2, 3)))
    wall = b.diffuse(b.texture(textures.wallpaper((256, 256), seed=5), (4, 2)))
    side_wall = b.diffuse(b.texture(textures.plaster((128, 128), seed=3), (2, 2)))
    frame = b.diffuse((0.85, 0.85, 0.82))
    dark_plastic = b.glossy((0.02, 0.02, 0.022), roughness=0.2)

    # Back wall at z = -1 with a window hole x ∈ [-1.35, -0.55], y ∈ [0.95, 2.15].
    wx0, wx1, wy0, wy1 = -1.35, -0.55, 0.95, 2.15
    back = {
        "wall_left": b.rect(((-1.6 + wx0) / 2, 1.3, -1.0), (wx0 + 1.6, 2.6), wall),
        "wall_right": b.rect(((wx1 + 1.6) / 2, 1.3, -1.0), (1.6 - wx1, 2.6), wall),
        "wall_below": b.rect(((wx0 + wx1) / 2, wy0 / 2, -1.0), (wx1 - wx0, wy0), wall),
        "wall_above": b.rect(((wx0 + wx1) / 2, (wy1 + 2.6) / 2, -1.0), (wx1 - wx0, 2.6 - wy1), wall),
    }
    cx, cy = (wx0 + wx1) / 2, (wy0 + wy1) / 2
    window = {
        "outdoor": b.rect((cx, cy, -1.3), (1.6, 1.8),
                          emitter=b.area(b.texture(textures.outdoor_view()[::-1] * WINDOW_RADIANCE))),
        "sill": b.box((cx, wy0 - 0.02, -0.93), (wx1 - wx0 + 0.12, 0.04, 0.16), frame),
        "mullion_v": b.box((cx, cy, -1.0), (0.035, wy1 - wy0, 0.05), frame),
        "mullion_h": b.box((cx, cy + 0.1, -1.0), (wx1 - wx0, 0.035, 0.05), frame),
        "frame_l": b.box((wx0, cy, -1.0), (0.05, wy1 - wy0 + 0.05, 0.1), frame),
        "frame_r": b.box((wx1, cy, -1.0), (0.05, wy1 - wy0 + 0.05, 0.1), frame),
        "frame_t": b.box((cx, wy1, -1.0), (wx1 - wx0 + 0.05, 0.05, 0.1), frame),
        "frame_b": b.box((cx, wy0, -1.0), (wx1 - wx0 + 0.05, 0.05, 0.1), frame),
    }

    desk = {
        "desk_top": b.box((0.15, 0.74, -0.62), (1.5, 0.04, 0.72), wood),
        "desk_leg_l": b.box((-0.55, 0.36, -0.62), (0.04, 0.72, 0.68), wood),
        "desk_leg_r": b.box((0.85, 0.36, -0.62), (0.04, 0.72, 0.68), wood),
        "desk_back": b.box((0.15, 0.45, -0.96), (1.36, 0.5, 0.02), wood),
    }
    monitor = {
        "monitor_foot": b.box((0.0, 0.765, -0.78), (0.22, 0.01, 0.16), dark_plastic),
        "monitor_neck": b.box((0.0, 0.9, -0.82), (0.05, 0.28, 0.03), dark_plastic),
        "monitor_body": b.box((0.0, 1.09, -0.8), (0.62, 0.38, 0.03), dark_plastic),
        "screen": b.rect((0.0, 1.095, -0.784), (0.58, 0.34),
                         bsdf=b.diffuse(0.02),
                         emitter=b.area(b.texture(textures.screen_text()[::-1] * SCREEN_RADIANCE))),
    }
    keyboard = {
        "keyboard_base": b.box((0.01, 0.775, -0.40), (0.31, 0.012, 0.12), dark_plastic),
        "keys": _keyboard(b, meshes, np),
        "mouse": b.sphere((0.25, 0.77, -0.40), 0.025, b.glossy((0.05, 0.05, 0.05), 0.25)),
    }
    books = {}
    thick = [0.035, 0.05, 0.03, 0.045, 0.04, 0.055, 0.032]
    heights = [0.24, 0.28, 0.22, 0.26, 0.23, 0.30, 0.25]
    x = 0.45
    for i, (t, h) in enumerate(zip(thick, heights)):
        spine = textures.book_cover(i)
        colour = tuple(float(c) for c in spine[spine.shape[0] // 2, 2])
        books[f"book_{i}"] = b.box((x + t / 2, 0.76 + h / 2, -0.82), (t, h, 0.18), b.diffuse(colour))
        books[f"spine_{i}"] = b.rect((x + t / 2, 0.76 + h / 2, -0.729), (t, h), b.diffuse(b.texture(spine[::-1])))
        x += t + 0.003
    books["lying_book"] = b.box((-0.38, 0.78, -0.55), (0.2, 0.04, 0.27), b.diffuse((0.12, 0.2, 0.42)),
                                rotate=(((0.0, 1.0, 0.0), 20.0),))
    room = {
        "floor": b.rect((0.0, 0.0, 0.3), (3.2, 2.6), floor, rotate=(rx,)),
        "carpet": b.rect((0.1, 0.002, -0.1), (2.0, 1.4), b.diffuse(b.texture(textures.carpet((512, 512)))),
                         rotate=(rx,)),
        "ceiling": b.rect((0.0, 2.6, 0.3), (3.2, 2.6), b.diffuse(0.7), rotate=(((1.0, 0.0, 0.0), 90.0),)),
        "ceiling_lamp": b.rect((0.2, 2.58, 0.2), (0.5, 0.5), b.diffuse(0.8), rotate=(((1.0, 0.0, 0.0), 90.0),),
                               emitter=b.area(LAMP_RADIANCE)),
        "left_wall": b.rect((-1.6, 1.3, 0.3), (2.6, 2.6), side_wall, rotate=(((0.0, 1.0, 0.0), 90.0),)),
        "right_wall": b.rect((1.6, 1.3, 0.3), (2.6, 2.6), side_wall, rotate=(((0.0, 1.0, 0.0), -90.0),)),
        "front_wall": b.rect((0.0, 1.3, 1.6), (3.2, 2.6), side_wall, rotate=(((0.0, 1.0, 0.0), 180.0),)),
    }
    return b.scene({
        "camera": b.camera(origin=(0.3, 1.15, 1.35), target=(-0.1, 0.75, -0.8), fov_deg=62.0),
        **room, **back, **window, **desk, **monitor, **keyboard, **books,
    }, max_depth=5)
