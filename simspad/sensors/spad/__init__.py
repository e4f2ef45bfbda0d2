"""SPAD sensor (docs/sensors.md, preset ``swissspad2``): gated binary frames with calibrated noise.

- :mod:`~simspad.sensors.spad.model`: the detection model (Λ, dark counts, gate, bins, bit packing, attrs);
- :mod:`~simspad.sensors.spad.kernel`: the numba sampler (sparse/dense, afterpulsing and crosstalk);
- :mod:`~simspad.sensors.spad.simulator`: the chunked driver that streams ``/spad`` into a recording.
"""

from simspad.sensors.spad.model import (
    auto_gate,
    dcr_map,
    n_bins,
    pack_bits,
    resolve_gate,
    spad_attrs,
    unpack_bits,
)
from simspad.sensors.spad.simulator import SpadChunker, chunk_bins, h5_chunk_bins, simulate_spad

__all__ = ["SpadChunker", "auto_gate", "chunk_bins", "dcr_map", "h5_chunk_bins", "n_bins", "pack_bits",
           "resolve_gate", "simulate_spad", "spad_attrs", "unpack_bits"]
