"""What a cell needs in memory, estimated before any work from counts, and the budget it
must fit: a share of this machine's memory per worker process.

The counts are the grid's M x M cells, the D scalars the GP is fitted to (read off the
cell's own sensor reading, which is cheap: no fit), the rank r of the GP's 1-D basis
along each axis, the n evaluation draws and S, the largest number of shape samples a
planner holds (``Planner.shape_samples``). In bytes, with the constants measured with
tracemalloc on this project's scenes (docs/experiments.md, "Memory"):

    L = 8 D^2                 the GP's Cholesky factor, kept
    W = 12 r^4                the weight-space posterior, kept once built
    peak = max(24 D^2,                                      fitting
               L + F,                                       grid fields
               L + W + B + 36 n M^2,                        evaluation draws
               L + W + 12 n M^2 + n (48 M^2 + 32e3) + G,    judging one plan
               L + W + 12 n M^2 + S (32 M^2 + 48e3) + G)    the largest planner
           + 280 MiB                                        the process

with F = 96 D x min(M^2, PREDICT_CHUNK) (pointwise fields) when an r^2 x r^2 matrix
exceeds FIELDS_BASIS_MAX_BYTES, else 32 r^4 (the weight-space posterior and its
covariance), B = 20 r^4 when the sampler builds the weight-space posterior the
fields did not (else 0), and G = harness.quality.BODY_BYTES, the group of bodies of
samples in several pieces that judging the lift builds at once (24 MB since 2026-11-29;
groups of 32 fields before, up to 5.6 MB at M = 50, were not counted).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.errors import InputError

#: The share of this machine's memory that the run may use, split among its workers.
BUDGET_FRACTION = 0.75
#: What a worker process holds besides its cells: Python and the imported modules, numba's
#: compiled contact search and the type caches its first call builds, the lazy imports of a
#: first cell, a pybullet client and MuJoCo. Their resident memory, measured on this machine
#: (2026-11-29, tests/test_memory.py measures it again): 85 MiB after the imports, 186 MiB
#: with the kernels, 205 MiB after a first small cell, 232 MiB with a pybullet client, 250
#: MiB with MuJoCo; 280 MiB, 12 % above the last, for other builds of the libraries. (200 MB
#: before 2026-11-29, when a fresh process's first cell paid the difference inside its peak.)
PROCESS_BYTES = 280 * 2**20


@dataclass(frozen=True)
class Need:
    """A cell's estimated peak in bytes, and the phase that sets it."""

    peak: float
    phase: str
    grid: int
    scalars: int
    rank: int | None
    draws: int
    shape_samples: int

    def describe(self) -> str:
        rank = "" if self.rank is None else f", basis rank {self.rank}"
        return (f"about {gib(self.peak)} ({self.phase}: {self.grid} x {self.grid} grid, {self.scalars} observed "
                f"scalars{rank}, {self.draws} draws, {self.shape_samples} planner samples)")


def gib(nbytes: float) -> str:
    return f"{nbytes / 2**30:.2f} GiB" if nbytes < 2**40 else f"{nbytes / 2**40:.2f} TiB"


def machine_bytes() -> int:
    """This machine's memory: physical memory, or the control group's limit when lower."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return total


def worker_budget(workers: int, budget_gib: float | None = None) -> float:
    """Bytes one worker process may use: ``budget_gib`` when given (a flag), else
    BUDGET_FRACTION of this machine's memory over the workers."""
    if budget_gib is not None:
        return budget_gib * 2**30
    return BUDGET_FRACTION * machine_bytes() / max(1, workers)


def cell_need(scene, seed: int, realisation: int, draws: int, shape_samples: int,
              budget: float | None = None) -> Need:
    """The estimated peak of one cell (see the module docstring): the sensor reads the
    scene with the cell's own stream, so D is the count the fit will see. When fitting
    alone exceeds ``budget``, the basis (seconds on a large grid) is not computed."""
    from harness.belief import fitted_readings, observe_scene
    from harness.gpis import grid_basis_rank
    from harness.seeding import stream

    observations = observe_scene(scene, stream(seed, scene.name, realisation, "sensor"))
    active, _, gradients = fitted_readings(scene, observations)  # as the fit takes them
    scalars = len(active) + (0 if gradients is None else 2 * int((~np.isnan(gradients).any(axis=1)).sum()))
    s = scene.gpis
    fitting = 24.0 * scalars**2 + PROCESS_BYTES
    if budget is not None and fitting > budget:
        return Need(fitting, "fitting the GP", scene.grid.size, scalars, None, draws, shape_samples)
    # With hyperparameters fitted by ML-II the lengthscale is not known yet: its lower
    # bound gives the largest basis.
    lengthscale = 0.5 * scene.grid.cell if s.hyperparameters == "ml" else s.lengthscale
    rank = grid_basis_rank(scene.grid.coords, lengthscale)
    return estimate(scene.grid.size, scalars, rank, draws, shape_samples)


def estimate(grid: int, scalars: int, rank: int, draws: int, shape_samples: int) -> Need:
    """The peak (bytes) for the counts: grid size M, observed scalars D, basis rank r, n
    draws, S planner samples (the formula of the module docstring)."""
    from harness.gpis import FIELDS_BASIS_MAX_BYTES, PREDICT_CHUNK, fast_strategy
    from harness.quality import BODY_BYTES

    m2, d, r4, n = float(grid) ** 2, float(scalars), float(rank) ** 4, float(draws)
    factor = 8 * d * d
    pointwise = 8 * r4 > FIELDS_BASIS_MAX_BYTES
    fields = 96 * d * min(m2, PREDICT_CHUNK) if pointwise else 32 * r4
    weight_space = not pointwise or fast_strategy(scalars, grid, grid, rank, rank, True, draws) == "weight-space"
    kept = factor + (12 * r4 if weight_space else 0) + 12 * n * m2
    phases = {
        "fitting the GP": 24 * d * d,
        "the grid fields": factor + fields,
        "the evaluation draws": kept - 12 * n * m2 + (20 * r4 if weight_space and pointwise else 0) + 36 * n * m2,
        "judging a plan": kept + n * (48 * m2 + 32e3) + BODY_BYTES,
        "the largest planner": kept + shape_samples * (32 * m2 + 48e3) + BODY_BYTES,
    }
    phase = max(phases, key=phases.get)
    return Need(phases[phase] + PROCESS_BYTES, phase, grid, scalars, rank, draws, shape_samples)


def check_config(config, workers: int, budget_gib: float | None = None) -> float:
    """Refuse (InputError naming the file and the field that sets the peak) an
    experiment whose largest cell cannot fit one worker's budget; returns that budget
    in bytes (each plan's process may grow by as much)."""
    from harness.pipeline import cell_draws
    from harness.scene import load_scene
    from planners.registry import make_planner

    budget = worker_budget(workers, budget_gib)
    draws = cell_draws(config.analytic_draws, config.posterior_trials)
    samples = [make_planner(e.name, e.params).shape_samples() for e in config.planners]
    largest = max(range(len(samples)), key=samples.__getitem__)
    for path, _, realisation in config.cells():
        scene = load_scene(path)
        need = cell_need(scene, config.seed, realisation, draws, samples[largest], budget)
        if need.peak > budget:
            if need.phase in ("fitting the GP", "the grid fields"):
                source, field = scene.source, "grid.size"
            elif need.phase == "the largest planner":
                source, field = config.source, f"planners[{largest}].params"
            else:
                which = "analytic_draws" if config.analytic_draws >= config.posterior_trials else "posterior_trials"
                source, field = config.source, f"evaluation.{which}"
            raise InputError(source, field, f"scene '{scene.name}' needs {need.describe()}, more than "
                                            f"{budget_text(workers, budget_gib)}")
    return budget


def check_single(scene, seed: int, draws: int, shape_samples: int = 0, field: str = "grid.size") -> float:
    """Refuse (InputError) a single-shot command whose cell cannot fit this machine's
    budget (one process); returns the budget in bytes. ``field`` names the option that
    sets the draws, for when they set the peak (--samples, --trials)."""
    budget = worker_budget(1)
    need = cell_need(scene, seed, 0, draws, shape_samples, budget)
    if need.peak > budget:
        source, where = ((scene.source, "grid.size") if need.phase in ("fitting the GP", "the grid fields")
                         else (field, None))
        raise InputError(source, where, f"scene '{scene.name}' needs {need.describe()}, more than the budget of "
                                        f"{gib(budget)} ({BUDGET_FRACTION:.0%} of this machine's "
                                        f"{gib(machine_bytes())})")
    return budget


def budget_text(workers: int, budget_gib: float | None) -> str:
    """The budget in words, with where it comes from."""
    if budget_gib is not None:
        return f"the budget of {gib(worker_budget(workers, budget_gib))} per worker (--memory-budget)"
    share = f" over {workers} workers" if workers > 1 else ""
    return (f"the budget of {gib(worker_budget(workers))} per worker ({BUDGET_FRACTION:.0%} of this machine's "
            f"{gib(machine_bytes())}{share}; eval --memory-budget GIB sets it)")
