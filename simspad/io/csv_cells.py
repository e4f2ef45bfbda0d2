"""Text cells of the CSV files SimSPAD writes (results.csv, frames.csv, mtf.csv, leaderboard*.csv) that a
spreadsheet cannot run as formulas.

A cell starting with ``=``, ``+``, ``-``, ``@``, a tab or a carriage return is a formula to Excel, LibreOffice and
Google Sheets (``=HYPERLINK(…)``, ``+cmd|…``, ``@SUM(…)`` in a submission's label). Such text gets a leading
apostrophe (the OWASP rule), which spreadsheets show as text and do not display. The escape is reversible:
:func:`csv_unescape` gives the text back when SimSPAD reads its own CSV (a label read from results.csv is shown
as it was written). Text that already starts with apostrophes before such a character gets one more, so the round
trip is exact for any text. Numbers pass unchanged: ``-2.0`` stays a number.
"""

from __future__ import annotations

#: First characters that make a spreadsheet cell a formula (OWASP "CSV injection").
FORMULA_PREFIXES = ("=", "+", "-", "@", "\t", "\r")


def csv_safe(value):
    """``value`` with a leading apostrophe when it is text a spreadsheet would run as a formula; else unchanged."""
    if isinstance(value, str) and value.lstrip("'")[:1] in FORMULA_PREFIXES and value.lstrip("'"):
        return "'" + value
    return value


def csv_unescape(text: str) -> str:
    """The text :func:`csv_safe` was given, from the cell it wrote (any other text unchanged)."""
    if text[:1] == "'" and text.lstrip("'")[:1] in FORMULA_PREFIXES and text.lstrip("'"):
        return text[1:]
    return text
