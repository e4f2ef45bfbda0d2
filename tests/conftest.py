"""Fixtures shared by the test suite; real components only (no mocks).

- ``simspad_cli``: runs ``python -m simspad.cli`` in a child process, so that tests of exit codes and stderr see
  what a user's shell sees; ``child_env`` is the environment of such a process (and of the examples' scripts):
  *this checkout's* package first on ``PYTHONPATH``, since an editable install may point at another copy.
- ``evaluation_dataset``: a small real dataset directory (manifest + two SPAD recordings, see
  ``tests.helpers.evaluation_data``), written once per session and shared read-only by the evaluation tests.
- ``_hermetic_environment`` (automatic): tests do not depend on the caller's ``SOURCE_DATE_EPOCH``.

Markers: ``slow`` marks the heavy tests (see ``pyproject.toml``); ``python -m pytest -m "not slow"`` is the quick
loop, the plain command (CI, README) runs everything. A per-test timeout is set in ``pyproject.toml``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from simspad.io.provenance import SOURCE_DATE_EPOCH
from tests.helpers.evaluation_data import write_dataset

REPO = Path(__file__).resolve().parents[1]
#: Seconds a child ``simspad`` process may take before the test fails (it compiles numba kernels on first use).
CLI_TIMEOUT_S = 300


@pytest.fixture(scope="session", autouse=True)
def _hermetic_environment():
    """Unset ``SOURCE_DATE_EPOCH`` for the session: it pins ``created_utc`` and would change recordings' bytes.

    Tests that need a pinned time pass it explicitly (``created_utc=``, or ``env=`` of ``simspad_cli``).
    """
    with pytest.MonkeyPatch.context() as patch:
        patch.delenv(SOURCE_DATE_EPOCH, raising=False)
        yield


@pytest.fixture(scope="session")
def child_env(_hermetic_environment) -> dict[str, str]:
    """The environment for a child Python process: the session's, with this repository first on ``PYTHONPATH``."""
    python_path = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
    return {**os.environ, "PYTHONPATH": python_path}


class SimspadProcess:
    """``simspad`` as a child process (``python -m simspad.cli``).

    Parameters
    ----------
    env : dict of str to str
        The child's environment (``child_env``); kept as ``self.env`` for ``subprocess.Popen``.
    """

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env

    @staticmethod
    def command(*args: object) -> list[str]:
        """The argument vector of ``simspad ARGS…`` (for ``subprocess.Popen``)."""
        return [sys.executable, "-m", "simspad.cli", *map(str, args)]

    def run(self, *args: object, env: dict[str, str] | None = None,
            timeout_s: float = CLI_TIMEOUT_S) -> subprocess.CompletedProcess:
        """Run ``simspad ARGS…`` to completion; text stdout and stderr are captured, ``env`` adds variables."""
        return subprocess.run(self.command(*args), capture_output=True, text=True, timeout=timeout_s,
                              env={**self.env, **(env or {})})


@pytest.fixture(scope="session")
def simspad_cli(child_env) -> SimspadProcess:
    """Runs the ``simspad`` command in a child process: ``simspad_cli.run("info", path).returncode``."""
    return SimspadProcess(child_env)


def _file_states(root: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(root.rglob("*"))}


@pytest.fixture(scope="session")
def evaluation_dataset(tmp_path_factory) -> Path:
    """A dataset of two static-scene SPAD recordings (10 and 100 lx) and a manifest with one 'failed' entry.

    Shared by the whole session, so read-only: a test that needs to change it copies it first. The fixture checks
    at the end of the session that no file in it was added, removed or rewritten.
    """
    root = write_dataset(tmp_path_factory.mktemp("evaluation") / "data")
    before = _file_states(root)
    yield root
    assert _file_states(root) == before, f"a test wrote into the shared evaluation dataset {root}"
