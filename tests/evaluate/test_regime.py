"""The leaderboard's regime map (lux × image speed), coverage flags, glossary and strips, on results tables written
the way ``simspad evaluate`` writes them."""

import csv
import math

import numpy as np
import pytest

from simspad.cli import main
from simspad.evaluate.leaderboard import build_board
from simspad.evaluate.leaderboard.plots import strip_keys
from simspad.evaluate.leaderboard.regime import build_regime, pareto_front
from simspad.io.results_dir import RESULT_COLUMNS, read_csv, write_csv

METHODS = {"nedi_akf": ("NEDI+AKF (S+E)", "S+E", 0.45), "akf_fe": ("AKF (F+E)", "F+E", 0.15),
           "qbp": ("QBP (S)", "S", 97.7), "cf": ("CF (E)", "E", 0.05)}
SPEEDS = {1.0: 60.0, 8.0: 480.0}  # speed factor → measured median image speed (px/s)


def psnr_model(method: str, lux: float, k: float) -> float:
    """A made-up but structured table: frames lose with speed (blur), SPAD loses with darkness."""
    light = math.log10(lux)
    return {"nedi_akf": 24 + 3 * light - 0.1 * k, "akf_fe": 18 + 7 * light - 1.0 * k,
            "qbp": 22 + 3 * light - 0.5 * k, "cf": 12.0}[method]


def rows_for(methods, scenes=("office", "fan"), luxes=(1.0, 100.0), speeds=SPEEDS, with_speed=True):
    rows = []
    for m in methods:
        label, sensors, bw = METHODS[m]
        for s in scenes:
            for lux in luxes:
                for k, v in speeds.items():
                    name = f"{s}_{lux:g}lx" + (f"_x{k:g}" if len(speeds) > 1 else "")
                    r = {"method": m, "label": label, "sensors": sensors, "scene": s, "sequence": s, "lux": lux,
                         "recording": f"recordings/{s}/{name}.h5", "psnr_db": psnr_model(m, lux, k), "ssim": 0.5,
                         "bandwidth_khz_per_pixel": bw, "bandwidth_bits_per_pixel_s": 1000 * bw,
                         "absolute_scale": m != "cf", "n_frames": 5, "error": ""}
                    if with_speed:
                        r.update(speed_factor=k, image_speed_px_s=v)
                    rows.append(r)
    return rows


def results_dir(path, rows):
    path.mkdir(parents=True)
    write_csv(path / "results.csv", RESULT_COLUMNS, rows)
    return path


def test_regime_map_numbers_difference_and_pareto(tmp_path):
    d = results_dir(tmp_path / "res", rows_for(METHODS))
    board = build_board([d])
    regime = build_regime(board)
    assert regime.speeds == [1.0, 8.0] and regime.luxes == [1.0, 100.0]
    assert regime.image_speed_px_s == {1.0: 60.0, 8.0: 480.0}
    diff = regime.spad_minus_frames()
    for i, k in enumerate(regime.speeds):
        for j, lux in enumerate(regime.luxes):
            se = psnr_model("nedi_akf", lux, k)
            fe = psnr_model("akf_fe", lux, k)
            assert diff[i, j] == pytest.approx(se - fe)
    assert diff[0, 1] < 0 < diff[1, 0]  # frames win bright and slow, SPAD + events dark and fast
    pts = {"a": (1.0, 10.0), "b": (2.0, 12.0), "c": (3.0, 11.0), "d": (1.0, 9.0), "e": (5.0, 20.0)}
    assert pareto_front(pts) == {"a", "b", "e"}

    out = tmp_path / "board"
    assert main(["leaderboard", str(d), "--out", str(out)]) == 0
    md = (out / "leaderboard.md").read_text()
    assert "## Regime map" in md and "single speed" not in md
    line = next(x for x in md.splitlines() if x.startswith("| best S+E − best F+E"))
    cells = [c.strip() for c in line.strip("|").split("|")][1:]
    # columns: (1 lx, ×1), (100 lx, ×1), (1 lx, ×8), (100 lx, ×8)
    expected = [psnr_model("nedi_akf", lux, k) - psnr_model("akf_fe", lux, k) for k in (1.0, 8.0) for lux in (1, 100)]
    assert cells == [f"{v:+.2f}" for v in expected]
    assert "×8 (480 px/s)" in md
    with open(out / "leaderboard_regime.csv", newline="", encoding="utf-8") as f:
        regime_csv = list(csv.DictReader(f))
    cell = [r for r in regime_csv if float(r["lux"]) == 1.0 and float(r["speed_factor"]) == 8.0]
    front = {r["method"] for r in cell if r["pareto_front"] == "true"}
    # At 1 lx, ×8: CF 12 dB at 0.05 kHz; AKF 10 dB at 0.15 kHz (dominated by CF); NEDI+AKF 23.2 dB at 0.45 kHz;
    # QBP 18 dB at 97.7 kHz (dominated by NEDI+AKF).
    assert front == {"cf", "nedi_akf"}
    for name in ("psnr", "se_minus_fe", "pareto"):
        assert (out / f"leaderboard_regime_{name}.png").stat().st_size > 5000
    page = (out / "leaderboard.html").read_text()
    assert "Regime map" in page and page.count("data:image/png;base64,") >= 5


def test_a_single_speed_degrades_to_one_row_and_says_so(tmp_path):
    d = results_dir(tmp_path / "res", rows_for(["nedi_akf", "akf_fe"], with_speed=False, speeds={1.0: 0.0}))
    rows = read_csv(d / "results.csv")
    assert all(math.isnan(r["speed_factor"]) for r in rows)  # older results: the columns are empty
    regime = build_regime(build_board([d]))
    assert regime.speeds == [1.0] and math.isnan(regime.image_speed_px_s[1.0])
    assert regime.spad_minus_frames().shape == (1, 2)
    out = tmp_path / "board"
    assert main(["leaderboard", str(d), "--out", str(out)]) == 0
    md = (out / "leaderboard.md").read_text()
    assert "single speed (×1 (speed not recorded))" in md and "one row" in md


def test_partial_coverage_is_flagged_not_ranked_and_the_glossary_explains(tmp_path):
    full = results_dir(tmp_path / "full", rows_for(["nedi_akf", "akf_fe", "cf"], speeds={1.0: 60.0}))
    part_rows = [dict(r, psnr_db=60.0) for r in rows_for(["qbp"], speeds={1.0: 60.0})[:1]]
    part = results_dir(tmp_path / "part", part_rows)
    board = build_board([full, part])
    assert board.is_partial("qbp") and board.coverage("qbp") == 1 and len(board.recordings) == 4
    assert board.ranked() == ["nedi_akf", "akf_fe", "cf"] and board.methods[-1] == "qbp"
    out = tmp_path / "board"
    assert main(["leaderboard", str(full), str(part), "--out", str(out)]) == 0
    md = (out / "leaderboard.md").read_text()
    summary = md.split("## Summary over all recordings")[1].split("##")[0]
    qbp = next(x for x in summary.splitlines() if "QBP" in x)
    assert qbp.startswith("| – | QBP (S) (partial: 1/4)") and "**" not in qbp  # 60 dB, yet neither ranked nor best
    assert next(x for x in summary.splitlines() if "NEDI+AKF" in x).startswith("| 1 |")
    glossary = md.split("## Glossary")[1]
    assert "Pan et al." not in glossary and "Wang, Ng, Scheerlinck, Mahony, ICCV 2021" in glossary
    assert "Scheerlinck, Barnes, Mahony, ACCV 2018" in glossary and "Ma et al., SIGGRAPH 2020" in glossary
    assert "CF starts from no image" in glossary and "partial k/N" in glossary
    for f in ("leaderboard.md", "leaderboard.html"):  # the page points only to files of the repository
        assert "§" not in (out / f).read_text()


def test_strips_show_every_scene_at_the_same_light_levels(tmp_path):
    rows = rows_for(["nedi_akf"], scenes=("office", "fan", "piano"), luxes=(1.0, 10.0, 100.0, 1000.0),
                    speeds={1.0: 60.0})
    rows = [r for r in rows if not (r["scene"] == "piano" and r["lux"] == 10.0)]  # piano lacks 10 lx
    board = build_board([results_dir(tmp_path / "res", rows)])
    keys, note = strip_keys(board)
    by_scene = {s: sorted(l for s2, l, _ in keys if s2 == s) for s in ("office", "fan", "piano")}
    assert by_scene["office"] == by_scene["fan"] == by_scene["piano"] == [1.0, 100.0, 1000.0]
    assert "missing for some scenes" in note
    rows = rows_for(["nedi_akf"], scenes=tuple(f"s{i}" for i in range(6)), luxes=(1.0, 10.0, 100.0, 1000.0),
                    speeds={1.0: 60.0})
    keys, note = strip_keys(build_board([results_dir(tmp_path / "res6", rows)]))
    levels = {s: sorted(l for s2, l, _ in keys if s2 == s) for s in {k[0] for k in keys}}
    assert len(keys) <= 15 and len(levels) == 6 and len({tuple(v) for v in levels.values()}) == 1
    assert levels["s0"] == [1.0, 1000.0] and "at most 15 strips" in note
    assert np.all(np.diff(levels["s0"]) > 0)


def test_evaluate_reads_the_speed_attributes_of_each_recording(evaluation_dataset, tmp_path):
    from shutil import copy2

    import h5py

    rec_dir = evaluation_dataset / "recordings" / "ramp"
    fast = copy2(rec_dir / "ramp_100lx.h5", tmp_path / "ramp_fast.h5")
    with h5py.File(fast, "r+") as f:
        f.attrs["speed_factor"] = 8.0
        f.attrs["image_speed_px_s_p50"] = 412.5
    copy2(rec_dir / "ramp_10lx.h5", tmp_path / "ramp_plain.h5")  # made before the speed axis: no attributes
    assert main(["evaluate", str(tmp_path), "--methods", "ni", "--out", str(tmp_path / "res")]) == 0
    rows = {r["recording"]: r for r in read_csv(tmp_path / "res" / "results.csv")}
    assert rows["ramp_fast.h5"]["speed_factor"] == 8.0 and rows["ramp_fast.h5"]["image_speed_px_s"] == 412.5
    assert rows["ramp_plain.h5"]["speed_factor"] == 1.0 and math.isnan(rows["ramp_plain.h5"]["image_speed_px_s"])
    with h5py.File(fast, "r+") as f:
        f.attrs["speed_factor"] = "fast"
    assert main(["evaluate", str(fast), "--methods", "ni", "--out", str(tmp_path / "bad")]) == 2
    assert not (tmp_path / "bad").exists()


def test_scene_tables_keep_each_speed_in_its_own_column(tmp_path):
    d = results_dir(tmp_path / "res", rows_for(["akf_fe"]))
    board = build_board([d])
    assert sorted({s for s, _ in board.columns}) == ["fan", "fan ×8", "office", "office ×8"]
    # Each cell is one recording's PSNR, not the mean of a scene's slow and fast recordings.
    assert board.psnr[("akf_fe", "office", 100.0)] == pytest.approx(psnr_model("akf_fe", 100.0, 1.0))
    assert board.psnr[("akf_fe", "office ×8", 100.0)] == pytest.approx(psnr_model("akf_fe", 100.0, 8.0))
    assert main(["leaderboard", str(d), "--out", str(tmp_path / "lb")]) == 0
    md = (tmp_path / "lb" / "leaderboard.md").read_text(encoding="utf-8")
    assert "| office | office ×8 |" in md
