"""The tabulated colour-science numbers (simspad/physics/colour_tables.py) against colour-science itself."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from simspad.physics import colour_tables
from simspad.physics.colour_tables import photons_per_lux_from_spectrum
from simspad.physics.radiometry import luminance_from_rgb, photons_per_lux


def test_tables_equal_what_colour_science_computes():
    """Every entry is the float colour-science gives today (regenerate with `python -m simspad.physics.colour_tables`
    if this fails after an upgrade), and the table covers every illuminant it names."""
    row, table = colour_tables.tabulate()
    assert colour_tables.SRGB_TO_Y == row
    assert colour_tables.PHOTONS_PER_LUX == table
    assert len(table) > 50 and abs(table["D65"] / 1.3887e16 - 1) < 1e-3  # D65: 1.389e16 photons s⁻¹ m⁻² lx⁻¹


def test_names_outside_the_table_are_computed_with_colour_science():
    """A wavelength (monochromatic light) and a name spelled otherwise than the table's go to colour-science."""
    assert photons_per_lux("d65") == photons_per_lux_from_spectrum("d65") == colour_tables.PHOTONS_PER_LUX["D65"]
    # 555 nm: 1 lx = 1/683 W m⁻², photons of hc/λ each
    assert abs(photons_per_lux(555.0) / (555e-9 / (6.62607015e-34 * 299792458.0) / 683.0) - 1) < 1e-3


def test_simulation_numbers_do_not_import_colour_science():
    """A simulation process gets photons per lux and luminance weights without paying colour-science's import."""
    code = ("import sys, numpy as np; from simspad.physics.radiometry import Optics, luminance_from_rgb; "
            "Optics(); luminance_from_rgb(np.ones((2, 2, 3), np.float32)); "
            "print('colour' in sys.modules, 'matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
    y = luminance_from_rgb(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], np.float32))
    assert np.allclose(y, [0.2126, 0.7152, 0.0722]) and abs(float(y.sum()) - 1) < 1e-6
