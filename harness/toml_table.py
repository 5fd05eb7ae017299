"""TOML input: read a file into a document, and read typed, validated fields from its
tables. Every problem is an InputError naming the file, the dotted field and what is
wrong (one line, exit code 2 at the command line). Scene files, experiment configs and
planner parameters are all read through here.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import tomllib
from pathlib import Path
from typing import Any

from harness.errors import InputError


#: The largest input file read (a scene, a config, an outline): 8 MiB is ten times the
#: largest outline a traced object needs, and stops a mistaken path (a disk image, a
#: device) before it fills the memory.
MAX_INPUT_BYTES = 8 * 2**20


def read_text(path: Path | str, source: str | None = None, limit: int = MAX_INPUT_BYTES) -> str:
    """A regular file's text (UTF-8, an initial byte-order mark dropped); InputError
    naming ``source`` (default: the path) for a device, a folder, a FIFO, a file larger
    than ``limit`` bytes, or bytes that are not text."""
    source = str(path) if source is None else source
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputError(source, None, f"cannot read: {exc.strerror or exc}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise InputError(source, None, "not a regular file")
        if info.st_size > limit:
            raise InputError(source, None, f"{info.st_size} bytes is larger than the {limit // 2**20} MiB an "
                                           "input file may have")
        data = os.read(fd, limit + 1)
        while len(data) <= limit and (more := os.read(fd, limit + 1 - len(data))):
            data += more
    except OSError as exc:
        raise InputError(source, None, f"cannot read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(data) > limit:
        raise InputError(source, None, f"larger than the {limit // 2**20} MiB an input file may have")
    try:
        text = data.decode("utf-8-sig")  # spreadsheet programs often start a CSV with a byte-order mark
    except UnicodeDecodeError:
        raise InputError(source, None, "not a text file (invalid UTF-8)") from None
    return text


def read_toml(path: Path) -> dict:
    """A TOML file's document; InputError (one line naming the file) when it cannot be read."""
    source = str(path)
    text = read_text(path)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(source, None, f"invalid TOML: {exc}") from None
    except RecursionError:  # tomllib recurses once per level of nested arrays and inline tables
        raise InputError(source, None, "invalid TOML: arrays or inline tables nested too deeply") from None


# ---------------------------------------------------------------------------
# A typed reader over one TOML table


_REQUIRED = object()
_LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-z]+)(\^2)?\s*$")


class Table:
    """Reads typed fields from one TOML table, tracking which keys were used; every
    problem is an InputError naming the file and the dotted field."""

    def __init__(self, data: Any, where: str, source: str):
        self.data = data
        self.where = where
        self.source = source
        self.used: set[str] = set()

    def _path(self, key: str | None) -> str | None:
        if key is None:
            return self.where or None
        return f"{self.where}.{key}" if self.where else key

    def error(self, key: str | None, message: str) -> InputError:
        return InputError(self.source, self._path(key), message)

    def _get(self, key: str, default: Any) -> Any:
        self.used.add(key)
        if key in self.data:
            return self.data[key]
        if default is _REQUIRED:
            raise self.error(key, "missing")
        return default

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.error(_key_name(unknown[0]), "unknown field")

    def table(self, key: str, required: bool = True) -> "Table":
        value = self._get(key, _REQUIRED if required else {})
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table, got {_type_name(value)}")
        return Table(value, self._path(key), self.source)

    def tables(self, key: str, min_count: int) -> list["Table"]:
        value = self._get(key, _REQUIRED if min_count else [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.error(key, f"expected a list of tables, got {_type_name(value)}")
        if len(value) < min_count:
            raise self.error(key, f"needs at least {min_count} entries")
        return [Table(v, f"{self._path(key)}[{k}]", self.source) for k, v in enumerate(value)]

    def list(self, key: str, default: Any = _REQUIRED) -> list:
        value = self._get(key, default)
        if not isinstance(value, list):
            raise self.error(key, f"expected a list, got {_type_name(value)}")
        return value

    def string(self, key: str, default: Any = _REQUIRED, choices: tuple[str, ...] | None = None) -> str:
        value = self._get(key, default)
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {_type_name(value)}")
        if choices is not None and value not in choices:
            raise self.error(key, f"'{value}' is not one of {', '.join(choices)}")
        return value

    def boolean(self, key: str, default: Any = _REQUIRED) -> bool:
        value = self._get(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f"expected true or false, got {_type_name(value)}")
        return value

    def integer(self, key: str, default: Any = _REQUIRED, lo: int | None = None, hi: int | None = None) -> int:
        value = self._get(key, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"expected an integer, got {_type_name(value)}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.error(key, f"{value} is out of range [{lo}, {hi}]")
        return value

    def number(self, key: str, default: Any = _REQUIRED, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False) -> float:
        value = self._get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, f"expected a number, got {_type_name(value)}")
        return self._in_range(key, _to_float(value), lo, hi, lo_open)

    def _in_range(self, key: str, value: float, lo: float | None, hi: float | None, lo_open: bool,
                  unit: str = "") -> float:
        if not math.isfinite(value):
            raise self.error(key, f"must be finite, got {value}")
        below = lo is not None and (value <= lo if lo_open else value < lo)
        above = hi is not None and value > hi
        if below or above:
            low = "-inf" if lo is None else f"{lo:g}"
            high = "inf" if hi is None else f"{hi:g}"
            bracket = "(" if lo_open else "["
            raise self.error(key, f"{value:g}{unit} is out of range {bracket}{low}, {high}]")
        return value

    def _quantity(self, key: str, value: Any, cell: float, power: int) -> float:
        """A number in SI units, or a string like '2 cells', '5 mm' (lengths) or
        '4 cells^2', '25 mm^2' (areas)."""
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise self.error(key, f"expected a number or a quantity like '2 cells', got {_type_name(value)}")
        if not isinstance(value, str):
            return _to_float(value)
        m = _QUANTITY.match(value)
        squared = bool(m and m.group(3))
        unit = m.group(2) if m else ""
        per_unit = cell if unit in ("cell", "cells") else _LENGTH_UNITS.get(unit)
        if m is None or per_unit is None or squared != (power == 2):
            units = "cells, m, cm, mm" + ("; squared, e.g. '4 cells^2'" if power == 2 else "")
            raise self.error(key, f"cannot read quantity '{value}' (units: {units})")
        return float(m.group(1)) * per_unit**power

    def length(self, key: str, cell: float, default: Any = _REQUIRED, lo: float | None = None,
               hi: float | None = 100.0, lo_open: bool = True) -> float:
        raw = self._get(key, default)
        value = self._quantity(key, raw, cell, 1)
        return self._in_range(key, value, lo, hi, lo_open and lo is not None and lo >= 0.0, " m")

    def area(self, key: str, cell: float, default: Any = _REQUIRED) -> float:
        raw = self._get(key, default)
        value = self._quantity(key, raw, cell, 2)
        return self._in_range(key, value, 0.0, 1e4, True, " m^2")

    def point(self, key: str, default: Any = _REQUIRED) -> tuple[float, float]:
        value = self._get(key, default)
        return self.point_value(value, key)

    def point_value(self, value: Any, key: str) -> tuple[float, float]:
        if (not isinstance(value, (list, tuple)) or len(value) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            raise self.error(key, f"expected a point [x, y] of two numbers, got {_short(value)}")
        x, y = _to_float(value[0]), _to_float(value[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            raise self.error(key, "coordinates must be finite")
        if max(abs(x), abs(y)) > 100.0:
            raise self.error(key, "coordinates must be within 100 m of the origin")
        return x, y

    def points(self, key: str) -> list[tuple[float, float]]:
        return self.points_value(self._get(key, _REQUIRED), key)

    def points_value(self, value: Any, key: str) -> list[tuple[float, float]]:
        if not isinstance(value, list):
            raise self.error(key, f"expected a list of points [[x, y], ...], got {_type_name(value)}")
        pts = [self.point_value(v, f"{key}[{k}]") for k, v in enumerate(value)]
        if len(pts) < 3:
            raise self.error(key, f"a polygon needs at least 3 points, got {len(pts)}")
        return pts


def _key_name(key: str) -> str:
    """A key as TOML writes it: bare when it can be, else quoted with escapes, so that
    an error naming it stays on one line."""
    return key if _BARE_KEY.fullmatch(key) else json.dumps(key)


def _to_float(value: int | float) -> float:
    """float(value); TOML integers are unbounded, and those too large for a float
    become +/-inf (then rejected as not finite) instead of raising OverflowError."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _type_name(value: Any) -> str:
    names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
             list: "a list", dict: "a table"}
    return names.get(type(value), type(value).__name__)


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
