"""Scores against closed forms (issue 36, goal 1): the ground truth scores the maximum with and without absolute
scale, and known degradations score what their closed forms say.

Most frames here are two-level: a dark level x₀·W inside the linear segment of the sRGB curve (display value
12.92·x₀) and white columns at the right edge (display 1, and ≥ 1 % of the pixels, so the 99th percentile — the
white point W — is the white level). A degradation that moves dark pixels by δ in linear units then moves their
display value by exactly 12.92·δ/W, so PSNR = −10·log₁₀(f_dark·(12.92·δ/W)²), and SSIM over windows that hold
only two levels is a closed form of the window's pixel counts (``_two_level_ssim``).
"""

import colour
import numpy as np
import pytest

from simspad.cli import main
from simspad.evaluate import metrics
from simspad.io.results_dir import read_csv
from tests.helpers.evaluation_data import write_submission

W_PT = 1e12  # the white level, ph s⁻¹ m⁻²
H, WD = 40, 48
N_WHITE_COLS = 2
X0 = 0.0015  # dark level / W: display 12.92 · 0.0015, inside the sRGB linear segment (< 0.0031308)
SRGB_LIN = 12.92
WIN = 7  # SSIM window (scikit-image's default)
#: The display mapping is float32 (relative rounding 6·10⁻⁸ per pixel): closed forms hold to these bounds.
PSNR_TOL = 1e-5
SSIM_TOL = 1e-6


def _two_level(x0: float = X0) -> np.ndarray:
    gt = np.full((H, WD), x0 * W_PT)
    gt[:, -N_WHITE_COLS:] = W_PT
    return gt


F_DARK = (WD - N_WHITE_COLS) / WD


def _two_level_ssim(d_gt: float, d_rec: float) -> float:
    """Mean SSIM (scikit-image's: 7×7 uniform window, sample covariance, C1 = 0.01², C2 = 0.03², mean over the
    pixels at least 3 from the edge) of two two-level frames with the same layout: dark pixels at display value
    ``d_gt`` (ground truth) and ``d_rec`` (reconstruction), white columns (display 1) in both."""
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    n = WIN * WIN

    def window(n_white):
        n_dark = n - n_white
        mx, my = (n_white + n_dark * d_gt) / n, (n_white + n_dark * d_rec) / n
        spread = n_white * n_dark / (n * (n - 1))  # sample (co)variance of a two-level population, per unit²
        vx, vy, vxy = spread * (1 - d_gt) ** 2, spread * (1 - d_rec) ** 2, spread * (1 - d_gt) * (1 - d_rec)
        return (2 * mx * my + c1) * (2 * vxy + c2) / ((mx * mx + my * my + c1) * (vx + vy + c2))

    half = WIN // 2
    cols = range(half, WD - half)  # window centres scored (every row alike)
    whites = [WIN * max(0, j + half - (WD - N_WHITE_COLS) + 1) for j in cols]
    return float(np.mean([window(k) for k in whites]))


def _scores(rec, gt, absolute: bool):
    white = metrics.white_point(gt)
    assert white == W_PT or not np.allclose(gt[:, -N_WHITE_COLS:], W_PT)
    return metrics.frame_scores(rec, gt, white, absolute_scale=absolute)


@pytest.mark.parametrize("absolute", [True, False])
def test_the_ground_truth_scores_the_cap_and_ssim_one_both_ways(absolute):
    rng = np.random.default_rng(7)
    textured = (W_PT * rng.lognormal(-3, 2, (H, WD))).astype(np.float32)  # many pixels below the 10⁻³ floor
    textured[:4, :4] = 0.0
    for gt in (_two_level(), textured):
        s = _scores(gt.copy(), gt, absolute)
        assert s["psnr_db"] == metrics.PSNR_CAP_DB
        assert s["ssim"] == pytest.approx(1.0, abs=1e-12)
        if not absolute:
            assert (s["fit_a"], s["fit_b"]) == (1.0, 0.0)  # both sides floored alike: x = y bit for bit


def test_a_gain_and_a_contrast_are_undone_exactly_without_absolute_scale():
    rng = np.random.default_rng(8)
    gt = W_PT * np.exp(rng.uniform(np.log(5e-3), 0.0, (H, WD)))  # no pixel below either side's floor
    for k, gamma in ((3.7, 1.0), (0.02, 1.0), (7.0, 0.6), (1e-9, 1.3)):
        s = _scores(k * gt ** gamma, gt, absolute=False)
        # a = 1/γ, b = −ln(k)/γ, the aligned frame is gt again: PSNR at the cap, SSIM 1
        assert s["fit_a"] == pytest.approx(1 / gamma, rel=1e-9)
        assert s["fit_b"] == pytest.approx(-np.log(k) / gamma, rel=1e-9, abs=1e-9)
        assert s["psnr_db"] == metrics.PSNR_CAP_DB
        assert s["ssim"] == pytest.approx(1.0, abs=1e-9)


def test_a_constant_gain_with_absolute_scale_matches_its_closed_form():
    gt = _two_level()
    k = 1.6  # dark pixels move by (k − 1)·x₀·W; white ones clip back to 1
    s = _scores(k * gt, gt, absolute=True)
    err = SRGB_LIN * (k - 1) * X0
    assert s["psnr_db"] == pytest.approx(-10 * np.log10(F_DARK * err ** 2), abs=PSNR_TOL)
    assert s["ssim"] == pytest.approx(_two_level_ssim(SRGB_LIN * X0, SRGB_LIN * k * X0), abs=SSIM_TOL)
    k = 0.5  # now the white columns move too: to sRGB(0.5) = 1.055·0.5^(1/2.4) − 0.055
    s = _scores(k * gt, gt, absolute=True)
    white_err = 1 - (1.055 * 0.5 ** (1 / 2.4) - 0.055)
    mse = F_DARK * (SRGB_LIN * (k - 1) * X0) ** 2 + (1 - F_DARK) * white_err ** 2
    assert s["psnr_db"] == pytest.approx(-10 * np.log10(mse), abs=PSNR_TOL)


def test_an_additive_offset_with_absolute_scale_matches_its_closed_form():
    gt = _two_level()
    c = 0.0012  # of W: dark pixels stay in the linear segment (0.0027 < 0.0031308), white ones clip back to 1
    s = _scores(gt + c * W_PT, gt, absolute=True)
    assert s["psnr_db"] == pytest.approx(-10 * np.log10(F_DARK * (SRGB_LIN * c) ** 2), abs=PSNR_TOL)
    assert s["ssim"] == pytest.approx(_two_level_ssim(SRGB_LIN * X0, SRGB_LIN * (X0 + c)), abs=SSIM_TOL)
    assert s["ssim"] < 0.99  # the closed form is not trivially 1


def test_gaussian_noise_of_known_sigma_matches_its_closed_form():
    gt = _two_level(0.0017)
    sigma = 0.0002  # of W
    rng = np.random.default_rng(11)
    noise = np.zeros_like(gt)
    noise[:, :-N_WHITE_COLS] = sigma * W_PT * rng.standard_normal((H, WD - N_WHITE_COLS))
    rec = gt + noise
    x = rec[:, :-N_WHITE_COLS] / W_PT
    assert x.min() > 0 and x.max() < 0.0031308  # every noisy pixel inside the linear segment: the closed form holds
    s = _scores(rec, gt, absolute=True)
    exact = -10 * np.log10(SRGB_LIN ** 2 * np.mean((noise / W_PT) ** 2))  # the drawn noise
    assert s["psnr_db"] == pytest.approx(exact, abs=PSNR_TOL)
    # and its expectation: mean(n²) has a relative spread √(2/N) ≈ 3.6 % here, 0.16 dB; 0.5 dB is over 3 spreads
    expected = -10 * np.log10(F_DARK * (SRGB_LIN * sigma) ** 2)
    assert abs(s["psnr_db"] - expected) < 0.5


def test_the_fit_without_absolute_scale_is_the_documented_formula():
    # an offset and noise are not in the fit's family: the scores are whatever the documented formula gives,
    # computed here independently (np.polyfit, colour's sRGB curve)
    rng = np.random.default_rng(12)
    gt = W_PT * np.exp(rng.uniform(np.log(1e-4), 0.3, (H, WD)))
    gt[:3] = 0.0
    for rec in (gt + 0.01 * W_PT, np.abs(gt + 0.05 * W_PT * rng.standard_normal(gt.shape)), 5.0 * gt ** 0.7):
        def floored_log(img):
            return np.log(np.maximum(img, 1e-3 * np.percentile(img, 99)))
        a, b = np.polyfit(floored_log(rec).ravel(), floored_log(gt).ravel(), 1)
        aligned = np.exp(b) * rec ** a
        white = float(np.percentile(gt, 99))

        def display(img):
            return colour.cctf_encoding(np.clip(img / white, 0, 1), function="sRGB")
        mse = np.mean((display(aligned) - display(gt)) ** 2)
        s = metrics.frame_scores(rec, gt, white, absolute_scale=False)
        assert (s["fit_a"], s["fit_b"]) == (pytest.approx(a, rel=1e-9), pytest.approx(b, rel=1e-9, abs=1e-9))
        assert s["psnr_db"] == pytest.approx(-10 * np.log10(mse), abs=1e-6)


@pytest.mark.parametrize("absolute", [True, False])
def test_a_submission_of_the_ground_truth_scores_the_maximum(evaluation_dataset, tmp_path, absolute):
    """End to end through ``simspad score``: the † case (absolute_scale false) scored 44.75 dB before the fix."""
    sub = write_submission(tmp_path / "gt.h5", evaluation_dataset, attrs={"absolute_scale": absolute})
    assert main(["score", str(sub), "--dataset", str(evaluation_dataset), "--out", str(tmp_path / "res")]) == 0
    rows = read_csv(tmp_path / "res" / "results.csv")
    assert len(rows) == 2
    for r in rows:
        assert (r["psnr_db"], r["ssim"]) == (metrics.PSNR_CAP_DB, pytest.approx(1.0, abs=1e-12))
    for f in read_csv(tmp_path / "res" / "frames.csv"):
        assert f["psnr_db"] == metrics.PSNR_CAP_DB
        if not absolute:
            assert (f["fit_a"], f["fit_b"]) == (1.0, 0.0)


def test_a_gain_on_the_ground_truth_without_absolute_scale_scores_the_maximum(evaluation_dataset, tmp_path):
    sub = write_submission(tmp_path / "gain.h5", evaluation_dataset, attrs={"absolute_scale": False},
                           transform=lambda f: f * np.float32(3e-7))
    assert main(["score", str(sub), "--dataset", str(evaluation_dataset), "--out", str(tmp_path / "res")]) == 0
    for r in read_csv(tmp_path / "res" / "results.csv"):
        assert r["psnr_db"] == metrics.PSNR_CAP_DB and r["ssim"] == pytest.approx(1.0, abs=1e-9)
