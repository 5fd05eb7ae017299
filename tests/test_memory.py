"""The memory estimate made before a run (harness.memory): its counts are the fit's own,
its peak bounds the peak tracemalloc measures while the cell runs, within a stated factor,
and its allowance for the process bounds what a fresh worker holds besides its cells."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import tracemalloc

import numpy as np
import pytest

from harness import memory
from harness.belief import build_belief
from harness.quality import default_streams, draw_evaluation, evaluate_draws
from harness.scene import load_scene
from harness.seeding import stream
from harness.settings import resolve


def _run_cell(scene, n: int, samples: int) -> None:
    """Fit, compute the fields, draw n evaluation draws, judge one grasp, and plan with gp-p
    on ``samples`` shape samples."""
    from planners.base import Problem
    from planners.gp_p import GPP

    belief = build_belief(scene, stream(0, scene.name, 0, "sensor")).prepare()
    draws = draw_evaluation(belief, n, *default_streams(0, scene.name, 0))
    settings = resolve(scene)
    evaluate_draws(np.array([[-0.045, 0.0], [0.045, 0.0]]), draws, settings)
    if samples:
        GPP(candidates=10, samples=samples).plan(Problem(belief, settings), stream(0, "memory", "gp-p"))


def _measured_peak(scene, n: int, samples: int) -> float:
    """The largest memory (bytes) numpy and Python hold while a cell of ``scene`` runs
    (:func:`_run_cell`); tracemalloc sees numpy's buffers. A small cell of the same scene
    runs first, untraced: what a process allocates once (the lazy imports, numba's kernels
    and the type caches their first call builds, about 29 MB traced) belongs to
    memory.PROCESS_BYTES, which the next test measures, not to the cell; without it the
    measurement would depend on the tests that ran before in the same process."""
    _run_cell(load_scene(scene.name, {"grid": {"size": 16}}), 20, 20 if samples else 0)
    tracemalloc.start()
    try:
        _run_cell(scene, n, samples)
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


#: A fresh worker's set-up, as an eval worker meets it: the imports, the compiled contact
#: search (pipeline.plan loads it first), a first small cell, a pybullet client, MuJoCo;
#: it prints the process's peak resident memory (kB).
_FRESH_PROCESS = textwrap.dedent("""
    import numpy as np
    import harness.cli, harness.pipeline, harness.physics.bullet, harness.quality, planners.gp_p
    from harness.grasp import load_kernels
    from harness.belief import build_belief
    from harness.quality import default_streams, draw_evaluation, evaluate_draws
    from harness.scene import load_scene
    from harness.seeding import stream
    from harness.settings import resolve
    load_kernels()
    scene = load_scene("tape", {"grid": {"size": 16}})
    belief = build_belief(scene, stream(0, scene.name, 0, "sensor")).prepare()
    draws = draw_evaluation(belief, 20, *default_streams(0, scene.name, 0))
    evaluate_draws(np.array([[-0.045, 0.0], [0.045, 0.0]]), draws, resolve(scene))
    import pybullet
    pybullet.connect(pybullet.DIRECT)
    import mujoco
    status = dict(line.split(":", 1) for line in open("/proc/self/status"))
    print(int(status["VmHWM"].split()[0]))
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_the_process_allowance_bounds_a_fresh_workers_resident_memory_within_1_5():
    # Measured in a new interpreter, so that nothing this test process loaded counts; its
    # peak resident memory (VmHWM) against PROCESS_BYTES (250 MiB against 280 MiB here).
    out = subprocess.run([sys.executable, "-c", _FRESH_PROCESS], capture_output=True, text=True, check=True)
    measured = int(out.stdout.split()[-1]) * 1024
    assert measured <= memory.PROCESS_BYTES <= 1.5 * measured, measured / 1e6


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
