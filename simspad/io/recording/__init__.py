"""The recording file (docs/format.md): one HDF5 file per sequence × lux.

Writing goes through :class:`RecordingWriter` (:mod:`.writer`), reading through :func:`open_recording`, which
returns a :class:`Recording` with one view per group (:mod:`.ground_truth`, :mod:`.spad`, :mod:`.frames`,
:mod:`.events`, and one per row of the sensor-group table) once :mod:`.validation` has checked the file against
docs/format.md; :mod:`.layout` names the format and holds that table (:data:`SENSOR_LAYOUTS`). This package
presents that API.
"""

from simspad.io.recording.layout import FORMAT, FORMAT_VERSION, SENSOR_KINDS, SENSOR_LAYOUTS, SensorLayout
from simspad.io.recording.reader import Recording, open_recording
from simspad.io.recording.writer import Appender, RecordingWriter

__all__ = ["FORMAT", "FORMAT_VERSION", "SENSOR_KINDS", "SENSOR_LAYOUTS", "Appender", "Recording", "RecordingWriter",
           "SensorLayout", "open_recording"]
