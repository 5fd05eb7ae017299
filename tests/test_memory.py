"""The memory estimate made before a run (harness.memory): its counts are the fit's own,
and its peak bounds the peak tracemalloc measures while the cell runs, within a stated
factor."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from harness import memory
from harness.belief import build_belief
from harness.quality import default_streams, draw_evaluation, evaluate_draws
from harness.scene import load_scene
from harness.seeding import stream
from harness.settings import resolve


def _measured_peak(scene, n: int, samples: int) -> float:
    """The largest memory (bytes) numpy and Python hold while a cell of ``scene`` fits,
    computes its fields, draws n evaluation draws, judges one grasp, and gp-p plans with
    ``samples`` shape samples; tracemalloc sees numpy's buffers."""
    from planners.base import Problem
    from planners.gp_p import GPP

    tracemalloc.start()
    try:
        belief = build_belief(scene, stream(0, scene.name, 0, "sensor")).prepare()
        draws = draw_evaluation(belief, n, *default_streams(0, scene.name, 0))
        settings = resolve(scene)
        evaluate_draws(np.array([[-0.045, 0.0], [0.045, 0.0]]), draws, settings)
        if samples:
            GPP(candidates=10, samples=samples).plan(Problem(belief, settings), stream(0, "memory", "gp-p"))
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize(("name", "size", "draws", "samples"), [
    ("tape", 40, 1000, 400),     # the weight-space fields: judging the draws sets the peak
    ("rectangle", 80, 300, 0),   # pointwise fields (an r^2 x r^2 matrix over 64 MB) set it
])
def test_the_estimate_bounds_the_measured_peak_within_a_factor_of_1_5(name, size, draws, samples):
    scene = load_scene(name, {"grid": {"size": size}})
    need = memory.cell_need(scene, 0, 0, draws, samples)
    measured = _measured_peak(scene, draws, samples)
    estimated = need.peak - memory.PROCESS_BYTES
    assert measured <= estimated <= 1.5 * measured, (need, measured / 2**20)


def test_the_counts_are_the_fitted_gps_own():
    scene = load_scene("marker")
    need = memory.cell_need(scene, 3, 1, 100, 0)
    belief = build_belief(scene, stream(3, "marker", 1, "sensor"))
    assert need.scalars == len(belief.gp.targets_)
    assert need.rank == belief.gp._basis(0, scene.grid.coords).rank == belief.gp._basis(1, scene.grid.coords).rank


def test_the_formula_grows_as_stated():
    base = memory.estimate(40, 2000, 30, 1000, 0)
    # Fitting sets the peak for many scalars: 24 D^2.
    big = memory.estimate(40, 100_000, 30, 1000, 0)
    assert big.phase == "fitting the GP" and big.peak == pytest.approx(24 * 1e10 + memory.PROCESS_BYTES)
    # Judging n draws on an M x M grid: 8 D^2 + 12 r^4 + 12 n M^2 + n (48 M^2 + 32 kB), and
    # the group of bodies of samples in pieces (harness.quality.BODY_BYTES).
    from harness.quality import BODY_BYTES

    many = memory.estimate(40, 2000, 30, 100_000, 0)
    assert many.phase == "judging a plan"
    assert many.peak == pytest.approx(8 * 2000**2 + 12 * 30**4 + 1e5 * (60 * 1600 + 32e3) + BODY_BYTES
                                      + memory.PROCESS_BYTES)
    assert base.peak < many.peak


def test_the_budget_is_a_share_of_the_machine_unless_given():
    machine = memory.machine_bytes()
    assert 2**28 < machine < 2**50
    assert memory.worker_budget(2) == pytest.approx(memory.BUDGET_FRACTION * machine / 2)
    assert memory.worker_budget(4, budget_gib=1.5) == 1.5 * 2**30
