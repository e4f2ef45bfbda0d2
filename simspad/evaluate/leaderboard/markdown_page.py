"""``leaderboard.md``: the tables in markdown, linking the plots and strips written beside it as PNG files.

Every user-supplied string is escaped with :func:`html.escape`, and Markdown's syntax characters with a backslash.
"""

from __future__ import annotations

import html

from simspad.evaluate.leaderboard.board import Board, failed_runs, lux_levels
from simspad.evaluate.leaderboard.glossary import glossary_rows, notes
from simspad.evaluate.leaderboard.regime import Regime, regime_cells, single_speed_note
from simspad.evaluate.leaderboard.tables import (
    ABOUT_NOTE,
    BANDWIDTH_NOTE,
    BUDGET_NOTE,
    MTF_NOTE,
    PREAMBLE,
    REGIME_NOTE,
    about_cells,
    budget_tables,
    lux_table,
    ranking_rule,
    recording_cells,
    star_tables,
    summary_cells,
    table_cells,
)


#: Markdown syntax characters escaped with a backslash in user text, so a method name cannot become a link, an
#: image (both need ``[``), emphasis or code: ``[x](http://evil)`` shows as written; ``(S)`` stays readable.
_MD_SPECIAL = "\\`*_[]|"


def md_escape(text: str) -> str:
    """``text`` for a markdown cell or line: &, < and > as entities (no raw HTML; quotes stay as typed, since they
    mean nothing to markdown and an entity such as ``&#x27;`` reads badly in the source), markdown's syntax
    characters backslash-escaped, newlines as spaces."""
    text = html.escape(str(text), quote=False).replace("\n", " ")
    return "".join("\\" + c if c in _MD_SPECIAL else c for c in text)


def md_table(header, body, text_columns: int = 2) -> str:
    lines = ["| " + " | ".join(md_escape(h) for h in header) + " |",
             "|" + "|".join(["---"] * text_columns + ["---:"] * (len(header) - text_columns)) + "|"]
    for row in body:
        lines.append("| " + " | ".join(f"**{md_escape(t)}**" if b and t != "–" else md_escape(t)
                                      for t, b in row) + " |")
    return "\n".join(lines)


def render_markdown(board: Board, plot_files: dict[str, str], strip_files: list[tuple[str, str]],
                    regime: Regime | None = None, regime_files: dict[str, str] | None = None,
                    strip_note: str | None = None, previews: dict[str, str] | None = None) -> str:
    lheader, lbody = lux_table(board)
    out = ["# SimSPAD leaderboard", "", md_escape(PREAMBLE), "",
           "## About this board", "", md_escape(ABOUT_NOTE), "", md_table(*about_cells(board), 9), "",
           md_table(*recording_cells(board), 2), "",
           "## Summary over all recordings", "", md_escape(ranking_rule(board)), "",
           md_table(*summary_cells(board), 3), "", md_escape(BANDWIDTH_NOTE), "",
           "## Mean PSNR per light level (dB)", "", md_table(lheader, lbody, 1), ""]
    budgets = budget_tables(board)
    if budgets:
        out += ["## PSNR at a bandwidth budget", "", md_escape(BUDGET_NOTE), ""]
        for lux, (header, body) in budgets:
            out += [f"### {lux:g} lx", "", md_table(header, body, 3), ""]
    out += ["## Methods × scenes at each light level (PSNR, dB)", ""]
    for lux in lux_levels(board):
        out += [f"### {lux:g} lx", "", md_table(*table_cells(board, lux)), ""]
    stars = star_tables(board)
    if stars:
        out += ["## Siemens star", "", md_escape(MTF_NOTE), ""]
        for title, (header, body) in stars:
            out += [f"### {md_escape(title)}", "", md_table(header, body, 1), ""]
    if regime is not None:
        out += ["## Regime map: light level × image speed", "", md_escape(REGIME_NOTE), ""]
        one = single_speed_note(regime)
        if one:
            out += [md_escape(one), ""]
        out += [md_table(*regime_cells(board, regime), 1), ""]
        out += [f"![{md_escape(name)}]({f})" for name, f in (regime_files or {}).items()] + [""]
    out += ["## Plots", ""]
    out += [f"![{md_escape(name)}]({f})" for name, f in plot_files.items()]
    if strip_files:
        out += ["", "## Reconstructions at the chosen instant (ground truth first)", ""]
        if strip_note:
            out += [md_escape(strip_note), ""]
        for t, f in strip_files:
            out.append(f"![{md_escape(t)}]({f})")
            if previews and t in previews:
                out += ["", f"[preview of the recording (GIF: ground truth, SPAD, frames, events)]({previews[t]})", ""]
    out += ["", "## Glossary", "", md_table(["Method", "Name", "Full name", "Sensors", "Source"],
                                            [[(c, False) for c in row] for row in glossary_rows(board)], 5), ""]
    out += [f"- {md_escape(n)}" for n in notes(board)]
    errs = failed_runs(board)
    if errs:
        out += ["", "## Failed runs", ""] + [f"- {md_escape(m)}: {md_escape(e)}" for m, e in errs]
    return "\n".join(out) + "\n"
