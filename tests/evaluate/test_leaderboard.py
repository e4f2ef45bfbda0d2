"""``simspad evaluate`` end to end on small real recordings, and ``simspad leaderboard`` (escaping, HTML page)."""

import html
import os
import shutil
import subprocess

import h5py
import numpy as np
import pytest
from PIL import Image

import simspad
from simspad.cli import main
from simspad.evaluate import metrics
from simspad.evaluate.recordings import list_recordings
from simspad.io.results_dir import read_csv
from tests.helpers.evaluation_data import write_submission

EVIL = "<script>alert(1)</script>"

pytestmark = pytest.mark.slow  # every test here needs the evaluated dataset (NI and a scored submission)


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory, evaluation_dataset):
    root = tmp_path_factory.mktemp("lb")
    ds = evaluation_dataset
    assert main(["evaluate", str(ds), "--methods", "ni", "--out", str(root / "res_ni")]) == 0
    sub = write_submission(root / "evil.h5", ds, method=EVIL, transform=lambda f: 3.0 * np.roll(f, 1, axis=2) ** 0.8,
                           attrs={"absolute_scale": False, "sensors": "E", "label": EVIL + " (E)"})
    assert main(["score", str(sub), "--dataset", str(ds), "--out", str(root / "res_evil")]) == 0
    return root, ds


def test_evaluate_writes_the_documented_results(evaluated):
    root, ds = evaluated
    res = root / "res_ni"
    rows = read_csv(res / "results.csv")
    assert len(rows) == 2 and all(r["method"] == "ni" and not r["error"] for r in rows)
    for col in ("method", "sensors", "scene", "lux", "psnr_db", "ssim", "bandwidth_khz_per_pixel",
                "bandwidth_bits_per_pixel_s", "absolute_scale", "n_frames"):
        assert col in rows[0]
    r = rows[0]
    assert r["lux"] == 10.0 and r["n_frames"] == 11 and r["absolute_scale"] is True
    # NI aggregates round(1/(400 Hz · 10.24 µs)) = 244 bins: 0.4 kHz readout, ceil(log2(245)) = 8 bits each
    assert r["bandwidth_khz_per_pixel"] == pytest.approx(0.4, rel=0.01)
    assert r["bandwidth_bits_per_pixel_s"] == pytest.approx(3200, rel=0.01)
    assert rows[1]["psnr_db"] > r["psnr_db"] > 12.0  # more light, better; and far above a blank guess
    # the saved reconstructions re-score to the reported mean PSNR
    with h5py.File(res / "reconstructions" / "ramp_10lx" / "ni.h5", "r") as f, \
            h5py.File(ds / r["recording"], "r") as g:
        rec, t = f["flux"][()], f["t"][()]
        gt = g["gt/flux"][::2]
        np.testing.assert_array_equal(t, g["gt/t"][::2])
    white = metrics.white_point(gt)
    again = np.mean([metrics.frame_scores(a, b, white, True)["psnr_db"] for a, b in zip(rec, gt)])
    assert r["psnr_db"] == pytest.approx(again, abs=1e-9)
    frames = read_csv(res / "frames.csv")
    assert len(frames) == 22 and np.mean([f["psnr_db"] for f in frames[:11]]) == pytest.approx(r["psnr_db"])
    assert (res / r["image"]).is_file() and (res / "results.json").is_file()


def test_evaluate_is_deterministic_and_records_failures(evaluated, tmp_path, capsys):
    root, ds = evaluated
    rec = ds / "recordings/ramp/ramp_100lx.h5"
    code = main(["evaluate", str(rec), "--methods", "ni,nedi", "--out", str(tmp_path / "a")])
    err = capsys.readouterr().err
    assert code == 1 and "1 of 2 method runs failed" in err and "Traceback" not in err
    rows = read_csv(tmp_path / "a" / "results.csv")
    assert [r["method"] for r in rows] == ["ni", "nedi"]
    assert "events" in rows[1]["error"] and np.isnan(rows[1]["psnr_db"])
    ref = read_csv(root / "res_ni" / "results.csv")[1]
    assert rows[0]["psnr_db"] == ref["psnr_db"] and rows[0]["ssim"] == ref["ssim"]  # same input, same numbers
    assert main(["evaluate", str(rec), "--methods", "no_such_method", "--out", str(tmp_path / "b")]) == 2
    assert "no_such_method" in capsys.readouterr().err and not (tmp_path / "b").exists()


def test_leaderboard_escapes_user_text_and_is_self_contained(evaluated, tmp_path, capsys):
    root, _ = evaluated
    out = tmp_path / "board"
    assert main(["leaderboard", str(root / "res_ni"), str(root / "res_evil"), "--out", str(out)]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.endswith(str(out / "leaderboard.html"))
    page = (out / "leaderboard.html").read_text()
    assert "<script" not in page.lower() and html.escape(EVIL) in page
    assert "src=\"http" not in page and "href=" not in page and page.count("data:image/png;base64,") >= 3
    md = (out / "leaderboard.md").read_text()
    assert "<script" not in md and "†" in md
    summary = md.split("## Summary over all recordings")[1].split("\n## ")[0]
    evil_line = next(line for line in summary.splitlines() if "alert" in line)
    assert "†" in evil_line and "**100.00**" not in evil_line  # the power law aligns away, the 1-px shift does not
    ni_line = next(line for line in md.splitlines() if "| NI (S) | S |" in line)
    assert "**0.4**" in ni_line  # lowest bandwidth marked best
    csv = (out / "leaderboard.csv").read_text().splitlines()
    assert csv[0].startswith("method,label,sensors,absolute_scale") and len(csv) == 3
    assert (out / "leaderboard_psnr_versus_lux.png").stat().st_size > 1000


CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed")
def test_leaderboard_renders_in_headless_chromium(evaluated, tmp_path):
    root, _ = evaluated
    out = tmp_path / "board"
    assert main(["leaderboard", str(root / "res_ni"), str(root / "res_evil"), "--out", str(out)]) == 0
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                    "--disable-component-update", "--disable-sync", "--no-first-run",
                    f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}", "--window-size=1200,4000",
                    (out / "leaderboard.html").resolve().as_uri()],
                   capture_output=True, timeout=120, check=False)
    assert shot.is_file() and shot.stat().st_size > 0
    img = np.asarray(Image.open(shot).convert("L"), np.float64)
    assert img.shape == (4000, 1200) and img.std() > 5.0  # tall: the description and tables come first
    # tables (dark text rows) and plots (coloured lines) are drawn: many distinct grey levels on the page
    assert len(np.unique(img.astype(np.uint8))) > 50
    rgb = np.asarray(Image.open(shot).convert("RGB"), np.int32)
    saturated = np.abs(rgb[..., 0] - rgb[..., 2]) > 60  # the plots' coloured lines and markers
    assert saturated.sum() > 500


def test_recordings_are_found_with_and_without_a_manifest(evaluated, tmp_path):
    root, ds = evaluated
    entries, manifest = list_recordings(ds)
    assert [e.rel for e in entries] == ["recordings/ramp/ramp_10lx.h5", "recordings/ramp/ramp_100lx.h5"]
    assert manifest["spec_hash"] == "x"  # the 'failed' ghost entry was skipped
    plain = tmp_path / "plain"
    shutil.copytree(ds / "recordings", plain / "recordings")
    shutil.copytree(root / "res_ni", plain / "results")  # saved reconstructions must not count as recordings
    (plain / "recordings" / ".ramp_1lx.h5.tmp-1-abc").write_bytes(b"")
    entries, manifest = list_recordings(plain)
    assert manifest is None
    assert [e.rel for e in entries] == ["recordings/ramp/ramp_100lx.h5", "recordings/ramp/ramp_10lx.h5"]


def test_the_board_describes_itself(evaluated, tmp_path):
    """Issue 36, goal 3: what the board ranks (dataset, spec hash, seed, version, date, each recording's resolution,
    duration and seed), the bandwidth accounting in words, strip titles with scene, speed, lux and instant, ASCII
    csv headers, and markdown without HTML entities for quotes."""
    root, ds = evaluated
    out = tmp_path / "board"
    assert main(["leaderboard", str(root / "res_ni"), str(root / "res_evil"), "--out", str(out)]) == 0
    md = (out / "leaderboard.md").read_text()
    about = md.split("## About this board")[1].split("\n## ")[0]
    ni_line = next(line for line in about.splitlines() if line.startswith("| res\\_ni "))
    cells = [c.strip() for c in ni_line.strip("|").split("|")]
    assert cells[1:5] == ["evaluate", "eval", "x", "0"]  # kind, dataset name, spec hash, seed (tests' manifest)
    assert cells[5] == simspad.__version__ and cells[6].startswith("20") and cells[7] == "1000"
    rec_line = next(line for line in about.splitlines() if line.startswith("| recordings/ramp/ramp\\_100lx.h5"))
    cells = [c.strip() for c in rec_line.strip("|").split("|")]
    assert cells[1:7] == ["ramp", "×1", "100", "32×24", "10", "100"]  # scene, speed, lux, W×H, ms, seed
    assert "a conventional frame one readout of its bit depth" in md and "one 32-bit readout" in md
    strips = [line for line in md.splitlines() if line.startswith("![ramp")]
    # the saved image is the middle of the 11 evaluation instants (0 to 10 ms at 1 kHz): 5 ms
    assert strips and all("ramp @ " in s and "lx, t = 5.0 ms (recordings/ramp/" in s for s in strips), strips
    assert "&#x27;" not in md and "&quot;" not in md
    header = (out / "leaderboard.csv").read_text().splitlines()[0]
    assert header.isascii() and " " not in header and "psnr_db_ramp_10lx" in header
    page = (out / "leaderboard.html").read_text()
    assert "About this board" in page and "32×24" in page


def test_the_winner_line_follows_cell_edges():
    from simspad.evaluate.leaderboard.regime_plots import sign_boundary

    diff = np.array([[1.0, -2.0, -1.0],
                     [3.0, 2.0, np.nan]])
    segments = set(sign_boundary(diff))
    # between (0,0)+ and (0,1)−: the vertical edge x = 0.5 of row 0; between (0,1)− and (1,1)+: the horizontal
    # edge y = 0.5 of column 1; nothing next to the missing cell (1,2) nor between cells of one sign
    assert segments == {((0.5, -0.5), (0.5, 0.5)), ((0.5, 0.5), (1.5, 0.5))}
    assert all(x % 1 == 0.5 or y % 1 == 0.5 for (x, y), _ in segments)  # every endpoint on a cell edge
