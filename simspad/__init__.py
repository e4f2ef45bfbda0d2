"""SimSPAD: physically rendered synthetic SPAD, frame and event datasets.

See ``docs/format.md`` (the file formats), ``docs/sensors.md`` (the physics), ``docs/methods.md`` (methods and
evaluation) and ``docs/internals.md`` (the package's layers and where to add things).

:func:`open_recording` reads a recording (``.h5``) for analysis or machine learning: ``rec.events.windows(dt_s)``,
``rec.spad.blocks(n)``, ``rec.frames.items()`` and ``rec.gt.items()`` are lazy sequences usable as a
``torch.utils.data.Dataset`` (see ``examples/torch_dataset.py``).

The method interface is public too: subclass :class:`Method` (yield flux frames, add reads to the bandwidth
tally) and declare it in your package's ``simspad.methods`` entry points, or :func:`register` it in this process;
:func:`get_method` builds any method by name with its parameters (``docs/methods.md``).
"""

__version__ = "0.1.0"
__all__ = ["__version__", "open_recording", "Method", "Reconstruction", "Bandwidth", "register", "get_method",
           "available_methods", "method_parameters"]

_METHOD_API = {"Method", "Reconstruction", "Bandwidth", "register", "get_method", "available_methods",
               "method_parameters"}


def __getattr__(name: str):
    if name == "open_recording":
        from simspad.io.recording import open_recording  # deferred: `import simspad` (so `simspad --help`) stays without h5py

        return open_recording
    if name in _METHOD_API:
        from simspad import methods  # deferred: `import simspad` stays without numba and the methods

        return getattr(methods, name)
    raise AttributeError(f"module 'simspad' has no attribute {name!r}")
