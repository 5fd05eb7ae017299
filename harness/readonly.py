"""Read-only inputs: every array reachable from a planner's problem made non-writeable,
and a fingerprint of everything reachable, to tell afterwards whether anything changed.

Both walk the same graph: arrays, containers, and the attributes of the harness's and the
planners' own objects (dataclasses, slots, instance dictionaries, cached properties).
Other objects (shapely geometries, functions, numbers) are leaves: immutable, or not the
harness's to guard.
"""

from __future__ import annotations

import hashlib
from dataclasses import fields, is_dataclass

import numpy as np

#: Modules whose objects' attributes are walked.
_OWN = ("harness", "planners")


def freeze(obj) -> None:
    """Make every numpy array reachable from ``obj`` non-writeable (a write raises
    ValueError: assignment destination is read-only)."""
    for _, value in _walk(obj, "", set()):
        if isinstance(value, np.ndarray) and value.flags.writeable:
            value.setflags(write=False)


def fingerprint(obj, contents: bool = True) -> dict[str, str]:
    """What is reachable from ``obj``, by path (``.belief.gp.L_``): each leaf's value and
    each array's identity, type, shape and writeable flag, and with ``contents`` a digest
    of its bytes. Two fingerprints differ where something changed; without contents the
    fingerprint is cheap (no array is read) and still sees an array replaced or made
    writeable again, which is how a read-only array could change."""
    out = {}
    for path, value in _walk(obj, "", set()):
        if isinstance(value, np.ndarray):
            text = f"array {id(value):#x} {value.dtype}{value.shape} writeable={value.flags.writeable}"
            if contents:
                digest = hashlib.blake2b(np.ascontiguousarray(value).view(np.uint8), digest_size=16)
                text += " " + digest.hexdigest()
            out[path] = text
        else:
            out[path] = repr(value)
    return out


def changes(before: dict[str, str], after: dict[str, str]) -> list[str]:
    """The paths of ``before`` whose value differs or is gone in ``after``. Paths new in
    ``after`` are not changes: caches computed on first use (a cached property, a GP's
    basis) add them."""
    return sorted(p for p in before if after.get(p) != before[p])


class InputsChanged(Exception):
    """A planner changed what it was given (its problem)."""

    def __init__(self, paths: list[str]):
        shown = ", ".join(f"problem{p}" for p in paths[:3]) + (f" and {len(paths) - 3} more" if len(paths) > 3 else "")
        super().__init__(f"plan() changed its inputs: {shown} (the problem is read-only; copy what you change)")
        self.paths = paths


def _walk(obj, path: str, seen: set[int]):
    """(path, value) of every array and leaf reachable from obj, each object once."""
    if id(obj) in seen:
        return
    if isinstance(obj, np.ndarray):
        seen.add(id(obj))
        yield path, obj
        if obj.dtype == object:
            for i, item in enumerate(obj.flat):
                yield from _walk(item, f"{path}[{i}]", seen)
        return
    if isinstance(obj, dict):
        seen.add(id(obj))
        for key in sorted(obj, key=repr):
            yield from _walk(obj[key], f"{path}[{key!r}]", seen)
        return
    if isinstance(obj, (list, tuple)):
        seen.add(id(obj))
        for i, item in enumerate(obj):
            yield from _walk(item, f"{path}[{i}]", seen)
        return
    if type(obj).__module__.split(".")[0] not in _OWN:
        yield path, _leaf(obj)
        return
    seen.add(id(obj))
    for name, value in _attributes(obj):
        yield from _walk(value, f"{path}.{name}", seen)


def _attributes(obj):
    """An own object's attributes: its dataclass fields, slots and instance dictionary
    (where cached properties keep their values)."""
    names = [f.name for f in fields(obj)] if is_dataclass(obj) else []
    for cls in type(obj).__mro__:
        names.extend(s for s in getattr(cls, "__slots__", ()) if s not in ("__dict__", "__weakref__"))
    names.extend(getattr(obj, "__dict__", {}))
    for name in dict.fromkeys(names):
        try:
            yield name, object.__getattribute__(obj, name)
        except AttributeError:  # an unset slot
            continue


def _leaf(obj):
    """What a fingerprint keeps of a leaf: numbers, strings and the like by value;
    other objects (geometries, functions) by type and identity."""
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes, np.generic)):
        return obj
    return f"<{type(obj).__qualname__} {id(obj):#x}>"
