"""What every exporter shares: checking that the recording holds the sensor a format needs, and the chunk size."""

from __future__ import annotations

from simspad.errors import InputError

#: Events per chunk when an exporter streams ``/events`` (bounded memory whatever the recording length).
EXPORT_CHUNK_EVENTS = 1 << 20


def require_group(rec, group: str, fmt: str) -> None:
    """InputError naming the recording and the group when ``rec`` lacks ``group``, which ``fmt`` needs."""
    if not rec.has(group):
        present = ", ".join(rec.sensors) or "none"
        raise InputError(f"the recording has no /{group} group, which export to {fmt} needs (sensors present: "
                         f"{present})", path=rec.path, field=f"/{group}")


def check_sorted(t_us, previous_us: int, rec, first_index: int) -> None:
    """InputError when event timestamps ``t_us`` (starting at event ``first_index``) go backwards.

    Every target format indexes events by time, so unsorted input would be written as a corrupt file.
    """
    if t_us.size == 0:
        return
    if t_us[0] < previous_us or (t_us.size > 1 and (t_us[1:] < t_us[:-1]).any()):
        bad = first_index + (0 if t_us[0] < previous_us else int((t_us[1:] < t_us[:-1]).argmax()) + 1)
        raise InputError(f"event timestamps are not sorted (event {bad} goes back in time)", path=rec.path,
                         field="/events/t")
