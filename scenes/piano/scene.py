"""Piano: an upright piano against a papered wall, four octaves of keys in view, a score on the music stand.

The key fronts lie on z = 0 at height 0.75 m, the keyboard centred on x = 0; the upright case stands behind
them (z < -0.17) against the wall at z = -0.6. Materials: lacquered case (smooth plastic), glossy keys (rough
plastic), matte paper, wood floor and wallpaper. A large soft light up front-left and a faint ambient term
light it. The default trajectory orbits the camera slowly around the keyboard.
"""

WHITE_PITCH_M = 0.0235
N_OCTAVES = 4
KEY_TOP_Y_M = 0.75


def _keys(b, meshes):
    n_white = 7 * N_OCTAVES + 1  # ends on a C
    x0 = -0.5 * n_white * WHITE_PITCH_M
    white_c = [(x0 + (i + 0.5) * WHITE_PITCH_M, KEY_TOP_Y_M - 0.011, -0.075) for i in range(n_white)]
    black_c = []
    for o in range(N_OCTAVES):
        for w in (0, 1, 3, 4, 5):  # black keys follow C, D, F, G, A
            black_c.append((x0 + (7 * o + w + 1) * WHITE_PITCH_M, KEY_TOP_Y_M + 0.006, -0.1))
    wv, wf, wuv = meshes.boxes(white_c, (WHITE_PITCH_M - 0.0012, 0.022, 0.15))
    bv, bf, buv = meshes.boxes(black_c, (0.0125, 0.022, 0.095))
    ivory = b.glossy((0.80, 0.78, 0.72), roughness=0.12, specular=0.6)
    ebony = b.glossy((0.012, 0.012, 0.012), roughness=0.08)
    return (b.mesh("white_keys", wv, wf, ivory, uv=wuv), b.mesh("black_keys", bv, bf, ebony, uv=buv),
            n_white * WHITE_PITCH_M)


def build() -> dict:
    from simspad.scenes.assets import build as b
    from simspad.scenes.assets import meshes, textures

    white, black, kb_w = _keys(b, meshes)
    lacquer = b.smooth_plastic((0.015, 0.012, 0.012))
    case_w = kb_w + 0.16
    tilt = ((1.0, 0.0, 0.0), -14.0)  # the stand leans back
    # Mitsuba puts a bitmap's first row at v = 0, the bottom of a rectangle: flip images to read upright.
    paper = b.diffuse(b.texture(textures.sheet_music()[::-1]))
    paper2 = b.diffuse(b.texture(textures.sheet_music(seed=24)[::-1]))
    floor = b.diffuse(b.texture(textures.wood((256, 512), light=(0.50, 0.32, 0.18), dark=(0.25, 0.13, 0.06),
                                              seed=29), (2, 3)))
    wall = b.diffuse(b.texture(textures.wallpaper((256, 256), seed=8), (5, 3)))
    brass = b.metal(0.25, "Au")
    return b.scene({
        "camera": b.camera(origin=(0.128, 1.32, 0.822), target=(0.0, 0.92, -0.22), fov_deg=52.0),
        "white_keys": white,
        "black_keys": black,
        "key_bed": b.box((0.0, KEY_TOP_Y_M - 0.05, -0.1), (case_w, 0.06, 0.24), lacquer),
        "key_slip": b.box((0.0, KEY_TOP_Y_M - 0.02, 0.012), (case_w, 0.04, 0.02), lacquer),
        "cheek_l": b.box((-(kb_w / 2 + 0.04), KEY_TOP_Y_M, -0.1), (0.08, 0.06, 0.24), lacquer),
        "cheek_r": b.box((kb_w / 2 + 0.04, KEY_TOP_Y_M, -0.1), (0.08, 0.06, 0.24), lacquer),
        "fallboard": b.box((0.0, KEY_TOP_Y_M + 0.05, -0.19), (kb_w, 0.1, 0.03), lacquer),
        "case_upper": b.box((0.0, 1.05, -0.45), (case_w, 0.6, 0.3), lacquer),
        "case_lower": b.box((0.0, 0.33, -0.33), (case_w, 0.66, 0.3), lacquer),
        "lid": b.box((0.0, 1.36, -0.4), (case_w + 0.02, 0.025, 0.44), lacquer),
        "stand": b.box((0.0, 1.04, -0.245), (0.62, 0.3, 0.012), lacquer, rotate=(tilt,)),
        "sheet_l": b.rect((-0.135, 1.04, -0.237), (0.25, 0.33), paper, rotate=(tilt,)),
        "sheet_r": b.rect((0.135, 1.04, -0.237), (0.25, 0.33), paper2, rotate=(tilt,)),
        "stand_ledge": b.box((0.0, 0.875, -0.205), (0.64, 0.012, 0.05), lacquer),
        "pedal_l": b.box((-0.05, 0.05, -0.08), (0.03, 0.015, 0.12), brass),
        "pedal_r": b.box((0.05, 0.05, -0.08), (0.03, 0.015, 0.12), brass),
        "candle_holder": b.cylinder((0.46, 1.373, -0.4), (0.46, 1.5, -0.4), 0.012, brass),
        "vase": b.sphere((-0.4, 1.44, -0.42), 0.07, b.glossy((0.1, 0.3, 0.6), roughness=0.05)),
        "floor": b.rect((0.0, 0.0, 0.0), (4.0, 3.0), floor, rotate=(((1.0, 0.0, 0.0), -90.0),)),
        "wall": b.rect((0.0, 1.5, -0.6), (4.0, 3.0), wall),
        "softbox": b.rect((-1.2, 2.3, 1.2), (1.2, 1.2), b.diffuse(0.5),
                          rotate=(((0.0, 1.0, 0.0), 135.0), ((1.0, 0.0, 0.0), -35.0)),
                          emitter=b.area(6.0)),
        "ambient": {"type": "constant", "radiance": b.rgb(0.05)},
    }, max_depth=5)
