"""A test hook that kills the worker process running a chosen task, as the kernel's OOM killer or a segfault would.

Set ``SIMSPAD_KILL_WORKER`` (inherited by every worker process) to a comma-separated list of task labels —
``simulate:<recording path>`` or ``render:<sequence>:<first keyframe index of the chunk>`` — and the worker that
starts such a task sends itself SIGKILL. ``LABEL@PATH`` kills only while ``PATH`` does not exist (the hook
creates it first), i.e. once: the retried task then succeeds. Unset (always, outside tests) it does nothing.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

KILL_ENV = "SIMSPAD_KILL_WORKER"


def maybe_inject_fault(label: str) -> None:
    """SIGKILL this process if ``$SIMSPAD_KILL_WORKER`` names ``label``."""
    spec = os.environ.get(KILL_ENV)
    if not spec:
        return
    for item in spec.split(","):
        name, _, once_path = item.partition("@")
        if name != label:
            continue
        if once_path:
            marker = Path(once_path)
            if marker.exists():
                return
            marker.touch()
        os.kill(os.getpid(), signal.SIGKILL)
