"""``simspad import``: a synthetic recording exported to capture formats (EVT 3.0, DSEC, structured .npy, packed
photon cubes, TIFF/PNG frames), imported back with a calibration file, must give the same recording; every
method's reconstructions on the import equal those on the original. Event streams written by outside encoders
(faery's EVT 3.0 writer, dv-processing's AEDAT 4 writer) are decoded against what was written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import hdf5plugin  # noqa: F401  (reconstructions are Zstandard-compressed)
import numpy as np
import pytest

from simspad.captures.build import import_captures
from simspad.errors import InputError
from simspad.io.export.dispatch import export_recording
from simspad.io.recording import open_recording
from simspad.methods.registry import available_methods, get_method
from tests.helpers.synthetic_recordings import EVENT_ATTRS, FRAME_ATTRS, SPAD_ATTRS, write_recording

H, W = 12, 16
DURATION_S = 0.02
COMPARED = ("spad/bits", "spad/t_start", "spad/dcr_cps", "frames/dn", "frames/t_start", "frames/t_end",
            "events/t", "events/x", "events/y", "events/p", "events/ms_to_idx")


def flux(t):
    yy, xx = np.mgrid[0:H, 0:W]
    return 1e11 * (1.5 + np.sin(0.6 * xx + 300 * t) * np.cos(0.4 * yy))


def _table(name: str, values: dict) -> str:
    return f"[{name}]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in values.items()) + "\n"


SPAD_RESPONSE = {k: SPAD_ATTRS[k] for k in ("pixel_pitch_m", "fill_factor", "qe")}
EVENT_RESPONSE = {k: EVENT_ATTRS[k] for k in ("threshold_on", "threshold_off", "pixel_pitch_m", "fill_factor",
                                               "qe")}


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    """The original recording and its exports: EVT 3.0, DSEC, npz (packed SPAD cube, TIFF stack)."""
    d = tmp_path_factory.mktemp("captures")
    write_recording(d / "orig.h5", flux, shape=(H, W), dcr_cps=5.0, duration_s=DURATION_S)
    export_recording(d / "orig.h5", "evt3", d / "events.raw")
    export_recording(d / "orig.h5", "dsec", d / "events.h5")
    export_recording(d / "orig.h5", "npz", d / "npz", frames_format="tiff")
    export_recording(d / "orig.h5", "npz", d / "npz_png", frames_format="png")
    return d


def _calibration(d: Path, *, events="events.raw", spad="npz/spad.npz", frames="npz/frames/frames.tif",
                 extra_spad=None, extra_events=None, capture=None) -> Path:
    text = _table("capture", {"name": "roundtrip", "lux": 1.0, "t_start_s": 0.0, "duration_s": DURATION_S,
                              **(capture or {})})
    if spad:
        text += _table("spad", {"path": spad, **SPAD_RESPONSE, **(extra_spad or {})})
    if frames:
        text += _table("frames", {"path": frames, "timestamps": "npz/frames/timestamps.csv", **FRAME_ATTRS})
    if events:
        text += _table("events", {"path": events, **EVENT_RESPONSE, **(extra_events or {})})
    path = d / "calibration.toml"
    path.write_text(text)
    return path


def _assert_same(a_path, b_path, names=COMPARED):
    with open_recording(a_path) as a, open_recording(b_path) as b:
        for name in names:
            np.testing.assert_array_equal(a.h5[name][()], b.h5[name][()], err_msg=name)
            assert a.h5[name].dtype == b.h5[name].dtype, name


def test_evt3_npz_tiff_round_trip_is_bit_exact(exported, tmp_path):
    cal = _calibration(exported)
    s = import_captures(cal, tmp_path / "imp.h5", progress=False)
    assert (s.n_bins, s.n_frames, s.n_events_dropped) == (1953, 10, 0)
    _assert_same(exported / "orig.h5", tmp_path / "imp.h5")
    with open_recording(tmp_path / "imp.h5") as rec:
        assert not rec.has("gt") and rec.attrs["ground_truth"] == 0
        assert rec.sensors == ("spad", "frames", "events")
        assert rec.attrs["duration_s"] == DURATION_S and rec.h5["calibration/valid_mask"][()].all()
        rec.events.check_time_order()


def test_dsec_and_png_folder_round_trip(exported, tmp_path):
    cal = _calibration(exported, events="events.h5", frames="npz_png/frames", extra_events={"width": W, "height": H})
    import_captures(cal, tmp_path / "imp.h5", progress=False)
    _assert_same(exported / "orig.h5", tmp_path / "imp.h5")


def test_structured_npy_events_visionsim_cube_and_raw_bin(exported, tmp_path):
    """tonic-style events (p ±1), a visionsim cube (big bit order, packed along the height, transforms.json) and
    a raw .bin with a 4-byte header per frame all give the original bits and events."""
    with open_recording(exported / "orig.h5") as rec:
        ev = rec.events.by_index(0, rec.events.n_events)
        bits = rec.spad.bits(0, rec.spad.n_bins)
    arr = np.zeros(ev["t"].size, dtype=[("x", "<i2"), ("y", "<i2"), ("t", "<i8"), ("p", "<i1")])
    arr["x"], arr["y"], arr["t"], arr["p"] = ev["x"], ev["y"], ev["t"], np.where(ev["p"] > 0, 1, -1)
    np.save(tmp_path / "events.npy", arr)
    vs = tmp_path / "visionsim"
    vs.mkdir()
    np.save(vs / "cube.npy", np.packbits(bits, axis=1)[..., None])  # [N, ceil(H/8), W, 1], big bit order
    (vs / "transforms.json").write_text(json.dumps({"bitpack": True, "bitpack_dim": 1, "w": W, "h": H, "c": 1}))
    shutil.copy(exported / "npz" / "spad.npz", tmp_path / "spad.npz")
    with np.load(tmp_path / "spad.npz") as z:
        np.save(tmp_path / "dcr.npy", z["dcr_cps"])
    spad_common = {"bin_s": SPAD_ATTRS["bin_s"], "dcr_map": "dcr.npy"}
    (tmp_path / "npz").mkdir()
    shutil.copytree(exported / "npz" / "frames", tmp_path / "npz" / "frames")
    cal = _calibration(tmp_path, events="events.npy", spad="visionsim/cube.npy", extra_spad=spad_common,
                       extra_events={"width": W, "height": H})
    import_captures(cal, tmp_path / "a.h5", progress=False)
    _assert_same(exported / "orig.h5", tmp_path / "a.h5")

    packed = np.packbits(bits, axis=2, bitorder="little")
    frames = np.concatenate([np.full((packed.shape[0], 4), 0xAB, np.uint8), packed.reshape(packed.shape[0], -1)],
                            axis=1)
    frames.tofile(tmp_path / "stream.bin")
    cal = _calibration(tmp_path, events="events.npy", spad="stream.bin",
                       extra_spad={**spad_common, "width": W, "height": H, "frame_header_bytes": 4},
                       extra_events={"width": W, "height": H})
    import_captures(cal, tmp_path / "b.h5", progress=False)
    _assert_same(exported / "orig.h5", tmp_path / "b.h5", ("spad/bits", "spad/t_start", "events/t", "events/x"))


def test_dark_capture_gives_the_ml_dark_count_rate(exported, tmp_path):
    """k ones in n gates of a dark capture: DCR = −ln(1 − k/n)/gate_s, per pixel."""
    rng = np.random.default_rng(3)
    n, gate = 4000, SPAD_ATTRS["bin_s"]
    rate = np.linspace(100.0, 5000.0, H * W).reshape(H, W)
    dark = (rng.random((n, H, W)) < -np.expm1(-rate * gate)).astype(np.uint8)
    np.save(tmp_path / "dark.npy", np.packbits(dark, axis=2, bitorder="little"))
    shutil.copytree(exported / "npz", tmp_path / "npz")
    cal = _calibration(tmp_path, events=None, frames=None,
                       extra_spad={"dark_capture": "dark.npy", "bin_s": gate, "bit_order": "little"},
                       spad="npz/spad.npz")
    import_captures(cal, tmp_path / "imp.h5", progress=False)
    with open_recording(tmp_path / "imp.h5") as rec:
        dcr = rec.spad.dcr_cps
    k = dark.sum(axis=0, dtype=np.int64)
    np.testing.assert_allclose(dcr, -np.log1p(-k / n) / gate, rtol=1e-6)
    assert np.corrcoef(dcr.ravel(), rate.ravel())[0, 1] > 0.95


def test_homography_moves_events_and_resamples_bits_and_frames(exported, tmp_path):
    """A translation by (+2, +1) px onto a grid of the same size: data shift, the uncovered band is invalid."""
    hom = [[1, 0, 2], [0, 1, 1], [0, 0, 1]]
    shutil.copytree(exported / "npz", tmp_path / "npz")
    shutil.copy(exported / "events.raw", tmp_path / "events.raw")
    text = _calibration(tmp_path).read_text()
    for table in ("spad", "frames", "events"):
        text = text.replace(f"[{table}]\n", f"[{table}]\nhomography = {hom}\n")
    (tmp_path / "calibration.toml").write_text(text)
    s = import_captures(tmp_path / "calibration.toml", tmp_path / "imp.h5", progress=False)
    with open_recording(exported / "orig.h5") as a, open_recording(tmp_path / "imp.h5") as b:
        valid = b.h5["calibration/valid_mask"][()].astype(bool)
        assert not valid[:1].any() and not valid[:, :2].any() and valid[1:, 2:].all()
        assert s.valid_fraction == pytest.approx(valid.mean())
        np.testing.assert_array_equal(b.spad.bits(0, 50)[:, 1:, 2:], a.spad.bits(0, 50)[:, :-1, :-2])
        assert not b.spad.bits(0, 50)[:, ~valid].any()
        np.testing.assert_array_equal(b.frames.dn()[:, 1:, 2:], a.frames.dn()[:, :-1, :-2])
        ea, eb = a.events.by_index(0, a.events.n_events), b.events.by_index(0, b.events.n_events)
        kept = (ea["x"] + 2 < W) & (ea["y"] + 1 < H)
        np.testing.assert_array_equal(eb["x"], ea["x"][kept] + 2)
        np.testing.assert_array_equal(eb["y"], ea["y"][kept] + 1)
        np.testing.assert_array_equal(eb["t"], ea["t"][kept])
        assert s.n_events_dropped == int((~kept).sum()) > 0


def test_time_offsets_shift_every_sensor_onto_the_common_clock(exported, tmp_path):
    """Events 3 ms late on their own clock (time_offset_s = −3 ms) land where they were."""
    with open_recording(exported / "orig.h5") as rec:
        ev = rec.events.by_index(0, rec.events.n_events)
    arr = np.zeros(ev["t"].size, dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("p", "u1")])
    arr["x"], arr["y"], arr["t"], arr["p"] = ev["x"], ev["y"], ev["t"] + 3000, ev["p"]
    np.save(tmp_path / "late.npy", arr)
    shutil.copytree(exported / "npz", tmp_path / "npz")
    cal = _calibration(tmp_path, events="late.npy", extra_events={"width": W, "height": H, "time_offset_s": -3e-3})
    import_captures(cal, tmp_path / "imp.h5", progress=False)
    _assert_same(exported / "orig.h5", tmp_path / "imp.h5", ("events/t", "events/x", "events/ms_to_idx"))


def test_every_methods_reconstructions_on_the_import_equal_the_originals(exported, tmp_path):
    """The imported recording is bit-identical, so each method (run through the registry, as evaluate does)
    reconstructs the same frames at the same instants; tolerance 0."""
    import_captures(_calibration(exported), tmp_path / "imp.h5", progress=False)
    times = np.arange(2, 19) * 1e-3
    with open_recording(exported / "orig.h5") as a, open_recording(tmp_path / "imp.h5") as b:
        names = available_methods(b)
        assert set(names) == set(available_methods(a)) and len(names) >= 7
        for name in names:
            if name == "qbp":
                continue  # 30 s of numba compilation; covered by the evaluate test below (slow)
            ra = np.stack(list(get_method(name).reconstruct(a, times)))
            rb = np.stack(list(get_method(name).reconstruct(b, times)))
            np.testing.assert_array_equal(ra, rb, err_msg=name)


@pytest.mark.slow
def test_evaluate_without_ground_truth_equals_the_original_reconstructions(exported, tmp_path, simspad_cli):
    """``simspad import`` then ``simspad evaluate`` (child processes): every method runs, scores are NaN with a
    note (never 0), reconstructions equal the original recording's at the same instants, previews exist."""
    cal = _calibration(exported, capture={"rate_hz": 500.0})
    r = simspad_cli.run("import", cal, "--out", tmp_path / "imp.h5", "--no-progress")
    assert r.returncode == 0, r.stderr
    r = simspad_cli.run("evaluate", tmp_path / "imp.h5", "--out", tmp_path / "res")
    assert r.returncode == 0, r.stderr
    assert "n/a" in r.stdout
    meta = json.loads((tmp_path / "res" / "results.json").read_text())
    assert meta["recordings"][0]["ground_truth"] is False and meta["notes"]
    assert (tmp_path / "res" / meta["recordings"][0]["preview"]).is_file()
    rows = meta["results"]
    assert {row["method"] for row in rows} == {"nedi_akf", "adaptive_nedi_akf", "akf_fe", "cf", "edi", "ni",
                                               "nedi", "qbp"}
    for row in rows:
        assert row["error"] == "" and row["psnr_db"] is None and row["ssim"] is None  # NaN, written as null
        assert row["bandwidth_khz_per_pixel"] > 0 and row["n_frames"] == 10
        assert (tmp_path / "res" / row["image"]).is_file()
    with open_recording(exported / "orig.h5") as orig:
        for row in rows:
            with h5py.File(tmp_path / "res" / "reconstructions" / "roundtrip_1lx" / f"{row['method']}.h5") as f:
                t, saved = f["t"][()], f["flux"][()]
            np.testing.assert_array_equal(t, np.arange(10) / 500.0)
            expected = np.stack(list(get_method(row["method"]).reconstruct(orig, t)))
            np.testing.assert_array_equal(saved, expected.astype(np.float32), err_msg=row["method"])


# -- outside writers -------------------------------------------------------------------------------------------

def test_evt3_written_by_faery_with_vectors_and_wraps_decodes_exactly(tmp_path):
    """faery's EVT 3.0 encoder (VECT_12/VECT_8 words for bursts on one row, 24-bit time wraps over 40 s)."""
    faery = pytest.importorskip("faery")
    from simspad.io.captures.events import read_evt3

    rng = np.random.default_rng(1)
    n = 50_000
    arr = np.zeros(n, dtype=faery.EVENTS_DTYPE)
    arr["t"] = np.sort(rng.integers(1000, 40_000_000, n))
    arr["x"], arr["y"], arr["on"] = rng.integers(0, 640, n), rng.integers(0, 480, n), rng.integers(0, 2, n)
    burst = np.zeros(640, dtype=faery.EVENTS_DTYPE)
    burst["t"], burst["y"], burst["x"], burst["on"] = 20_000_123, 7, np.arange(640), True
    arr = np.sort(np.concatenate([arr, burst]), order="t", kind="stable")
    faery.events_stream_from_array(arr, dimensions=(640, 480)).to_file(tmp_path / "f.raw", version="evt3",
                                                                       zero_t0=False)
    words = np.fromfile(tmp_path / "f.raw", "<u2")
    assert np.isin([0x3, 0x4], words >> 12).all()  # the file does use vector words
    chunks = list(read_evt3(tmp_path / "f.raw", chunk=4097))  # chunk boundaries inside vectors
    got = {k: np.concatenate([c[k] for c in chunks]) for k in ("t", "x", "y", "p")}
    a = np.lexsort((got["p"], got["x"], got["y"], got["t"]))
    b = np.lexsort((arr["on"], arr["x"], arr["y"], arr["t"]))
    np.testing.assert_array_equal(got["t"][a], arr["t"][b].astype(np.int64))
    np.testing.assert_array_equal(got["x"][a], arr["x"][b])
    np.testing.assert_array_equal(got["y"][a], arr["y"][b])
    np.testing.assert_array_equal(got["p"][a], arr["on"][b].astype(np.uint8))
    # the `evt3` package decodes the same file to the same events up to the first 24-bit wrap (it does not count
    # wraps: past 2²⁴ µs its timestamps fold back)
    evt3 = pytest.importorskip("evt3")
    ref = evt3.decode_file(str(tmp_path / "f.raw"))
    n_first = int((got["t"] < (1 << 24)).sum())
    rt, rx, ry, rp = (np.asarray(v)[:n_first].astype(np.int64) for v in (ref.t, ref.x, ref.y, ref.p))
    c = np.lexsort((rp, rx, ry, rt))
    first = a[got["t"][a] < (1 << 24)]
    np.testing.assert_array_equal(rt[c], got["t"][first])
    np.testing.assert_array_equal(rx[c], got["x"][first])
    np.testing.assert_array_equal(ry[c], got["y"][first])
    np.testing.assert_array_equal(rp[c], got["p"][first])


def test_aedat4_written_by_dv_processing_imports_exactly(exported, tmp_path):
    dv = pytest.importorskip("dv_processing")
    rng = np.random.default_rng(5)
    n = 3000
    t = np.sort(rng.integers(0, int(DURATION_S * 1e6), n)).astype(np.int64)
    x, y, p = rng.integers(0, W, n), rng.integers(0, H, n), rng.integers(0, 2, n)
    writer = dv.io.MonoCameraWriter(str(tmp_path / "ev.aedat4"), dv.io.MonoCameraWriter.EventOnlyConfig("DVX",
                                                                                                        (W, H)))
    for i0 in range(0, n, 1000):
        store = dv.EventStore()
        for k in range(i0, min(i0 + 1000, n)):
            store.push_back(int(t[k]), int(x[k]), int(y[k]), bool(p[k]))
        writer.writeEvents(store)
    del writer
    shutil.copytree(exported / "npz", tmp_path / "npz")
    cal = _calibration(tmp_path, events="ev.aedat4")
    s = import_captures(cal, tmp_path / "imp.h5", progress=False)
    assert s.n_events == n
    with open_recording(tmp_path / "imp.h5") as rec:
        ev = rec.events.by_index(0, n)
    np.testing.assert_array_equal(ev["t"], t)
    np.testing.assert_array_equal(ev["x"], x)
    np.testing.assert_array_equal(ev["y"], y)
    np.testing.assert_array_equal(ev["p"], p)


# -- bad input -------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("edit, field", [
    (lambda t: t.replace("[spad]\n", "[spad]\nbin_width = 1\n"), "spad.bin_width"),
    (lambda t: t.replace('"npz/spad.npz"', '"npz/missing.npz"'), "spad.path"),
    (lambda t: t.replace("lux = 1.0", 'lux = "bright"'), "capture.lux"),
    (lambda t: t.replace("[events]\n", "[events]\nhomography = [[1, 0], [0, 1]]\n"), "events.homography"),
    (lambda t: t.replace("[events]\n", "[events]\nwidth = 8\n"), "events.width"),
])
def test_bad_calibration_is_one_line_naming_file_and_field(exported, tmp_path, edit, field):
    shutil.copytree(exported / "npz", tmp_path / "npz")
    shutil.copy(exported / "events.raw", tmp_path / "events.raw")
    cal = _calibration(tmp_path)
    cal.write_text(edit(cal.read_text()))
    with pytest.raises(InputError) as info:
        import_captures(cal, tmp_path / "imp.h5", progress=False)
    assert field in info.value.format() and "\n" not in info.value.format()
    assert not (tmp_path / "imp.h5").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_truncated_bin_and_events_outside_the_sensor_are_refused_by_the_cli(exported, tmp_path, simspad_cli):
    shutil.copytree(exported / "npz", tmp_path / "npz")
    (tmp_path / "stream.bin").write_bytes(bytes(2 * 24 + 5))
    arr = np.zeros(3, dtype=[("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("p", "u1")])
    arr["x"] = [1, 2, W + 3]
    np.save(tmp_path / "ev.npy", arr)
    cal = _calibration(tmp_path, spad="stream.bin", events="ev.npy",
                       extra_spad={"width": W, "height": H, "bin_s": 1e-5, "dcr_cps": 1.0},
                       extra_events={"width": W, "height": H})
    r = simspad_cli.run("import", cal, "--out", tmp_path / "imp.h5")
    assert r.returncode == 2 and "stream.bin" in r.stderr and "spad.width" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "imp.h5").exists()
    (tmp_path / "stream.bin").write_bytes(bytes(2 * 24))
    r = simspad_cli.run("import", cal, "--out", tmp_path / "imp.h5")
    assert r.returncode == 2 and "ev.npy" in r.stderr and "events.x" in r.stderr and "event 2" in r.stderr
    assert not (tmp_path / "imp.h5").exists()


def test_emva_capture_set_measures_the_frame_response(exported, tmp_path):
    """Flat fields at 12 levels up to saturation and a dark stack (K = 0.39 DN/e⁻, σ_d = 2.8 e⁻, 10 500 e⁻ full
    well, black 40 DN, 12 bit) stand in for the gain, noise, full well and black level of the calibration; a
    value the calibration gives wins over the measured one."""
    import tifffile

    rng = np.random.default_rng(11)
    K, sigma_d, full, black = 0.39, 2.8, 10_500.0, 40.0

    def stack(mean_e, n=4):
        e = np.minimum(rng.poisson(mean_e, (n, 48, 48)) + rng.normal(0, sigma_d, (n, 48, 48)), full)
        return np.clip(np.rint(K * e + black), 0, 4095).astype(np.uint16)

    def write(path, frames):
        with tifffile.TiffWriter(path) as tw:
            for f in frames:
                tw.write(f, contiguous=True)

    (tmp_path / "emva").mkdir()
    flats = []
    for i, mean_e in enumerate(np.linspace(200, 13_000, 12)):
        write(tmp_path / "emva" / f"flat{i:02d}.tif", stack(mean_e))
        flats.append(f"emva/flat{i:02d}.tif")
    write(tmp_path / "emva" / "dark.tif", stack(0.0, 16))
    shutil.copytree(exported / "npz", tmp_path / "npz")
    cal = _calibration(tmp_path, events=None, spad=None)
    text = cal.read_text()
    for key in ("gain_dn_per_e", "read_noise_e", "full_well_e", "black_level_dn"):
        text = "\n".join(line for line in text.splitlines() if not line.startswith(key + " ")) + "\n"
    text += f"[frames.emva]\nflats = {json.dumps(flats)}\ndark = \"emva/dark.tif\"\n"
    cal.write_text(text)
    import_captures(cal, tmp_path / "imp.h5", progress=False)
    with open_recording(tmp_path / "imp.h5") as rec:
        a = rec.frames.attrs
    assert a["gain_dn_per_e"] == pytest.approx(K, rel=0.03)
    assert a["read_noise_e"] == pytest.approx(sigma_d, rel=0.1)
    assert a["full_well_e"] == pytest.approx(full, rel=0.1)
    assert a["black_level_dn"] == pytest.approx(black, abs=0.5)
    cal.write_text(text.replace("[frames]\n", "[frames]\nread_noise_e = 3.5\n"))
    import_captures(cal, tmp_path / "imp2.h5", progress=False)
    with open_recording(tmp_path / "imp2.h5") as rec:
        assert rec.frames.attrs["read_noise_e"] == 3.5
        assert rec.frames.attrs["gain_dn_per_e"] == pytest.approx(K, rel=0.03)


def test_a_pose_gives_the_plane_induced_homography(exported, tmp_path):
    """K, R, t and a plane at distance d: H = K_ref (R + t nᵀ/d) K⁻¹. A sideways baseline of 2 cm to a plane 1 m
    away at f = 100 px shifts the image by 2 px (the event stream lands as under that shift's homography); a
    rotation alone gives K R K⁻¹, whatever the distance."""
    from simspad.captures.geometry import pose_homography

    K = [[100.0, 0.0, 8.0], [0.0, 100.0, 6.0], [0.0, 0.0, 1.0]]
    shutil.copytree(exported / "npz", tmp_path / "npz")
    shutil.copy(exported / "events.raw", tmp_path / "events.raw")
    cal = _calibration(tmp_path, spad=None, frames=None,
                       extra_events={"intrinsics": K, "rotation": np.eye(3).tolist(), "translation_m": [0.02, 0, 0],
                                     "plane_distance_m": 1.0})
    cal.write_text(cal.read_text() + _table("reference", {"width": W, "height": H, "intrinsics": K}))
    import_captures(cal, tmp_path / "pose.h5", progress=False)
    shifted = _calibration(tmp_path, spad=None, frames=None,
                           extra_events={"homography": [[1, 0, 2], [0, 1, 0], [0, 0, 1]]})
    import_captures(shifted, tmp_path / "hom.h5", progress=False)
    _assert_same(tmp_path / "hom.h5", tmp_path / "pose.h5", ("events/t", "events/x", "events/y", "events/p"))
    with open_recording(tmp_path / "pose.h5") as rec:
        np.testing.assert_allclose(rec.h5["calibration/homography_events"][()], [[1, 0, 2], [0, 1, 0], [0, 0, 1]],
                                   atol=1e-12)
    c, s_ = np.cos(0.1), np.sin(0.1)
    R = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
    Km = np.array(K)
    expected = Km @ R @ np.linalg.inv(Km)
    np.testing.assert_allclose(pose_homography(Km, R, np.zeros(3), 5.0, Km), expected / expected[2, 2], atol=1e-12)


def test_a_pose_without_reference_intrinsics_or_with_a_homography_is_refused(exported, tmp_path):
    shutil.copytree(exported / "npz", tmp_path / "npz")
    shutil.copy(exported / "events.raw", tmp_path / "events.raw")
    pose = {"intrinsics": np.eye(3).tolist(), "rotation": np.eye(3).tolist(), "translation_m": [0, 0, 0],
            "plane_distance_m": 1.0}
    cal = _calibration(tmp_path, spad=None, frames=None, extra_events=pose)
    with pytest.raises(InputError, match="reference.intrinsics"):
        import_captures(cal, tmp_path / "a.h5", progress=False)
    cal = _calibration(tmp_path, spad=None, frames=None, extra_events={**pose, "homography": np.eye(3).tolist()})
    with pytest.raises(InputError, match="events.intrinsics: give either a homography or a pose"):
        import_captures(cal, tmp_path / "a.h5", progress=False)
    bad = {**pose, "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}
    cal = _calibration(tmp_path, spad=None, frames=None, extra_events=bad)
    with pytest.raises(InputError, match="events.rotation: not a rotation"):
        import_captures(cal, tmp_path / "a.h5", progress=False)


def test_aedat4_without_dv_processing_says_what_to_install(exported, tmp_path, monkeypatch):
    import sys

    from simspad.errors import SimSpadError

    monkeypatch.setitem(sys.modules, "dv_processing", None)  # import fails as when the package is absent
    (tmp_path / "ev.aedat4").write_bytes(b"#!AER-DAT4.0\r\n")
    cal = _calibration(tmp_path, spad=None, frames=None, events="ev.aedat4")
    with pytest.raises(SimSpadError, match=r"ev\.aedat4: events\.format: reading AEDAT 4 needs the dv-processing"):
        import_captures(cal, tmp_path / "a.h5", progress=False)
    assert not (tmp_path / "a.h5").exists()


def test_a_damaged_aedat4_file_is_one_line(exported, tmp_path):
    pytest.importorskip("dv_processing")
    (tmp_path / "ev.aedat4").write_bytes(b"garbage")
    cal = _calibration(tmp_path, spad=None, frames=None, events="ev.aedat4", extra_events={"width": W, "height": H})
    with pytest.raises(InputError) as info:
        import_captures(cal, tmp_path / "a.h5", progress=False)
    msg = info.value.format()
    assert "ev.aedat4: events.path: not a readable AEDAT 4 file" in msg and "\n" not in msg


@pytest.mark.slow
def test_a_folder_of_simulated_and_real_recordings_evaluates_and_ranks_both(exported, tmp_path):
    """One folder: the simulated recording (scored against its ground truth) and its import (no ground truth,
    a star region declared). Evaluate and leaderboard keep them apart: PSNR for the first, NaN — not 0 — for the
    second, which the real-data section lists alone."""
    from simspad.cli import main
    from simspad.io.results_dir import read_csv

    (tmp_path / "data").mkdir()
    shutil.copy(exported / "orig.h5", tmp_path / "data" / "sim.h5")
    text = _calibration(exported).read_text() + _table("star", {"center_px": [7.5, 5.5], "radius_px": 5.5,
                                                                "n_cycles": 8})
    (exported / "star_cal.toml").write_text(text)
    import_captures(exported / "star_cal.toml", tmp_path / "data" / "real.h5", progress=False)
    assert main(["evaluate", str(tmp_path / "data"), "--methods", "ni,cf", "--out", str(tmp_path / "res")]) == 0
    rows = {(r["method"], r["recording"]): r for r in read_csv(tmp_path / "res" / "results.csv")}
    for m in ("ni", "cf"):
        sim, real = rows[(m, "sim.h5")], rows[(m, "real.h5")]
        assert np.isfinite(sim["psnr_db"]) and np.isnan(real["psnr_db"]) and np.isnan(real["ssim"])
        assert real["bandwidth_khz_per_pixel"] == pytest.approx(sim["bandwidth_khz_per_pixel"])
        assert np.isfinite(real["mtf_at_0p40_cyc_px"]) and not real["error"]
    assert main(["leaderboard", str(tmp_path / "res"), "--out", str(tmp_path / "board")]) == 0
    md = (tmp_path / "board" / "leaderboard.md").read_text()
    section = md.split("## Real captures (no ground truth)")[1]
    assert "real.h5" in section and "sim.h5" not in section
    assert len([line for line in section.splitlines() if line.startswith("| ") and "Method" not in line]) == 2
    assert "Real captures (no ground truth)" in (tmp_path / "board" / "leaderboard.html").read_text()
