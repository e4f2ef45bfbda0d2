"""``leaderboard.md``: the tables in markdown, linking the plots and strips written beside it as PNG files.

Every user-supplied string is escaped with :func:`html.escape`, and Markdown's syntax characters with a backslash.
"""

from __future__ import annotations

import html

from simspad.evaluate.leaderboard.board import DAGGER, Board, failed_runs, lux_levels
from simspad.evaluate.leaderboard.tables import MTF_NOTE, lux_table, mtf_table, summary_cells, table_cells


#: Markdown syntax characters escaped with a backslash in user text, so a method name cannot become a link, an
#: image (both need ``[``), emphasis or code: ``[x](http://evil)`` shows as written; ``(S)`` stays readable.
_MD_SPECIAL = "\\`*_[]|"


def md_escape(text: str) -> str:
    text = html.escape(str(text)).replace("\n", " ")
    return "".join("\\" + c if c in _MD_SPECIAL else c for c in text)


def md_table(header, body, text_columns: int = 2) -> str:
    lines = ["| " + " | ".join(md_escape(h) for h in header) + " |",
             "|" + "|".join(["---"] * text_columns + ["---:"] * (len(header) - text_columns)) + "|"]
    for row in body:
        lines.append("| " + " | ".join(f"**{md_escape(t)}**" if b and t != "–" else md_escape(t)
                                      for t, b in row) + " |")
    return "\n".join(lines)


def render_markdown(board: Board, plot_files: dict[str, str], strip_files: list[tuple[str, str]]) -> str:
    lheader, lbody = lux_table(board)
    out = ["# SimSPAD leaderboard", "",
           f"PSNR in dB (DESIGN §8 display mapping). Best per column in bold. {DAGGER}: scored after a per-frame "
           "least-squares affine fit in log space (no absolute scale). Bandwidth: mean over recordings.", "",
           "## Summary over all recordings", "", md_table(*summary_cells(board)), "",
           "## Mean PSNR per light level (dB)", "", md_table(lheader, lbody, 1), "",
           "## Methods × scenes at each light level (PSNR, dB)", ""]
    for lux in lux_levels(board):
        out += [f"### {lux:g} lx", "", md_table(*table_cells(board, lux)), ""]
    mt = mtf_table(board)
    if mt is not None:
        out += ["## Siemens star: MTF50", "", md_escape(MTF_NOTE), "", md_table(*mt, 1), ""]
    out += ["## Plots", ""]
    out += [f"![{md_escape(name)}]({f})" for name, f in plot_files.items()]
    if strip_files:
        out += ["", "## Reconstructions at the chosen instant (ground truth first)", ""]
        out += [f"![{md_escape(t)}]({f})" for t, f in strip_files]
    errs = failed_runs(board)
    if errs:
        out += ["", "## Failed runs", ""] + [f"- {md_escape(m)}: {md_escape(e)}" for m, e in errs]
    return "\n".join(out) + "\n"
