"""Method table and dispatcher: every reconstruction method by name (docs/methods.md, docs/internals.md).

The table starts with the built-in methods in the order of the reference paper; :func:`register` adds more.
:func:`get_method` builds a method by name, :func:`available_methods` lists the names (all, or those whose
inputs a recording has). The interface the methods implement lives in :mod:`simspad.methods.method`; this
module sits above every method module, so none of them imports it (no cycle).
"""

from __future__ import annotations

from collections.abc import Callable

from simspad.errors import SimSpadError
from simspad.methods.adaptive import AdaptiveNediAkf
from simspad.methods.akf import AkfFrames, NediAkf
from simspad.methods.cf import CF
from simspad.methods.edi import EDI
from simspad.methods.method import Method
from simspad.methods.nedi import NEDI
from simspad.methods.ni import NI
from simspad.methods.qbp import QBP

#: The built-in methods, in the order of the reference paper (the order :func:`available_methods` lists them).
BUILTIN_METHODS: tuple[type[Method], ...] = (NediAkf, AdaptiveNediAkf, AkfFrames, CF, EDI, NI, NEDI, QBP)

_REGISTRY: dict[str, Callable[..., Method]] = {}


def register(method) -> None:
    """Register a method instance or a zero-argument factory (class) under its ``name``."""
    if isinstance(method, Method):
        instance = method

        def factory(**params):
            return type(instance)(**params) if params else instance
    else:
        factory = method
    name = method.name
    if not name:
        raise ValueError("a method needs a non-empty name")
    _REGISTRY[name] = factory


for _cls in BUILTIN_METHODS:
    register(_cls)


def get_method(name: str, **params) -> Method:
    """The method registered as ``name``, built with optional keyword parameters.

    Raises :class:`simspad.errors.SimSpadError` naming the unknown method and the known ones.
    """
    if name not in _REGISTRY:
        raise SimSpadError(f"unknown method {name!r} (expected one of {', '.join(sorted(_REGISTRY))})",
                           field="methods")
    factory = _REGISTRY[name]
    if not params:
        return factory()
    try:
        return factory(**params)
    except TypeError as exc:
        raise SimSpadError(f"bad parameters {sorted(params)} for method {name!r} ({exc})",
                           field=f"methods.{name}") from None


def available_methods(rec=None) -> list[str]:
    """Names of registered methods, in registration order; with ``rec`` only those whose inputs it has."""
    names = list(_REGISTRY)
    if rec is None:
        return names
    return [n for n in names if all(rec.has(k) for k in _REGISTRY[n]().requires)]
