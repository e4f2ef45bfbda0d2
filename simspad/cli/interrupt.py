"""Ctrl-C: one line and exit 130, however many times it is pressed.

The first SIGINT raises ``KeyboardInterrupt`` as usual, so ``finally`` blocks and context managers remove
temporary files and stop the workers. A second Ctrl-C, pressed while that clean-up runs, would raise again inside
it (a traceback from a ``finally`` block, an atexit handler or a pool's thread) and leave the clean-up half done,
so from the first one on SIGINT is ignored until the process exits.

SIGTERM (``kill PID``, a batch system's time limit) is turned into :class:`Terminated` the same way
(:func:`sigterm_raises`), so the same clean-up runs — a killed ``simulate`` leaves no 100 MB temporary file — and
the command exits with status 143 (128 + SIGTERM) after one line. Only kill -9 skips it (the next write of the
same name removes what it left).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from typing import Iterator


class SigintState:
    """Whether a SIGINT arrived (``interrupted``): the caller ends the run as interrupted even when the
    ``KeyboardInterrupt`` was swallowed where it was raised."""

    interrupted = False


@contextlib.contextmanager
def first_sigint_only(restore: bool = True) -> Iterator[SigintState]:
    """Turn the first SIGINT into ``KeyboardInterrupt`` and ignore every later one.

    Without an interrupt the previous handler is restored on exit when ``restore`` (``main`` is also called
    inside test processes); with ``restore=False`` (the ``simspad`` program itself, which exits next) SIGINT is
    ignored from then on: the work is done, and a press while the interpreter exits (joining pools and threads)
    would otherwise raise there and end the process by SIGINT, with no line and status −2 instead of the
    command's own. A ``KeyboardInterrupt`` that Python swallows (raised inside a weakref callback or a ``__del__``,
    where it is only reported) is not reported; the state yielded says that SIGINT arrived. Where SIGINT was already ignored (a background job) or outside the main thread, a no-op.
    """
    state = SigintState()
    previous = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or previous is signal.SIG_IGN:
        yield state
        return

    def on_sigint(signum, frame):
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        state.interrupted = True
        raise KeyboardInterrupt

    def unraisable(info) -> None:
        # A SIGINT landing in a weakref callback or a __del__ raises there, where Python only reports it: silent
        if not issubclass(info.exc_type, KeyboardInterrupt):
            previous_hook(info)

    previous_hook = sys.unraisablehook
    sys.unraisablehook = unraisable
    signal.signal(signal.SIGINT, on_sigint)
    try:
        yield state
    except KeyboardInterrupt:
        state.interrupted = True
        raise
    finally:
        sys.unraisablehook = previous_hook
        if state.interrupted:
            # However the interrupt arrived (also a KeyboardInterrupt that did not come through this handler, which
            # used to put the previous handler back), SIGINT stays ignored to the end. With Python's own handler put
            # back, a second press while the interpreter exits (joining threads and pools) raises there, and Python
            # ends an exit interrupted that way by SIGINT: status −2 after the one line, not 130.
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        else:
            signal.signal(signal.SIGINT, previous if restore else signal.SIG_IGN)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the main thread is, so ``finally`` blocks and pools' clean-up run as for Ctrl-C
    (a subclass of ``KeyboardInterrupt`` for that reason); the CLI exits 143."""


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Turn the first SIGTERM into :class:`Terminated` and ignore later ones (they would break into the
    clean-up). A forked worker that inherited the handler dies by SIGTERM as usual. Where SIGTERM was ignored,
    or outside the main thread, a no-op; the previous handler is restored on exit unless SIGTERM arrived."""
    previous = signal.getsignal(signal.SIGTERM)
    if threading.current_thread() is not threading.main_thread() or previous is signal.SIG_IGN:
        yield
        return
    pid = os.getpid()
    arrived = False

    def on_sigterm(signum, frame):
        nonlocal arrived
        if os.getpid() != pid:  # a forked worker: terminate as the signal means, no clean-up of the driver's
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)
            return
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        arrived = True
        raise Terminated

    signal.signal(signal.SIGTERM, on_sigterm)
    try:
        yield
    finally:
        if not arrived:
            signal.signal(signal.SIGTERM, previous)
