"""Event simulation in a fresh process starts warm: every kernel it dispatches loads from numba's on-disk cache."""

import json
import os
import subprocess
import sys
from pathlib import Path

import simspad

# A small simulation over two time chunks (so the held-back events are merged too), then the cache statistics of
# every numba dispatcher of the events package that was called: {name: [hits, misses]}.
_SIMULATE = """
import json, numba, numpy as np
from simspad.radiance.timeline import Timeline
from simspad.sensors import events
from simspad.sensors.events import codes, crossing, kernel, knot_table, simulator, sort
from simspad.sensors.presets import EventParams

rng = np.random.default_rng(1)
times = np.arange(6) * 1e-3
frames = np.exp(2.0 * rng.normal(size=(6, 8, 8))).astype(np.float32) * 1e17  # photons s⁻¹ m⁻²: ≈ 10⁵ e⁻ s⁻¹
tl = Timeline.from_arrays(times, frames)
params = EventParams()
maps = events.draw_pixel_maps(params, (8, 8), np.random.default_rng(0))
sim = events.EventSimulator(params, (8, 8), events.sensor_photocurrent_e_s(tl.sample(0.0), params).ravel(), 0.0,
                            events.sensor_current_1lux_e_s(float(frames[0].mean()), 1.0, params), maps)
n = sum(sim.advance(t, c).t_s.size for t, c in events.iter_knot_chunks(tl, 0.0, tl.t_end, params, max_pieces=2))
n += sim.finish().t_s.size
assert n > 0
stats = {}
for mod in (codes, crossing, kernel, knot_table, simulator, sort):
    for name, obj in vars(mod).items():
        if isinstance(obj, numba.core.registry.CPUDispatcher) and obj.signatures:
            stats[f"{mod.__name__}.{name}"] = [sum(obj.stats.cache_hits.values()),
                                               sum(obj.stats.cache_misses.values())]
print(json.dumps(stats))
"""


def _simulate_in_fresh_process() -> dict:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(simspad.__file__).resolve().parents[1]),
                                                         os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _SIMULATE], capture_output=True, text=True, env=env, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_second_process_compiles_nothing():
    """The first process compiles and caches whatever this checkout has not cached yet; the second finds every
    signature it dispatches in the cache: numba's own start-up is all it pays."""
    _simulate_in_fresh_process()
    stats = _simulate_in_fresh_process()
    assert {"simspad.sensors.events.kernel.init_state", "simspad.sensors.events.kernel.simulate_blocks",
            "simspad.sensors.events.sort.merge_front"} <= stats.keys()
    compiled = {name: hits_misses for name, hits_misses in stats.items() if hits_misses[1] > 0}
    assert not compiled, f"compiled in the second process (cache hits, misses): {compiled}"
    assert all(hits > 0 for hits, _ in stats.values())
