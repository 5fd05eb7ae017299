"""Reproducible across machines: trials do not see differences far below the canonical
grid (the size of the last-bit differences between hosts), which without the rounding
change every trial."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import shapely

from harness.belief import build_belief
from harness.canonical import GRID
from harness.geometry import inside_region, largest_region
from harness.physics.bodies import simplified_outline
from harness.physics.simulate import make_trials
from harness.physics.trial import Runner
from harness.scene import load_scene
from harness.seeding import stream
from harness.settings import resolve

#: A plan of the marker (gp-gpis-opt-lift's in the quick experiment, to eight digits).
GRASP = np.array([[0.04291604, -0.01250224], [0.02351490, 0.03833332]])


@pytest.fixture(scope="module")
def marker():
    """Eight posterior samples of the marker (their traced regions, before the outline is
    made canonical), the settings, approach deviates, and the trials' rows."""
    scene = load_scene("marker")
    belief = build_belief(scene, stream(0, "marker", 0, "sensor"))
    regions = [largest_region(inside_region(f, scene.grid)) for f in belief.sample(8, stream(0, "test-repro")).values]
    settings, approach = resolve(scene), stream(0, "test-repro-approach").standard_normal((8, 2, 2))
    trials = make_trials(settings, GRASP, [simplified_outline(r, scene.grid.cell) for r in regions], approach)
    return scene, regions, settings, approach, trials, Runner().run(trials)


def _changed(rows, reference) -> int:
    return sum(a != b for a, b in zip(rows, reference, strict=True))


def _moved(geometry, distance: float):
    """Every vertex moved by ``distance`` along x and y, the sign a function of the
    coordinate (so rings stay closed)."""
    return shapely.transform(geometry, lambda xy: xy + distance * np.sign(np.sin(1e5 * xy)))


def test_a_plan_moved_by_1e_11_m_gives_the_same_trials(marker):
    _, regions, settings, approach, trials, rows = marker
    offset = GRASP / GRID - np.round(GRASP / GRID)
    assert np.all(np.abs(np.abs(offset) - 0.5) > 0.01)  # no coordinate next to a half-way point
    assert {r.outcome for r in rows} == {"success"}      # every trial simulated to the end
    moved = GRASP + 1e-11 * np.array([[1.0, -1.0], [-1.0, 1.0]])
    again = Runner().run(make_trials(settings, moved, [t.polygon for t in trials], approach))
    assert _changed(again, rows) == 0
    # Not rounded, the same change reaches Bullet and changes (nearly) every row.
    raw = [replace(t, g1=(t.g1[0] + 1e-11, t.g1[1] - 1e-11), g2=(t.g2[0] - 1e-11, t.g2[1] + 1e-11)) for t in trials]
    assert _changed(Runner().run(raw), rows) >= 6


def test_outlines_moved_by_1e_12_m_give_the_same_trials(marker):
    scene, regions, settings, approach, trials, rows = marker
    outlines = [simplified_outline(_moved(r, 1e-12), scene.grid.cell) for r in regions]
    assert all(a.equals_exact(t.polygon, 0.0) for a, t in zip(outlines, trials, strict=True))
    assert _changed(Runner().run(make_trials(settings, GRASP, outlines, approach)), rows) == 0
    raw = [replace(t, polygon=_moved(t.polygon, 1e-12)) for t in trials]
    assert _changed(Runner().run(raw), rows) >= 6
