"""Candidate grasps on the mean shape, shared by the sampling planners: a random point on
the mean surface, a direction towards the centre of mass or along the inward normal
(with angular noise), and jaw starts marched out until the plates clear the object."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from harness.belief import Belief
from harness.grasp import interpolate, read_lines
from harness.geometry import polygons
from harness.settings import GraspSettings

#: Parallel lines across the plate used to place the jaws (edges and middle).
LINES = 3


def clearance(belief: Belief, sigma_g: float) -> float:
    """How far outside the object a jaw starts (metres): two cells, plus two sigma_g so
    that approach noise rarely starts a jaw inside."""
    return 2.0 * belief.grid.cell + 2.0 * sigma_g


def surface_points(belief: Belief, n: int, rng: np.random.Generator) -> np.ndarray:
    """n points (n, 2) uniform by arc length on the outline (holes included) of the mean
    shape; an empty array when the mean has no inside."""
    shape = belief.mean_shape
    rings = [np.asarray(r.coords) for poly in polygons(shape) for r in (poly.exterior, *poly.interiors)]
    if not rings:
        return np.zeros((0, 2))
    segments = np.concatenate([np.stack([r[:-1], r[1:]], axis=1) for r in rings])  # (S, 2, 2)
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    at = rng.uniform(0.0, cumulative[-1], n)
    seg = np.clip(np.searchsorted(cumulative, at, side="right") - 1, 0, len(segments) - 1)
    frac = ((at - cumulative[seg]) / np.maximum(lengths[seg], 1e-300))[:, None]
    return segments[seg, 0] + frac * (segments[seg, 1] - segments[seg, 0])


def generate(belief: Belief, n: int, rng: np.random.Generator, settings: GraspSettings,
             angular_noise: float = np.radians(10.0), attempts: int = 4) -> np.ndarray:
    """Up to n candidate grasps as jaw starts (G, 2, 2), G <= n, in the order drawn.

    From each surface point p the axis u points towards the mean shape's centre of mass
    (half the draws) or along the inward normal (the other half), turned by Gaussian
    noise of std ``angular_noise`` radians. The mean SDF is read along the plate's lines
    p + t u; the object is the run of t where any line is inside, gaps narrower than
    twice the clearance filled in, around p; the jaws start one clearance beyond its two
    ends. Candidates wider than the opening or starting outside the grid are dropped.
    """
    grid = belief.grid
    count = attempts * n
    p = surface_points(belief, count, rng)
    if len(p) == 0:
        return np.zeros((0, 2, 2))
    mean = belief.mean_field
    normal = _mean_normals(mean, p)
    toward = belief.center_of_mass - p
    toward /= np.maximum(np.linalg.norm(toward, axis=1, keepdims=True), 1e-300)
    u = np.where((rng.random(count) < 0.5)[:, None], toward, -normal)
    angle = rng.normal(0.0, angular_noise, count)
    c, s = np.cos(angle), np.sin(angle)
    u = np.column_stack([c * u[:, 0] - s * u[:, 1], s * u[:, 0] + c * u[:, 1]])

    h = grid.cell
    opening = settings.opening
    gap = clearance(belief, settings.sigma_g)
    reach = opening  # no valid grasp extends further than the opening from p
    steps = int(np.ceil(2 * reach / (0.5 * h))) + 1
    ts = np.linspace(-reach, reach, steps)
    perp = np.column_stack([-u[:, 1], u[:, 0]])
    offsets = np.linspace(-0.5 * settings.jaw_width, 0.5 * settings.jaw_width, LINES)
    starts = (p - reach * u)[:, None, :] + offsets[None, :, None] * perp[:, None, :]
    inside = (read_lines(mean, np.zeros(count, dtype=np.int64), starts, 2 * reach * u, (ts + reach) / (2 * reach))
              <= 0).any(axis=1)  # (count, T)
    width = int(np.ceil(gap / (ts[1] - ts[0])))
    closed = ndimage.binary_closing(inside, structure=np.ones((1, 2 * width + 1), dtype=bool))
    closed |= inside
    # The run containing p: just inside p (p is on the surface, u points inwards).
    centre = np.searchsorted(ts, 0.5 * h)
    run = _run_around(closed, centre)
    if run is None:
        return np.zeros((0, 2, 2))
    lo, hi = run
    ok = lo >= 0
    t1 = np.where(ok, ts[np.clip(lo, 0, steps - 1)] - gap, np.nan)
    t2 = np.where(ok, ts[np.clip(hi, 0, steps - 1)] + gap, np.nan)
    g1 = p + t1[:, None] * u
    g2 = p + t2[:, None] * u
    half = 0.5 * grid.extent
    valid = (ok & (t2 - t1 <= opening) & (np.abs(g1) < half).all(axis=1) & (np.abs(g2) < half).all(axis=1)
             & (lo > 0) & (hi < steps - 1))
    grasps = np.stack([g1, g2], axis=1)[valid]
    return grasps[:n]


def _run_around(mask: np.ndarray, centre: int):
    """Per row, the first and last index of the run of True containing ``centre``
    (lo = -1 where mask[centre] is False)."""
    rows, t = mask.shape
    idx = np.arange(t)
    outside = ~mask
    before = np.where(outside[:, :centre], idx[:centre], -1).max(axis=1) if centre > 0 else np.full(rows, -1)
    after = np.where(outside[:, centre:], idx[centre:], t).min(axis=1)
    lo = np.where(mask[:, centre], before + 1, -1)
    hi = np.where(mask[:, centre], after - 1, -1)
    return lo, hi


def _mean_normals(mean, points: np.ndarray) -> np.ndarray:
    _, grad = interpolate(mean, np.zeros(len(points), dtype=np.int64), points)
    return grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-300)
