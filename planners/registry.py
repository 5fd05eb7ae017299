"""Finding planners: the built-ins, and plugins registered under the entry-point group
``gpis_harness.planners``; making one from parameters checked against the types of their
defaults and the planner's BOUNDS (the one check for configs and ``--param``)."""

from __future__ import annotations

import functools
import importlib
import inspect
import math
import numbers
from importlib.metadata import entry_points

from harness.errors import InputError, describe
from planners.base import Planner

ENTRY_POINT_GROUP = "gpis_harness.planners"
BUILTINS = ("planners.mean_shape:MeanShape", "planners.gp_p:GPP", "planners.gp_gpis_opt:GPGPISOpt",
            "planners.gp_bandit:GPBandit")

_TRUE = ("true", "yes", "1")
_FALSE = ("false", "no", "0")


def _load(target: str):
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def class_problem(cls) -> str | None:
    """What keeps ``cls`` from being used as a planner, or None: not a Planner subclass,
    ``plan`` not implemented, or BOUNDS that are not ``{parameter: (low, high)}``."""
    if not (isinstance(cls, type) and issubclass(cls, Planner)):
        return "not a Planner subclass"
    if inspect.isabstract(cls):
        return f"does not implement {', '.join(sorted(cls.__abstractmethods__))}()"
    bounds = cls.BOUNDS
    if not isinstance(bounds, dict):
        return "BOUNDS must be a dict {parameter: (low, high)}"
    defaults = cls.parameters()
    for key, pair in bounds.items():
        if key not in defaults:
            return f"BOUNDS names '{key}', which is not a parameter"
        if not (isinstance(pair, (tuple, list)) and len(pair) == 2
                and all(end is None or _is_number(end) for end in pair)):
            return f"BOUNDS['{key}'] must be (low, high), numbers or None, got {pair!r}"
    return None


@functools.cache
def builtins() -> dict:
    """The built-in planners by name (their modules imported once per process)."""
    return {cls.name: cls for cls in map(_load, BUILTINS)}


def available() -> tuple[dict, dict]:
    """(planners by name, plugins that failed to load: entry point -> error)."""
    found: dict = dict(builtins())
    broken: dict = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            cls = ep.load()
            problem = class_problem(cls) or (None if cls.name else "a Planner subclass without a name")
        except (Exception, SystemExit) as exc:  # a broken plugin must not break the harness
            problem = describe(exc)
        if problem:
            broken[ep.name] = problem
            continue
        found.setdefault(cls.name, cls)
    return found, broken


def planner_class(name: str) -> type:
    """The class registered as ``name``, or, for ``module:Class``, that class imported
    directly (a planner under development needs no packaging). Importing runs the
    module's code: whatever it raises, or a sys.exit, is bad input naming the planner."""
    if ":" in name:
        cls = _import(name)
        problem = class_problem(cls)
        if problem:
            raise InputError("--planner", None, f"planner '{name}': {problem}")
        return cls
    if name in builtins():  # a built-in wins over a plugin of its name: no need to load the plugins
        return builtins()[name]
    found, broken = available()
    if name not in found:
        extra = f"; {name} failed to load: {broken[name]}" if name in broken else ""
        base = name.removesuffix("-lift")
        if base != name and base in found:  # make eval's labels are not planner names
            extra += (f"; '{name}' is make eval's label for planner '{base}' planning for the lift: in a "
                      f"config name = \"{base}\" with params = {{ quality = \"lift\" }}, on the command line "
                      f"--planner {base} --param quality=lift")
        raise InputError("--planner", None, f"unknown planner '{name}' (known: {', '.join(sorted(found))}){extra}")
    return found[name]


def _import(name: str):
    module, _, attr = name.partition(":")
    if not module.strip() or not attr.strip():
        raise InputError("--planner", None, f"planner '{name}': expected module:Class")
    try:
        loaded = importlib.import_module(module)
    except (Exception, SystemExit) as exc:  # the module's own code failed (or exited) while importing
        missing = isinstance(exc, ModuleNotFoundError) and exc.name is not None and \
            (module == exc.name or module.startswith(exc.name + "."))
        reason = (f"no module named '{exc.name}' (is its folder on PYTHONPATH?)" if missing
                  else f"importing {module} raised {describe(exc)}")
        raise InputError("--planner", None, f"planner '{name}': {reason}") from None
    if not hasattr(loaded, attr):
        raise InputError("--planner", None, f"planner '{name}': module {module} has no attribute '{attr}'")
    return getattr(loaded, attr)


def make_planner(name: str, params: dict | None = None, source: str = "--param") -> Planner:
    """A planner with the given parameters, each checked by :func:`parameter_value`.
    Unknown parameters, values of the wrong type or out of range, and a constructor that
    refuses a value (ValueError), raises anything else or does not store its parameters
    are bad input (InputError)."""
    cls = planner_class(name)
    defaults = cls.parameters()
    values = {}
    for key, raw in (params or {}).items():
        if key not in defaults:
            known = ", ".join(defaults) or "none"
            raise InputError(source, key, f"unknown parameter of planner '{name}' (parameters: {known})")
        try:
            values[key] = parameter_value(cls, key, raw)
        except ValueError as exc:
            raise InputError(source, key, str(exc)) from None
    try:
        planner = cls(**values)
    except ValueError as exc:  # the contract's way of refusing a value
        raise InputError(source, None, f"planner '{name}': {exc}") from None
    except (Exception, SystemExit) as exc:
        raise InputError("--planner", None, f"planner '{name}': constructing it raised {describe(exc)}") \
            from None
    unstored = [k for k in defaults if not hasattr(planner, k)]
    if unstored:
        raise InputError("--planner", None, f"planner '{name}' does not store its parameters under their own "
                                            f"names (missing: {', '.join(unstored)}; see planners/base.py)")
    return planner


def parameter_value(cls, key: str, raw):
    """``raw`` as a value of ``cls``'s parameter ``key``; ValueError saying why not.

    The default's type is the parameter's type: an int parameter takes integers (not 2.5,
    not true), a float parameter finite numbers (an integer becomes a float), a bool
    parameter true or false, a str parameter a string. A string given to a parameter of
    another type is read as its text (``--param KEY=VALUE`` gives strings). A parameter
    whose default is None and which has a range in BOUNDS is an optional float (None: the
    planner chooses); any other default type (None without a range, a tuple) takes any
    value unchecked. Numbers must then lie in ``cls.BOUNDS[key]`` (inclusive), when given.
    """
    default = cls.parameters()[key]
    if default is None and raw is None:
        return None
    kind = float if default is None and key in cls.BOUNDS else type(default)
    if kind is bool:
        return _boolean(raw)
    if kind is str:
        if not isinstance(raw, str):
            raise ValueError(f"expected a string, got {_show(raw)}")
        return raw
    if kind is int:
        value = _integer(raw)
    elif kind is float:
        value = _finite(raw)
    else:
        return raw
    lo, hi = cls.BOUNDS.get(key, (None, None))
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ValueError(f"{_show(value)} is out of range {range_text(cls, key)}")
    return value


def range_text(cls, key: str) -> str:
    """A parameter's range as ``[low, high]`` (open ends as -inf, inf), or "" without one."""
    if key not in cls.BOUNDS:
        return ""
    lo, hi = cls.BOUNDS[key]
    return f"[{'-inf' if lo is None else lo}, {'inf' if hi is None else hi}]"


def _boolean(raw) -> bool:
    if isinstance(raw, bool):
        return raw
    if isinstance(raw, str) and raw.strip().lower() in _TRUE + _FALSE:
        return raw.strip().lower() in _TRUE
    raise ValueError(f"expected true or false, got {_show(raw)}")


def _integer(raw) -> int:
    if isinstance(raw, str):
        try:
            return int(raw)
        except ValueError:
            raise ValueError(f"expected an integer, got {_show(raw)}") from None
    if isinstance(raw, numbers.Integral) and not isinstance(raw, bool):
        return int(raw)
    raise ValueError(f"expected an integer, got {_show(raw)}")


def _finite(raw) -> float:
    if not (isinstance(raw, str) or _is_number(raw)):
        raise ValueError(f"expected a finite number, got {_show(raw)}")
    try:
        value = float(raw)
    except OverflowError:  # an integer beyond float's range
        value = math.inf
    except ValueError:
        raise ValueError(f"expected a finite number, got {_show(raw)}") from None
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {_show(raw)}")
    return value


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _show(value) -> str:
    """A value as the user wrote it: TOML's true and false, strings quoted, long ones cut."""
    if isinstance(value, bool):
        return "true" if value else "false"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."

