"""Choose and set the Mitsuba variant once per process (main process or Dask worker).

``llvm_ad_rgb`` (vectorised, JIT-compiled) needs a working libLLVM; Dr.Jit finds it through
``DRJIT_LIBLLVM_PATH``, which must be set before its LLVM backend first initialises. Without one we fall back to
``scalar_rgb`` and say so once on stderr.
"""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys

LLVM_VARIANT = "llvm_ad_rgb"
SCALAR_VARIANT = "scalar_rgb"
_LLVM_ENV = "DRJIT_LIBLLVM_PATH"
_LLVM_GLOBS = ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19*", "/usr/lib/x86_64-linux-gnu/libLLVM-19.so*",
               "/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*")
_notice_given = False


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


def select_variant(prefer: str | None = None) -> str:
    """Set (once) and return the Mitsuba variant of this process.

    Parameters
    ----------
    prefer : str, optional
        ``"llvm_ad_rgb"`` or ``"scalar_rgb"`` to force one (the environment variable ``SIMSPAD_MITSUBA_VARIANT``
        does the same). Default: llvm when a working libLLVM is found, else scalar with one notice on stderr.

    Returns
    -------
    str
        The variant in use. If Mitsuba already has a variant set in this process and none is forced, it is kept.
    """
    global _notice_given
    prefer = prefer or os.environ.get("SIMSPAD_MITSUBA_VARIANT") or None
    if prefer is None and "mitsuba" in sys.modules:
        current = sys.modules["mitsuba"].variant()
        if current:
            return current
    if prefer == SCALAR_VARIANT:
        return _set(SCALAR_VARIANT)
    lib = find_libllvm()
    if lib and not os.environ.get(_LLVM_ENV):
        os.environ[_LLVM_ENV] = lib
    reason = "no libLLVM found (set DRJIT_LIBLLVM_PATH)" if lib is None else None
    if lib is not None:
        try:
            import drjit as dr  # deferred: DRJIT_LIBLLVM_PATH must be set before Dr.Jit initialises LLVM

            if not dr.has_backend(dr.JitBackend.LLVM):
                raise RuntimeError(f"Dr.Jit cannot use {lib}")
            variant = _set(LLVM_VARIANT)
            import drjit.llvm as drl  # deferred: heavy, and only once the LLVM variant is set

            drl.Float([1.0, 2.0]).numpy()  # initialise the backend now, not inside the first render
            return variant
        except Exception as exc:  # any failure of the LLVM backend: fall back, do not crash
            reason = f"the LLVM backend failed ({exc})"
    if not _notice_given:
        print(f"simspad: notice: rendering with {SCALAR_VARIANT} (slower): {reason}", file=sys.stderr)
        _notice_given = True
    return _set(SCALAR_VARIANT)


def _set(variant: str) -> str:
    import mitsuba as mi  # deferred: heavy, and after DRJIT_LIBLLVM_PATH is set

    if mi.variant() != variant:
        mi.set_variant(variant)
    return variant
