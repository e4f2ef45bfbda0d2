"""Siemens star: a 36-cycle binary star (ISO 12233 style) printed on a disk that spins about the optical axis.

The star (shape id ``star``, a mesh so the renderer can move its vertices) is centred at the world origin in
the z = 0 plane, facing the camera on +Z; its default trajectory spins it about +Z through the origin. A large
area light behind the camera lights it evenly (irradiance varies < 3 % across the star).
"""

STAR_RADIUS_M = 0.25
CYCLES = 36


def build() -> dict:
    from simspad.scenes.assets import build as b
    from simspad.scenes.assets import meshes, textures

    star_v, star_f, star_uv = meshes.disk(STAR_RADIUS_M, segments=720)
    star = b.mesh("star", star_v, star_f, b.diffuse(b.texture(textures.siemens_star(1024, CYCLES))), uv=star_uv)
    board = b.texture(textures.plaster((256, 256), colour=(0.45, 0.45, 0.47), seed=51, amount=0.35), (2, 2))
    return b.scene({
        "camera": b.camera(origin=(0.0, 0.0, 1.2), target=(0.0, 0.0, 0.0), fov_deg=34.0),
        "star": star,
        "board": b.rect((0.0, 0.0, -0.02), (1.6, 1.2), b.diffuse(board)),
        "stand": b.box((0.0, -0.45, -0.05), (0.06, 0.5, 0.04), b.diffuse((0.05, 0.05, 0.05))),
        "softbox": b.rect((0.0, 0.0, 3.0), (4.0, 4.0), rotate=(((1.0, 0.0, 0.0), 180.0),),
                          emitter=b.area(1.0)),
        "ambient": {"type": "constant", "radiance": b.rgb(0.02)},
    }, max_depth=3)
