"""SimSPAD: physically rendered synthetic SPAD, frame and event datasets.

See ``docs/format.md`` (the file formats), ``docs/sensors.md`` (the physics), ``docs/methods.md`` (methods and
evaluation) and ``docs/internals.md`` (the package's layers and where to add things).

:func:`open_recording` reads a recording (``.h5``) for analysis or machine learning: ``rec.events.windows(dt_s)``,
``rec.spad.blocks(n)``, ``rec.frames.items()`` and ``rec.gt.items()`` are lazy sequences usable as a
``torch.utils.data.Dataset`` (see ``examples/torch_dataset.py``).

The method interface is public in :mod:`simspad.methods` (``Method``, ``Reconstruction``, ``Bandwidth``,
``register``, ``get_method``, ``method_parameters``, ``available_methods``): subclass ``Method`` and declare it in
your package's ``simspad.methods`` entry points (``docs/methods.md``). It is not re-exported here, because every
layer imports this module for ``__version__`` and must not reach the methods through it.
"""

__version__ = "0.1.0"
__all__ = ["__version__", "open_recording"]


def __getattr__(name: str):
    if name == "open_recording":
        from simspad.io.recording import open_recording  # deferred: `import simspad` (so `simspad --help`) stays without h5py

        return open_recording
    raise AttributeError(f"module 'simspad' has no attribute {name!r}")
