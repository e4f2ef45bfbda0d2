"""The recording file (docs/format.md): one HDF5 file per sequence × lux.

Writing goes through :class:`RecordingWriter` (:mod:`.writer`), reading through :func:`open_recording`, which
returns a :class:`Recording` with one view per group (:mod:`.ground_truth`, :mod:`.spad`, :mod:`.frames`,
:mod:`.events`) once :mod:`.validation` has checked the file against docs/format.md; :mod:`.layout` names the
format and what each group holds. This package presents that API.
"""

from simspad.io.recording.layout import FORMAT, FORMAT_VERSION, SENSOR_KINDS
from simspad.io.recording.reader import Recording, open_recording
from simspad.io.recording.writer import Appender, RecordingWriter

__all__ = ["FORMAT", "FORMAT_VERSION", "SENSOR_KINDS", "Appender", "Recording", "RecordingWriter",
           "open_recording"]
