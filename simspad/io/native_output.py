"""Capture what a C/C++ library prints on the process's stdout and stderr, so it never reaches the user raw.

The OpenEXR bindings print "Warning: Exception raised reading pixel data …" on *stdout* (``std::cout``) and the
OpenEXR core library its ``EXR_ERR_…`` diagnostics on stderr when a file is corrupt, then raise an exception that
says less ("file has 0 parts"). Python's ``sys.stdout`` redirection does not see native writes, so the file
descriptors themselves are redirected into a temporary file for the duration of the call; the caller puts the
useful part into its own one-line message.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import tempfile
import threading
from typing import Iterator


#: File descriptors 1 and 2 are process-wide: one capture at a time (a Dask worker may run tasks in threads).
_CAPTURE_LOCK = threading.Lock()


class NativeOutput:
    """The text captured by :func:`captured_native_output` (``text``: available once the block has ended)."""

    def __init__(self) -> None:
        self.text = ""

    def first_line(self, containing: str = "") -> str:
        """The first non-empty captured line that contains ``containing`` ("" if none)."""
        for line in self.text.splitlines():
            if line.strip() and containing in line:
                return line.strip()
        return ""


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers (a native ``printf`` to a pipe is block-buffered)."""
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def captured_native_output() -> Iterator[NativeOutput]:
    """Redirect file descriptors 1 and 2 into a temporary file while the block runs; yield what was written.

    Python-level output of the block is captured as well (it is flushed first). Where the descriptors cannot be
    duplicated (no stdout at all), the block runs uncaptured.
    """
    with _CAPTURE_LOCK:
        with _capture() as captured:
            yield captured


@contextlib.contextmanager
def _capture() -> Iterator[NativeOutput]:
    captured = NativeOutput()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    try:
        saved = (os.dup(1), os.dup(2))
    except OSError:
        yield captured
        return
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 1)
        os.dup2(sink.fileno(), 2)
        try:
            yield captured
        finally:
            for stream in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    stream.flush()
            _flush_c_stdio()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            captured.text = sink.read(1 << 16).decode("utf-8", "replace")
