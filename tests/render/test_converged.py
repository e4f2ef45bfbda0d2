"""Converged radiance (``convergence = "cache"``, :mod:`simspad.render.converged`): the irradiance cache's
lookup, the settings, and real renders at tiny size against a brute-force path-traced reference."""

from __future__ import annotations

import json

import numpy as np
import pytest

from simspad.errors import SimSpadError
from simspad.io.exr import read_exr
from simspad.render.converged import IrradianceCache, normal_bin, probe_indices
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.render.warp.rendering import noise_map


def _plane_samples(cell_m: float):
    """Points on the plane z = 0 (normal +z) on a fine grid, with Q linear in x: Q = (x, 2x, 3x) + 1."""
    centres = (np.arange(200) + 0.5) / 200  # evenly inside every cell, so a cell's mean sits at its centre
    xs, ys = np.meshgrid(centres, centres)
    p = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    n = np.tile([0.0, 0.0, 1.0], (p.shape[0], 1))
    q = 1.0 + p[:, :1] * np.array([1.0, 2.0, 3.0])
    return IrradianceCache.from_samples(cell_m, p, n, np.zeros(p.shape[0], dtype=np.int64), q, np.ones(p.shape[0]))


def test_lookup_interpolates_between_cells_and_keeps_surfaces_apart():
    cache = _plane_samples(0.1)
    p = np.array([[0.43, 0.5, 0.0], [0.57, 0.21, 0.0]])
    n = np.tile([0.0, 0.0, 1.0], (2, 1))
    q, found = cache.lookup(p, n, np.zeros(2, dtype=np.int64))
    assert found.all()
    # Trilinear interpolation of cell means reproduces a field linear in x (cells' means sit at their centres).
    np.testing.assert_allclose(q, 1.0 + p[:, :1] * np.array([1.0, 2.0, 3.0]), rtol=1e-6)
    # The other side of the surface (normal −z), another object, or a point far from every cell: not found.
    _, other_side = cache.lookup(p, -n, np.zeros(2, dtype=np.int64))
    _, other_object = cache.lookup(p, n, np.ones(2, dtype=np.int64))
    _, far = cache.lookup(p + [0.0, 0.0, 50.0], n, np.zeros(2, dtype=np.int64))
    assert not other_side.any() and not other_object.any() and not far.any()


def test_lookup_falls_back_to_coarser_cells():
    cache = _plane_samples(0.01)
    # 0.05 m above the plane: no finest cell (0.01 m) there, but the 4× and 16× levels reach it.
    q, found = cache.lookup(np.array([[0.5, 0.5, 0.05]]), np.array([[0.0, 0.0, 1.0]]), np.zeros(1, dtype=np.int64))
    assert found.all() and 1.2 < q[0, 0] < 1.8


def test_normal_bins_and_probe_indices():
    assert normal_bin(np.array([[0.1, 0.9, 0.0], [0.0, -0.2, -0.9], [-1.0, 0.0, 0.0]])).tolist() == [2, 5, 1]
    assert probe_indices(10, 4) == [0, 3, 6, 9]
    assert probe_indices(2, 4) == [0, 1]


@pytest.mark.parametrize("field, value", [("convergence", "denoise"), ("cache_samples", 0),
                                          ("cache_cell_px", 0.0), ("cache_probes", 0), ("cache_width_px", 4),
                                          ("cache_width_px", 128.0)])
def test_bad_convergence_settings_are_refused(field, value):
    with pytest.raises(SimSpadError) as err:
        RenderSettings(duration_s=0.01, **{field: value}).checked_size()
    assert err.value.field == field


def test_convergence_works_with_either_interpolation():
    for interpolation in ("linear", "warp"):
        assert RenderSettings(duration_s=0.01, resolution=(16, 12), convergence="cache",
                              interpolation=interpolation).checked_size() == (16, 12)


def _luminance_frames(out):
    timeline = json.loads((out / "timeline.json").read_text())
    frames = [read_exr(out / k["file"])["rgb"].astype(np.float64) for k in timeline["keyframes"]]
    return timeline, np.stack([f @ np.array([0.2126, 0.7152, 0.0722]) for f in frames])


@pytest.mark.slow
def test_converged_office_is_closer_to_the_reference_than_brute_force(tmp_path):
    """The office at 24×18 px (its dim, window-lit room is the noisiest built-in scene): a converged render at
    16 camera rays per pixel is within 12 % (median per pixel; its 1-px cells are 11 cm wide at this size, and
    the reference's own noise is a few %) of a 1024-spp path-traced reference, where the path tracer at 16 spp is
    more than 2.5× further off (measured: 9.6 % against 27.9 %); its settings are recorded, its cache kept, and it renders the same
    pixels again."""
    base = RenderSettings(duration_s=0.001, resolution=(24, 18), spp=16)
    ref_tl, ref = _luminance_frames(_render(tmp_path / "ref", RenderSettings(duration_s=0.001, resolution=(24, 18),
                                                                               spp=1024)))
    bf_tl, bf = _luminance_frames(_render(tmp_path / "bf16", base))
    cv_settings = RenderSettings(duration_s=0.001, resolution=(24, 18), spp=16, convergence="cache",
                                 cache_samples=256)
    out = _render(tmp_path / "cache", cv_settings)
    cv_tl, cv = _luminance_frames(out)
    ok = ref > 0
    err_cv = np.median(np.abs(cv[ok] - ref[ok]) / ref[ok])
    err_bf = np.median(np.abs(bf[ok] - ref[ok]) / ref[ok])
    assert err_cv < 0.12 and err_bf > 2.5 * err_cv, (err_cv, err_bf)

    # Recorded: the mode and its knobs; the cache file it names is there; other names than a path-traced render.
    conv = cv_tl["renderer"]["convergence"]
    assert conv["mode"] == "cache" and conv["cache_samples"] == 256 and (out / conv["cache_file"]).is_file()
    assert "convergence" not in bf_tl["renderer"]
    assert {k["file"] for k in cv_tl["keyframes"]}.isdisjoint({k["file"] for k in bf_tl["keyframes"]})
    # Deterministic: a second render (cache rebuilt in a fresh directory) gives the same pixels.
    _, again = _luminance_frames(_render(tmp_path / "again", cv_settings))
    np.testing.assert_array_equal(again, cv)


@pytest.mark.slow
def test_converged_warp_render_synthesizes_from_converged_keyframes(tmp_path):
    """Warp with the cache: the anchors and the noise probe are cache renders (the warps are judged against the
    cache's noise), keyframes between are synthesized, and the whole timeline stays as close to a 1024-spp
    path-traced reference of the same keyframes as the all-rendered converged timeline."""
    common = dict(duration_s=0.006, resolution=(24, 18), warp_stride=2)
    _, ref = _luminance_frames(_render(tmp_path / "ref", RenderSettings(**common, spp=1024)))
    lin_tl, lin = _luminance_frames(_render(tmp_path / "lin", RenderSettings(**common, spp=16, convergence="cache",
                                                                                 cache_samples=256)))
    out = _render(tmp_path / "warp", RenderSettings(**common, spp=16, convergence="cache", cache_samples=256,
                                                    interpolation="warp"))
    warp_tl, warp = _luminance_frames(out)
    sources = [k["source"] for k in warp_tl["keyframes"]]
    assert warp_tl["schedule"]["interpolation"] == "warp" and "warp" in sources and sources[0] == "render"
    assert warp_tl["schedule"]["warp"]["emission_layer"] is False  # the emission pass is path-traced: not mixed in
    # Rendered keyframes are the linear converged render's own files (same names, same pixels).
    lin_files = [k["file"] for k in lin_tl["keyframes"]]
    for i, kf in enumerate(warp_tl["keyframes"]):
        if kf["source"] == "render":
            assert kf["file"] == lin_files[i]
            np.testing.assert_array_equal(warp[i], lin[i])
    # The warps were judged against the render's own noise probe, which for a converged render is keyframe 0 from
    # the same cache with the next seed (the noise that changes between keyframes); its budget also states the
    # cache's noise apart.
    key0 = read_exr(out / warp_tl["keyframes"][0]["file"])["rgb"]
    _, probe_noise = noise_map(key0, read_exr(out / warp_tl["render_noise"]["probe_file"])["rgb"])
    judged = warp_tl["schedule"]["warp"]["render_noise"]
    assert 0 < judged and judged == pytest.approx(probe_noise, rel=1e-9), (judged, probe_noise)
    assert warp_tl["render_noise"]["cache_relative_noise_median"] > 0
    ok = ref > 0
    err_warp = np.median(np.abs(warp[ok] - ref[ok]) / ref[ok])
    err_lin = np.median(np.abs(lin[ok] - ref[ok]) / ref[ok])
    assert err_warp < 0.12 and err_warp < 1.2 * err_lin, (err_warp, err_lin)


def _render(out, settings):
    render_sequence("office", None, settings, out_dir=out, progress=False)
    return out


def test_an_empty_cache_finds_nothing():
    empty = IrradianceCache.from_samples(0.1, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64),
                                         np.zeros((0, 3)), np.zeros(0))
    q, found = empty.lookup(np.zeros((2, 3)), np.tile([0.0, 0.0, 1.0], (2, 1)), np.zeros(2, dtype=np.int64))
    assert not found.any() and not q.any()


def test_the_cli_default_is_the_settings_default():
    # The CLI names the number itself (it does not import the renderer's settings to start): keep them one.
    from simspad.cli.app import cli
    from simspad.render.settings import DEFAULT_CACHE_SAMPLES

    option = next(p for p in cli.commands["render"].params if p.name == "cache_samples")
    assert option.default == DEFAULT_CACHE_SAMPLES == RenderSettings(duration_s=0.01).cache_samples


def test_the_open_table_holds_every_cell_where_linear_probing_finds_it():
    cache = _plane_samples(0.01)  # 10 000 cells at the finest level
    keys, values = cache.keys[1], cache.values[1]
    tab_k, tab_v = cache.open_table(1)
    assert tab_k.size >= 4 * keys.size and tab_k.size & (tab_k.size - 1) == 0
    assert np.count_nonzero(tab_k) == keys.size
    mask = np.uint64(tab_k.size - 1)

    def probe(key):
        slot = int(key & mask)
        while tab_k[slot] != 0:
            if tab_k[slot] == key:
                return slot
            slot = (slot + 1) & int(mask)
        return None

    slots = [probe(k) for k in keys]
    assert None not in slots
    np.testing.assert_allclose(tab_v[slots], values, rtol=1e-6)
    absent = np.setdiff1d(np.arange(1, 2000, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15), keys)
    assert all(probe(k) is None for k in absent)
    displaced = np.asarray(slots) != (keys & mask).astype(np.int64)
    assert displaced.any()  # the table has collisions to resolve

    # The kernel's probe (Dr.Jit lanes) finds the same slots, and finds no absent key.
    from simspad.render import converged as cv
    from simspad.render.mitsuba_env import select_variant

    select_variant()
    import drjit as dr  # deferred: after the variant is set
    import mitsuba as mi

    query = np.concatenate([keys, absent])
    slot, found = cv._probe(mi, dr, mi.UInt64(tab_k), tab_k.size - 1, mi.UInt64(query), mi.Bool(True))
    found = np.array(found, dtype=bool)
    assert found[:keys.size].all() and not found[keys.size:].any()
    assert np.array_equal(np.array(slot, dtype=np.int64)[:keys.size], slots)


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["office", "fan"])
def test_the_kernel_lookup_renders_what_the_numpy_lookup_renders(scene, monkeypatch):
    """A keyframe's lookup runs in Dr.Jit at the finest level; the numpy lookup, given every vertex instead, gives
    the same pixels to float32 rounding (the fan: its blades' points in their rest frame)."""
    from simspad.render import converged as cv
    from simspad.render.flow import object_poses
    from simspad.render.renderer import layout_render, load_scene

    loaded = load_scene(scene, None, 32, 24, 16)
    layout = layout_render(scene, None, RenderSettings(duration_s=0.004, resolution=(32, 24), spp=16),
                           loaded=loaded)
    poses = [(np.asarray(layout.camera_to_world[i]), object_poses(loaded.ts, layout.times_s[i]))
             for i in (0, layout.n_keyframes - 1)]
    cr = cv.ConvergedRenderer(loaded.ms, 16)
    cache = cv.build_cache(cr, poses, 0, 8, 2.0)
    camera_to_world, objects = poses[1]
    loaded.ms.set_pose(camera_to_world, objects)
    kernel = cr.render(cache, 3, objects)
    lookup = cv.ConvergedRenderer._lookup_lanes
    monkeypatch.setattr(cv.ConvergedRenderer, "_lookup_lanes",
                        lambda self, *a: (lambda q, ok: (q, ok & False))(*lookup(self, *a)))
    numpy_only = cr.render(cache, 3, objects)
    assert kernel.max() > 0 and np.isfinite(kernel).all()
    np.testing.assert_allclose(kernel, numpy_only, rtol=2e-5, atol=1e-7 * float(numpy_only.max()))


@pytest.mark.slow
def test_a_converged_render_of_moving_objects_compiles_its_kernels_once(tmp_path):
    # The blades' poses, the cache's cell size and its table's size enter the lookup kernel as opaque values: as
    # literals they were baked into it, and every keyframe of the fan compiled it again (6 of 6).
    summary = render_sequence("fan", None, RenderSettings(duration_s=0.004, resolution=(32, 24), spp=16,
                                                          convergence="cache", cache_samples=16),
                              out_dir=tmp_path / "fan", progress=False)
    assert summary.n_rendered >= 4 and summary.compiled_after_first == 0, summary


@pytest.fixture(scope="module")
def office_32x24():
    """The office at 32×24 px, 16 camera rays, and two probe views of its default trajectory: (scene, poses)."""
    from simspad.render.flow import object_poses
    from simspad.render.renderer import layout_render, load_scene

    loaded = load_scene("office", None, 32, 24, 16)
    layout = layout_render("office", None, RenderSettings(duration_s=0.004, resolution=(32, 24), spp=16),
                           loaded=loaded)
    return loaded, [(np.asarray(layout.camera_to_world[i]), object_poses(loaded.ts, layout.times_s[i]))
                    for i in (0, layout.n_keyframes - 1)]


def _office_cache(office, block: int = 1):
    """A small cache of ``office`` (2 probe views, 8 estimates per point, 2-px cells of a probe grid of
    ``block``-px blocks), the scene posed at its last probe view: (renderer, cache, object poses)."""
    from simspad.render import converged as cv

    loaded, poses = office
    cr = cv.ConvergedRenderer(loaded.ms, 16)
    cache = cv.build_cache(cr, poses, 0, 8, 2.0, block)
    loaded.ms.set_pose(*poses[1])
    return cr, cache, poses[1][1]


@pytest.mark.slow
def test_a_keyframe_traced_in_tiles_is_the_whole_keyframe_where_it_draws_the_same_numbers(office_32x24, monkeypatch):
    # Tiles of 4 pixel rows: the first tile draws the whole keyframe's random numbers (its rows are the same, up to
    # the blur's reach into the second tile), the others their own: the same image up to the glossy chains' noise.
    from simspad.render import converged as cv
    from simspad.render.mitsuba_scene import PSF_REACH_PX

    cr, cache, objects = _office_cache(office_32x24)
    whole = cr.render(cache, 3, objects)
    monkeypatch.setattr(cv, "TILE_LANES", 4 * 32 * 16)
    tiled = cr.render(cache, 3, objects)
    assert np.array_equal(tiled[:4 - PSF_REACH_PX], whole[:4 - PSF_REACH_PX])
    assert not np.array_equal(tiled, whole)  # the other tiles drew other numbers
    lum = lambda rgb: rgb @ np.array([0.2126, 0.7152, 0.0722])  # noqa: E731
    rel = np.abs(lum(tiled) - lum(whole)) / lum(whole)
    assert np.median(rel) < 0.01 and abs(lum(tiled).mean() / lum(whole).mean() - 1) < 0.01


def test_the_probe_grid_is_the_image_up_to_its_width_then_blocks():
    from simspad.render.converged import cache_block

    assert [cache_block(w, 128) for w in (16, 80, 128, 191, 256, 512)] == [1, 1, 1, 1, 2, 4]


@pytest.mark.slow
def test_a_coarser_probe_grid_makes_cells_as_wide_in_the_scene_and_the_same_light(office_32x24):
    # Probe rays one per 2×2 pixels: cells twice as wide (the same 2 px of the probe grid), about a quarter of the
    # probe points, and a keyframe lit from it is the one lit from the per-pixel grid's cache, up to the caches' noise.
    _, coarse, _ = _office_cache(office_32x24, block=2)
    cr, fine, objects = _office_cache(office_32x24, block=1)
    assert coarse.cell_m == pytest.approx(2 * fine.cell_m, rel=1e-12)
    assert 0.15 < coarse.counts[1].sum() / fine.counts[1].sum() < 0.35
    lum = lambda rgb: rgb @ np.array([0.2126, 0.7152, 0.0722])  # noqa: E731
    a, b = lum(cr.render(fine, 3, objects)), lum(cr.render(coarse, 3, objects))
    assert abs(b.mean() / a.mean() - 1) < 0.05


@pytest.mark.slow
def test_simspad_render_converges_unless_spp_is_given(tmp_path):
    # `simspad render` with no quality flag: the cache at 64 camera rays; `--spp N` alone: path tracing, the reference.
    from simspad.cli.app import main

    common = ["siemens-star", "--duration", "0.001", "--resolution", "16x12"]
    assert main(["render", *common, "--cache-samples", "16", "--out", str(tmp_path / "c")]) == 0
    assert main(["render", *common, "--spp", "4", "--out", str(tmp_path / "p")]) == 0
    assert main(["render", *common, "--convergence", "off", "--out", str(tmp_path / "o")]) == 0
    renderer = {k: json.loads((tmp_path / k / "timeline.json").read_text())["renderer"] for k in "cpo"}
    assert renderer["c"]["spp"] == 64 and renderer["c"]["convergence"]["mode"] == "cache"
    assert renderer["c"]["convergence"]["cache_width_px"] == 128
    assert renderer["p"]["spp"] == 4 and not renderer["p"].get("convergence")
    assert renderer["o"]["spp"] == 16 and not renderer["o"].get("convergence")


def test_the_default_camera_rays_fall_from_256_px_wide():
    from simspad.defaults import camera_rays

    assert [camera_rays(w) for w in (16, 128, 255, 256, 512)] == [64, 64, 64, 16, 16]
