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

    numpy's SeedSequence reads the keys as one run of 32-bit words, with no separator
    and with trailing zero words ignored: a name counts as the two words of its 64-bit
    hash, an integer of 2**32 or more as two words, and ``stream(s, "x", 0)`` is
    ``stream(s, "x")``. Every stream of an experiment ends with a name (its purpose), and
    the integers inside are small (realisations), so no two of them coincide unless two
    names' 64-bit hashes do; three benchmark streams end with an index (bench sampling's
    and bench planning's repetitions, the convergence study's initialisations), and none
    of those is also used without it. A new stream should end with a name. (A change to
    the encoding would move every result, the reference run's included, so it stays.)
    """
    entropy = [_key_int(seed)] + [_key_int(k) for k in keys]
    return np.random.default_rng(np.random.SeedSequence(entropy))
