"""Finding planners: the built-ins, and plugins registered under the entry-point group
``gpis_harness.planners``; making one from KEY=VALUE parameters."""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from harness.errors import InputError
from planners.base import Planner

ENTRY_POINT_GROUP = "gpis_harness.planners"
BUILTINS = ("planners.mean_shape:MeanShape", "planners.gp_p:GPP", "planners.gp_gpis_opt:GPGPISOpt")


def _load(target: str):
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def available() -> tuple[dict, dict]:
    """(planners by name, plugins that failed to load: entry point -> error)."""
    found: dict = {}
    broken: dict = {}
    for target in BUILTINS:
        cls = _load(target)
        found[cls.name] = cls
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            cls = ep.load()
            if not (isinstance(cls, type) and issubclass(cls, Planner) and cls.name):
                raise TypeError("not a Planner subclass with a name")
        except Exception as exc:  # a broken plugin must not break the harness
            broken[ep.name] = f"{type(exc).__name__}: {exc}"
            continue
        found.setdefault(cls.name, cls)
    return found, broken


def planner_class(name: str) -> type:
    """The class registered as ``name``, or, for ``module:Class``, that class imported
    directly (a planner under development needs no packaging)."""
    if ":" in name:
        try:
            cls = _load(name)
        except (ImportError, AttributeError, ValueError) as exc:
            raise InputError("--planner", None, f"cannot import planner '{name}': {exc}") from None
        if not (isinstance(cls, type) and issubclass(cls, Planner)):
            raise InputError("--planner", None, f"'{name}' is not a Planner subclass")
        return cls
    found, broken = available()
    if name not in found:
        extra = f"; {name} failed to load: {broken[name]}" if name in broken else ""
        raise InputError("--planner", None, f"unknown planner '{name}' (known: {', '.join(sorted(found))}){extra}")
    return found[name]


def make_planner(name: str, params: dict | None = None, source: str = "--param") -> Planner:
    """A planner with the given parameters; string values are read as the type of the
    parameter's default. Unknown parameters and unreadable values are bad input."""
    cls = planner_class(name)
    defaults = cls.parameters()
    values = {}
    for key, raw in (params or {}).items():
        if key not in defaults:
            known = ", ".join(defaults) or "none"
            raise InputError(source, key, f"unknown parameter of planner '{name}' (parameters: {known})")
        values[key] = _convert(raw, defaults[key], source, key) if isinstance(raw, str) else raw
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise InputError(source, None, f"planner '{name}': {exc}") from None


def _convert(raw: str, default, source: str, key: str):
    kind = type(default)
    try:
        if kind is bool:
            if raw.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return raw.lower() in ("true", "1", "yes")
        if kind is int:
            return int(raw)
        if kind is float:
            value = float(raw)
            if value != value or value in (float("inf"), float("-inf")):
                raise ValueError
            return value
    except ValueError:
        raise InputError(source, key, f"expected {kind.__name__}, got '{raw}'") from None
    return raw
