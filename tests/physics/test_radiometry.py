"""Radiometry: photons per lux from the illuminant spectrum, luminance from RGB, the lux → flux chain."""

import math

import colour
import numpy as np
import pytest
from colour.constants import CONSTANT_K_M, CONSTANT_LIGHT_SPEED, CONSTANT_PLANCK

from simspad.physics import radiometry as rad


def _photons_per_lux_reference(name: str) -> float:
    """Independent route: colour's luminous_flux on a 1 nm re-interpolated SPD over 380–780 nm."""
    sd = colour.SDS_ILLUMINANTS[name].copy()
    sd = sd.interpolate(colour.SpectralShape(380, 780, 1))
    wl_m = sd.wavelengths * 1e-9
    photons = np.sum(sd.values * wl_m / (CONSTANT_PLANCK * CONSTANT_LIGHT_SPEED)) * 1.0  # 1 nm steps
    return photons / colour.luminous_flux(sd)


@pytest.mark.parametrize("name, literature", [("D65", 1.389e16), ("A", 2.10e16), ("LED-B3", None)])
def test_photons_per_lux_matches_colour_integral(name, literature):
    value = rad.photons_per_lux(name)
    assert value == pytest.approx(_photons_per_lux_reference(name), rel=5e-3)
    if literature is not None:
        assert value == pytest.approx(literature, rel=5e-3)


def test_photons_per_lux_monochromatic_555nm():
    # At 555 nm, 1 lx = 1/683 W m⁻², and a photon carries hc/λ.
    expected = (1 / CONSTANT_K_M) / (CONSTANT_PLANCK * CONSTANT_LIGHT_SPEED / 555e-9)
    assert rad.photons_per_lux(555.0) == pytest.approx(expected, rel=1e-3)
    assert rad.photons_per_lux(555.0) == pytest.approx(4.09e15, rel=5e-3)


def test_unknown_illuminant_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown illuminant 'D99'"):
        rad.photons_per_lux("D99")
    with pytest.raises(ValueError, match="f_number"):
        rad.Optics(f_number=0)


def test_luminance_from_rgb_matches_colour():
    rgb = np.random.default_rng(1).random((7, 5, 3)).astype(np.float32)
    expected = colour.RGB_to_XYZ(rgb, "sRGB")[..., 1]
    np.testing.assert_allclose(rad.luminance_from_rgb(rgb), expected, rtol=1e-5, atol=1e-7)
    assert rad.luminance_from_rgb(rgb).dtype == np.float32


def test_flux_scale_follows_the_lux_convention_and_camera_equation():
    y_rel = np.random.default_rng(2).gamma(2.0, 0.3, size=(40, 60)).astype(np.float32)
    lux = 37.0
    optics = rad.Optics(f_number=2.8, lens_transmission=0.85, illuminant="A")
    luminance = y_rel * rad.luminance_scale(float(y_rel.mean()), lux, optics)
    assert luminance.mean() == pytest.approx(0.18 * lux / math.pi, rel=1e-5)
    flux = y_rel * rad.flux_scale(float(y_rel.mean()), lux, optics)
    e_img = math.pi * luminance * 0.85 / (4 * 2.8**2)
    np.testing.assert_allclose(flux, e_img * rad.photons_per_lux("A"), rtol=1e-5)
    # Linear in lux and in 1/N².
    assert rad.flux_scale(1.0, 2 * lux, optics) == pytest.approx(2 * rad.flux_scale(1.0, lux, optics))
    assert rad.flux_scale(1.0, lux, rad.Optics(f_number=1.4, lens_transmission=0.85, illuminant="A")) == \
        pytest.approx(rad.flux_scale(1.0, lux, optics) * 4.0)


def test_detection_rate_and_spad_saturation_sanity():
    # docs/sensors.md: with the SwissSPAD2 preset at f/2, mid-grey λ·bin is about 1.8 near 100 lx.
    flux_mid_grey = rad.flux_scale(1.0, 100.0) * 1.0
    rate = rad.detection_rate(flux_mid_grey, 16.38e-6, 0.105, 0.45)
    assert float(rate) * 10.24e-6 == pytest.approx(1.8, rel=0.25)
    assert rad.detection_rate(2.0, 1e-5, 0.5, 0.5) == pytest.approx(2.0 * 1e-10 * 0.25)


def test_bad_lux_is_rejected():
    with pytest.raises(ValueError, match="lux"):
        rad.flux_scale(1.0, 0.0)
    with pytest.raises(ValueError, match="mean_relative_luminance"):
        rad.flux_scale(float("nan"), 1.0)
