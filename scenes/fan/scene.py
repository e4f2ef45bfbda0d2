"""Fan: a desk fan on a wooden table, its five-blade rotor (shape id ``blades``) facing the camera.

The rotor is a mesh (so the renderer can move its vertices) built around the hub centre ``HUB_CENTER`` with its
axis along +Z; the default trajectory spins it about that axis. Behind it, 0.55 m away, a printed poster hangs on
a brick wall. A soft light above and in front and a faint ambient term light the scene evenly, so only the
blades' own motion (and their faint shadow) changes the image.
"""

HUB_CENTER = (0.0, 0.62, 0.0)
TIP_RADIUS_M = 0.17
CAGE_RADIUS_M = 0.19


def _cage(b, np, metal):
    """A wire guard in front of the rotor: a rim of short cylinders and radial spokes."""
    cx, cy, cz = HUB_CENTER
    z = cz + 0.045
    shapes = {}
    n = 36
    th = np.linspace(0, 2 * np.pi, n + 1)
    for i in range(n):
        p0 = (cx + CAGE_RADIUS_M * np.cos(th[i]), cy + CAGE_RADIUS_M * np.sin(th[i]), z)
        p1 = (cx + CAGE_RADIUS_M * np.cos(th[i + 1]), cy + CAGE_RADIUS_M * np.sin(th[i + 1]), z)
        shapes[f"cage_rim_{i}"] = b.cylinder(p0, p1, 0.003, metal)
    for i in range(12):
        a = 2 * np.pi * i / 12
        p0 = (cx + 0.035 * np.cos(a), cy + 0.035 * np.sin(a), z + 0.012)
        p1 = (cx + CAGE_RADIUS_M * np.cos(a), cy + CAGE_RADIUS_M * np.sin(a), z)
        shapes[f"cage_spoke_{i}"] = b.cylinder(p0, p1, 0.0015, metal)
    shapes["cage_badge"] = b.disk((cx, cy, z + 0.013), 0.035, b.glossy((0.75, 0.7, 0.6), 0.2))
    return shapes


def build() -> dict:
    import numpy as np

    from simspad.scenes.assets import build as b
    from simspad.scenes.assets import meshes, textures

    cx, cy, cz = HUB_CENTER
    v, f, uv = meshes.fan_blades(n_blades=5, hub_radius_m=0.035, tip_radius_m=TIP_RADIUS_M, pitch_deg=25.0,
                                 sweep_deg=42.0, radial=10, angular=10)
    blade_tex = textures.brushed_metal((64, 128), seed=89, tone=1.0) * np.array([0.12, 0.30, 0.62])
    blades = b.mesh("blades", v + np.array(HUB_CENTER), f,
                    b.twosided(b.glossy(b.texture(blade_tex), roughness=0.25)), uv=uv)
    chrome = b.metal(0.15, "Cr")
    body = b.glossy((0.85, 0.85, 0.82), roughness=0.3)
    # Mitsuba puts a bitmap's first row at v = 0, the bottom of a rectangle: images are flipped to read upright.
    poster = b.diffuse(b.texture(textures.poster()[::-1]))
    bricks = b.diffuse(b.texture(textures.bricks((512, 512)), (3, 2)))
    table = b.diffuse(b.texture(textures.wood((256, 512), seed=97), (1, 1)))
    return b.scene({
        "camera": b.camera(origin=(0.0, 0.66, 0.95), target=(0.0, 0.6, 0.0), fov_deg=40.0),
        "blades": blades,
        **_cage(b, np, chrome),
        "motor": b.cylinder((cx, cy, cz - 0.03), (cx, cy, cz - 0.13), 0.055, body),
        "motor_cap": b.sphere((cx, cy, cz - 0.13), 0.055, body),
        "neck": b.cylinder((cx, cy - 0.05, cz - 0.09), (cx, 0.42, cz - 0.09), 0.012, chrome),
        "base": b.cylinder((cx, 0.40, cz - 0.09), (cx, 0.42, cz - 0.09), 0.11, body),
        "base_top": b.disk((cx, 0.42, cz - 0.09), 0.11, body, rotate=(((1.0, 0.0, 0.0), -90.0),)),
        "table": b.box((0.0, 0.38, -0.1), (1.6, 0.04, 0.9), table),
        "poster": b.rect((0.05, 0.78, -0.548), (0.8, 0.6), poster),
        "wall": b.rect((0.0, 1.0, -0.55), (3.0, 2.0), bricks),
        "floor": b.rect((0.0, 0.0, 0.0), (3.0, 3.0), b.diffuse(0.2), rotate=(((1.0, 0.0, 0.0), -90.0),)),
        "softbox": b.rect((0.3, 1.6, 1.2), (1.2, 1.2), b.diffuse(0.5),
                          rotate=(((1.0, 0.0, 0.0), 135.0),), emitter=b.area(5.0)),
        "ambient": {"type": "constant", "radiance": b.rgb(0.08)},
    }, max_depth=4)
