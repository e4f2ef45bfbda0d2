"""Fusion methods and baselines (DESIGN §7): read recordings only, output flux frames and their bandwidth."""

from simspad.methods.registry import Bandwidth, Method, Reconstruction, available_methods, get_method, register

__all__ = ["Bandwidth", "Method", "Reconstruction", "available_methods", "get_method", "register"]
