"""The sampling planners' candidate grasps (planners.candidates) against their contract:
surface points uniform by arc length on the mean shape's outline, and jaw starts that
clear the mean shape by the clearance along every plate line and fit the opening."""

from __future__ import annotations

import math

import numpy as np
import shapely

from harness.grasp import interpolate
from harness.seeding import stream
from harness.settings import resolve
from planners import candidates as cand


def test_surface_points_lie_on_the_mean_outline_uniformly_by_length(beliefs):
    """On the rectangle (6 x 3 cm, fully observed): every point on the mean shape's
    outline, and the share on its long sides two thirds, as their share of the perimeter
    (4 binomial standard deviations)."""
    belief = beliefs("rectangle")
    n = 4000
    points = cand.surface_points(belief, n, stream(0, "test-surface-points"))
    outline = belief.mean_shape.boundary
    assert len(points) == n
    assert np.max(shapely.distance(outline, shapely.points(points))) < 1e-9
    long_sides = np.abs(np.abs(points[:, 1]) - 0.015) < np.abs(np.abs(points[:, 0]) - 0.03)
    expected = 0.12 / 0.18
    assert abs(long_sides.mean() - expected) < 4 * math.sqrt(expected * (1 - expected) / n)


def test_candidates_start_one_clearance_beyond_the_mean_shape_along_every_plate_line(beliefs):
    """Each candidate's jaws start outside the mean shape, the nearer of the plate's three
    lines (its edges and middle) meeting it one clearance in, and no wider apart than the
    opening; found by reading the mean SDF's smooth interpolant along each line at 0.05
    mm, independently of the search's own sampling. The search reads the bilinear field
    every half cell: the surface lies within one of its steps short of the clearance, or
    two where a plate line clips a corner between two of its samples (measured: 2.75 mm
    short of 15 at most, with steps of 2.5 mm), and up to 0.25 mm beyond it where the two
    interpolants place the surface apart (0.1 mm on the stapler)."""
    for name in ("rectangle", "stapler"):
        belief = beliefs(name)
        settings = resolve(belief.scene)
        grasps = cand.generate(belief, 40, stream(0, name, "test-candidates"), settings)
        assert len(grasps) == 40
        gap = cand.clearance(belief, settings.sigma_g)
        assert gap == 2 * belief.grid.cell + 2 * settings.sigma_g
        step = 0.5 * belief.grid.cell
        g1, g2 = grasps[:, 0], grasps[:, 1]
        width = np.linalg.norm(g2 - g1, axis=1)
        assert np.all(width <= settings.opening + 1e-12)
        u = (g2 - g1) / width[:, None]
        across = np.column_stack([-u[:, 1], u[:, 0]])
        offsets = np.linspace(-0.5 * settings.jaw_width, 0.5 * settings.jaw_width, cand.LINES)
        ts = np.arange(0.0, settings.opening, 5e-5)
        for start, sense in ((g1, 1.0), (g2, -1.0)):
            first = np.full(len(grasps), np.inf)
            for offset in offsets:
                points = (start[:, None, :] + offset * across[:, None, :]
                          + sense * ts[None, :, None] * u[:, None, :]).reshape(-1, 2)
                values, _ = interpolate(belief.mean_field, np.zeros(len(points), dtype=np.int64), points)
                inside = values.reshape(len(grasps), len(ts)) <= 0
                first = np.minimum(first, np.where(inside.any(axis=1), ts[np.argmax(inside, axis=1)], np.inf))
            assert np.all(first > gap - 2 * step) and np.all(first <= gap + 2.5e-4), name


def _keyed_score(candidates, values, ties, floors=None):
    """A score that gives candidate i of ``candidates`` (recognised by its first jaw's x)
    the pair (values[i], ties[i]) and, when bounded, records the floor it was called with."""
    index = {float(g[0, 0]): i for i, g in enumerate(candidates)}

    def score(grasps, state, **kwargs):
        if floors is not None:
            floors.append(kwargs["floor"])
        k = [index[float(g[0, 0])] for g in grasps]
        return values[k], ties[k]

    return score


def test_the_search_keeps_the_first_candidate_of_the_highest_value_and_tie_break(beliefs, monkeypatch):
    """``planners.sampling.search`` over 60 candidates with many equal scores (values in
    five levels, tie-breaks in three; the highest pair twice, after lesser tie-breaks of
    its value in its own chunk and an earlier one): the plan is the first candidate, in the
    candidates' order, of the largest (value, tie-break) pair, found here by a plain
    scan; a bounded search calls the score with the best value so far as its floor
    (-inf first); a search over its time budget stops after its first chunk of ten with
    status "budget"."""
    from planners import sampling
    from planners.base import Problem

    belief = beliefs("rectangle")
    problem = Problem.for_belief(belief, resolve(belief.scene))
    rng = np.random.default_rng(3)
    grasps = cand.generate(belief, 60, stream(0, "test-search"), problem.settings, math.radians(10.0))
    values = rng.integers(0, 4, len(grasps)).astype(float)
    ties = rng.integers(0, 3, len(grasps)).astype(float)
    # The best (4, 2) first at 23, again at 47; lesser ties of the same value before it,
    # in its chunk of ten and in the first.
    for i, pair in ((5, (4, 0)), (21, (4, 1)), (23, (4, 2)), (47, (4, 2))):
        values[i], ties[i] = pair
    monkeypatch.setattr(cand, "generate", lambda *args, **kwargs: grasps)
    best = max(range(len(grasps)), key=lambda i: (values[i], ties[i], -i))
    assert best == 23
    for bounded in (False, True):
        floors = []
        score = _keyed_score(grasps, values, ties, floors if bounded else None)
        plan = sampling.search(problem, rng, len(grasps), 10.0, score, bounded=bounded, fixed_chunks=True)
        assert plan.status == "ok" and plan.iterations == len(grasps)
        assert np.allclose(plan.grasp.g1, grasps[best, 0]) and np.allclose(plan.grasp.g2, grasps[best, 1])
        if bounded:
            chunks = [values[:k].max() for k in range(10, len(grasps), 10)]
            assert floors == [-np.inf, *chunks]
    plan = sampling.search(Problem.for_belief(belief, resolve(belief.scene), 1e-9), rng, len(grasps), 10.0,
                           _keyed_score(grasps, values, ties))
    assert plan.status == "budget" and plan.iterations == sampling.CHUNK
