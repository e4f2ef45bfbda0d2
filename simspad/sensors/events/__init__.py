"""Event camera (docs/sensors.md, preset ``prophesee_gen4``): a per-pixel DVS model with exact crossing times.

- :mod:`.model` — the model's equations, event labels, fixed pattern (:class:`PixelMaps`), parameter checks;
- :mod:`.crossing` — threshold crossings of the change detector inside one internal step;
- :mod:`.kernel` — the per-pixel integrator (numba) and the records it takes;
- :mod:`.knot_table` — ln I and slopes at the knots, computed a tile of pixels ahead of the integrator;
- :mod:`.codes` — an event's pixel, polarity and label packed in one int64;
- :mod:`.sort` — the canonical (µs, pixel) order of a chunk's events;
- :mod:`.simulator` — the streaming simulator and the ``/events`` writer.

The photoreceptor formulas (photocurrent, cutoff, shot-noise rate) live in :mod:`simspad.physics.photoreceptor`.
"""

from simspad.sensors.events.model import (
    LABEL_HOT,
    LABEL_LEAK,
    LABEL_NAMES,
    LABEL_SHOT,
    LABEL_SIGNAL,
    PixelMaps,
    draw_pixel_maps,
    sensor_current_1lux_e_s,
    sensor_photocurrent_e_s,
)
from simspad.sensors.events.simulator import (
    CHUNK_BYTES,
    CHUNK_PIECES,
    EVENT_CHUNK_ROWS,
    EventSimulator,
    check_noise_work,
    iter_knot_chunks,
    simulate_events,
    timestamps_us,
)
from simspad.sensors.events.sort import EventColumns, sort_events

__all__ = [
    "CHUNK_BYTES",
    "CHUNK_PIECES",
    "EVENT_CHUNK_ROWS",
    "LABEL_HOT",
    "LABEL_LEAK",
    "LABEL_NAMES",
    "LABEL_SHOT",
    "LABEL_SIGNAL",
    "EventColumns",
    "EventSimulator",
    "check_noise_work",
    "PixelMaps",
    "draw_pixel_maps",
    "iter_knot_chunks",
    "sensor_current_1lux_e_s",
    "sensor_photocurrent_e_s",
    "simulate_events",
    "sort_events",
    "timestamps_us",
]
