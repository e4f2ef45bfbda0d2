"""The glossary printed under the leaderboard's tables: each method's full name, sensors and origin, and the
marks used in the tables.

Built-in methods describe themselves (``full_name`` and ``citation`` of :class:`simspad.methods.method.Method`);
a method the registry does not know (a scored submission) is described by its results rows only.
"""

from __future__ import annotations

from simspad.errors import SimSpadError
from simspad.evaluate.leaderboard.board import DAGGER, Board, method_label
from simspad.methods.registry import get_method

SENSOR_NAMES = {"S": "SPAD binary frames", "F": "conventional frames", "E": "events"}

DAGGER_NOTE = (f"{DAGGER} no absolute scale: the method's output is scored after a per-frame least-squares affine "
               "fit of ln(reconstruction) to ln(ground truth). CF starts from no image (events carry only changes), "
               "so its brightness and contrast are unknown; every other method is scored as it is.")

PARTIAL_NOTE = ("partial k/N: scored on only k of the N recordings of this board (a submission covering part of "
                "the dataset, or failed runs). Such methods are listed after the ranked ones, get no rank and are "
                "never marked best: a mean over a subset is not comparable with a mean over all recordings.")


def sensor_text(sensors: str) -> str:
    """``S+E`` → ``SPAD binary frames + events``."""
    parts = [p.strip() for p in str(sensors).split("+") if p.strip()]
    return " + ".join(SENSOR_NAMES.get(p, p) for p in parts) or "–"


def glossary_rows(board: Board) -> list[tuple[str, str, str, str, str]]:
    """(label, name, full name, sensors, citation) of every method on the board, in board order."""
    rows = []
    for m in board.methods:
        try:
            method = get_method(m)
            full, cite = method.full_name or method.label, method.citation or "–"
        except SimSpadError:
            full, cite = "submitted reconstructions (not a built-in method)", "see the submission"
        rows.append((method_label(board, m), m, full, sensor_text(board.info[m]["sensors"]), cite))
    return rows


def notes(board: Board) -> list[str]:
    """The explanations of the marks that occur on this board."""
    out = []
    if any(not board.info[m]["absolute_scale"] for m in board.methods):
        out.append(DAGGER_NOTE)
    if any(board.is_partial(m) for m in board.methods):
        out.append(PARTIAL_NOTE)
    return out
