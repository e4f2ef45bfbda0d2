"""Real captures in: ``simspad import`` assembles a recording from a calibration file and the captures it names
(``build.py``), mapping every sensor onto the reference grid (``geometry.py``). The file formats themselves are
read by :mod:`simspad.io.captures`."""
