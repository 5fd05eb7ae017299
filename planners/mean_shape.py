"""The mean-shape baseline: candidates on the GPIS mean, each judged once on the mean
with no noise, ranked by Ferrari-Canny quality. It ignores shape uncertainty."""

from __future__ import annotations

import numpy as np

from harness.grasp import OK, ferrari_canny, find_contacts
from planners.base import Plan, Planner, Problem
from planners.sampling import search


class MeanShape(Planner):
    name = "mean-shape"
    description = "baseline: candidates ranked by Ferrari-Canny quality on the posterior mean shape"

    def __init__(self, candidates: int = 100, angular_noise_deg: float = 10.0):
        if candidates < 1:
            raise ValueError("candidates must be at least 1")
        self.candidates = int(candidates)
        self.angular_noise_deg = float(angular_noise_deg)

    def plan(self, problem: Problem, rng: np.random.Generator) -> Plan:
        return search(problem, rng, self.candidates, self.angular_noise_deg, self._score, setup=self._setup)

    @staticmethod
    def _setup(problem: Problem, rng):
        return problem, problem.belief.mean_field

    @staticmethod
    def _score(grasps, state):
        problem, mean = state
        belief = problem.belief
        c = find_contacts(mean, grasps[:, 0], grasps[:, 1], problem.settings.jaw_width)
        quality = np.zeros(len(grasps))
        ok = c.status == OK
        quality[ok] = ferrari_canny(c.c1[ok], c.c2[ok], c.n1[ok], c.n2[ok], problem.settings.friction,
                                    belief.center_of_mass, belief.characteristic_length)
        return quality, np.zeros(len(grasps))
