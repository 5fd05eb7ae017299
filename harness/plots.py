"""Figures: the scene picture (observations, GPIS-Blur, posterior uncertainty)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from shapely.geometry import box  # noqa: E402

from harness.belief import Belief  # noqa: E402
from harness.geometry import Grid, polygons, zero_contours  # noqa: E402
from harness.sensor import KIND_NAMES  # noqa: E402

#: GPIS-Blur resolution: samples are drawn on a lattice this many times finer than the
#: grid (odd, so that the cell centres are lattice points).
BLUR_REFINE = 3
REGION_STYLE = {"occluded": ("0.55", "//"), "transparent": ("tab:cyan", ".."), "specular": ("tab:orange", "xx")}


def _outline(ax, geometry, **style):
    for poly in polygons(geometry):
        for ring in [poly.exterior, *poly.interiors]:
            xy = np.asarray(ring.coords)
            ax.plot(xy[:, 0] * 1e3, xy[:, 1] * 1e3, **style)


def _contours(ax, field, grid, **style):
    for line in zero_contours(field, grid):
        ax.plot(line[:, 0] * 1e3, line[:, 1] * 1e3, **style)


def inside_probability(belief: Belief, n: int, rng: np.random.Generator, refine: int = BLUR_REFINE):
    """Fraction of ``n`` posterior shapes covering each point of a lattice ``refine``
    times finer than the grid (the paper's GPIS-Blur); returns (probability, fine grid)."""
    grid = belief.grid
    fine = Grid(grid.size * refine, grid.extent)
    values, _ = belief.gp.sample_grid(fine.coords, fine.coords, n, rng)
    return (values < 0).mean(axis=0), fine


def scene_figure(belief: Belief, rng: np.random.Generator, n_blur: int = 100, title: str | None = None):
    """Three panels: what the sensor saw, the GPIS-Blur with the mean and true shapes,
    and the posterior standard deviation of the SDF."""
    scene, grid, obs = belief.scene, belief.grid, belief.observations
    half = 0.5 * grid.extent * 1e3
    extent_mm = (-half, half, -half, half)
    fig, axes = plt.subplots(1, 3, figsize=(15.5, 5.4), constrained_layout=True)

    ax = axes[0]
    std_mm = np.full((grid.size, grid.size), np.nan)
    std_mm[obs.cells[:, 1], obs.cells[:, 0]] = np.sqrt(obs.noise_var) * 1e3
    lo = np.nanmin(std_mm)
    im = ax.imshow(std_mm, origin="lower", extent=extent_mm, cmap="viridis", interpolation="nearest",
                   norm=LogNorm(vmin=lo, vmax=max(np.nanmax(std_mm), 10 * lo)))
    fig.colorbar(im, ax=ax, shrink=0.8, label="reading noise std (mm); blank: not observed")
    frame = box(-grid.extent / 2, -grid.extent / 2, grid.extent / 2, grid.extent / 2)
    handles = {}
    for region in scene.sensor.regions:
        colour, hatch = REGION_STYLE[region.kind]
        for poly in polygons(region.geometry.intersection(frame)):
            xy = np.asarray(poly.exterior.coords) * 1e3
            ax.fill(xy[:, 0], xy[:, 1], facecolor="none", edgecolor=colour, hatch=hatch, lw=1.0, zorder=3)
        handles[region.kind] = Patch(facecolor="none", edgecolor=colour, hatch=hatch, label=f"{region.kind} region")
    _outline(ax, scene.shape, color="crimson", lw=1.4, zorder=4)
    counts = np.bincount(obs.kind, minlength=len(KIND_NAMES))
    seen = ", ".join(f"{counts[k]} {KIND_NAMES[k]}" for k in range(len(KIND_NAMES)) if counts[k])
    ax.set_title(f"Observations ({len(obs)} of {grid.size**2} cells)\n{seen}", fontsize=10)
    legend = [*handles.values(), plt.Line2D([], [], color="crimson", lw=1.4, label="true shape")]
    ax.legend(handles=legend, loc="lower left", fontsize=8, framealpha=0.85)

    ax = axes[1]
    prob, fine = inside_probability(belief, n_blur, rng)
    ax.imshow(prob, origin="lower", extent=extent_mm, cmap="Greys", vmin=0, vmax=1, interpolation="bilinear")
    _contours(ax, belief.mean, grid, color="tab:red", lw=1.6)
    _outline(ax, scene.shape, color="tab:blue", lw=1.1, ls="--")
    ax.set_title(f"GPIS-Blur: {n_blur} posterior shapes\nred: mean zero level, blue dashed: truth", fontsize=10)

    ax = axes[2]
    im = ax.imshow(np.sqrt(belief.var) * 1e3, origin="lower", extent=extent_mm, cmap="magma",
                   interpolation="nearest")
    _contours(ax, belief.mean, grid, color="white", lw=1.2)
    _outline(ax, scene.shape, color="tab:cyan", lw=1.0, ls="--")
    com = belief.center_of_mass * 1e3
    ax.plot(*com, marker="+", color="white", ms=10, mew=2)
    fig.colorbar(im, ax=ax, shrink=0.8, label="posterior SDF std (mm)")
    ax.set_title("Posterior uncertainty\nwhite: mean zero level, +: mean-shape centre of mass", fontsize=10)

    for ax in axes:
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
    axes[0].set_ylabel("y (mm)")
    gp = belief.gp
    fig.suptitle(
        (title or f"{scene.name}: {scene.description}") + "\n"
        f"grid {grid.size} x {grid.size} over {grid.extent * 1e3:.0f} mm; GPIS l = {gp.lengthscale_ * 1e3:.2f} mm, "
        f"scale = ({np.sqrt(gp.scale_) * 1e3:.2f} mm)^2, prior mean = {gp.prior_mean_ * 1e3:.2f} mm; "
        f"fitted on {len(belief.active)} readings",
        fontsize=10,
    )
    return fig
