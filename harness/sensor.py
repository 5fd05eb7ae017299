"""The observation model: noisy, heteroscedastic SDF readings at grid cells, with
occluded, transparent and specular regions and a sparsely seen interior (PAPER.md 1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from harness.geometry import Grid

REGION_KINDS = ("occluded", "transparent", "specular")

#: Codes of ``Observations.kind``: why a cell reads the way it does.
KIND_NAMES = ("normal", "interior", "transparent", "specular")
NORMAL, INTERIOR, TRANSPARENT, SPECULAR = range(4)


@dataclass(frozen=True)
class Region:
    """A part of the scene where the sensor misbehaves in one way.

    occluded: cells inside are not observed at all.
    transparent: cells with -depth < sdf < surface_band read ``value`` (an "outside"
        reading) with noise std ``noise``. With the default depth = surface_band only
        the surface is misread, as in the original; a larger depth makes the part
        see-through to that depth.
    specular: surface cells are dropped with ``drop_probability``; the kept ones get
        noise variance base^2 + U(0,1) * noise^2.
    """

    kind: str
    geometry: BaseGeometry
    noise: float = 0.0
    value: float = 0.0
    depth: float = 0.0
    drop_probability: float = 0.0


@dataclass(frozen=True)
class SensorModel:
    """Sensor parameters, all lengths in metres.

    noise: std of the value noise of an ordinary cell.
    surface_band: cells with |sdf| below this are surface cells (for the regions).
    interior_depth: cells with sdf below -interior_depth are deep interior cells...
    interior_keep: ...and each is observed with this probability.
    """

    noise: float
    surface_band: float
    interior_depth: float
    interior_keep: float = 1.0
    regions: tuple[Region, ...] = ()


@dataclass(frozen=True)
class Observations:
    """What the sensor saw, one row per observed cell.

    points (N, 2) cell centres; values (N,) measured SDF; noise_var (N,) their noise
    variances; gradients (N, 2) central differences of the measured field, NaN rows
    where a neighbour was not observed; gradient_noise_var (N, 2) per component;
    cells (N, 2) integer (column, row); kind (N,) codes into ``KIND_NAMES``.
    """

    points: np.ndarray
    values: np.ndarray
    noise_var: np.ndarray
    gradients: np.ndarray
    gradient_noise_var: np.ndarray
    cells: np.ndarray
    kind: np.ndarray

    def __len__(self) -> int:
        return len(self.values)

    def subset(self, index: np.ndarray) -> "Observations":
        """The observations at ``index`` (an integer or boolean index array)."""
        return Observations(*(np.asarray(getattr(self, f))[index] for f in (
            "points", "values", "noise_var", "gradients", "gradient_noise_var", "cells", "kind")))


def observe(sensor: SensorModel, grid: Grid, truth: np.ndarray, rng: np.random.Generator) -> Observations:
    """Simulate one sensor reading of the (truncated) true SDF ``truth`` (M, M).

    Every cell consumes the same random numbers whatever the regions, so a reading
    is a deterministic function of the generator's state.
    """
    m = grid.size
    f = np.asarray(truth, dtype=float).ravel()
    x, y = grid.points[:, 0], grid.points[:, 1]
    u_keep, u_drop, u_spec = rng.random((3, m * m))
    z = rng.standard_normal(m * m)

    observed = np.ones(m * m, dtype=bool)
    mean = f.copy()
    var = np.full(m * m, sensor.noise**2)
    kind = np.full(m * m, NORMAL, dtype=np.int8)

    deep = f < -sensor.interior_depth
    kind[deep] = INTERIOR
    observed &= ~deep | (u_keep < sensor.interior_keep)

    surface = np.abs(f) < sensor.surface_band
    # Regions apply kind by kind, so occlusion beats transparency beats specularity.
    # Where regions of one kind overlap, the later one's parameters replace the
    # earlier one's, and (one uniform per cell) drops act as the larger probability.
    for kind_name in ("specular", "transparent", "occluded"):
        for region in (r for r in sensor.regions if r.kind == kind_name):
            inside = shapely.contains_xy(region.geometry, x, y)
            if kind_name == "occluded":
                observed &= ~inside
            elif kind_name == "transparent":
                hit = inside & (f < sensor.surface_band) & (f > -region.depth)
                mean[hit] = region.value
                var[hit] = region.noise**2
                kind[hit] = TRANSPARENT
            else:
                hit = inside & surface
                observed &= ~hit | (u_drop >= region.drop_probability)
                var[hit] = sensor.noise**2 + u_spec[hit] * region.noise**2
                kind[hit] = SPECULAR

    values = mean + np.sqrt(var) * z
    gradients, gradient_var = _central_differences(
        np.where(observed, values, np.nan).reshape(m, m),
        np.where(observed, var, np.nan).reshape(m, m),
        grid.cell,
    )
    idx = np.flatnonzero(observed)
    cells = np.column_stack([idx % m, idx // m])
    return Observations(
        points=grid.points[idx].copy(),
        values=values[idx],
        noise_var=var[idx],
        gradients=gradients.reshape(-1, 2)[idx],
        gradient_noise_var=gradient_var.reshape(-1, 2)[idx],
        cells=cells,
        kind=kind[idx],
    )


def _central_differences(values: np.ndarray, var: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (M, M, 2) of a measured field by central differences, with the noise
    variance of each component; NaN where either neighbour is missing (or at the border)."""
    m = values.shape[0]
    grad = np.full((m, m, 2), np.nan)
    gvar = np.full((m, m, 2), np.nan)
    grad[:, 1:-1, 0] = (values[:, 2:] - values[:, :-2]) / (2 * h)
    gvar[:, 1:-1, 0] = (var[:, 2:] + var[:, :-2]) / (4 * h * h)
    grad[1:-1, :, 1] = (values[2:, :] - values[:-2, :]) / (2 * h)
    gvar[1:-1, :, 1] = (var[2:, :] + var[:-2, :]) / (4 * h * h)
    missing = np.any(np.isnan(grad), axis=-1)
    grad[missing] = np.nan
    gvar[missing] = np.nan
    return grad, gvar
