"""Random streams derived from the experiment seed and named purposes, so that every
draw is reproducible and independent of how work is split between processes."""

from __future__ import annotations

import hashlib

import numpy as np


def _key_int(key: str | int) -> int:
    if isinstance(key, int) and key >= 0:
        return key
    return int.from_bytes(hashlib.sha256(str(key).encode("utf-8")).digest()[:8], "little")


def stream(seed: int, *keys: str | int) -> np.random.Generator:
    """A generator for (seed, key1, key2, ...), e.g. ``stream(7, "tape", 0, "sensor")``.

    Keys are hashed stably (not with Python's salted ``hash``), so the same names give
    the same numbers in every process and on every machine.
    """
    entropy = [_key_int(seed)] + [_key_int(k) for k in keys]
    return np.random.default_rng(np.random.SeedSequence(entropy))
