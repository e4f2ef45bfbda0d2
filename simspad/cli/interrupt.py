"""Ctrl-C: one line and exit 130, however many times it is pressed.

The first SIGINT raises ``KeyboardInterrupt`` as usual, so ``finally`` blocks and context managers remove
temporary files and stop the workers. A second Ctrl-C, pressed while that clean-up runs, would raise again inside
it (a traceback from a ``finally`` block, an atexit handler or a pool's thread) and leave the clean-up half done,
so from the first one on SIGINT is ignored until the process exits.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator


@contextlib.contextmanager
def first_sigint_only() -> Iterator[None]:
    """Turn the first SIGINT into ``KeyboardInterrupt`` and ignore every later one.

    Without an interrupt the previous handler is restored on exit (``main`` is also called inside test
    processes). Where SIGINT was already ignored (a background job) or outside the main thread, a no-op.
    """
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is signal.SIG_IGN:
        yield
        return
    interrupted = False

    def on_sigint(signum, frame):
        nonlocal interrupted
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        interrupted = True
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_sigint)
    try:
        yield
    finally:
        if not interrupted:
            signal.signal(signal.SIGINT, previous)
