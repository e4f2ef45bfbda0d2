"""Registers the built-in methods (imported lazily by the registry), in the order of the reference paper."""

from simspad.methods.adaptive import AdaptiveNediAkf
from simspad.methods.akf import AkfFrames, NediAkf
from simspad.methods.cf import CF
from simspad.methods.edi import EDI
from simspad.methods.nedi import NEDI
from simspad.methods.ni import NI
from simspad.methods.qbp import QBP
from simspad.methods.registry import register

for _cls in (NediAkf, AdaptiveNediAkf, AkfFrames, CF, EDI, NI, NEDI, QBP):
    register(_cls)
