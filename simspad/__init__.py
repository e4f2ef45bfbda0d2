"""SimSPAD: physically rendered synthetic SPAD, frame and event datasets.

See ``docs/format.md`` (the file formats), ``docs/sensors.md`` (the physics), ``docs/methods.md`` (methods and
evaluation) and ``docs/internals.md`` (the package's layers and where to add things).
"""

__version__ = "0.1.0"
