"""Fusion methods and baselines (docs/methods.md): read recordings only, output flux frames and their bandwidth.

=====================  ==========================  =========================================================
name                   label                       what it reads / does (defaults and their source)
=====================  ==========================  =========================================================
``nedi_akf``           NEDI+AKF (S+E)              SPAD aggregates at 0.4 kHz (the paper's rate) deblurred by
                                                   NEDI, fused with events by the AKF (:mod:`.akf`)
``adaptive_nedi_akf``  Adaptive NEDI+AKF (S+E)     the same, reading a tile's aggregate only when its mean P
                                                   exceeds (c/2)² or a readout would halve it (:mod:`.adaptive`)
``akf_fe``             AKF (F+E)                   conventional frames, EDI-deblurred, fused by the AKF
``cf``                 CF (E)                      events only, complementary filter, f_cut 0.1 Hz (:mod:`.cf`)
``edi``                EDI (F+E)                   event double integral at the nominal threshold (:mod:`.edi`)
``ni``                 NI (S)                      SPAD aggregates at 0.4 kHz, ML inversion (:mod:`.ni`)
``nedi``               NEDI (S+E)                  SPAD aggregates deblurred by NEDI (:mod:`.nedi`)
``qbp``                QBP (S)                     raw bits: align and merge 1000-bin bursts (:mod:`.qbp`)
=====================  ==========================  =========================================================

All parameters come from the recording's attrs (docs/format.md); none is tuned per scene.
"""

from simspad.methods.method import Bandwidth, Method, Reconstruction
from simspad.methods.registry import available_methods, get_method, method_parameters, register

__all__ = ["Bandwidth", "Method", "Reconstruction", "available_methods", "get_method", "method_parameters", "register"]
