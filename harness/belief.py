"""The shape belief: one sensor reading of a scene and its GPIS posterior, as fields
on the scene's grid, shape samples, and the mean shape's centre of mass."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from harness.geometry import Grid, inside_region, largest_region, zero_contours
from harness.gpis import GPIS, select_active_set
from harness.scene import Scene
from harness.sensor import Observations, observe


@dataclass(frozen=True)
class ShapeSamples:
    """Posterior shape samples on the grid: SDF values (n, M, M) and gradients (n, M, M, 2)."""

    values: np.ndarray
    gradients: np.ndarray

    def __len__(self) -> int:
        return len(self.values)


class Belief:
    """GPIS posterior over a scene's SDF, fitted to one set of observations.

    ``observations`` are all the sensor's readings; ``active`` indexes the ones the GP
    was fitted on (see :func:`harness.gpis.select_active_set`).
    """

    def __init__(self, scene: Scene, observations: Observations, gp: GPIS, active: np.ndarray):
        self.scene = scene
        self.observations = observations
        self.gp = gp
        self.active = active

    @property
    def grid(self) -> Grid:
        return self.scene.grid

    @cached_property
    def _fields(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.gp.grid_fields(self.grid.coords, self.grid.coords)

    @property
    def mean(self) -> np.ndarray:
        """Posterior mean SDF on the grid, (M, M)."""
        return self._fields[0]

    @property
    def var(self) -> np.ndarray:
        """Posterior variance of the SDF on the grid, (M, M), in m^2."""
        return self._fields[1]

    @property
    def gradient(self) -> np.ndarray:
        """Gradient of the posterior mean on the grid, (M, M, 2)."""
        return self._fields[2]

    @property
    def gradient_var(self) -> np.ndarray:
        """Posterior variance of each component of the SDF's gradient on the grid, (M, M, 2)."""
        return self._fields[3]

    @cached_property
    def mean_field(self):
        """The posterior mean as a field batch (harness.grasp.SDFBatch) for contacts and
        smooth interpolation; built once per belief."""
        from harness.grasp import SDFBatch

        return SDFBatch(self.grid, self.mean, self.gradient)

    @cached_property
    def mean_shape(self):
        """The largest connected region inside the mean's zero level (a shapely Polygon)."""
        return largest_region(inside_region(self.mean, self.grid))

    @cached_property
    def center_of_mass(self) -> np.ndarray:
        """Centroid (2,) of the mean shape (uniform density); NaN if the mean has no inside."""
        shape = self.mean_shape
        if shape.is_empty:
            return np.full(2, np.nan)
        return np.array([shape.centroid.x, shape.centroid.y])

    @cached_property
    def characteristic_length(self) -> float:
        """The largest distance (m) from the mean shape's centre of mass to its outline:
        the length that makes torque comparable with force in the Ferrari-Canny quality
        (a unit force at the farthest point gives a unit scaled torque). Half the gripper
        opening when the mean has no inside."""
        shape = self.mean_shape
        if shape.is_empty:
            return 0.5 * self.scene.gripper.opening
        outline = np.asarray(shape.exterior.coords)
        return float(np.linalg.norm(outline - self.center_of_mass, axis=1).max())

    def surface_std(self) -> np.ndarray:
        """Posterior std of the SDF (m) at points along the mean's zero level (bilinear
        between cells), one per contour vertex: how uncertain the surface is."""
        from scipy.interpolate import RegularGridInterpolator

        lines = zero_contours(self.mean, self.grid)
        if not lines:
            return np.zeros(0)
        c = self.grid.coords
        std = RegularGridInterpolator((c, c), np.sqrt(self.var), bounds_error=False, fill_value=None)
        return std(np.concatenate(lines)[:, ::-1])

    def prepare(self) -> "Belief":
        """Compute the grid fields, the mean shape and its centre of mass now (they are
        otherwise computed on first use), so that planning times exclude them."""
        self.gradient_var, self.characteristic_length, self.mean_field.twist  # noqa: B018
        return self

    def sample(self, n: int, rng: np.random.Generator, method: str = "fast") -> ShapeSamples:
        """``n`` posterior shapes on the grid (values and gradients); see GPIS.sample_grid."""
        c = self.grid.coords
        values, gradients = self.gp.sample_grid(c, c, n, rng, method=method)
        return ShapeSamples(values, gradients)

    def sampler(self, n: int) -> str:
        """The exact sampler ``sample(n, rng)`` uses: "pathwise" or "weight-space" (see
        GPIS.grid_strategy)."""
        c = self.grid.coords
        return self.gp.grid_strategy(c, c, n)


def make_gp(scene: Scene) -> GPIS:
    """The scene's GPIS, unfitted, with ML-II bounds scaled to its grid."""
    s, h = scene.gpis, scene.grid.cell
    return GPIS(
        lengthscale=s.lengthscale, scale=s.scale, prior_mean=s.prior_mean,
        fit_hyperparameters=s.hyperparameters == "ml",
        lengthscale_bounds=(0.5 * h, 0.25 * scene.grid.extent),
        scale_bounds=((0.05 * h) ** 2, scene.grid.extent**2),
        prior_mean_bounds=(-4 * scene.truncation, 4 * scene.truncation),
    )


def fitted_readings(scene: Scene, observations: Observations) -> tuple[np.ndarray, Observations, np.ndarray | None]:
    """What the scene's GPIS is fitted to: the indices of the active readings, those
    readings, and their gradients (NaN where unused; None without gradients)."""
    s = scene.gpis
    if s.active_set:
        active = select_active_set(observations.points, observations.values, observations.noise_var,
                                   s.active_band, s.active_spacing)
    else:
        active = np.arange(len(observations))
    obs = observations.subset(active)
    if not s.use_gradients:
        return active, obs, None
    gradients = obs.gradients
    if s.active_set:
        # Gradients far from the surface are central differences of a flat, clipped
        # field; measured to change the posterior near the surface by < 0.05 mm.
        gradients = np.where((np.abs(obs.values) <= s.active_band)[:, None], gradients, np.nan)
    return active, obs, gradients


def fit_belief(scene: Scene, observations: Observations) -> Belief:
    """Fit the scene's GPIS to observations (on its active set, when enabled)."""
    gp = make_gp(scene)
    active, obs, gradients = fitted_readings(scene, observations)
    if gradients is None:
        gp.fit(obs.points, obs.values, obs.noise_var)
    else:
        gp.fit(obs.points, obs.values, obs.noise_var, gradients, obs.gradient_noise_var)
    return Belief(scene, observations, gp, active)


def observe_scene(scene: Scene, rng: np.random.Generator) -> Observations:
    """One reading of the scene's true shape by its sensor."""
    return observe(scene.sensor, scene.grid, scene.true_sdf, rng)


def build_belief(scene: Scene, rng: np.random.Generator) -> Belief:
    """Observe the scene once with ``rng`` and fit the GPIS."""
    return fit_belief(scene, observe_scene(scene, rng))
