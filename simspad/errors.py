"""User-facing errors.

A :class:`SimSpadError` is bad input, not a bug: the CLI prints its message on one line (no traceback) and
exits non-zero. Its message names the file and the field at fault and what was expected.
"""

from __future__ import annotations

from pathlib import Path


class SimSpadError(Exception):
    """Bad input that the user can fix.

    Parameters
    ----------
    message : str
        What is wrong and what was expected.
    path : str or Path, optional
        The file at fault.
    field : str, optional
        The field (dotted path, dataset name, column, ...) at fault.
    """

    exit_code = 2

    def __init__(self, message: str, *, path: str | Path | None = None, field: str | None = None):
        self.message = message
        self.path = None if path is None else str(path)
        self.field = field
        super().__init__(self.format())

    def format(self) -> str:
        where = ": ".join(p for p in (self.path, self.field) if p)
        return f"{where}: {self.message}" if where else self.message


class SpecError(SimSpadError):
    """One or more validation errors in a dataset spec; ``errors`` holds one line each."""

    def __init__(self, errors: list[str], *, path: str | Path | None = None):
        self.errors = list(errors)
        super().__init__("\n".join(self.errors), path=None)
        self.path = None if path is None else str(path)

    def format(self) -> str:
        # Each line names its own file and field; prefix the path only to lines that lack it.
        if self.path is None:
            return self.message
        return "\n".join(line if line.startswith(self.path) else f"{self.path}: {line}" for line in self.errors)


class InputError(SimSpadError):
    """A malformed input file (render directory, trajectory, recording, submission)."""
