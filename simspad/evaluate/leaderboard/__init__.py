"""``simspad leaderboard``: merge results directories into a leaderboard (markdown, CSV, self-contained HTML).

Input: one or more results directories written by ``simspad evaluate`` or ``simspad score`` (``results.csv``,
``images/``). When two directories score the same method on the same recording, the later one wins.

Output (in ``--out``, default the first results directory):

- ``leaderboard.md``   the table (methods × scenes × lux, PSNR in dB, with bandwidth), the mean PSNR per lux
                       level, the plots and the image strips as PNG files beside it;
- ``leaderboard.csv``  the same table, one row per method, one column per (scene, lux);
- ``leaderboard_regime.csv`` PSNR and bandwidth per method and (lux, speed) cell, Pareto membership, and the best
                       S+E − best F+E difference per cell (:mod:`.regime`);
- ``leaderboard.html`` one file with everything embedded (plots and strips as base64 PNG, inline CSS, no
                       script and no external asset).

Best value per column is marked (bold; highest PSNR, lowest bandwidth). Methods scored without absolute scale
(after the log-affine alignment of :mod:`simspad.evaluate.metrics`) are marked †; a glossary under the tables
names every method and explains the marks. Every user-supplied string (method names, labels,
scenes, sensors, error messages) is escaped with :func:`html.escape` in HTML and markdown (and ``|``
in markdown cells; ``$`` in plot text so matplotlib never parses it as mathtext).
"""

from simspad.evaluate.leaderboard.board import Board, build_board
from simspad.evaluate.leaderboard.build import build_leaderboard

__all__ = ["Board", "build_board", "build_leaderboard"]
