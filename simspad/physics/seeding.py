"""Stable random streams: one SeedSequence per dataset, one child per (sequence, lux, sensor, ...) key.

Children are derived from the *key*, never from spawn order, so outputs are bit-identical whatever the
executor, worker count or order of execution.
"""

from __future__ import annotations

import hashlib

import numpy as np


def _key_words(*keys: object) -> tuple[int, ...]:
    digest = hashlib.blake2b("\x1f".join(repr(k) for k in keys).encode(), digest_size=16).digest()
    return tuple(int.from_bytes(digest[i : i + 4], "little") for i in range(0, 16, 4))


def child_seed(seed: int | np.random.SeedSequence, *keys: object) -> np.random.SeedSequence:
    """The SeedSequence for ``keys`` under a dataset ``seed``.

    Examples
    --------
    >>> ss = child_seed(42, "office", 10.0, "spad")
    >>> rng = np.random.default_rng(ss)
    """
    if isinstance(seed, np.random.SeedSequence):
        entropy, base_key = seed.entropy, tuple(seed.spawn_key)
    else:
        entropy, base_key = int(seed), ()
    return np.random.SeedSequence(entropy=entropy, spawn_key=base_key + _key_words(*keys))


def child_rng(seed: int | np.random.SeedSequence, *keys: object) -> np.random.Generator:
    """A ``numpy.random.Generator`` (PCG64) on :func:`child_seed`."""
    return np.random.default_rng(child_seed(seed, *keys))
