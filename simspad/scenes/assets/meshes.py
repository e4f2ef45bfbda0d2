"""Procedural triangle meshes as numpy arrays: ``(vertices [N, 3] m, faces [F, 3] uint32, uv [N, 2])``.

Pure numpy (no Mitsuba), deterministic; :func:`simspad.scenes.assets.build.mesh` turns them into ``mi.Mesh``.
"""

from __future__ import annotations

import numpy as np

Mesh = tuple[np.ndarray, np.ndarray, np.ndarray]


def merge(meshes: list[Mesh]) -> Mesh:
    """Concatenate meshes into one (face indices offset)."""
    vs, fs, uvs, offset = [], [], [], 0
    for v, f, uv in meshes:
        vs.append(v)
        fs.append(f + offset)
        uvs.append(uv)
        offset += len(v)
    return np.concatenate(vs), np.concatenate(fs).astype(np.uint32), np.concatenate(uvs)


def grid_faces(n_rows: int, n_cols: int) -> np.ndarray:
    """Two triangles per cell of a row-major ``n_rows × n_cols`` vertex grid."""
    idx = np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)]).astype(np.uint32)


def disk(radius_m: float = 1.0, segments: int = 720) -> Mesh:
    """Flat disk in the z = 0 plane facing +Z, centred at the origin; planar UV (u, v) = (½ + x/2r, ½ + y/2r)."""
    th = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(th), np.sin(th), np.zeros_like(th)], 1) * radius_m
    v = np.concatenate([[[0.0, 0.0, 0.0]], ring])
    i = np.arange(segments)
    f = np.stack([np.zeros(segments, int), 1 + i, 1 + (i + 1) % segments], 1)
    uv = 0.5 + 0.5 * v[:, :2] / radius_m
    return v, f.astype(np.uint32), uv


_CUBE_V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
_CUBE_QUADS = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]


def box(center, size, yaw_deg: float = 0.0, pitch_deg: float = 0.0) -> Mesh:
    """Box of full extents ``size`` (flat-shaded, 6 separate quads so normals stay sharp), rotated by yaw about
    +Y then pitch about +X, then moved to ``center``."""
    verts, faces, uvs = [], [], []
    half = np.asarray(size, dtype=np.float64) / 2
    cy, sy = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
    cp, sp = np.cos(np.deg2rad(pitch_deg)), np.sin(np.deg2rad(pitch_deg))
    r = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]) @ np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    for k, quad in enumerate(_CUBE_QUADS):
        p = (_CUBE_V[list(quad)] * half) @ r.T + np.asarray(center, dtype=np.float64)
        verts.append(p)
        faces += [[4 * k, 4 * k + 1, 4 * k + 2], [4 * k, 4 * k + 2, 4 * k + 3]]
        uvs.append([[0, 0], [1, 0], [1, 1], [0, 1]])
    return np.concatenate(verts), np.asarray(faces, dtype=np.uint32), np.asarray(uvs, dtype=np.float64).reshape(-1, 2)


def boxes(centers, sizes, yaw_deg: float = 0.0, pitch_deg: float = 0.0) -> Mesh:
    """Many boxes merged into one mesh (keyboard keys, piano keys)."""
    sizes = np.broadcast_to(np.asarray(sizes, dtype=np.float64), np.shape(centers))
    return merge([box(c, s, yaw_deg, pitch_deg) for c, s in zip(np.asarray(centers, dtype=np.float64), sizes)])


def leaf(base, azimuth_deg: float, elevation_deg: float, length_m: float, width_m: float,
         droop: float = 0.3, twist_deg: float = 0.0, fold: float = 0.2, stations: int = 24) -> Mesh:
    """A sword-shaped leaf (yucca): a V-folded strip along a drooping curve with a sharp tip.

    The centreline leaves ``base`` at ``elevation_deg`` above the horizontal towards ``azimuth_deg`` (about +Y,
    0 = +X) and bends down by ``droop`` × length at the tip. Width peaks at a third of the length and tapers
    to a point; ``fold`` raises the midrib by that fraction of the half-width. UV: u along, v across.
    """
    s = np.linspace(0.0, 1.0, stations)
    az, el = np.deg2rad(azimuth_deg), np.deg2rad(elevation_deg)
    horiz = np.array([np.cos(az), 0.0, np.sin(az)])
    up = np.array([0.0, 1.0, 0.0])
    centre = (np.asarray(base, dtype=np.float64) + length_m * (s[:, None] * np.cos(el) * horiz
              + (s * np.sin(el) - droop * s**2)[:, None] * up))
    tangent = np.gradient(centre, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    side = np.cross(tangent, up)
    side_norm = np.linalg.norm(side, axis=1, keepdims=True)
    side = np.where(side_norm > 1e-6, side / np.maximum(side_norm, 1e-12), np.cross(horiz, up))
    normal = np.cross(side, tangent)
    tw = np.deg2rad(twist_deg) * s[:, None]
    side, normal = np.cos(tw) * side + np.sin(tw) * normal, -np.sin(tw) * side + np.cos(tw) * normal
    half = 0.5 * width_m * np.clip((s + 0.08) / 0.33, 0, 1) * np.clip((1.0 - s) / 0.67, 0, 1) ** 0.7
    left = centre - half[:, None] * side
    mid = centre + (fold * half)[:, None] * normal
    right = centre + half[:, None] * side
    v = np.stack([left, mid, right], 1).reshape(-1, 3)
    uv = np.stack(np.meshgrid(s, [0.0, 0.5, 1.0], indexing="ij"), -1).reshape(-1, 2)
    return v, grid_faces(stations, 3), uv


def fan_blades(n_blades: int = 5, hub_radius_m: float = 0.04, tip_radius_m: float = 0.2,
               pitch_deg: float = 25.0, sweep_deg: float = 40.0, radial: int = 10, angular: int = 12) -> Mesh:
    """Fan rotor in the z ≈ 0 plane, axis +Z through the origin: ``n_blades`` swept, pitched paddles plus a hub.

    Each blade spans ``sweep_deg`` of arc (wider towards the tip) and is pitched ``pitch_deg`` about its radial
    axis, so its edges move in depth like a real blade. UV: u radial, v across the blade.
    """
    parts = []
    for b in range(n_blades):
        a0 = 2 * np.pi * b / n_blades
        r = np.linspace(hub_radius_m * 0.8, tip_radius_m, radial)
        t = np.linspace(-0.5, 0.5, angular)
        rr, tt = np.meshgrid(r, t, indexing="ij")
        width = np.deg2rad(sweep_deg) * (0.45 + 0.55 * (rr - r[0]) / (r[-1] - r[0]))
        # round the tip: narrow the last 15 % of the radius
        frac = (rr - r[0]) / (r[-1] - r[0])
        width *= np.sqrt(np.clip(1 - ((frac - 0.85) / 0.15).clip(0) ** 2, 0.05, 1))
        ang = a0 + tt * width + 0.25 * np.deg2rad(sweep_deg) * frac  # swept back towards the tip
        x, y = rr * np.cos(ang), rr * np.sin(ang)
        z = -np.tan(np.deg2rad(pitch_deg)) * tt * width * rr
        v = np.stack([x, y, z], -1).reshape(-1, 3)
        uv = np.stack([frac, tt + 0.5], -1).reshape(-1, 2)
        parts.append((v, grid_faces(radial, angular), uv))
    hub_v, hub_f, hub_uv = disk(hub_radius_m, 48)
    hub_v = hub_v + np.array([0.0, 0.0, 0.012])
    hub_v[0, 2] += 0.01  # a shallow cone: the nose of the hub
    parts.append((hub_v, hub_f, hub_uv * 0.0))
    return merge(parts)


def lathe(profile_rz, segments: int = 64, center=(0.0, 0.0, 0.0)) -> Mesh:
    """Surface of revolution about +Y of a (radius, height) profile, e.g. a pot; UV: u around, v along."""
    prof = np.asarray(profile_rz, dtype=np.float64)
    th = np.linspace(0.0, 2 * np.pi, segments + 1)
    rr, tt = np.meshgrid(prof[:, 0], th, indexing="ij")
    hh = np.repeat(prof[:, 1][:, None], segments + 1, axis=1)
    v = np.stack([rr * np.cos(tt), hh, rr * np.sin(tt)], -1).reshape(-1, 3) + np.asarray(center)
    uv = np.stack(np.meshgrid(np.linspace(0, 1, len(prof)), th / (2 * np.pi), indexing="ij")[::-1], -1).reshape(-1, 2)
    return v, grid_faces(len(prof), segments + 1), uv
