"""Motion-compensated keyframe synthesis: an in-between keyframe from the two rendered keyframes around it.

A rendered keyframe (:class:`WarpSource`: linear RGB, depth Z, optional object ids, camera and object poses)
is carried to the target pose by reprojection (:mod:`simspad.render.reprojection`):

1. **Geometry of the target.** The renderer gives it: a depth + object-id pass rendered at the target pose
   (1 spp, a few % of a radiance render at useful sizes). Without one, every pixel of both sources is
   reprojected to the target and splatted to its nearest target pixel through a z-buffer (nearest surface
   wins); holes left by magnification or disocclusion take the *farthest* depth around them (what a
   disocclusion reveals is background). The splat misplaces silhouette pixels by up to a pixel, which is why
   the renderer does not rely on it.
2. **Backward warp of radiance.** Each target pixel's surface point is moved back to each source's instant (with
   its object's transform) and projected into the source, whose radiance is sampled there with a cubic spline.
   The sample counts only where it is the same surface (**consistency check**): the source sees the point at the
   projected depth (within :data:`DEPTH_TOLERANCE` plus the source's local depth slope) on the same object, and
   inside the image.
3. **Occlusion-aware blend.** Consistent samples are blended with the linear-in-time weights (1 − w, w); a pixel
   that only one source sees takes that one; a pixel neither sees consistently is a *hole*.
4. **Emission layer.** When the sources carry their directly visible emission (the same samples, from an
   emission pass), steps 2–3 move only the reflected light, and the target's own emission pass is added: a
   bright textured emitter behind thin occluders (the office window) is then rendered, not resampled.

The **disagreement** of a synthesized keyframe measures how far the two warps are from the same image: the
relative RMS difference of their luminance where both are consistent, plus the fraction of holes
(:class:`Disagreement`); :mod:`simspad.render.warp.schedule` renders a keyframe for real where it exceeds a
threshold. Everything is deterministic numpy (no atomics, no threads): the same sources give bit-identical
frames.

Rays that hit nothing (``Z = inf``) are handled as points at :data:`FAR_DEPTH_M`, where only rotation moves
them; the synthesized depth is ``inf`` there again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import map_coordinates, maximum_filter, spline_filter

from simspad.physics.radiometry import luminance_from_rgb
from simspad.render.blocks import TILE_PX
from simspad.render.reprojection import PinholeCamera, move_points, project, unproject

#: Stand-in depth (m) for rays that hit nothing: far enough that only rotation moves them.
FAR_DEPTH_M = 1e7
#: Relative depth mismatch (of Z) tolerated by the consistency check, on top of the source's local slope.
DEPTH_TOLERANCE = 0.02
#: Rounds of hole filling (each closes holes one pixel wide) after the forward splat.
HOLE_FILL_ROUNDS = 3
#: A tile's noise is floored at this fraction of the frame's RMS noise (tiles a render gets noiseless, e.g. flat
#: light, must not turn any resampling round-off into a failure).
TILE_NOISE_FLOOR = 0.5
#: Fraction of hole pixels that counts as one noise unit of disagreement.
HOLE_TOLERANCE = 0.01
#: Tiles past those over the threshold that :meth:`Disagreement.failing_tiles` may add to leave room for holes.
_EXTRA_RATIO_TILES = 16
#: Cubic B-spline resampling of radiance: interpolating, so an unmoved pixel keeps its value exactly.
SPLINE_ORDER = 3


@dataclass(frozen=True)
class WarpSource:
    """A rendered keyframe as the warp needs it.

    Attributes
    ----------
    rgb : ndarray [H, W, 3] float32
        Linear radiance.
    depth_z : ndarray [H, W] float32
        Depth along the optical axis, m (inf: no hit).
    camera_to_world : ndarray (4, 4)
    object_id : ndarray [H, W] or None
        Per-pixel object ids (:data:`simspad.render.reprojection.OBJECT_ID_CHANNEL`).
    object_poses : tuple of ndarray (4, 4)
        ``object_to_world`` of animated object k at this instant, entry k − 1.
    emission : ndarray [H, W, 3] float32 or None
        The directly visible emission inside ``rgb``, from the same samples
        (:meth:`simspad.render.mitsuba_scene.MitsubaScene.render_emission`); None: none in view. With it only the
        reflected light ``rgb − emission`` is warped, and the target's own emission pass is added
        (:func:`synthesize`).
    """

    rgb: np.ndarray
    depth_z: np.ndarray
    camera_to_world: np.ndarray
    object_id: np.ndarray | None = None
    object_poses: tuple = ()
    emission: np.ndarray | None = None


@dataclass(frozen=True)
class Disagreement:
    """How far the two warps of a synthesized keyframe are from each other.

    Attributes
    ----------
    rel_rms : float
        RMS difference of the two warps' luminance where both are consistent, ÷ mean luminance of the frame.
    hole_fraction : float
        Fraction of pixels neither source sees consistently.
    single_fraction : float
        Fraction of pixels only one source sees (disocclusions; taken from that source alone).
    noise_ratio : float
        With a noise map: the largest, over :data:`TILE_PX`-pixel tiles, of the RMS difference of the two warps
        ÷ the RMS difference two renders' Monte Carlo noise alone would give there (√2 × the tile's noise);
        about 1 where the warps agree up to noise, whatever part of the frame goes wrong. NaN without one.
    tile_ratio : ndarray [ceil(H / TILE_PX), ceil(W / TILE_PX)] or None
        With a noise map: that ratio per tile (0 where too few pixels are seen by both sources to judge).
    tile_holes : ndarray [ceil(H / TILE_PX), ceil(W / TILE_PX)] or None
        Hole pixels per tile.
    """

    rel_rms: float
    hole_fraction: float
    single_fraction: float
    noise_ratio: float = float("nan")
    tile_ratio: np.ndarray | None = field(default=None, compare=False, repr=False)
    tile_holes: np.ndarray | None = field(default=None, compare=False, repr=False)

    def score(self) -> float:
        """One number to threshold. With a noise map: ``noise_ratio + hole_fraction / HOLE_TOLERANCE`` (in
        units of the render noise); without: ``rel_rms + hole_fraction`` (a hole counts as a 100 % mismatch)."""
        if np.isnan(self.noise_ratio):
            return float(self.rel_rms + self.hole_fraction)
        return float(self.noise_ratio + self.hole_fraction / HOLE_TOLERANCE)

    def failing_tiles(self, threshold: float) -> np.ndarray:
        """The fewest tiles to render for real so that what stays synthesized scores ≤ ``threshold``
        (:meth:`score_outside`; bool, tile grid): every tile whose ratio exceeds it, then the tiles with the most
        holes until the holes left fit in what the largest ratio left leaves of the threshold (a few more
        high-ratio tiles are tried to make that room, whichever needs fewer tiles in all). Needs the tile maps
        (a noise map was given)."""
        if self.tile_ratio is None or self.tile_holes is None:
            raise ValueError("failing_tiles needs the per-tile maps of a synthesis with a noise map")
        ratio, holes = self.tile_ratio.ravel(), self.tile_holes.ravel().astype(np.float64)
        total = holes.sum()
        # Holes as a score: a hole pixel is worth 1 / (pixels · HOLE_TOLERANCE).
        hole_unit = self.hole_fraction / total / HOLE_TOLERANCE if total else 0.0
        by_ratio = np.argsort(-ratio, kind="stable")
        k0 = int(np.count_nonzero(ratio > threshold))
        best = None
        for k in range(k0, min(k0 + _EXTRA_RATIO_TILES, ratio.size) + 1):
            chosen = np.zeros(ratio.size, dtype=bool)
            chosen[by_ratio[:k]] = True
            left = float(ratio[by_ratio[k]]) if k < ratio.size else 0.0
            kept_holes = np.where(chosen, 0.0, holes)
            budget = threshold - left
            if budget < 0:
                continue
            order = np.argsort(-kept_holes, kind="stable")
            excess = kept_holes.sum() * hole_unit - budget
            if excess > 0:
                removed = np.cumsum(kept_holes[order]) * hole_unit
                n_more = int(np.searchsorted(removed, excess - 1e-12)) + 1
                chosen[order[:n_more]] = True
            if best is None or chosen.sum() < best.sum():
                best = chosen
        return best.reshape(self.tile_ratio.shape)

    def score_outside(self, rendered: np.ndarray) -> float:
        """:meth:`score` of what is left synthesized once the tiles in ``rendered`` (bool, tile grid) are
        rendered for real."""
        if self.tile_ratio is None or self.tile_holes is None:
            raise ValueError("score_outside needs the per-tile maps of a synthesis with a noise map")
        kept = ~rendered
        ratio = float(self.tile_ratio[kept].max()) if kept.any() else 0.0
        total = int(self.tile_holes.sum())
        holes = self.hole_fraction * float(self.tile_holes[kept].sum()) / total if total else 0.0
        return float(ratio + holes / HOLE_TOLERANCE)


class _Prepared:
    """A source with what every warp from it reuses: spline coefficients, finite depth, depth slope."""

    def __init__(self, src: WarpSource):
        self.src = src
        moved = np.asarray(src.rgb, dtype=np.float64)
        #: The source shows directly seen emission: a target warped from it needs its own emission pass.
        self.emits = src.emission is not None and bool(np.any(np.asarray(src.emission) > 0))
        if self.emits:  # only reflected light is warped; the target renders its own emission
            moved = np.maximum(moved - np.asarray(src.emission, dtype=np.float64), 0.0)
        self.coeffs = [spline_filter(moved[..., c], order=SPLINE_ORDER, mode="nearest") for c in range(3)]
        z = np.asarray(src.depth_z, dtype=np.float64)
        self.z = np.where(np.isfinite(z), z, FAR_DEPTH_M)
        gy, gx = np.gradient(self.z)
        self.slope = np.maximum(np.abs(gx), np.abs(gy))
        self.ids = None if src.object_id is None else np.rint(src.object_id).astype(np.int64)


def prepare(src: WarpSource) -> _Prepared:
    """Pre-compute what every warp from ``src`` reuses (call once per rendered keyframe)."""
    return _Prepared(src)


def _splat(camera: PinholeCamera, p: _Prepared, to_camera, to_objects) -> tuple[np.ndarray, np.ndarray]:
    """Forward-splat source ``p``'s depth (and ids) into the target: [H·W] depth (inf: nothing landed), ids."""
    src = p.src
    points = unproject(camera, p.z, src.camera_to_world)
    points = move_points(points, p.ids, list(src.object_poses), list(to_objects))
    col, row, z = project(camera, points, to_camera)
    ci, ri = np.rint(col), np.rint(row)
    ok = np.isfinite(ci) & np.isfinite(ri) & (z > 0)
    ok &= (ci >= 0) & (ci < camera.width) & (ri >= 0) & (ri < camera.height)
    idx = (ri[ok] * camera.width + ci[ok]).astype(np.int64)
    zs = z[ok]
    zbuf = np.full(camera.width * camera.height, np.inf)
    np.minimum.at(zbuf, idx, zs)
    ids = np.zeros(camera.width * camera.height, dtype=np.int64)
    if p.ids is not None:
        win = zs <= zbuf[idx]
        ids[idx[win]] = p.ids[ok][win]
    return zbuf, ids


def target_geometry(camera: PinholeCamera, sources: list[_Prepared], to_camera, to_objects
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth (m, FAR_DEPTH_M for sky), object ids and a 'covered' mask of the target, by z-buffer splatting."""
    zbuf = np.full(camera.width * camera.height, np.inf)
    ids = np.zeros(camera.width * camera.height, dtype=np.int64)
    for p in sources:
        z, i = _splat(camera, p, to_camera, to_objects)
        nearer = z < zbuf
        zbuf = np.where(nearer, z, zbuf)
        ids = np.where(nearer, i, ids)
    zbuf = zbuf.reshape(camera.height, camera.width)
    ids = ids.reshape(camera.height, camera.width)
    covered = np.isfinite(zbuf)
    for _ in range(HOLE_FILL_ROUNDS):
        holes = ~np.isfinite(zbuf)
        if not holes.any():
            break
        filled = maximum_filter(np.where(np.isfinite(zbuf), zbuf, -np.inf), size=3, mode="nearest")
        # The farthest neighbour's id goes with its depth: take it from the neighbour that holds that depth.
        idfill = _id_of_value(zbuf, ids, filled)
        ok = holes & np.isfinite(filled)
        zbuf = np.where(ok, filled, zbuf)
        ids = np.where(ok, idfill, ids)
    return zbuf, ids, covered


def _given_geometry(camera: PinholeCamera, depth_z, object_id) -> tuple[np.ndarray, np.ndarray]:
    """A rendered target geometry as :func:`target_geometry` gives it: depth (m, inf: no hit) and int ids."""
    z = np.asarray(depth_z, dtype=np.float64)
    if z.shape != (camera.height, camera.width):
        raise ValueError(f"target depth must be {(camera.height, camera.width)}, got {z.shape}")
    z = np.where(np.isfinite(z), z, np.inf)
    ids = (np.zeros(z.shape, dtype=np.int64) if object_id is None
           else np.rint(np.asarray(object_id)).astype(np.int64))
    return z, ids


def _id_of_value(z: np.ndarray, ids: np.ndarray, target: np.ndarray) -> np.ndarray:
    """For each pixel, the id of a 3×3 neighbour whose depth equals ``target`` (0 if none)."""
    out = np.zeros_like(ids)
    zp = np.pad(z, 1, mode="edge")
    ip = np.pad(ids, 1, mode="edge")
    h, w = z.shape
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            zn = zp[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
            out = np.where((zn == target) & (out == 0), ip[1 + dy:1 + dy + h, 1 + dx:1 + dx + w], out)
    return out


def _backward(camera: PinholeCamera, p: _Prepared, target_points: np.ndarray, target_ids: np.ndarray,
              to_objects) -> tuple[np.ndarray, np.ndarray]:
    """Sample source ``p`` at the target's surface points: rgb [H, W, 3] and the consistency mask [H, W]."""
    src = p.src
    points = move_points(target_points, target_ids if p.ids is not None else None, list(to_objects),
                         list(src.object_poses))
    col, row, z = project(camera, points, src.camera_to_world)
    h, w = camera.height, camera.width
    inside = np.isfinite(col) & np.isfinite(row) & (col >= -0.5) & (col <= w - 0.5) & (row >= -0.5) & (row <= h - 0.5)
    col = np.where(inside, col, 0.0)
    row = np.where(inside, row, 0.0)
    ci = np.clip(np.rint(col).astype(np.int64), 0, w - 1)
    ri = np.clip(np.rint(row).astype(np.int64), 0, h - 1)
    zs = p.z[ri, ci]
    tol = DEPTH_TOLERANCE * z + 1.5 * p.slope[ri, ci]
    valid = inside & (np.abs(z - zs) <= tol)
    if p.ids is not None:
        valid &= p.ids[ri, ci] == target_ids
    coords = np.stack([row, col])
    rgb = np.stack([map_coordinates(c, coords, order=SPLINE_ORDER, mode="nearest", prefilter=False)
                    for c in p.coeffs], axis=-1)
    return np.maximum(rgb, 0.0), valid


def _same_pose(src: WarpSource, to_camera, to_objects) -> bool:
    return (np.array_equal(src.camera_to_world, to_camera) and len(src.object_poses) == len(to_objects)
            and all(np.array_equal(m, n) for m, n in zip(src.object_poses, to_objects)))


def _tile_sums(a: np.ndarray) -> np.ndarray:
    """Sum of ``a`` [H, W] over :data:`TILE_PX`-pixel tiles (the last row and column of tiles may be partial)."""
    h, w = a.shape
    th, tw = -(-h // TILE_PX), -(-w // TILE_PX)
    pad = ((0, th * TILE_PX - h), (0, tw * TILE_PX - w))
    return np.pad(a, pad).reshape(th, TILE_PX, tw, TILE_PX).sum(axis=(1, 3))


def _tile_noise_ratios(diff: np.ndarray, both: np.ndarray, noise_y: np.ndarray) -> np.ndarray:
    """Per tile: RMS of ``diff`` (where ``both``) over √2 × the tile RMS of ``noise_y`` (floored); 0 where fewer
    than a quarter of the tile's pixels are in ``both``."""
    n = _tile_sums(both.astype(np.float64))
    sq = _tile_sums(np.where(both, diff.astype(np.float64) ** 2, 0.0))
    noise2 = _tile_sums(np.asarray(noise_y, dtype=np.float64) ** 2) / _tile_sums(np.ones(diff.shape))
    floor2 = (TILE_NOISE_FLOOR ** 2) * float(np.mean(np.asarray(noise_y, dtype=np.float64) ** 2))
    enough = n >= TILE_PX * TILE_PX / 4
    ratio = np.zeros(n.shape)
    if floor2 > 0:
        ratio[enough] = np.sqrt(sq[enough] / n[enough] / (2.0 * np.maximum(noise2[enough], floor2)))
    return ratio


def _no_disagreement(camera: PinholeCamera, with_noise: bool) -> Disagreement:
    """The disagreement of a target that is a rendered keyframe itself."""
    if not with_noise:
        return Disagreement(0.0, 0.0, 0.0)
    grid = (-(-camera.height // TILE_PX), -(-camera.width // TILE_PX))
    return Disagreement(0.0, 0.0, 0.0, 0.0, np.zeros(grid), np.zeros(grid, dtype=np.int64))


def synthesize(camera: PinholeCamera, a: _Prepared, b: _Prepared, weight_b: float, to_camera: np.ndarray,
               to_objects=(), noise_y: np.ndarray | None = None, geometry: tuple | None = None,
               emission: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, Disagreement]:
    """The keyframe at pose ``to_camera`` between rendered keyframes ``a`` and ``b``.

    Parameters
    ----------
    camera : PinholeCamera
    a, b : prepared sources (:func:`prepare`)
        The rendered keyframes before and after the target.
    weight_b : float
        Blend weight of ``b`` in [0, 1]: (t − t_a) / (t_b − t_a).
    to_camera : ndarray (4, 4)
        Camera-to-world at the target instant.
    to_objects : sequence of ndarray (4, 4)
        ``object_to_world`` of each animated object at the target instant (as in :class:`WarpSource`).
    noise_y : ndarray [H, W], optional
        Monte Carlo noise (σ of luminance, absolute) of one render, per pixel: scales the disagreement
        (:attr:`Disagreement.noise_ratio`).
    geometry : (depth_z, object_id), optional
        The target's own depth (m, inf: no hit) and object ids (or None), rendered by a geometry pass
        (:meth:`simspad.render.mitsuba_scene.MitsubaScene.render_depth_ids`). Used instead of the forward splat
        (step 1), whose nearest-pixel rounding misplaces silhouette pixels by a pixel (on the fan's blades those
        flicker into events); they are returned as the keyframe's depth and ids.
    emission : ndarray [H, W, 3], optional
        The target's directly visible emission from its own emission pass. Only reflected light is warped and
        blended (each source's ``rgb`` less its :attr:`WarpSource.emission`; a source without one shows none), and
        this is added: emitters seen directly (a bright textured window, a screen) are exact rather than
        resampled, and their antialiasing noise stays where the renderer puts it. ``noise_y`` is then the
        reflected light's noise. Required when a source shows emission; it may be left out when neither does
        (the warp is then the same as without the layer).

    Returns
    -------
    rgb : ndarray [H, W, 3] float32
    depth_z : ndarray [H, W] float32 (inf: no hit)
    object_id : ndarray [H, W] float32 or None (None when the sources carry none)
    disagreement : Disagreement
    """
    for p, at in ((a, weight_b == 0.0), (b, weight_b == 1.0)):
        if at and _same_pose(p.src, to_camera, to_objects):  # the target is that rendered keyframe
            ids = None if p.src.object_id is None else np.asarray(p.src.object_id, dtype=np.float32).copy()
            return (np.asarray(p.src.rgb, dtype=np.float32).copy(), np.asarray(p.src.depth_z, np.float32).copy(),
                    ids, _no_disagreement(camera, noise_y is not None))
    if emission is None and (a.emits or b.emits):
        raise ValueError("sources that show directly seen emission need the target's emission pass")
    if geometry is None:
        z, ids, _ = target_geometry(camera, [a, b], to_camera, to_objects)
    else:
        z, ids = _given_geometry(camera, *geometry)
    finite = np.isfinite(z)
    z_far = np.where(finite, z, FAR_DEPTH_M)
    points = unproject(camera, z_far, to_camera)
    rgb_a, va = _backward(camera, a, points, ids, to_objects)
    rgb_b, vb = _backward(camera, b, points, ids, to_objects)
    wa = (1.0 - weight_b) * va
    wb = weight_b * vb
    total = wa + wb
    hole = ~(va | vb)
    # Holes (neither source consistent) fall back to the plain time blend of both samples; they are counted.
    wa = np.where(hole, 1.0 - weight_b, np.where(total > 0, wa, np.where(va, 1.0, 0.0)))
    wb = np.where(hole, weight_b, np.where(total > 0, wb, np.where(vb, 1.0, 0.0)))
    norm = wa + wb
    rgb = (rgb_a * wa[..., None] + rgb_b * wb[..., None]) / norm[..., None]
    both = va & vb
    ya, yb = luminance_from_rgb(rgb_a), luminance_from_rgb(rgb_b)
    if emission is not None:
        rgb = rgb + np.asarray(emission, dtype=np.float64)
    mean_y = float(np.mean(luminance_from_rgb(rgb), dtype=np.float64))
    rel_rms = (float(np.sqrt(np.mean((ya[both] - yb[both]) ** 2, dtype=np.float64))) / mean_y
               if both.any() and mean_y > 0 else 0.0)
    n = float(z.size)
    tiles = None if noise_y is None else _tile_noise_ratios(ya - yb, both, noise_y)
    dis = Disagreement(rel_rms=rel_rms, hole_fraction=float(hole.sum()) / n,
                       single_fraction=float((va ^ vb).sum()) / n,
                       noise_ratio=float("nan") if tiles is None else float(tiles.max()), tile_ratio=tiles,
                       tile_holes=None if tiles is None else _tile_sums(hole.astype(np.int64)))
    depth = np.where(z_far >= 0.5 * FAR_DEPTH_M, np.inf, z_far).astype(np.float32)
    has_ids = a.ids is not None or b.ids is not None
    return (rgb.astype(np.float32), depth, ids.astype(np.float32) if has_ids else None, dis)
