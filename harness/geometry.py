"""Planar geometry: the grid, exact signed distance fields of polygons, and
sub-cell zero-level regions of sampled fields (shapely and contourpy do the work)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import contourpy
import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.base import BaseGeometry


@dataclass(frozen=True)
class Grid:
    """An M x M grid of cells over a square of side ``extent`` metres centred on the origin.

    Fields on the grid are arrays of shape (M, M) indexed ``[row, column] = [y, x]``,
    so ``field[j, i]`` is the value at the centre ``(xs[i], ys[j])``; row 0 is the
    bottom (most negative y).
    """

    size: int
    extent: float

    def __post_init__(self):
        # Plain Python numbers: a float32 field times the cell is then float32 whatever
        # made the grid (numpy's rule for Python scalars), as the compiled reads assume.
        object.__setattr__(self, "size", int(self.size))
        object.__setattr__(self, "extent", float(self.extent))

    @property
    def cell(self) -> float:
        """Cell side h in metres."""
        return self.extent / self.size

    @cached_property
    def coords(self) -> np.ndarray:
        """Cell-centre coordinates along either axis, shape (M,)."""
        return -0.5 * self.extent + (np.arange(self.size) + 0.5) * self.cell

    @cached_property
    def points(self) -> np.ndarray:
        """All cell centres, shape (M*M, 2), in the row-major order of a flattened field."""
        xx, yy = np.meshgrid(self.coords, self.coords)
        return np.column_stack([xx.ravel(), yy.ravel()])

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """True where points lie inside the grid square shrunk by ``margin`` metres."""
        half = 0.5 * self.extent - margin
        p = np.asarray(points, dtype=float)
        return np.all(np.abs(p) <= half, axis=-1)

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        """Integer (column, row) of the cell containing each point, shape (..., 2)."""
        p = np.asarray(points, dtype=float)
        idx = np.floor((p + 0.5 * self.extent) / self.cell).astype(int)
        return np.clip(idx, 0, self.size - 1)


def signed_distance(geometry: BaseGeometry, points: np.ndarray) -> np.ndarray:
    """Exact signed distance from points (P, 2) to the boundary of a polygonal region.

    Negative inside, positive outside; the distance is to the polygon edges (holes
    included), not a rasterised approximation.
    """
    p = np.asarray(points, dtype=float)
    pts = shapely.points(p)
    dist = shapely.distance(geometry.boundary, pts)
    inside = shapely.contains_xy(geometry, p[:, 0], p[:, 1])
    return np.where(inside, -dist, dist)


def signed_distance_gradient(geometry: BaseGeometry, points: np.ndarray) -> np.ndarray:
    """Exact gradient (P, 2) of the signed distance: the unit vector from the nearest
    boundary point, pointing outwards; zero on the boundary itself."""
    p = np.asarray(points, dtype=float)
    lines = shapely.shortest_line(geometry.boundary, shapely.points(p))
    nearest = shapely.get_coordinates(lines)[0::2]
    away = p - nearest
    dist = np.linalg.norm(away, axis=1)
    inside = shapely.contains_xy(geometry, p[:, 0], p[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(dist[:, None] > 0, away / dist[:, None], 0.0)
    return np.where(inside[:, None], -unit, unit)


def grid_sdf(geometry: BaseGeometry, grid: Grid, truncation: float | None = None) -> np.ndarray:
    """Signed distance field of ``geometry`` at the grid's cell centres, shape (M, M),
    clipped to [-truncation, truncation] when a truncation is given."""
    field = signed_distance(geometry, grid.points).reshape(grid.size, grid.size)
    if truncation is not None:
        field = np.clip(field, -truncation, truncation)
    return field


def grid_sdf_gradient(geometry: BaseGeometry, grid: Grid, truncation: float | None = None) -> np.ndarray:
    """Gradient (M, M, 2) of :func:`grid_sdf`: exact, and zero where the field is clipped."""
    grad = signed_distance_gradient(geometry, grid.points).reshape(grid.size, grid.size, 2)
    if truncation is not None:
        clipped = np.abs(signed_distance(geometry, grid.points)).reshape(grid.size, grid.size) >= truncation
        grad[clipped] = 0.0
    return grad


def polygons(geometry: BaseGeometry) -> list[Polygon]:
    """The polygon parts of a (multi)polygon, as a list."""
    if geometry.is_empty:
        return []
    if isinstance(geometry, Polygon):
        return [geometry]
    if isinstance(geometry, MultiPolygon):
        return list(geometry.geoms)
    return [g for g in getattr(geometry, "geoms", []) if isinstance(g, Polygon)]


def largest_region(geometry: BaseGeometry) -> Polygon:
    """The connected part of largest area (holes kept); an empty Polygon if there is none."""
    parts = polygons(geometry)
    if not parts:
        return Polygon()
    return max(parts, key=lambda g: g.area)


def inside_region(field: np.ndarray, grid: Grid, level: float = 0.0) -> BaseGeometry:
    """The region where the bilinear interpolant of ``field`` is below ``level``.

    Marching squares (contourpy) with sub-cell edges; the region is clipped to the
    square spanned by the cell centres. Returns a (Multi)Polygon, possibly empty.
    """
    gen = contourpy.contour_generator(
        grid.coords, grid.coords, np.asarray(field, dtype=float),
        fill_type=contourpy.FillType.OuterOffset,
    )
    lower = min(float(np.min(field)), level) - 1.0
    points_list, offsets_list = gen.filled(lower, level)
    parts = []
    for pts, offs in zip(points_list, offsets_list):
        rings = [pts[offs[k]:offs[k + 1]] for k in range(len(offs) - 1)]
        if len(rings[0]) < 4:
            continue
        poly = Polygon(rings[0], [r for r in rings[1:] if len(r) >= 4])
        if not poly.is_valid:
            poly = shapely.make_valid(poly)
        parts.extend(polygons(poly))
    if not parts:
        return Polygon()
    return shapely.union_all(parts) if len(parts) > 1 else parts[0]


def zero_contours(field: np.ndarray, grid: Grid, level: float = 0.0) -> list[np.ndarray]:
    """Polylines (K_i, 2) of the ``level`` set of the bilinear interpolant of ``field``."""
    gen = contourpy.contour_generator(grid.coords, grid.coords, np.asarray(field, dtype=float))
    return [np.asarray(line) for line in gen.lines(level)]
