"""Scene files (TOML) -> validated Scene values; the built-in scene library.

Every check happens at load time, before any work: a bad file raises InputError
naming the file, the field and what is wrong. ``docs/scenes.md`` documents the format.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import shapely
import shapely.affinity
from scipy import ndimage
from shapely.geometry import Point, Polygon, box
from shapely.geometry.base import BaseGeometry

from harness.errors import InputError
from harness.geometry import Grid, grid_sdf, grid_sdf_gradient, inside_region, largest_region, polygons
from harness.sensor import REGION_KINDS, Region, SensorModel
from harness.settings import BOUNDS
from harness.toml_table import Table, read_text, read_toml

LIBRARY = Path(os.environ.get("GPIS_HARNESS_SCENES", Path(__file__).resolve().parent.parent / "scenes"))

#: A shape must keep this many cells away from the grid border (room for the jaws).
BORDER_CELLS = 2.0
#: The shape's largest inscribed circle must have at least this radius, in cells.
MIN_INSCRIBED_CELLS = 1.0
#: A scene's name keys its plans and trials and names its figures: a file name's safe subset.
#: The sensor's smallest noise std, in cells (harness.gpis draws in single precision).
MIN_NOISE_CELLS = 0.01
SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
SAFE_NAME_RULE = "use 1 to 64 letters, digits, '.', '_' or '-', starting with a letter or digit"
SHAPE_TYPES = ("polygon", "outline", "rectangle", "disk", "ring", "capsule", "union", "random")


@dataclass(frozen=True)
class GPISSettings:
    """Hyperparameters (metres) and fitting choices of the scene's GPIS."""

    lengthscale: float
    scale: float
    prior_mean: float
    hyperparameters: str = "fixed"  # "fixed" or "ml" (ML-II fit, starting from the values above)
    use_gradients: bool = True
    active_set: bool = True
    active_band: float = 0.0
    active_spacing: float = 0.0


@dataclass(frozen=True)
class Physics:
    """Physical properties of the extruded object."""

    thickness: float = 0.03
    density: float = 400.0
    friction: float = 0.5


@dataclass(frozen=True)
class Gripper:
    """Parallel-jaw gripper geometry (metres)."""

    opening: float = 0.10
    jaw_width: float = 0.01
    sigma_g: float = 0.0025  # approach noise: std of each jaw start's placement error
    force: float = 20.0  # N: the jaws' force limit
    closing_speed: float = 0.05  # m/s: the jaws' largest closing speed, each
    plate_height: float = 0.01  # m: how far the jaw plates reach above the object's top


@dataclass(frozen=True)
class Scene:
    """A validated scene: true shape, grid, sensor, GPIS settings, physics, gripper."""

    name: str
    description: str
    source: str
    grid: Grid
    shape: Polygon
    truncation: float
    sensor: SensorModel
    gpis: GPISSettings
    physics: Physics
    gripper: Gripper

    @cached_property
    def true_sdf(self) -> np.ndarray:
        """Exact signed distance of the true shape at the cell centres, truncated, (M, M)."""
        return grid_sdf(self.shape, self.grid, self.truncation)

    @cached_property
    def true_sdf_gradient(self) -> np.ndarray:
        """Exact gradient of :attr:`true_sdf`, (M, M, 2); zero where it is truncated."""
        return grid_sdf_gradient(self.shape, self.grid, self.truncation)



# ---------------------------------------------------------------------------
# Finding and loading scenes


def library_names() -> list[str]:
    """Names of the scenes in the library, sorted."""
    if not LIBRARY.is_dir():
        return []
    return sorted(p.stem for p in LIBRARY.glob("*.toml"))


def resolve(name_or_path: str) -> Path:
    """The file of a library scene name or a path; InputError when neither exists."""
    if not name_or_path:
        raise InputError("scene", None, "an empty name is neither a library scene nor a file")
    candidate = Path(name_or_path)
    if candidate.suffix == ".toml" or os.sep in name_or_path or candidate.exists():
        if not candidate.is_file():
            what = ("is a folder, not a scene file" if candidate.is_dir() else
                    "is not a regular file" if candidate.exists() else "no such scene file")
            raise InputError(name_or_path, None, what)
        return candidate
    path = LIBRARY / f"{name_or_path}.toml"
    if not path.is_file():
        known = ", ".join(library_names()) or "none"
        raise InputError(name_or_path, None, f"unknown scene (library: {known})")
    return path


def load_scene(name_or_path: str | Path, overrides: dict | None = None) -> Scene:
    """Load and validate a scene by library name or path.

    ``overrides`` (nested tables, e.g. ``{"grid": {"size": 100}}``) replace the file's
    values before validation, so quantities given in cells follow the new grid.
    """
    path = resolve(str(name_or_path))
    data = read_toml(path)
    return parse_scene(_merged(data, overrides or {}), source=str(path), base_dir=path.parent, default_name=path.stem)


def _printable(text: str) -> str:
    """``text`` for a one-line message: control characters escaped, long text cut."""
    shown = text.encode("unicode_escape").decode("ascii")
    return shown if len(shown) <= 70 else shown[:67] + "..."


def _merged(data: dict, overrides: dict) -> dict:
    out = dict(data)
    for key, value in overrides.items():
        both_tables = isinstance(value, dict) and isinstance(out.get(key), dict)
        out[key] = _merged(out[key], value) if both_tables else value
    return out


def parse_scene(data: dict, source: str, base_dir: Path, default_name: str = "scene") -> Scene:
    """Validate a parsed scene document (see ``docs/scenes.md``)."""
    root = Table(data, "", source)
    name = root.string("name", default_name)
    if not SAFE_NAME.fullmatch(name):
        field = "name" if "name" in data else None
        raise root.error(field, f"scene name '{_printable(name)}' is not usable: {SAFE_NAME_RULE}"
                                + ("" if field else " (it comes from the file name; set `name` in the file)"))
    if name == "all":
        raise root.error("name" if "name" in data else None,
                         "scene name 'all' is the tables' name for every scene pooled; give the scene another name")
    description = root.string("description", "")

    g = root.table("grid")
    size = g.integer("size", lo=8, hi=1024)
    extent = g.number("extent", lo=0.0, hi=100.0, lo_open=True)
    cell = extent / size
    truncation = g.length("truncation", cell, default=3 * cell, lo=cell)
    g.finish()
    grid = Grid(size, extent)

    shape = _shape(root.table("shape"), cell, base_dir)
    _check_shape_on_grid(shape, grid, source)

    sensor = _sensor(root.table("sensor", required=False), grid, base_dir)
    gpis = _gpis(root.table("gpis", required=False), cell, truncation)

    p = root.table("physics", required=False)
    physics = Physics(
        thickness=p.length("thickness", cell, default=Physics.thickness, **_range("thickness")),
        density=p.number("density", Physics.density, **_range("density")),
        friction=p.number("friction", Physics.friction, **_range("friction")),
    )
    p.finish()
    gr = root.table("gripper", required=False)
    gripper = Gripper(**{key: (gr.number(key, getattr(Gripper, key), **_range(key))
                               if key in ("force", "closing_speed") else
                               gr.length(key, cell, default=getattr(Gripper, key), **_range(key)))
                         for key in ("opening", "jaw_width", "sigma_g", "force", "closing_speed", "plate_height")})
    gr.finish()
    root.finish()
    return Scene(name, description, source, grid, shape, truncation, sensor, gpis, physics, gripper)


def _range(name: str) -> dict:
    """The range of a grasp setting (harness.settings.BOUNDS) as keyword arguments of
    Table.length or Table.number."""
    lo, hi, lo_open = BOUNDS[name]
    return {"lo": lo, "hi": hi, "lo_open": lo_open}


# ---------------------------------------------------------------------------
# Shapes


def _shape(t: Table, cell: float, base_dir: Path) -> BaseGeometry:
    kind = t.string("type", choices=SHAPE_TYPES)
    if kind == "polygon":
        exterior = t.points("exterior")
        holes = [t.points_value(h, f"holes[{k}]") for k, h in enumerate(t.list("holes", []))]
        geom = _valid_polygon(t, Polygon(exterior, holes), "exterior")
    elif kind == "outline":
        geom = _outline(t, cell, base_dir)
    elif kind == "rectangle":
        w = t.length("width", cell, lo=0.0)
        h = t.length("height", cell, lo=0.0)
        c = t.point("center", (0.0, 0.0))
        angle = t.number("angle", 0.0)
        geom = shapely.affinity.rotate(box(-w / 2, -h / 2, w / 2, h / 2), angle, origin=(0, 0), use_radians=True)
        geom = shapely.affinity.translate(geom, *c)
    elif kind == "disk":
        r = t.length("radius", cell, lo=0.0)
        geom = Point(t.point("center", (0.0, 0.0))).buffer(r, quad_segs=64)
    elif kind == "ring":
        r_out = t.length("outer_radius", cell, lo=0.0)
        r_in = t.length("inner_radius", cell, lo=0.0)
        if r_in >= r_out:
            raise t.error("inner_radius", f"must be smaller than outer_radius ({r_in:g} >= {r_out:g} m)")
        c = Point(t.point("center", (0.0, 0.0)))
        geom = c.buffer(r_out, quad_segs=64).difference(c.buffer(r_in, quad_segs=64))
    elif kind == "capsule":
        a, b = t.point("start"), t.point("end")
        r = t.length("radius", cell, lo=0.0)
        geom = shapely.LineString([a, b]).buffer(r, quad_segs=32) if a != b else Point(a).buffer(r, quad_segs=64)
    elif kind == "union":
        parts = [_shape(p, cell, base_dir) for p in t.tables("parts", min_count=1)]
        cutouts = [_shape(p, cell, base_dir) for p in t.tables("cutouts", min_count=0)]
        geom = shapely.union_all(parts)
        if cutouts:
            geom = geom.difference(shapely.union_all(cutouts))
    else:
        geom = _random_shape(t, cell)
    angle = t.number("rotate", 0.0)
    offset = t.point("offset", (0.0, 0.0))
    t.finish()
    if angle:
        geom = shapely.affinity.rotate(geom, angle, origin=(0, 0), use_radians=True)
    if offset != (0.0, 0.0):
        geom = shapely.affinity.translate(geom, *offset)
    if geom.is_empty or geom.area <= 0.0:
        raise t.error(None, "shape is empty (zero area)")
    return geom


def _valid_polygon(t: Table, geom: Polygon, field: str) -> Polygon:
    if not geom.is_valid:
        reason = shapely.is_valid_reason(geom)
        m = re.match(r"([^\[]+)\[([-0-9.eE+]+) ([-0-9.eE+]+)\]", reason)
        if m:
            reason = f"{m.group(1).lower()} at ({float(m.group(2)):.4g}, {float(m.group(3)):.4g})"
        raise t.error(field, f"invalid polygon: {reason}")
    return geom


def outline_files(path: str | Path) -> list[tuple[str, Path]]:
    """The outline files a scene file reads (``type = "outline"`` tables anywhere in it:
    the shape, a union's parts, a region's shape), each as written in the file and
    resolved against the file's folder, in file order. Their content is part of the scene
    (harness.config hashes it beside the scene's own text)."""
    found: list[tuple[str, Path]] = []

    def walk(value) -> None:
        if isinstance(value, dict):
            if value.get("type") == "outline" and isinstance(value.get("path"), str):
                found.append((value["path"], (Path(path).parent / value["path"]).resolve()))
            for v in value.values():
                walk(v)
        elif isinstance(value, list):
            for v in value:
                walk(v)

    walk(read_toml(Path(path)))
    return found


def _outline(t: Table, cell: float, base_dir: Path) -> Polygon:
    rel = t.string("path")
    scale = t.number("scale", lo=0.0, lo_open=True, hi=100.0)
    centring = t.string("center", "centroid", choices=("centroid", "bbox", "none"))
    flip_y = t.boolean("flip_y", False)
    if "\0" in rel:
        raise t.error("path", "must not contain a NUL character")
    path = (base_dir / rel).resolve()
    try:
        text = read_text(path)
        if "\0" in text:
            raise InputError(str(path), None, "not a text file (it contains NUL bytes)")
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except InputError as exc:
        raise t.error("path", f"outline {path}: {exc.message}") from None
    except csv.Error as exc:
        raise t.error("path", f"outline {path}: not a CSV file ({exc})") from None
    if not rows or [c.strip().lower() for c in rows[0]] != ["x", "y"]:
        raise t.error("path", f"outline {path}: first line must be the header 'x,y'")
    vertices = []
    for line_no, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            if len(row) != 2:
                raise ValueError
            x, y = float(row[0]), float(row[1])
            if not (math.isfinite(x) and math.isfinite(y)):
                raise ValueError
        except ValueError:
            raise t.error("path", f"outline {path}, line {line_no}: expected two finite numbers") from None
        vertices.append((x, -y if flip_y else y))
    if len(vertices) < 3:
        raise t.error("path", f"outline {path}: needs at least 3 vertices, has {len(vertices)}")
    vertices = np.asarray(vertices) * scale
    if np.abs(vertices).max() > 100.0:
        raise t.error("path", f"outline {path}: coordinates times scale must be within 100 m of the origin")
    geom = _valid_polygon(t, Polygon(vertices), "path")
    if centring == "centroid":
        c = geom.centroid
        geom = shapely.affinity.translate(geom, -c.x, -c.y)
    elif centring == "bbox":
        x0, y0, x1, y1 = geom.bounds
        geom = shapely.affinity.translate(geom, -(x0 + x1) / 2, -(y0 + y1) / 2)
    return geom


def _random_shape(t: Table, cell: float) -> Polygon:
    """The largest region below zero of |x|^2/R^2 - 1 + amplitude * xi(x), where xi is
    white noise smoothed by a Gaussian of standard deviation ``lengthscale`` (so its
    correlation is exp(-d^2 / (4 lengthscale^2))), shifted and scaled to mean 0, std 1.

    The field lives on a 256 x 256 lattice over [-H, H]^2 with H = 2R for amplitudes up
    to 0.5, widened with the amplitude (H = 2R sqrt((1 + 4 amplitude) / 3)) so that even
    a four-sigma excursion of xi stays inside it; the shape depends only on its own
    parameters, never on the scene's grid.
    """
    seed = t.integer("seed", lo=0, hi=2**63 - 1)
    radius = t.length("radius", cell, lo=1e-4, lo_open=False)  # from 0.1 mm: the lattice's cells stay finite
    # The lattice is periodic and 4R wide: beyond 2R its lowest modes, not the lengthscale,
    # set the correlation, while the filter's cost keeps growing with the lengthscale.
    lengthscale = t.length("lengthscale", cell, default=0.5 * radius, lo=0.0, hi=2.0 * radius)
    amplitude = t.number("amplitude", 0.5, lo=0.0, hi=5.0)
    n = 256
    lattice = Grid(n, 4 * radius * max(1.0, math.sqrt((1 + 4 * amplitude) / 3)))
    rng = np.random.default_rng(seed)
    xi = ndimage.gaussian_filter(rng.standard_normal((n, n)), lengthscale / lattice.cell, mode="wrap")
    # Smoothing keeps the noise's sample mean while it shrinks every other mode; left in,
    # that constant would scale the whole shape by a seed-dependent factor.
    xi = (xi - xi.mean()) / xi.std()
    r2 = (lattice.points**2).sum(axis=1).reshape(n, n) / radius**2
    region = largest_region(inside_region(r2 - 1.0 + amplitude * xi, lattice))
    if region.is_empty:
        raise t.error("amplitude", "the random field has no region below zero; lower the amplitude")
    return region.simplify(lattice.cell / 4)


def _check_shape_on_grid(shape: BaseGeometry, grid: Grid, source: str) -> None:
    field = "shape"
    parts = polygons(shape)
    if len(parts) != 1:
        raise InputError(source, field, f"shape has {len(parts)} disconnected parts; an object must be one piece")
    limit = 0.5 * grid.extent - BORDER_CELLS * grid.cell
    x0, y0, x1, y1 = shape.bounds
    worst = max(abs(x0), abs(y0), abs(x1), abs(y1))
    if worst > limit:
        raise InputError(
            source, field,
            f"shape outside the grid: it reaches {worst:.4g} m from the centre, the grid allows "
            f"{limit:.4g} m (half the extent less {BORDER_CELLS:g} cells)",
        )
    radius = shapely.maximum_inscribed_circle(shape, grid.cell / 20).length
    # The relative slack forgives rounding in rotated coordinates: a part exactly two
    # cells thick passes whatever its orientation.
    if radius < MIN_INSCRIBED_CELLS * grid.cell * (1 - 1e-9):
        raise InputError(
            source, "grid.size",
            f"grid too coarse for the shape: its thickest part is {2 * radius / grid.cell:.2f} cells across, "
            f"needs at least {2 * MIN_INSCRIBED_CELLS:g} (raise grid.size)",
        )


# ---------------------------------------------------------------------------
# Sensor and GPIS sections


def _sensor(t: Table, grid: Grid, base_dir: Path) -> SensorModel:
    cell = grid.cell
    # Readings' noise from a hundredth of a cell: far below it the GP's posterior is singular
    # in the precision its samples are drawn in (at 1e-4 cells every posterior sample of
    # a rectangle came out with no body the jaws could meet).
    noise = t.length("noise", cell, default=0.5 * cell, lo=MIN_NOISE_CELLS * cell, lo_open=False)
    band = t.length("surface_band", cell, default=1.5 * cell, lo=0.0, lo_open=True)
    depth = t.length("interior_depth", cell, default=2.0 * cell, lo=0.0)
    keep = t.number("interior_keep", 1.0, lo=0.0, hi=1.0)
    regions = []
    for r in t.tables("regions", min_count=0):
        kind = r.string("kind", choices=REGION_KINDS)
        has_shape, has_plane = "shape" in r.data, "half_plane" in r.data
        if has_shape == has_plane:
            raise r.error(None, "give exactly one of 'shape' or 'half_plane'")
        if has_shape:
            geom = _shape(r.table("shape"), cell, base_dir)
        else:
            hp = r.table("half_plane")
            normal = np.asarray(hp.point("normal"))
            if np.hypot(*normal) == 0.0:
                raise hp.error("normal", "must not be the zero vector")
            offset = hp.length("offset", cell, default=0.0, lo=-100.0, hi=100.0, lo_open=False)
            hp.finish()
            geom = _half_plane(normal / np.hypot(*normal), offset)
        params: dict[str, float] = {}
        if kind == "transparent":
            params["depth"] = r.length("depth", cell, default=band, lo=0.0, lo_open=True)
            params["value"] = r.length("value", cell, default=0.5 * cell, lo=-100.0, hi=100.0)
            params["noise"] = r.length("noise", cell, default=math.sqrt(3.0) * cell, lo=MIN_NOISE_CELLS * cell,
                                       lo_open=False)
        elif kind == "specular":
            params["noise"] = r.length("noise", cell, default=2.0 * cell, lo=0.0, lo_open=True)
            params["drop_probability"] = r.number("drop_probability", 0.5, lo=0.0, hi=1.0)
        r.finish()
        regions.append(Region(kind=kind, geometry=geom, **params))
    occluded = [r.geometry for r in regions if r.kind == "occluded"]
    if occluded and shapely.contains_xy(shapely.union_all(occluded), grid.points[:, 0], grid.points[:, 1]).all():
        raise t.error("regions", "the occluded regions cover every cell of the grid: the sensor would see nothing")
    t.finish()
    return SensorModel(noise, band, depth, keep, tuple(regions))


def _half_plane(normal: np.ndarray, offset: float) -> Polygon:
    """The points p with normal . p >= offset, as a polygon much larger than any grid."""
    big = 1e3
    tangent = np.array([-normal[1], normal[0]])
    base = normal * offset
    corners = [base + big * tangent, base + big * tangent + big * normal,
               base - big * tangent + big * normal, base - big * tangent]
    return Polygon(corners)


def _gpis(t: Table, cell: float, truncation: float) -> GPISSettings:
    # From a tenth of a cell: a GP whose length scale is far below the cell is white noise on
    # the grid, and its basis (harness.gpis) is not defined in the limit.
    lengthscale = t.length("lengthscale", cell, default=2.7 * cell, lo=0.1 * cell, lo_open=False)
    settings = GPISSettings(
        lengthscale=lengthscale,
        scale=t.area("scale", cell, default=4.0 * cell**2),
        prior_mean=t.length("prior_mean", cell, default=-1.0 * cell, lo=-100.0, hi=100.0),
        hyperparameters=t.string("hyperparameters", "fixed", choices=("fixed", "ml")),
        use_gradients=t.boolean("use_gradients", True),
        active_set=t.boolean("active_set", True),
        active_band=t.length("active_band", cell, default=max(min(2.5 * cell, truncation - 0.5 * cell), 0.5 * cell),
                             lo=0.0),
        active_spacing=t.length("active_spacing", cell, default=lengthscale, lo=0.1 * cell, lo_open=False),
    )
    t.finish()
    return settings
