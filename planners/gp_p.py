"""GP-P: candidate grasps ranked by the Monte-Carlo probability of force closure (or, with
``quality = "lift"``, of force closure and the lift) over one pool of shape samples and
approach-noise draws (the planner's own, not the evaluation's)."""

from __future__ import annotations

import numpy as np

from harness.quality import DrawPool, ranking_scores
from planners.base import Plan, Planner, Problem, check_quality
from planners.sampling import search


class GPP(Planner):
    name = "gp-p"
    description = "Monte-Carlo ranking: candidates ranked by P_F (or P_L) over a shared pool of shape samples"
    BOUNDS = {"candidates": (1, 10_000), "samples": (1, 10_000), "angular_noise_deg": (0.0, 90.0)}

    def __init__(self, candidates: int = 100, samples: int = 1000, angular_noise_deg: float = 10.0,
                 quality: str = "force_closure"):
        if candidates < 1 or samples < 1:
            raise ValueError("candidates and samples must be at least 1")
        self.candidates = int(candidates)
        self.samples = int(samples)
        self.angular_noise_deg = float(angular_noise_deg)
        self.quality = check_quality(quality)

    def shape_samples(self) -> int:
        return self.samples

    def plan(self, problem: Problem, rng: np.random.Generator, record: list | None = None,
             fixed_chunks: bool = False) -> Plan:
        """As Planner.plan; ``record`` (a list) receives (seconds, grasps, P_F) per chunk of
        candidates, for convergence studies; ``fixed_chunks``: score the candidates ten at a
        time (planners.sampling.search; the same plan, for benchmarks)."""
        # The best estimate of many is biased upwards (the winner's curse); the harness
        # re-estimates every returned grasp on its own evaluation draws.
        return search(problem, rng, self.candidates, self.angular_noise_deg, self._score, setup=self._setup,
                      estimate_of=lambda best: best, record=record, bounded=True, fixed_chunks=fixed_chunks)

    def _setup(self, problem: Problem, rng: np.random.Generator):
        # The pool drawn block by block, as gp-bandit draws it (harness.quality.DrawPool):
        # under the commands' pinned BLAS kernels a product's rounding can depend on how
        # many samples it holds, and uniform allocation must judge gp-p's very numbers.
        return problem, DrawPool(problem.belief, self.samples, *rng.spawn(4)).draws(self.samples)

    def _score(self, grasps, state, floor=None):
        problem, draws = state
        return ranking_scores(grasps, draws, problem.settings, self.quality == "lift", floor=floor)
