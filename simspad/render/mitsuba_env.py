"""Choose and set the Mitsuba variant once per process (main process or Dask worker), and route Mitsuba's log.

Three backends, fastest first: ``cuda_ad_rgb`` when Dr.Jit finds a CUDA device, ``llvm_ad_rgb`` (vectorised,
JIT-compiled on the CPU) when it finds a working libLLVM, else ``scalar_rgb`` with one notice on stderr. Dr.Jit
finds libLLVM through ``DRJIT_LIBLLVM_PATH``, which must be set before its LLVM backend first initialises.
``SIMSPAD_MITSUBA_VARIANT`` forces one of the three; a forced backend that does not work here is refused.

The choice itself is :func:`choose_variant`, a pure function of what is available (:class:`Backends`), so that
every case (a GPU, no GPU, no libLLVM, a forced variant) is tested on any machine; :func:`probe_backends` finds
what is available, and :func:`select_variant` puts the two together.

Mitsuba's own log (warnings such as a sampler rounding its sample count) is written by :class:`_PlainAppender`:
one plain ``simspad: mitsuba: warning: …`` line per distinct message, no colour codes, no timestamps, so it never
runs into SimSPAD's own messages.
"""

from __future__ import annotations

import ctypes
import glob
import os
import re
import subprocess
import sys
from dataclasses import dataclass

from simspad.errors import SimSpadError

CUDA_VARIANT = "cuda_ad_rgb"
LLVM_VARIANT = "llvm_ad_rgb"
SCALAR_VARIANT = "scalar_rgb"
#: The variants SimSPAD renders with, fastest first.
VARIANTS = (CUDA_VARIANT, LLVM_VARIANT, SCALAR_VARIANT)
#: Environment variable that forces a variant.
VARIANT_ENV = "SIMSPAD_MITSUBA_VARIANT"
_LLVM_ENV = "DRJIT_LIBLLVM_PATH"
_LLVM_GLOBS = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19*", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so*",
               "/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*")
_notice_given = False
_log_routed = False


@dataclass(frozen=True)
class Backends:
    """What this process can render with.

    Attributes
    ----------
    cuda_device : str or None
        Name of the CUDA device Dr.Jit found (e.g. ``"NVIDIA H200"``); None when there is none.
    cuda_problem : str or None
        Why there is no CUDA device (for the message when one is forced); None when there is one.
    llvm : bool
        Whether Dr.Jit's LLVM backend works (a libLLVM was found and initialised).
    llvm_problem : str or None
        Why it does not (None when it does).
    """

    cuda_device: str | None = None
    cuda_problem: str | None = "not probed"
    llvm: bool = False
    llvm_problem: str | None = "not probed"


def choose_variant(forced: str | None, backends: Backends) -> tuple[str, str | None]:
    """The variant to render with, and the one-line notice to give (None: nothing to say).

    Parameters
    ----------
    forced : str or None
        A variant forced by the caller or ``SIMSPAD_MITSUBA_VARIANT``; None lets the backends decide.
    backends : Backends
        What is available.

    Returns
    -------
    (str, str or None)
        ``cuda_ad_rgb`` when a CUDA device is found, else ``llvm_ad_rgb`` when the LLVM backend works, else
        ``scalar_rgb`` with a notice saying why (it is several times slower). A forced variant is returned as is.

    Raises
    ------
    SimSpadError
        A forced variant that is not one of :data:`VARIANTS`, or whose backend does not work here.
    """
    if forced is not None:
        if forced not in VARIANTS:
            raise SimSpadError(f"unknown Mitsuba variant {forced!r}; SimSPAD renders with one of "
                               f"{', '.join(VARIANTS)}", field=VARIANT_ENV)
        if forced == CUDA_VARIANT and backends.cuda_device is None:
            raise SimSpadError(f"{CUDA_VARIANT} is forced but there is no CUDA device here "
                               f"({backends.cuda_problem})", field=VARIANT_ENV)
        if forced == LLVM_VARIANT and not backends.llvm:
            raise SimSpadError(f"{LLVM_VARIANT} is forced but {backends.llvm_problem}", field=VARIANT_ENV)
        return forced, None
    if backends.cuda_device is not None:
        return CUDA_VARIANT, None
    if backends.llvm:
        return LLVM_VARIANT, None
    return SCALAR_VARIANT, f"rendering with {SCALAR_VARIANT} (slower): {backends.llvm_problem}"


def find_libllvm() -> str | None:
    """Path of a libLLVM shared library: ``$DRJIT_LIBLLVM_PATH``, known Debian paths, then ``ldconfig -p``."""
    env = os.environ.get(_LLVM_ENV)
    if env and os.path.isfile(env):
        return env
    for pattern in _LLVM_GLOBS:
        hits = sorted(glob.glob(pattern), key=_version_key, reverse=True)
        if hits:
            return hits[0]
    try:
        listing = subprocess.run(["ldconfig", "-p"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    hits = re.findall(r"libLLVM[^\s]*\.so[^\s]*\s.*=>\s*(\S+)", listing)
    return sorted(hits, key=_version_key, reverse=True)[0] if hits else None


def _version_key(path: str) -> tuple[int, ...]:
    return tuple(int(n) for n in re.findall(r"\d+", os.path.basename(path))) or (0,)


def probe_backends(*, cuda: bool = True, llvm: bool = True) -> Backends:
    """Find what this process can render with (each backend only when asked: probing LLVM initialises it).

    A ``DRJIT_LIBLLVM_PATH`` that names no file is kept (Dr.Jit then fails on it, and the reason says so); when it
    is unset, the libLLVM :func:`find_libllvm` finds is put there first.
    """
    cuda_device, cuda_problem = (probe_cuda() if cuda else (None, "not probed"))
    llvm_ok, llvm_problem = False, "not probed"
    if llvm:
        lib = find_libllvm()
        if lib and not os.environ.get(_LLVM_ENV):
            os.environ[_LLVM_ENV] = lib
        tried = os.environ.get(_LLVM_ENV)
        if lib is None and not tried:
            llvm_problem = "no libLLVM found (set DRJIT_LIBLLVM_PATH)"
        else:
            try:
                import drjit as dr  # deferred: DRJIT_LIBLLVM_PATH must be set before Dr.Jit initialises LLVM

                if not dr.has_backend(dr.JitBackend.LLVM):
                    raise RuntimeError(f"Dr.Jit cannot use {tried}")
                llvm_ok, llvm_problem = True, None
            except Exception as exc:  # any failure of the LLVM backend: report it, do not crash
                llvm_problem = f"the LLVM backend failed ({exc})"
    return Backends(cuda_device=cuda_device, cuda_problem=cuda_problem, llvm=llvm_ok, llvm_problem=llvm_problem)


def probe_cuda() -> tuple[str | None, str | None]:
    """(device name, None) when Dr.Jit finds a CUDA device, else (None, why not)."""
    try:
        import drjit as dr  # deferred: heavy

        if not dr.has_backend(dr.JitBackend.CUDA):
            return None, "Dr.Jit found no CUDA driver or device"
    except Exception as exc:  # a broken driver is "no GPU", not a crash
        return None, f"the CUDA backend failed ({exc})"
    return cuda_device_name() or "CUDA device", None


def cuda_device_name() -> str | None:
    """Name of CUDA device 0 from the driver library (the one Dr.Jit loaded), None where it cannot be read."""
    try:
        cuda = ctypes.CDLL("libcuda.so.1")
        device, name = ctypes.c_int(), ctypes.create_string_buffer(256)
        if cuda.cuInit(0) != 0 or cuda.cuDeviceGet(ctypes.byref(device), 0) != 0:
            return None
        if cuda.cuDeviceGetName(name, len(name), device) != 0:
            return None
        return name.value.decode(errors="replace").strip() or None
    except (OSError, AttributeError):
        return None


def select_variant(prefer: str | None = None) -> str:
    """Set (once) and return the Mitsuba variant of this process.

    Parameters
    ----------
    prefer : str, optional
        One of :data:`VARIANTS` to force (the environment variable ``SIMSPAD_MITSUBA_VARIANT`` does the same).
        Default: :func:`choose_variant` of what :func:`probe_backends` finds, with one notice on stderr when that
        is the scalar fallback.

    Returns
    -------
    str
        The variant in use. If Mitsuba already has a variant set in this process and none is forced, it is kept.

    Raises
    ------
    SimSpadError
        A forced variant that is unknown or does not work here.
    """
    global _notice_given
    prefer = prefer or os.environ.get(VARIANT_ENV) or None
    if prefer is None and "mitsuba" in sys.modules:
        current = sys.modules["mitsuba"].variant()
        if current:
            return current
    # Probe only what the choice needs: a forced scalar needs nothing, a forced LLVM no GPU.
    backends = Backends(llvm_problem=None) if prefer == SCALAR_VARIANT else probe_backends(
        cuda=prefer in (None, CUDA_VARIANT), llvm=prefer in (None, LLVM_VARIANT))
    variant, notice = choose_variant(prefer, backends)
    if notice is not None and not _notice_given:
        print(f"simspad: notice: {notice}", file=sys.stderr)
        _notice_given = True
    _set(variant)
    if variant != SCALAR_VARIANT:
        import drjit as dr  # deferred: heavy, and only once the variant is set

        # initialise the backend now, not inside the first render
        backend = dr.cuda if variant == CUDA_VARIANT else dr.llvm
        backend.Float([1.0, 2.0]).numpy()
    return variant


def _set(variant: str) -> str:
    import mitsuba as mi  # deferred: heavy, and after DRJIT_LIBLLVM_PATH is set

    if mi.variant() != variant:
        mi.set_variant(variant)
    route_mitsuba_log(mi)
    return variant


#: What Mitsuba's default formatter puts before a message: optional date and time, then the level.
_LOG_PREFIX = re.compile(r"^(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\s+)?(TRACE|DEBUG|INFO|WARN|ERROR)\s+")
#: ANSI colour codes (Mitsuba colours its terminal output).
ANSI_ESCAPE = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def plain_log_line(level_name: str, text: str) -> str:
    """One of Mitsuba's log messages as SimSPAD writes it: ``simspad: mitsuba: warning: <message>``, without
    colour codes, timestamp or level tag (``level_name``: ``"warning"``, ``"error"``, …)."""
    text = ANSI_ESCAPE.sub("", text).strip()
    text = _LOG_PREFIX.sub("", text)
    return f"simspad: mitsuba: {level_name}: {' '.join(text.split())}"


def route_mitsuba_log(mi) -> None:
    """Replace Mitsuba's coloured stream appender by :class:`_PlainAppender` (once per process)."""
    global _log_routed
    if _log_routed:
        return
    logger = mi.logger() if hasattr(mi, "logger") else mi.Thread.thread().logger()
    logger.clear_appenders()
    logger.add_appender(_make_appender(mi))
    _log_routed = True


def _make_appender(mi):
    class _PlainAppender(mi.Appender):
        """Writes each distinct Mitsuba log message once, as :func:`plain_log_line`; progress bars are dropped."""

        def __init__(self):
            super().__init__()
            self.seen = set()

        def append(self, level, text):
            name = {mi.LogLevel.Warn: "warning", mi.LogLevel.Error: "error"}.get(level, "info")
            line = plain_log_line(name, str(text))
            if line not in self.seen:
                self.seen.add(line)
                print(line, file=sys.stderr, flush=True)

        def log_progress(self, *args):
            pass

    return _PlainAppender()
