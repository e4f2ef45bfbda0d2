"""Fair ranks on the leaderboard (issue 36, goal 2): only methods scored on the same recordings are compared; a
partial submission is shown but never bolded, ranked, put on a Pareto front or used in the S+E − F+E difference;
the ranking rule is stated; PSNR at a bandwidth budget per light level is the Pareto front of the ranked methods."""

import csv
import math

import pytest

from simspad.cli import main
from simspad.evaluate.leaderboard import build_board
from simspad.evaluate.leaderboard.tables import budget_fronts
from tests.evaluate.test_regime import METHODS, psnr_model, results_dir, rows_for

SPEED = {1.0: 60.0}


@pytest.fixture
def board_dirs(tmp_path):
    """Three complete methods on 2 scenes × 2 lux (4 recordings) and a 1-of-4 submission: an S+E method at 60 dB
    on office @ 100 lx, far above every complete method there, and cheapest (0.01 kHz/px)."""
    full = results_dir(tmp_path / "full", rows_for(["nedi_akf", "akf_fe", "cf"], speeds=SPEED))
    one = next(r for r in rows_for(["qbp"], speeds=SPEED) if r["scene"] == "office" and r["lux"] == 100.0)
    one.update(method="sub", label="Sub (S+E)", sensors="S+E", psnr_db=60.0, bandwidth_khz_per_pixel=0.01,
               bandwidth_bits_per_pixel_s=10.0)
    part = results_dir(tmp_path / "part", [one])
    return full, part


def _bold_cells(md: str, who: str) -> list[str]:
    return [line for line in md.splitlines() if who in line and "**" in line]


def test_a_one_of_n_submission_is_never_bolded_ranked_or_on_a_front(board_dirs, tmp_path):
    full, part = board_dirs
    board = build_board([full, part])
    assert board.is_partial("sub") and board.ranked() == ["nedi_akf", "akf_fe", "cf"]
    out = tmp_path / "board"
    assert main(["leaderboard", str(full), str(part), "--out", str(out)]) == 0
    md = (out / "leaderboard.md").read_text()
    sub_lines = [line for line in md.splitlines() if "Sub (S+E)" in line]
    # summary, lux table, the 100 lx table, the regime table, the glossary: shown everywhere it has a number...
    assert len(sub_lines) >= 5 and any("60.00" in line for line in sub_lines)
    # ...but bold nowhere (not in the office @ 100 lx column, the 100 lx mean, nor the "100 lx, ×1" cell)
    assert _bold_cells(md, "Sub (S+E)") == []
    summary = md.split("## Summary over all recordings")[1].split("\n## ")[0]
    assert next(x for x in summary.splitlines() if "Sub (S+E)" in x).startswith("| – |")
    # the complete methods still compete: AKF holds the best office @ 100 lx value among them
    scenes = md.split("## Methods × scenes at each light level")[1].split("\n## ")[0]
    table_100 = scenes.split("### 100 lx")[1]
    akf = next(x for x in table_100.splitlines() if x.startswith("| AKF (F+E)"))
    assert f"**{psnr_model('akf_fe', 100.0, 1.0):.2f}**" in akf
    page = (out / "leaderboard.html").read_text()
    sub_row = next(x for x in page.split("<tr>") if "Sub (S+E)" in x and "60.00" in x)
    assert "best" not in sub_row
    with open(out / "leaderboard_regime.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    sub = [r for r in rows if r["method"] == "sub"]
    assert len(sub) == 1 and sub[0]["pareto_front"] == "false"  # cheapest and best, but not comparable
    diff = next(r for r in rows if r["method"] == "best_S+E-best_F+E" and float(r["lux"]) == 100.0)
    assert diff["label"] == "nedi_akf - akf_fe"
    assert float(diff["psnr_db"]) == pytest.approx(psnr_model("nedi_akf", 100.0, 1.0) - psnr_model("akf_fe", 100.0, 1.0))


def test_the_board_states_its_ranking_rule(board_dirs, tmp_path):
    full, part = board_dirs
    out = tmp_path / "board"
    assert main(["leaderboard", str(full), str(part), "--out", str(out)]) == 0
    for name in ("leaderboard.md", "leaderboard.html"):
        text = (out / name).read_text()
        assert "Rank: the methods scored on all 4 recordings of this board, by mean PSNR" in text
        assert "never in bold" in text and "PSNR at a bandwidth budget" in text


def test_psnr_at_a_bandwidth_budget_is_the_pareto_front_per_lux(board_dirs, tmp_path):
    full, part = board_dirs
    board = build_board([full, part])
    fronts = budget_fronts(board)
    bw = {m: METHODS[m][2] for m in ("nedi_akf", "akf_fe", "cf")}
    for lux, front in fronts.items():
        psnr = {m: psnr_model(m, lux, 1.0) for m in bw}
        # independent: a method is on the front when no other is at least as cheap and at least as good
        expected = sorted((m for m in bw if not any(bw[o] <= bw[m] and psnr[o] >= psnr[m] and
                                                  (bw[o], psnr[o]) != (bw[m], psnr[m]) for o in bw)),
                          key=lambda m: bw[m])
        assert [f[0] for f in front] == expected
        assert [f[3] for f in front] == pytest.approx([psnr[m] for m in expected])
        assert all(a[3] < b[3] for a, b in zip(front, front[1:]))  # more budget buys more PSNR along the front
    # at 1 lx each step buys PSNR: CF 12 dB at 0.05, AKF 17 dB at 0.15, NEDI+AKF 23.9 dB at 0.45 kHz/px
    assert [f[0] for f in fronts[1.0]] == ["cf", "akf_fe", "nedi_akf"]
    # at 100 lx AKF (31 dB at 0.15) beats CF's 12 dB; NEDI+AKF (29.9 dB at 0.45) costs more for less: dominated
    assert [f[0] for f in fronts[100.0]] == ["cf", "akf_fe"]
    out = tmp_path / "board"
    assert main(["leaderboard", str(full), str(part), "--out", str(out)]) == 0
    md = (out / "leaderboard.md").read_text()
    section = md.split("## PSNR at a bandwidth budget")[1].split("\n## ")[0]
    assert "Sub" not in section
    assert (out / "leaderboard_psnr_at_a_bandwidth_budget.png").stat().st_size > 5000
    assert "![PSNR at a bandwidth budget](leaderboard_psnr_at_a_bandwidth_budget.png)" in md
    rows_100 = [x for x in section.split("### 100 lx")[1].splitlines() if x.startswith("| 0")]
    assert [x.split("|")[2].strip() for x in rows_100] == ["CF (E) †", "AKF (F+E)"]
    assert rows_100[1].split("|")[5].strip() == f"{psnr_model('akf_fe', 100.0, 1.0):.2f}"


def test_a_board_of_partial_methods_marks_nothing_best(tmp_path):
    rows = rows_for(["nedi_akf", "akf_fe"], speeds=SPEED)
    a = results_dir(tmp_path / "a", [r for r in rows if r["method"] == "nedi_akf" and r["scene"] == "office"])
    b = results_dir(tmp_path / "b", [r for r in rows if r["method"] == "akf_fe" and r["scene"] == "fan"])
    board = build_board([a, b])
    assert board.ranked() == [] and all(board.is_partial(m) for m in board.methods)
    out = tmp_path / "board"
    assert main(["leaderboard", str(a), str(b), "--out", str(out)]) == 0
    md = (out / "leaderboard.md").read_text()
    assert "**" not in md.split("## Glossary")[0]  # two methods on disjoint recordings: nothing to compare
    assert "## PSNR at a bandwidth budget" not in md
    assert math.isfinite(board.info["nedi_akf"]["psnr_mean"])
