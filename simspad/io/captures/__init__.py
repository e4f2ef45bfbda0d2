"""Readers of real captures for ``simspad import``: the calibration file (``calibration.py``), event streams
(``events.py``: EVT 3.0, DSEC, AEDAT 4, structured ``.npy``), SPAD photon cubes (``spad.py``: packed ``.npy``,
``.npz``, raw ``.bin``) and frame stacks (``frames.py``: TIFF, PNG folders, timestamps). File formats only: the
recording is assembled by :mod:`simspad.captures`."""
