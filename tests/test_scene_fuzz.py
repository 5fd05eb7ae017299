"""Malformed scene files, generated: one random mutation of a valid scene must always end
in exit code 2 and one line that names the file (and the field, where there is one)."""

from __future__ import annotations

import contextlib
import copy
import io
import json
import math
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from harness.cli import main

REPO = Path(__file__).resolve().parents[1]
PREFIX = "gpis-harness: error: "

# ---------------------------------------------------------------------------
# Valid base scenes (nested dicts, written as TOML below)

SQUARE_CSV = b"x,y\n0,0\n4,0\n4,3\n2,5\n0,3\n"

COMMON = {
    "grid": {"size": 40, "extent": 0.2, "truncation": "3 cells"},
    "sensor": {
        "noise": 0.0005, "surface_band": "1.5 cells", "interior_depth": "2 cells", "interior_keep": 0.1,
        "regions": [
            {"kind": "occluded", "shape": {"type": "disk", "radius": 0.01, "center": [0.05, 0.05]}},
            {"kind": "transparent", "value": "0.5 cells", "noise": "2 cells",
             "half_plane": {"normal": [1.0, 0.0], "offset": "2 cells"}},
            {"kind": "specular", "noise": "2 cells", "drop_probability": 0.3,
             "shape": {"type": "rectangle", "width": 0.04, "height": 0.02, "center": [0.0, 0.02]}},
        ],
    },
    "gpis": {"lengthscale": "2.7 cells", "scale": "4 cells^2", "prior_mean": "-1 cells", "hyperparameters": "fixed",
             "use_gradients": True, "active_set": True, "active_band": "2 cells", "active_spacing": "3 cells"},
    "physics": {"thickness": 0.03, "density": 400.0, "friction": 0.5},
    "gripper": {"opening": 0.1, "jaw_width": 0.01},
}

#: Every base shape reaches at least 0.025 m from the centre in metres (not cells).
SHAPES = {
    "rectangle": {"type": "rectangle", "width": 0.06, "height": "6 cells", "center": [0.0, 0.0], "angle": 0.1},
    "polygon": {"type": "polygon", "exterior": [[-0.03, -0.02], [0.03, -0.02], [0.03, 0.02], [-0.03, 0.02]],
                "holes": [[[-0.01, -0.005], [0.01, -0.005], [0.0, 0.01]]], "rotate": 0.3},
    "outline": {"type": "outline", "path": "outline.csv", "scale": 0.01, "center": "bbox", "flip_y": True,
                "rotate": 0.2, "offset": [0.005, 0.0]},
    "union": {"type": "union", "offset": [0.0, -0.005],
              "parts": [{"type": "capsule", "start": [-0.03, 0.0], "end": [0.03, 0.0], "radius": 0.008},
                        {"type": "disk", "radius": "3 cells", "center": [0.0, 0.01]},
                        {"type": "ring", "outer_radius": 0.02, "inner_radius": 0.01, "center": [0.02, 0.0]}],
              "cutouts": [{"type": "rectangle", "width": 0.01, "height": 0.004, "center": [-0.02, 0.0]}]},
    "random": {"type": "random", "seed": 7, "radius": 0.03, "lengthscale": 0.015, "amplitude": 0.4},
}


def base_scene(shape: str) -> dict:
    return {"name": f"fuzz-{shape}", "description": "fuzzing base", **copy.deepcopy(COMMON),
            "shape": copy.deepcopy(SHAPES[shape])}


# ---------------------------------------------------------------------------
# Writing TOML (every value inline, so a document is one `key = value` line per table)


def toml_string(text: str) -> str:
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)  # floats: nan, inf, -inf and exponents are all TOML
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{toml_string(k)} = {toml_value(v)}" for k, v in value.items()) + "}"


def dump_toml(doc: dict) -> str:
    return "".join(f"{toml_string(k)} = {toml_value(v)}\n" for k, v in doc.items())


# ---------------------------------------------------------------------------
# What each field accepts, and values it must reject

NAN, INF = float("nan"), float("inf")
HUGE_INT = 10**400  # TOML integers are unbounded

ALL_KEYS = {
    "name", "description", "grid", "size", "extent", "truncation", "shape", "type", "exterior", "holes", "path",
    "scale", "center", "flip_y", "width", "height", "angle", "radius", "outer_radius", "inner_radius", "start",
    "end", "parts", "cutouts", "seed", "lengthscale", "amplitude", "rotate", "offset", "sensor", "noise",
    "surface_band", "interior_depth", "interior_keep", "regions", "kind", "half_plane", "normal", "value",
    "drop_probability", "gpis", "prior_mean", "hyperparameters", "use_gradients", "active_set", "active_band",
    "active_spacing", "physics", "thickness", "density", "friction", "gripper", "opening", "jaw_width",
}
SHAPE_REQUIRED = {"polygon": {"exterior"}, "outline": {"path", "scale"}, "rectangle": {"width", "height"},
                  "disk": {"radius"}, "ring": {"outer_radius", "inner_radius"}, "capsule": {"start", "end", "radius"},
                  "union": {"parts"}, "random": {"seed", "radius"}}

WRONG_TYPE = {
    "int": [40.0, "40", True, [40], {"a": 1}],
    "number": ["0.2", "2 cells", True, [0.2], {"a": 1}],
    "length": [True, False, [0.01], {"v": 1}, "abc", "0.01"],
    "string": [1, 2.5, True, ["a"], {"a": "b"}],
    "choice": [1, True, ["disk"], {"a": 1}],
    "bool": ["true", 1, 0, 1.0, [True], {"a": True}],
    "point": ["0,0", 0.0, [0.0], [0.0, 0.0, 0.0], ["a", 0.0], [True, 0.0], {"x": 0}, [[0, 0], [1, 1]]],
    "points": ["x", 1, [[0, 0], [0.01, 0]], [[0, 0], [0.01], [0, 0.01]], [[0, 0], "a", [0, 0.01]], {"a": 1}],
    "holes": ["x", 1, [1], [[[0, 0], [0.01, 0.01]]], [[]], {"a": 1}],
    "table": [1, "x", True, [1, 2], 0.5],
    "tables": [1, "x", {"type": "disk"}, [1], ["x"]],
}
POSITIVE_LENGTH = [0, 0.0, -0.01, "-2 cells", "0 mm", 1e3, "1e5 m", NAN, INF, -INF, HUGE_INT]
OUT_OF_RANGE = {
    "size": [0, 7, -40, 1025, HUGE_INT],
    "seed": [-1, 2**63, HUGE_INT],
    "extent": [0, -0.2, 1e3, NAN, INF, HUGE_INT],
    "truncation": ["1 cell", 0.005, 0.001, 0, -1, 1e3, NAN],
    "outline scale": [0, -0.01, 1e3, NAN, INF],
    "density": [0.5, 0, -1, 1e6, NAN],
    "friction": [-0.1, 10.5, NAN, INF],
    "probability": [-0.1, 1.1, NAN, INF, -INF],
    "amplitude": [-0.1, 5.5, NAN],
    "angle": [NAN, INF, -INF, HUGE_INT],
    "signed length": [-1e3, 1e3, "-200 m", NAN, INF, -INF],
    "area": [0, -1e-4, "-4 cells^2", "0 mm^2", 1e5, NAN, INF],
    "point": [[NAN, 0.0], [0.0, INF], [1e3, 0.0], [0.0, -1e3], [HUGE_INT, 0]],
    "normal": [[0, 0], [0.0, 0.0], [NAN, 1.0], [1e3, 0.0]],
    "type": ["circle", "", "Disk", "polygons"],
    "hyperparameters": ["ML", "map", ""],
    "kind": ["opaque", "Occluded", ""],
    "centring": ["middle", "centre", "Centroid"],
}
BAD_QUANTITIES = ["cells", "mm", "", " ", "3 parsecs", "5 MM", "2 Cells", "2 cells cells", "1..2 mm", "1e mm",
                  "+-1 mm", "\u221e mm", "2 cells^3", "nan mm", "inf m", "2 m m", "0x10 mm", "1,5 mm"]


@dataclass(frozen=True)
class Spec:
    """What one field is: its kind (for wrong types) and its range (for bad values)."""

    kind: str
    bad: str | None = None  # key of OUT_OF_RANGE, "positive length", or None (no range)


def spec(parent: dict, key: str, path: tuple) -> Spec:
    """The spec of ``parent[key]``; ``path`` is the parent's path."""
    in_half_plane = path[-1:] == ("half_plane",)
    is_outline = parent.get("type") == "outline"
    table_keys = {"grid", "shape", "sensor", "gpis", "physics", "gripper", "half_plane"}
    if key in table_keys:
        return Spec("table")
    if key in ("parts", "cutouts", "regions"):
        return Spec("tables")
    if key in ("name", "description", "path"):
        return Spec("string")
    if key in ("type", "hyperparameters", "kind"):
        return Spec("choice", key)
    if key == "center" and is_outline:
        return Spec("choice", "centring")
    if key in ("flip_y", "use_gradients", "active_set"):
        return Spec("bool")
    if key in ("size", "seed"):
        return Spec("int", key)
    if key == "scale":
        return Spec("number", "outline scale") if is_outline else Spec("length", "area")
    if key in ("extent", "density", "friction", "amplitude"):
        return Spec("number", key)
    if key in ("interior_keep", "drop_probability"):
        return Spec("number", "probability")
    if key in ("angle", "rotate"):
        return Spec("number", "angle")
    if key == "offset" and in_half_plane:
        return Spec("length", "signed length")
    if key in ("center", "offset", "start", "end"):
        return Spec("point", "point")
    if key == "normal":
        return Spec("point", "normal")
    if key == "exterior":
        return Spec("points")
    if key == "holes":
        return Spec("holes")
    if key == "truncation":
        return Spec("length", "truncation")
    if key in ("prior_mean", "value"):
        return Spec("length", "signed length")
    return Spec("length", "positive length")


def bad_values(s: Spec) -> list:
    if s.bad is None:
        return []
    return POSITIVE_LENGTH if s.bad == "positive length" else OUT_OF_RANGE[s.bad]


def walk(node, path: tuple = ()):
    """(path, parent table, key) of every field of the document, depth first."""
    for key, value in node.items():
        yield path, node, key
        if isinstance(value, dict):
            yield from walk(value, path + (key,))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for k, item in enumerate(value):
                yield from walk(item, path + (key, k))


def tables(node, path: tuple = ()):
    """(path, table) of the document and of every table inside it."""
    yield path, node
    for key, value in node.items():
        if isinstance(value, dict):
            yield from tables(value, path + (key,))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for k, item in enumerate(value):
                yield from tables(item, path + (key, k))


def field_name(path: tuple) -> str:
    """The loader's name of a field: dotted keys, [k] for entries of an array of tables."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else part)
    return text


def key_name(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def get(doc, path: tuple):
    for part in path:
        doc = doc[part]
    return doc


def required(parent: dict, key: str, path: tuple) -> bool:
    if path == ():
        return key in ("grid", "shape")
    if path == ("grid",):
        return key in ("size", "extent")
    if path[-1:] == ("half_plane",):
        return key == "normal"
    if len(path) >= 2 and path[-2] == "regions":
        return key in ("kind", "shape", "half_plane")
    if "type" in parent:
        return key == "type" or key in SHAPE_REQUIRED.get(parent["type"], set())
    return False


# ---------------------------------------------------------------------------
# One malformed file


@dataclass(frozen=True)
class Case:
    """A malformed scene: the file's bytes, extra files beside it, and what the error must name.

    ``field`` is the field the line must name; None means a whole-file error whose message
    starts with ``message``; ``message`` None with ``field`` None accepts any one-line error.
    """

    mutation: str
    content: bytes
    files: dict[str, bytes] = field(default_factory=dict)
    field: str | None = None
    message: str | None = None


def scene_case(mutation: str, doc: dict, field_: str, files: dict[str, bytes] | None = None) -> Case:
    return Case(mutation, dump_toml(doc).encode("utf-8"), {"outline.csv": SQUARE_CSV, **(files or {})}, field_)


def shape_paths(doc: dict) -> list[tuple]:
    """Paths of every shape table: the object, union parts and cutouts, region shapes."""
    return [p for p, t in tables(doc) if isinstance(t, dict) and "type" in t]


GARBAGE_LINES = ["= 1", "[grid", "a = ", 'b = "unterminated', "c = 1 2", "[[", "d = [1, 2", "e = {f = 1",
                 "g = 01", "h = 1__0", "name = 'duplicate'", "i = 1.", "j = .5", "k = tru", "l = {m = 1,}",
                 '"n" "o" = 1', "p = 1979-13-40", "\x00", "q = \"a\x01b\""]
INVALID_UTF8 = [b"\xff", b"\xfe\xff", b"\xc0\xaf", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80", b"\x80",
                b"\xe2\x82", b"\xc3"]
BAD_CSV_ROWS = ["a,1", "1", "1,2,3", "nan,0", "1,inf", "0x10,1", "1;2", "--1,0", "1e,2", "'1',2"]


@st.composite
def malformed_scenes(draw) -> Case:
    doc = base_scene(draw(st.sampled_from(sorted(SHAPES))))
    mutation = draw(st.sampled_from([
        "delete required", "wrong type", "out of range", "unknown key", "bowtie", "outside the grid",
        "too coarse", "bad quantity", "broken toml", "invalid utf-8", "random bytes", "bad outline",
        "bad region",
    ]))
    fields = list(walk(doc))

    if mutation == "delete required":
        path, parent, key = draw(st.sampled_from([f for f in fields if required(f[1], f[2], f[0])]))
        del parent[key]
        region_geometry = key in ("shape", "half_plane") and len(path) >= 2 and path[-2] == "regions"
        return scene_case(mutation, doc, field_name(path if region_geometry else path + (key,)))

    if mutation == "wrong type":
        path, parent, key = draw(st.sampled_from(fields))
        s = spec(parent, key, path)
        values = WRONG_TYPE[s.kind] + ([[]] if key == "parts" else [])
        parent[key] = draw(st.sampled_from(values))
        return scene_case(mutation, doc, field_name(path + (key,)))

    if mutation == "out of range":
        path, parent, key = draw(st.sampled_from([f for f in fields if bad_values(spec(f[1], f[2], f[0]))]))
        parent[key] = draw(st.sampled_from(bad_values(spec(parent, key, path))))
        return scene_case(mutation, doc, field_name(path + (key,)))

    if mutation == "unknown key":
        path, table = draw(st.sampled_from(list(tables(doc))))
        key = draw(st.one_of(
            st.sampled_from(["colour", "radius2", "Size", "extent ", "a.b", "a\nb", "\u00fcn\u00efcode", "x y", ""]),
            st.text(max_size=12),
        ).filter(lambda k: k not in ALL_KEYS))
        table[key] = draw(st.one_of(st.integers(), st.floats(allow_nan=False), st.text(max_size=5), st.booleans()))
        return scene_case(mutation, doc, field_name(path) + ("." if path else "") + key_name(key))

    if mutation == "bowtie":
        path = draw(st.sampled_from(shape_paths(doc)))
        s = draw(st.floats(0.005, 0.04))
        cx, cy = draw(st.floats(-0.02, 0.02)), draw(st.floats(-0.02, 0.02))
        bowtie = [[cx - s, cy - s], [cx + s, cy + s], [cx + s, cy - s], [cx - s, cy + s]]
        parent = get(doc, path[:-1])
        parent[path[-1]] = {"type": "polygon", "exterior": bowtie}
        return scene_case(mutation, doc, field_name(path + ("exterior",)))

    if mutation == "outside the grid":
        if draw(st.booleans()):
            far = draw(st.floats(0.1, 99.0)) * draw(st.sampled_from([-1, 1]))
            near = draw(st.floats(-0.05, 0.05))
            doc["shape"]["offset"] = [far, near] if draw(st.booleans()) else [near, far]
        else:
            doc["grid"]["extent"] = draw(st.floats(0.01, 0.05))
        return scene_case(mutation, doc, "shape")

    if mutation == "too coarse":
        if draw(st.booleans()):
            doc["shape"] = {"type": "rectangle", "width": draw(st.floats(0.02, 0.08)),
                            "height": draw(st.floats(0.0005, 0.0099)), "angle": draw(st.floats(-3.0, 3.0))}
        else:
            doc["grid"]["size"] = 8  # cells of 25 mm
            doc["shape"] = {"type": "disk", "radius": draw(st.floats(0.005, 0.024))}
        return scene_case(mutation, doc, "grid.size")

    if mutation == "bad quantity":
        quantities = [f for f in fields if spec(f[1], f[2], f[0]).kind == "length"]
        path, parent, key = draw(st.sampled_from(quantities))
        unit = draw(st.from_regex(r"[a-zA-Z]{1,6}", fullmatch=True).filter(
            lambda u: u not in ("m", "cm", "mm", "cell", "cells")))
        number = draw(st.floats(-10, 10, allow_nan=False))
        parent[key] = draw(st.one_of(st.sampled_from(BAD_QUANTITIES), st.just(f"{number} {unit}")))
        return scene_case(mutation, doc, field_name(path + (key,)))

    if mutation == "broken toml":
        lines = dump_toml(doc).splitlines(keepends=True)
        if draw(st.booleans()):
            at = draw(st.integers(0, len(lines)))
            lines.insert(at, draw(st.sampled_from(GARBAGE_LINES)) + "\n")
            text = "".join(lines)
        else:  # cut the file inside an inline table: it is never closed
            k = draw(st.sampled_from([i for i, line in enumerate(lines) if "{" in line]))
            line = lines[k]
            cut = draw(st.integers(line.index("{") + 1, line.rindex("}") - 1))
            text = "".join(lines[:k]) + line[:cut]
        return Case(mutation, text.encode("utf-8"), {"outline.csv": SQUARE_CSV}, None, "invalid TOML: ")

    if mutation == "invalid utf-8":
        text = dump_toml(doc).encode("utf-8")
        at = draw(st.integers(0, len(text)))
        content = text[:at] + draw(st.sampled_from(INVALID_UTF8)) + text[at:]
        return Case(mutation, content, {"outline.csv": SQUARE_CSV}, None, "not a text file (invalid UTF-8)")

    if mutation == "random bytes":
        return Case(mutation, draw(st.binary(max_size=200)))

    if mutation == "bad outline":
        doc = base_scene("outline")
        problem = draw(st.sampled_from(["missing", "header", "row", "few", "crossing", "bytes", "huge",
                                        "directory", "nul"]))
        csv = SQUARE_CSV
        if problem == "missing":
            doc["shape"]["path"] = "missing-" + draw(st.from_regex(r"[a-z0-9]{1,8}", fullmatch=True)) + ".csv"
        elif problem == "header":
            header = draw(st.sampled_from(["x;y", "X Y", "a,b", "y,x", "x,y,z", "", "x", "1,2"]))
            csv = (header + "\n").encode() + SQUARE_CSV.split(b"\n", 1)[1]
        elif problem == "row":
            lines = SQUARE_CSV.split(b"\n")
            at = draw(st.integers(1, len(lines) - 1))
            csv = b"\n".join(lines[:at] + [draw(st.sampled_from(BAD_CSV_ROWS)).encode()] + lines[at:])
        elif problem == "few":
            csv = b"x,y\n0,0\n1,1\n"
        elif problem == "crossing":
            csv = b"x,y\n0,0\n4,4\n4,0\n0,4\n"
        elif problem == "bytes":
            csv = SQUARE_CSV + draw(st.sampled_from(INVALID_UTF8)) + b",1\n"
        elif problem == "huge":
            csv = b"x,y\n0,0\n1e300,0\n0,1e300\n"
        elif problem == "directory":
            doc["shape"]["path"] = "."
        else:
            doc["shape"]["path"] = "outline\x00.csv"
        return scene_case(mutation, doc, "shape.path", {"outline.csv": csv})

    # bad region
    regions = doc["sensor"]["regions"]
    k = draw(st.integers(0, len(regions) - 1))
    region = regions[k]
    where = ("sensor", "regions", k)
    problem = draw(st.sampled_from(["both", "neither", "zero normal", "bowtie", "drop", "noise",
                                    "other kind's parameter", "not tables"]))
    if problem == "both":
        region["shape"] = {"type": "disk", "radius": 0.01}
        region["half_plane"] = {"normal": [0.0, 1.0]}
        return scene_case(mutation, doc, field_name(where))
    if problem == "neither":
        region.pop("shape", None)
        region.pop("half_plane", None)
        return scene_case(mutation, doc, field_name(where))
    if problem == "zero normal":
        region.pop("shape", None)
        region["half_plane"] = {"normal": [0.0, 0.0], "offset": 0.0}
        return scene_case(mutation, doc, field_name(where + ("half_plane", "normal")))
    if problem == "bowtie":
        region.pop("half_plane", None)
        region["shape"] = {"type": "polygon", "exterior": [[0, 0], [0.01, 0.01], [0.01, 0], [0, 0.01]]}
        return scene_case(mutation, doc, field_name(where + ("shape", "exterior")))
    if problem == "drop":
        region["kind"] = "specular"
        region.pop("value", None)
        region["drop_probability"] = draw(st.sampled_from(OUT_OF_RANGE["probability"]))
        return scene_case(mutation, doc, field_name(where + ("drop_probability",)))
    if problem == "noise":
        if region["kind"] == "occluded":
            region["kind"] = "transparent"
        region["noise"] = draw(st.sampled_from(POSITIVE_LENGTH))
        return scene_case(mutation, doc, field_name(where + ("noise",)))
    if problem == "other kind's parameter":
        foreign = {"occluded": ["value", "noise", "drop_probability"], "transparent": ["drop_probability"],
                   "specular": ["value"]}[region["kind"]]
        key = draw(st.sampled_from(foreign))
        region[key] = 0.5
        return scene_case(mutation, doc, field_name(where + (key,)))
    doc["sensor"]["regions"] = draw(st.sampled_from(WRONG_TYPE["tables"]))
    return scene_case(mutation, doc, "sensor.regions")


def check_file(case: Case, folder: Path) -> tuple[int, str, str, Path]:
    """Writes the case into ``folder`` and runs ``gpis-harness scenes check`` on it in-process."""
    for name, content in case.files.items():
        (folder / name).write_bytes(content)
    path = folder / "bad.toml"
    path.write_bytes(case.content)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["scenes", "check", str(path)])
    return code, out.getvalue(), err.getvalue(), path


def assert_one_line_error(case: Case, code: int, out: str, err: str, path: Path) -> None:
    lines = err.splitlines()
    assert code == 2, f"{case.mutation}: exit {code}\n{err}"
    assert out == ""
    assert "Traceback" not in err
    assert len(lines) == 1, f"{case.mutation}: {len(lines)} lines:\n{err}"
    line = lines[0]
    assert line.startswith(PREFIX + str(path) + ": "), line
    rest = line[len(PREFIX + str(path) + ": "):]
    if case.field is not None:
        named = rest.startswith(case.field + ": ") or rest.startswith(case.field + ".") \
            or rest.startswith(case.field + "[")
        assert named, f"{case.mutation}: expected field {case.field!r} in: {line}"
    elif case.message is not None:
        assert rest.startswith(case.message), f"{case.mutation}: expected {case.message!r} in: {line}"
    assert rest.strip()


# ---------------------------------------------------------------------------
# The tests


@pytest.mark.parametrize("shape", sorted(SHAPES))
def test_every_fuzzing_base_scene_is_valid(shape, tmp_path):
    case = scene_case("none", base_scene(shape), "")
    code, out, err, path = check_file(case, tmp_path)
    assert (code, err) == (0, "")
    assert out.startswith(f"{path}: ok (fuzz-{shape}, grid 40 x 40)")


def test_toml_writer_round_trips_awkward_strings_and_numbers():
    import tomllib

    doc = {"a\nb": "q\"\\\x00\x7f\u00e9\u2028", "n": [NAN, INF, -INF, 1e-300, HUGE_INT, True], "t": {"": {}}}
    back = tomllib.loads(dump_toml(doc))
    assert back["a\nb"] == doc["a\nb"] and back["n"][3:] == doc["n"][3:] and back["t"] == {"": {}}
    assert math.isnan(back["n"][0]) and back["n"][1:3] == [INF, -INF]


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=malformed_scenes())
def test_malformed_scene_exits_2_with_one_line_naming_the_file(case):
    event(case.mutation)  # pytest --hypothesis-show-statistics shows the mix
    with tempfile.TemporaryDirectory() as folder:
        code, out, err, path = check_file(case, Path(folder))
        assert_one_line_error(case, code, out, err, path)


def command() -> list[str]:
    installed = REPO / ".venv" / "bin" / "gpis-harness"
    return [str(installed)] if installed.exists() else [sys.executable, "-m", "harness"]


@pytest.mark.parametrize("content, field", [
    (dump_toml({**base_scene("rectangle"), "extra": 1}).encode(), "extra"),
    (b"[grid]\nsize = 40\nextent = 0.2\n[shape]\ntype = 'polygon'\n"
     b"exterior = [[-0.02, -0.02], [0.02, 0.02], [0.02, -0.02], [-0.02, 0.02]]\n", "shape.exterior"),
    (b"\x00\xff\xfegarbage", None),
])
def test_installed_command_exits_2_with_one_stderr_line(content, field, tmp_path):
    path = tmp_path / "BAD.toml"
    path.write_bytes(content)
    run = subprocess.run(command() + ["scenes", "check", str(path)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert run.stdout == ""
    lines = run.stderr.splitlines()
    assert len(lines) == 1, run.stderr
    expected = PREFIX + f"{path}: " + (f"{field}: " if field else "")
    assert lines[0].startswith(expected), lines[0]
