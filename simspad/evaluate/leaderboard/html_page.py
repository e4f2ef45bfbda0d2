"""``leaderboard.html``: one self-contained page (inline CSS, plots and strips as base64 PNG, no script and no
external asset). Every user-supplied string (method names, labels, scenes, sensors, error messages) is escaped
with :func:`html.escape`.
"""

from __future__ import annotations

import base64
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

_CSS = """body{font-family:system-ui,Helvetica,Arial,sans-serif;margin:24px;color:#222;background:#fff}
table{border-collapse:collapse;margin:12px 0;font-size:13px}th,td{border:1px solid #bbb;padding:4px 8px}
th{background:#eef2f7}td.num{text-align:right;font-variant-numeric:tabular-nums}td.best{background:#d9f2d9;
font-weight:bold}img{max-width:100%;border:1px solid #ddd;margin:6px 0}h1{font-size:22px}h2{font-size:17px;
margin-top:28px}.note{color:#555;font-size:12px}.plots{display:flex;flex-wrap:wrap;gap:12px}
.plots img{max-width:48%}"""


def _html_table(header, body) -> str:
    out = ["<table>", "<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in header) + "</tr>"]
    for row in body:
        cells = []
        for j, (t, best) in enumerate(row):
            cls = ("num" if j > 0 and _is_number(t) else "") + (" best" if best and t != "–" else "")
            cells.append(f"<td class=\"{cls.strip()}\">{html.escape(t)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return text == "–"
    return True


def _img_tag(png: bytes, alt: str) -> str:
    return f"<img alt=\"{html.escape(alt)}\" src=\"data:image/png;base64,{base64.b64encode(png).decode()}\">"


def render_html(board: Board, plots: dict[str, bytes], strips: list[tuple[str, bytes]],
                regime: Regime | None = None, regime_plots: dict[str, bytes] | None = None,
                strip_note: str | None = None, previews: dict[str, bytes] | None = None) -> str:
    lheader, lbody = lux_table(board)
    parts = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
             "<title>SimSPAD leaderboard</title>", f"<style>{_CSS}</style></head><body>",
             "<h1>SimSPAD leaderboard</h1>", f"<p class=\"note\">{html.escape(PREAMBLE)}</p>",
             "<h2>About this board</h2>", f"<p class=\"note\">{html.escape(ABOUT_NOTE)}</p>",
             _html_table(*about_cells(board)), _html_table(*recording_cells(board)),
             "<h2>Summary over all recordings</h2>", f"<p class=\"note\">{html.escape(ranking_rule(board))}</p>",
             _html_table(*summary_cells(board)), f"<p class=\"note\">{html.escape(BANDWIDTH_NOTE)}</p>",
             "<h2>Mean PSNR per light level (dB)</h2>", _html_table(lheader, lbody)]
    budgets = budget_tables(board)
    if budgets:
        parts += ["<h2>PSNR at a bandwidth budget</h2>", f"<p class=\"note\">{html.escape(BUDGET_NOTE)}</p>"]
        for lux, table in budgets:
            parts += [f"<h3>{lux:g} lx</h3>", _html_table(*table)]
    parts.append("<h2>Methods × scenes at each light level (PSNR, dB)</h2>")
    for lux in lux_levels(board):
        parts += [f"<h3>{lux:g} lx</h3>", _html_table(*table_cells(board, lux))]
    stars = star_tables(board)
    if stars:
        parts += ["<h2>Siemens star</h2>", f"<p class=\"note\">{html.escape(MTF_NOTE)}</p>"]
        for title, table in stars:
            parts += [f"<h3>{html.escape(title)}</h3>", _html_table(*table)]
    if regime is not None:
        parts += ["<h2>Regime map: light level × image speed</h2>", f"<p class=\"note\">{html.escape(REGIME_NOTE)}</p>"]
        one = single_speed_note(regime)
        if one:
            parts.append(f"<p class=\"note\">{html.escape(one)}</p>")
        parts.append(_html_table(*regime_cells(board, regime)))
        parts += [_img_tag(png, name) for name, png in (regime_plots or {}).items()]
    parts.append("<h2>Plots</h2>")
    parts.append("<div class=\"plots\">" + "".join(_img_tag(png, name) for name, png in plots.items()) + "</div>")
    if strips:
        parts.append("<h2>Reconstructions at the chosen instant (ground truth first)</h2>")
        if strip_note:
            parts.append(f"<p class=\"note\">{html.escape(strip_note)}</p>")
        for title, png in strips:
            parts.append(f"<h3>{html.escape(title)}</h3>{_img_tag(png, title)}")
            if previews and title in previews:  # embedded, as everything on the page: it stays one file
                gif = base64.b64encode(previews[title]).decode("ascii")
                parts.append("<details><summary>preview of the recording (ground truth, SPAD, frames, events: "
                             f"the first ms, slowed down)</summary><img src=\"data:image/gif;base64,{gif}\" "
                             f"alt=\"{html.escape(title)} preview\"></details>")
    parts += ["<h2>Glossary</h2>", _html_table(["Method", "Name", "Full name", "Sensors", "Source"],
                                               [[(c, False) for c in row] for row in glossary_rows(board)])]
    parts += [f"<p class=\"note\">{html.escape(n)}</p>" for n in notes(board)]
    errs = failed_runs(board)
    if errs:
        parts.append("<h2>Failed runs</h2><ul>" + "".join(
            f"<li>{html.escape(m)}: {html.escape(e)}</li>" for m, e in errs) + "</ul>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
