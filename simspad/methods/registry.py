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
#: The class behind each registered name (its :meth:`Method.parameters` and descriptive attributes).
_CLASSES: dict[str, type[Method]] = {}
#: Entry-point group through which an installed package adds methods (docs/methods.md, "Adding a method").
ENTRY_POINT_GROUP = "simspad.methods"
#: Plugin methods that could not be loaded: name → the one-line reason, reported when the name is asked for.
_BROKEN_PLUGINS: dict[str, str] = {}


def register(method) -> None:
    """Register a method instance or a method class (called with the parameters) under its ``name``.

    Registered in one process only: ``simspad evaluate`` runs methods in worker processes, which see a method
    registered by an installed package's ``simspad.methods`` entry point (loaded when this module is imported).
    """
    if isinstance(method, Method):
        instance = method

        def factory(**params):
            return type(instance)(**params) if params else instance
        cls = type(instance)
    elif isinstance(method, type) and issubclass(method, Method):
        factory = cls = method
    else:
        raise TypeError(f"expected a Method subclass or instance, got {method!r}")
    name = method.name
    if not name:
        raise ValueError("a method needs a non-empty name")
    _REGISTRY[name] = factory
    _CLASSES[name] = cls


for _cls in BUILTIN_METHODS:
    register(_cls)


def _load_plugins() -> None:
    """Register the methods of installed packages (entry points of :data:`ENTRY_POINT_GROUP`). A plugin that
    fails to import, is not a Method or takes a built-in method's name is kept out and remembered, so that the
    run that asks for it gets one line naming the entry point, and every other run is unaffected."""
    from importlib.metadata import entry_points  # deferred: only the registry asks for plugins

    builtin = {c.name for c in BUILTIN_METHODS}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        where = f"plugin method {ep.name!r} (entry point {ep.value!r} of group {ENTRY_POINT_GROUP!r})"
        try:
            obj = ep.load()
        except Exception as exc:  # a broken plugin must not stop the built-in methods
            _BROKEN_PLUGINS[ep.name] = f"{where} failed to load: {type(exc).__name__}: {exc}"
            continue
        name = getattr(obj, "name", None)
        if not ((isinstance(obj, type) and issubclass(obj, Method)) or isinstance(obj, Method)):
            _BROKEN_PLUGINS[ep.name] = f"{where} is not a simspad.methods.Method subclass or instance"
        elif name != ep.name:
            _BROKEN_PLUGINS[ep.name] = f"{where}: the method's name is {name!r}; the entry point must be named so"
        elif name in builtin:
            _BROKEN_PLUGINS[ep.name] = f"{where} takes the name of a built-in method"
        else:
            register(obj)


_load_plugins()


def _check_known(name: str) -> None:
    if name in _BROKEN_PLUGINS:
        raise SimSpadError(_BROKEN_PLUGINS[name], field="methods")
    if name not in _REGISTRY:
        raise SimSpadError(f"unknown method {name!r} (expected one of {', '.join(sorted(_REGISTRY))})",
                           field="methods")


def get_method(name: str, **params) -> Method:
    """The method registered as ``name``, built with optional keyword parameters.

    Raises :class:`simspad.errors.SimSpadError` naming the unknown method and the known ones, or the parameters
    the method refused.
    """
    _check_known(name)
    factory = _REGISTRY[name]
    if not params:
        return factory()
    try:
        return factory(**params)
    except (TypeError, ValueError) as exc:
        raise SimSpadError(f"bad parameters {sorted(params)} for method {name!r} ({exc})",
                           field=f"methods.{name}") from None


def method_class(name: str) -> type[Method]:
    """The class registered as ``name`` (its label, sensors and :meth:`~Method.parameters`)."""
    _check_known(name)
    return _CLASSES[name]


def method_parameters(name: str) -> dict[str, object]:
    """Parameters of method ``name`` with their defaults (None: derived from the recording)."""
    return method_class(name).parameters()


def check_method_params(name: str, params, *, path=None, field: str = "params") -> dict[str, object]:
    """Validate parameters of method ``name`` as a user wrote them; return them with numbers as the defaults'
    types (an int where the default is an int, a float where it is a float).

    A name the method does not take, a value of the wrong kind, or one the method's constructor refuses is one
    :class:`SimSpadError` naming ``field``.KEY (and ``path``, the spec or manifest it came from).
    """
    if not isinstance(params, dict):
        raise SimSpadError(f"expected a table of parameters of method {name!r}, got {params!r}", path=path,
                           field=f"{field}.{name}")
    _check_known(name)
    known = method_parameters(name)
    out = {}
    for key, value in params.items():
        where = f"{field}.{name}.{key}"
        if key not in known:
            raise SimSpadError(f"unknown parameter of method {name!r} (expected one of {', '.join(known) or 'none'})",
                               path=path, field=where)
        out[key] = _coerce(value, known[key], path=path, field=where)
    try:
        get_method(name, **out)
    except SimSpadError as exc:
        raise SimSpadError(exc.message, path=path, field=f"{field}.{name}") from None
    return out


def _coerce(value, default, *, path, field):
    """``value`` checked against the kind of ``default``: bool for a bool, an integral number for an int, a finite
    number for a float, a string or number for a string (e.g. ``threshold = "auto"`` or 0.2), any finite number,
    string or bool where the default is None."""
    import math  # deferred: only parameter checks need it

    def bad(expected):
        return SimSpadError(f"got {value!r} (expected {expected})", path=path, field=field)

    is_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if is_number and not math.isfinite(value):
        raise bad("a finite number")
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if isinstance(default, int):
        if not is_number or float(value) != int(value):
            raise bad("an integer")
        return int(value)
    if isinstance(default, float):
        if not is_number:
            raise bad("a number")
        return float(value)
    if isinstance(default, str):
        if not (isinstance(value, str) or is_number):
            raise bad("a string or a number")
        return value
    if not (is_number or isinstance(value, (str, bool))):
        raise bad("a number, string or boolean")
    return value


def available_methods(rec=None) -> list[str]:
    """Names of registered methods, in registration order; with ``rec`` only those whose inputs it has."""
    names = list(_REGISTRY)
    if rec is None:
        return names
    return [n for n in names if all(rec.has(k) for k in _CLASSES[n].requires)]
