"""Keep the warnings of numpy, matplotlib and multiprocessing away from a user of the command line.

Inputs are validated up front and every problem a user must know about is one ``simspad: error:`` or
``simspad: warning:`` line (SimSPAD itself never uses :mod:`warnings`). What remains under ``RuntimeWarning``
and ``UserWarning`` is library noise — "divide by zero encountered in log10" from a degenerate plot,
matplotlib's "No artists with labels found to put in legend", multiprocessing's resource tracker reporting
"leaked semaphore objects" after a worker or the driver was killed — that the user can do nothing about.

The filters go into this process and, through ``PYTHONWARNINGS``, into every process it starts (render,
simulation and evaluation workers, the resource tracker). ``--debug``, or a ``PYTHONWARNINGS`` / ``-W`` of the
user's own, shows everything as Python would.
"""

from __future__ import annotations

import os
import sys
import warnings

#: The warning filters, in ``PYTHONWARNINGS`` syntax.
QUIET_FILTERS = "ignore::RuntimeWarning,ignore::UserWarning"


def quiet_library_warnings(debug: bool) -> None:
    """Ignore RuntimeWarning and UserWarning here and in child processes, unless ``debug`` or the user chose."""
    if debug or sys.warnoptions or os.environ.get("PYTHONWARNINGS"):
        return
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    warnings.filterwarnings("ignore", category=UserWarning)
    os.environ["PYTHONWARNINGS"] = QUIET_FILTERS  # spawned workers and the resource tracker read it at start
