"""When an output was made: the creation timestamp written into recordings and manifests.

``SOURCE_DATE_EPOCH`` (the reproducible-builds convention, an integer Unix time) pins it, so that separate runs
of one spec write byte-identical files.
"""

from __future__ import annotations

import datetime as _dt
import os

from simspad.errors import SimSpadError

SOURCE_DATE_EPOCH = "SOURCE_DATE_EPOCH"


def format_utc(when: _dt.datetime) -> str:
    """ISO 8601 UTC to the second with a ``Z`` suffix, e.g. ``2023-11-14T22:13:20Z``."""
    return when.astimezone(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def utc_now() -> str:
    """The current time, formatted by :func:`format_utc`."""
    return format_utc(_dt.datetime.now(_dt.timezone.utc))


def source_date_epoch() -> str | None:
    """``$SOURCE_DATE_EPOCH`` as a formatted UTC time, or None when unset or empty.

    Raises
    ------
    SimSpadError
        When it is set but not an integer Unix time.
    """
    when = _source_date_epoch_datetime()
    return None if when is None else format_utc(when)


def _source_date_epoch_datetime() -> _dt.datetime | None:
    epoch = os.environ.get(SOURCE_DATE_EPOCH, "").strip()
    if not epoch:
        return None
    try:
        return _dt.datetime.fromtimestamp(int(epoch), _dt.timezone.utc)
    except (ValueError, OverflowError, OSError):
        raise SimSpadError(f"expected an integer Unix time, got {epoch!r}", field=SOURCE_DATE_EPOCH) from None


def created_datetime() -> _dt.datetime:
    """The creation time of an output, timezone-aware UTC to the second: ``$SOURCE_DATE_EPOCH`` when set, else
    now (``results.json`` writes it in ISO 8601 with ``+00:00``)."""
    return _source_date_epoch_datetime() or _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0)


def created_utc() -> str:
    """``$SOURCE_DATE_EPOCH`` when set, else now (:func:`format_utc`)."""
    return format_utc(created_datetime())
