"""Small helpers that write Mitsuba scene-dict entries (shapes, materials, textures, lights, camera).

Import this only inside a scene's ``build()``: it imports Mitsuba, and a variant must already be set (the
renderer picks it). Transforms are composed in numpy (float64) and converted once.
"""

from __future__ import annotations

import mitsuba as mi
import numpy as np

Vec = tuple[float, float, float]


def matrix(translate: Vec = (0.0, 0.0, 0.0), rotate: tuple = (), scale=1.0) -> np.ndarray:
    """4×4 = T(translate) · R(rotate[0]) · R(rotate[1]) ⋯ · S(scale); ``rotate`` is ((axis xyz, degrees), ...)."""
    m = np.eye(4)
    m[:3, 3] = translate
    for axis, deg in rotate:
        a = np.asarray(axis, dtype=np.float64)
        a = a / np.linalg.norm(a)
        th = np.deg2rad(deg)
        k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        r = np.eye(4)
        r[:3, :3] = np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * (k @ k)
        m = m @ r
    s = np.eye(4)
    s[0, 0], s[1, 1], s[2, 2] = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
    return m @ s


def xform(m: np.ndarray):
    """numpy 4×4 → ``mi.ScalarTransform4f``."""
    return mi.ScalarTransform4f(np.asarray(m, dtype=np.float64))


def transform(translate: Vec = (0.0, 0.0, 0.0), rotate: tuple = (), scale=1.0):
    """``mi.ScalarTransform4f`` of :func:`matrix`."""
    return xform(matrix(translate, rotate, scale))


def rgb(c) -> dict:
    return {"type": "rgb", "value": [float(v) for v in np.broadcast_to(np.asarray(c, dtype=float), (3,))]}


def texture(image: np.ndarray, repeat=(1.0, 1.0), filter_type: str = "bilinear") -> dict:
    """A bitmap texture from a linear float ``[H, W, 3]`` array (``raw``: no sRGB decoding)."""
    tex = {"type": "bitmap", "bitmap": mi.Bitmap(np.array(image, dtype=np.float32, order="C", copy=True)), "raw": True,
           "filter_type": filter_type, "wrap_mode": "repeat"}
    if tuple(repeat) != (1.0, 1.0):
        tex["to_uv"] = mi.ScalarTransform4f().scale([float(repeat[0]), float(repeat[1]), 1.0])
    return tex


def _colour(c) -> dict:
    return c if isinstance(c, dict) else rgb(c)


def diffuse(c) -> dict:
    return {"type": "diffuse", "reflectance": _colour(c)}


def twosided(bsdf: dict) -> dict:
    return {"type": "twosided", "material": bsdf}


def glossy(c, roughness: float = 0.15, specular: float = 1.0) -> dict:
    """Rough plastic (diffuse base under a rough dielectric coat): varnish, lacquer, plastic keys."""
    return {"type": "roughplastic", "diffuse_reflectance": _colour(c), "alpha": float(roughness),
            "specular_reflectance": float(specular)}


def smooth_plastic(c) -> dict:
    """Smooth plastic (mirror-like coat): piano lacquer."""
    return {"type": "plastic", "diffuse_reflectance": _colour(c)}


def metal(roughness: float = 0.2, material: str = "Al") -> dict:
    return {"type": "roughconductor", "material": material, "alpha": float(roughness)}


def area(radiance) -> dict:
    return {"type": "area", "radiance": _colour(radiance)}


def box(center: Vec, size: Vec, bsdf: dict, rotate: tuple = ()) -> dict:
    """Axis-aligned (then rotated about its centre) box of full extents ``size`` metres."""
    return {"type": "cube", "to_world": transform(center, rotate, np.asarray(size, dtype=float) / 2), "bsdf": bsdf}


def rect(center: Vec, size: tuple[float, float], bsdf: dict | None = None, rotate: tuple = (),
         emitter: dict | None = None) -> dict:
    """A ``size`` (x, y) rectangle facing +Z before ``rotate``."""
    d = {"type": "rectangle", "to_world": transform(center, rotate, (size[0] / 2, size[1] / 2, 1.0))}
    if bsdf is not None:
        d["bsdf"] = bsdf
    if emitter is not None:
        d["emitter"] = emitter
    return d


def cylinder(p0: Vec, p1: Vec, radius: float, bsdf: dict) -> dict:
    return {"type": "cylinder", "p0": list(map(float, p0)), "p1": list(map(float, p1)), "radius": float(radius),
            "bsdf": bsdf}


def sphere(center: Vec, radius: float, bsdf: dict) -> dict:
    return {"type": "sphere", "center": list(map(float, center)), "radius": float(radius), "bsdf": bsdf}


def disk(center: Vec, radius: float, bsdf: dict, rotate: tuple = ()) -> dict:
    return {"type": "disk", "to_world": transform(center, rotate, (radius, radius, 1.0)), "bsdf": bsdf}


def camera(origin: Vec, target: Vec, fov_deg: float, up: Vec = (0.0, 1.0, 0.0), width: int = 256,
           height: int = 192, spp: int = 16) -> dict:
    """Perspective camera (horizontal ``fov_deg``) with an HDR RGB film; the renderer replaces film and pose."""
    return {"type": "perspective", "fov": float(fov_deg), "fov_axis": "x", "near_clip": 0.01, "far_clip": 1000.0,
            "to_world": mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target), up=list(up)),
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": int(spp)}}


def scene(entries: dict, max_depth: int = 6) -> dict:
    """The top-level dict: a path tracer plus ``entries`` (shapes, emitters, the ``camera`` sensor)."""
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": int(max_depth)}}
    d.update(entries)
    return d


def mesh(name: str, vertices: np.ndarray, faces: np.ndarray, bsdf: dict, uv: np.ndarray | None = None,
         emitter: dict | None = None, smooth_normals: bool = False):
    """A ``mi.Mesh`` from numpy arrays (vertices ``[N, 3]`` m, faces ``[F, 3]``, optional ``uv`` ``[N, 2]``).

    Shapes that trajectories animate must be meshes: the renderer moves their ``vertex_positions``.
    """
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    if emitter is not None:
        props["emitter"] = mi.load_dict(emitter)
    if not smooth_normals:
        props["face_normals"] = True
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.uint32)
    m = mi.Mesh(name, len(v), len(f), props=props, has_vertex_normals=smooth_normals,
                has_vertex_texcoords=uv is not None)
    params = mi.traverse(m)
    # Each buffer takes its own type: mi.Float/mi.UInt32 in the JIT variants, but in scalar_rgb those are Python
    # scalars and a mesh buffer is a dynamic array (drjit.scalar.ArrayXf / ArrayXu).
    params["vertex_positions"] = _buffer(params, "vertex_positions", v.ravel())
    params["faces"] = _buffer(params, "faces", f.ravel())
    if uv is not None:
        params["vertex_texcoords"] = _buffer(params, "vertex_texcoords",
                                             np.ascontiguousarray(uv, dtype=np.float32).ravel())
    params.update()
    if smooth_normals:
        m.recompute_vertex_normals()
    return m


def _buffer(params, key: str, values: np.ndarray):
    """``values`` (1-D numpy) as the array type of the mesh parameter ``key`` in the current variant."""
    return type(params[key])(values)
