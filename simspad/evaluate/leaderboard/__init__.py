"""``simspad leaderboard``: merge results directories into a leaderboard (markdown, CSV, self-contained HTML).

Input: one or more results directories written by ``simspad evaluate`` or ``simspad score`` (``results.csv``,
``images/``). When two directories score the same method on the same recording, the later one wins.

The board describes itself first ("About this board"): the results directories it merges, with the dataset name,
spec hash, seed, SimSPAD version, creation time and evaluation rate their ``results.json`` give, and every
recording with its scene, speed, lux, resolution, duration, seed and render settings. Image strips are titled
with scene, speed, lux and the instant shown.

Output (in ``--out``, default the first results directory):

- ``leaderboard.md``   the table (methods × scenes × lux, PSNR in dB, with bandwidth), the mean PSNR per lux
                       level, the plots and the image strips as PNG files beside it;
- ``leaderboard.csv``  the same table, one row per method, one column per (scene, lux) with an ASCII header
                       (``psnr_db_fan_x16_100lx``);
- ``leaderboard_regime.csv`` PSNR and bandwidth per method and (lux, speed) cell, Pareto membership, and the best
                       S+E − best F+E difference per cell (:mod:`.regime`);
- ``leaderboard.html`` one file with everything embedded (plots and strips as base64 PNG, inline CSS, no
                       script and no external asset).

Methods scored on every recording of the board are ranked by mean PSNR; only they are compared: the best value
per column, cell and mean is marked (bold; highest PSNR, lowest bandwidth) among them, and only they enter the
Pareto fronts and the S+E − F+E difference. A method scored on part of the recordings is shown, unranked and
never marked. The board states this rule, and lists per light level the PSNR at a bandwidth budget (the Pareto
front of PSNR against bandwidth). Methods scored without absolute scale
(after the log-affine alignment of :mod:`simspad.evaluate.metrics`) are marked †; a glossary under the tables
names every method and explains the marks. Every user-supplied string (method names, labels,
scenes, sensors, error messages) is escaped with :func:`html.escape` in HTML and markdown (and ``|``
in markdown cells; ``$`` in plot text so matplotlib never parses it as mathtext).
"""

from simspad.evaluate.leaderboard.board import Board, build_board
from simspad.evaluate.leaderboard.build import build_leaderboard

__all__ = ["Board", "build_board", "build_leaderboard"]
