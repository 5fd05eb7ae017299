"""The canonical grid: lengths that reach the physics (jaw starts, outlines) are rounded
to multiples of GRID, so last-bit differences between hosts (BLAS kernels, SIMD paths)
in the numbers computed upstream do not reach Bullet, whose contacts would amplify them."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import Polygon

#: The grid (m): 0.1 um, a ten-thousandth of Bullet's collision margin (1 mm) and of the
#: outlines' simplification tolerance (a quarter of the smallest library cell, 4 mm), and
#: 1/25,000 of the approach noise (2.5 mm): the physics cannot tell a rounded input from
#: the exact one. It is 10^10 times the last-bit differences of an outline (about 1e-17 m).
GRID = 1e-7
#: 1 / GRID, an exact double: x * _SCALE rounded, divided by _SCALE, is the double nearest
#: to an integer times 0.1 um (as the decimal text "0.0123457" reads), whatever x was.
_SCALE = 1e7


def canonical(x):
    """``x`` (metres; a number or an array) rounded to the nearest multiple of GRID, as
    floats (a 0-d input gives a numpy float). Idempotent, and a function of the value
    alone: two hosts whose ``x`` differ by much less than GRID get the same result
    unless ``x`` lies that close to a half-way point between two multiples."""
    return (np.round(np.asarray(x, dtype=float) * _SCALE) / _SCALE)[()]


def canonical_polygon(polygon: Polygon) -> Polygon:
    """The polygon with every vertex canonical (the rings keep their vertices and order).
    Should rounding make it invalid (a ring touching itself across a gap narrower than
    GRID; never seen in 3,000 posterior samples of the library), the polygon is returned
    as it was."""
    rounded = shapely.transform(polygon, canonical)
    return rounded if rounded.is_valid else polygon
