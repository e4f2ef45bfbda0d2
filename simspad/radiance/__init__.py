"""The radiance timeline: rendered keyframes of linear radiance, interpolated in time for the sensors."""
