"""``simspad preview``: the video, GIF and PNG strip read back: frame count, size, and panels that show exactly the
recording's data (the SPAD binary frame at each instant, the events of each window)."""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest

from simspad.analysis.preview import STRIP_INSTANTS, PreviewSettings, write_preview
from simspad.io.recording import open_recording
from tests.helpers.synthetic_recordings import write_recording

H, W = 12, 16


def _moving_bar(t):
    """A bright bar sweeping right at 2000 px/s over a dim background (ph s⁻¹ m⁻²)."""
    img = np.full((H, W), 2e15)
    x = int(2 + 2000.0 * t) % W
    img[:, x:x + 2] = 4e16
    return img


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("preview") / "bar.h5"
    write_recording(path, _moving_bar, shape=(H, W), duration_s=0.01, frame_rate_hz=500.0, exposure_s=1e-3)
    return path


def _panel_pixels(image, box, row_offset=0.0):
    """The panel's image sampled at the centre of each recording pixel: ``[H, W, 3]`` uint8."""
    x0, y0, x1, y1 = box
    ys = (y0 + (np.arange(H) + 0.5) * (y1 - y0) / H + row_offset).astype(int)
    xs = (x0 + (np.arange(W) + 0.5) * (x1 - x0) / W).astype(int)
    return image[np.ix_(ys, xs)]


def test_png_strip_shows_the_spad_binary_frame_and_the_event_window_of_each_instant(recording, tmp_path):
    settings = PreviewSettings(event_window_s=1e-3)
    res = write_preview(recording, tmp_path / "strip.png", settings)
    strip = imageio.imread(res.path)[..., :3]
    assert strip.shape == (res.height_px, res.width_px, 3) and len(res.times_s) == STRIP_INSTANTS
    assert set(res.panels) == {"gt", "spad_aggregate", "spad_bit", "frames", "events"}
    frame_h = res.height_px / STRIP_INSTANTS
    with open_recording(recording) as rec:
        bin_s = float(rec.spad.attrs["bin_s"])
        for k, t in enumerate(res.times_s):
            shown = _panel_pixels(strip, res.panels["spad_bit"], k * frame_h)
            i = int(np.floor(t / bin_s + 1e-9))
            assert np.array_equal(shown[..., 0] > 127, rec.spad.bits(i, i + 1)[0] == 1), f"instant {k}"
            ev = rec.events.window(t - settings.event_window_s, t)
            on = np.zeros((H, W), bool)
            off = np.zeros((H, W), bool)
            on[ev["y"][ev["p"] > 0], ev["x"][ev["p"] > 0]] = True
            off[ev["y"][ev["p"] <= 0], ev["x"][ev["p"] <= 0]] = True
            panel = _panel_pixels(strip, res.panels["events"], k * frame_h).astype(int)
            assert on.any() or off.any()  # the bar moves: every window has events
            # white where nothing fired; red (blue channel down) where ON fired, blue where OFF fired
            assert np.array_equal(panel[..., 2] < 250, on), f"instant {k}"
            assert np.array_equal(panel[..., 0] < 250, off), f"instant {k}"


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_video_has_one_frame_per_instant_at_the_slowdown(recording, tmp_path, suffix):
    settings = PreviewSettings(duration_s=0.004, slowdown=500.0, fps=25.0)
    res = write_preview(recording, tmp_path / f"bar{suffix}", settings)
    # 4 ms × 500 = 2 s of video at 25 fps
    assert res.n_frames == 50 and np.allclose(np.diff(res.times_s), 1 / (25.0 * 500.0))
    reader = imageio.get_reader(res.path)
    frames = [f for f in reader]
    assert len(frames) == 50
    assert frames[0].shape[:2] == (res.height_px, res.width_px)
    # the ground-truth panel (lossy in H.264): the bar is where the recording has it
    with open_recording(recording) as rec:
        for n in (0, 25, 49):
            t = res.times_s[n]
            gt_i = int(np.searchsorted(rec.gt.t, t + 1e-12, side="right") - 1)
            truth = rec.gt.flux(gt_i) > 1e16
            shown = _panel_pixels(frames[n][..., :3], res.panels["gt"])[..., 1] > 128
            assert np.array_equal(shown, truth), f"frame {n}"


def test_bad_settings_and_spans_are_one_clear_error(recording, tmp_path, simspad_cli):
    res = simspad_cli.run("preview", recording, "--out", tmp_path / "x.mp4", "--start", "0.5")
    assert res.returncode == 2 and "outside the recording" in res.stderr and "Traceback" not in res.stderr
    res = simspad_cli.run("preview", recording, "--out", tmp_path / "x.avi")
    assert res.returncode == 2 and "unknown preview kind" in res.stderr
    res = simspad_cli.run("preview", recording, "--out", tmp_path / "x.mp4", "--slowdown", "1e9")
    assert res.returncode == 2 and "video frames" in res.stderr
    assert not any(tmp_path.iterdir())  # nothing half-written
    ok = simspad_cli.run("preview", recording, "--out", tmp_path / "x.gif", "--duration", "0.002")
    assert ok.returncode == 0, ok.stderr
    assert "wrote" in ok.stdout and (tmp_path / "x.gif").stat().st_size > 0


@pytest.mark.slow
def test_the_leaderboard_links_a_short_preview_of_each_strips_recording(simspad_cli, evaluation_dataset, tmp_path):
    import shutil

    data = Path(shutil.copytree(evaluation_dataset, tmp_path / "data"))
    assert simspad_cli.run("evaluate", data, "--methods", "ni", "--out", data / "results").returncode == 0
    res = simspad_cli.run("leaderboard", data / "results", "--out", tmp_path / "board")
    assert res.returncode == 0, res.stderr
    md = (tmp_path / "board" / "leaderboard.md").read_text()
    gifs = sorted((tmp_path / "board" / "leaderboard_strips").glob("*.gif"))
    assert gifs and all(f"(leaderboard_strips/{g.name})" in md for g in gifs)
    page = (tmp_path / "board" / "leaderboard.html").read_text()
    assert page.count('src="data:image/gif;base64,') == len(gifs)  # embedded: the page stays one file
    frames = list(imageio.get_reader(gifs[0]))
    assert len(frames) == 10  # 4 ms at 250× slower and 10 fps
