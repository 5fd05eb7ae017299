"""The canonical grid: rounding to multiples of 0.1 um, idempotent, polygons keep their
structure, and differences far below the grid vanish."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import Polygon, box

from harness.canonical import GRID, canonical, canonical_polygon


def test_canonical_values_are_the_nearest_multiples_of_the_grid_written_in_decimal():
    x = np.array([0.0123456789, -0.04500004, 0.04500006, 1e-9, -0.2])
    c = canonical(x)
    np.testing.assert_array_equal(c, [0.0123457, -0.045, 0.0450001, 0.0, -0.2])
    assert np.all(np.abs(c - x) <= 0.5 * GRID + 1e-18)
    assert [repr(float(v)) for v in c[:3]] == ["0.0123457", "-0.045", "0.0450001"]


def test_canonical_is_idempotent_and_keeps_shapes_and_scalars():
    x = np.random.default_rng(0).uniform(-0.2, 0.2, (1000, 2, 2))
    c = canonical(x)
    assert c.shape == x.shape
    np.testing.assert_array_equal(canonical(c), c)
    assert isinstance(canonical(0.01234567), float) and canonical(0.01234567) == 0.0123457
    assert np.isnan(canonical(np.nan)) and canonical(np.inf) == np.inf


def test_differences_far_below_the_grid_round_to_the_same_value():
    # Away from the half-way points (all but a fraction 2e-4 of them), a difference of
    # 1e-11 m, the size of the planners' cross-host differences, is invisible.
    rng = np.random.default_rng(1)
    x = rng.uniform(-0.1, 0.1, 100_000)
    offset = np.abs(x / GRID - np.round(x / GRID))
    clear = np.abs(offset - 0.5) > 1e-3
    same = canonical(x + 1e-11 * rng.choice([-1.0, 1.0], x.shape)) == canonical(x)
    assert same[clear].all()
    assert same.mean() > 0.999


def test_a_canonical_polygon_keeps_its_rings_and_has_every_vertex_on_the_grid():
    rng = np.random.default_rng(2)
    outer = box(-0.03, -0.02, 0.04, 0.025).exterior.coords[:-1] + rng.uniform(-1e-3, 1e-3, (4, 2))
    hole = box(-0.01, -0.005, 0.01, 0.005).exterior.coords[:-1] + rng.uniform(-1e-4, 1e-4, (4, 2))
    polygon = Polygon(outer, [hole])
    rounded = canonical_polygon(polygon)
    assert len(rounded.interiors) == 1 and rounded.is_valid
    xy, rxy = shapely.get_coordinates(polygon), shapely.get_coordinates(rounded)
    np.testing.assert_array_equal(rxy, canonical(xy))
    assert np.abs(rxy - xy).max() <= 0.5 * GRID
    assert canonical_polygon(Polygon()).is_empty


def test_a_polygon_that_rounding_would_make_invalid_is_kept_as_it_was():
    # A slit 0.04 um wide: rounded, its two sides touch.
    slit = Polygon([(0.0, 0.0), (0.02, 0.0), (0.02, 0.01), (0.01000002, 0.01), (0.01000002, 0.002),
                    (0.00999998, 0.002), (0.00999998, 0.01), (0.0, 0.01)])
    assert slit.is_valid and not shapely.transform(slit, canonical).is_valid
    assert canonical_polygon(slit) is slit
