"""The mean-shape baseline: candidates on the GPIS mean, each judged once on the mean
with no noise, ranked by Ferrari-Canny quality or, with ``quality = "lift"``, by the lift
model's smooth probability on the mean shape (its weight and centre of mass taken as
certain; force closure required, at once or after the push and the plates' squeeze).
It ignores shape uncertainty."""

from __future__ import annotations

import numpy as np

from harness.grasp import find_contacts, plate_closure
from harness.lift import MassBelief
from harness.push import push_and_squeeze
from planners.base import Plan, Planner, Problem, check_quality
from planners.sampling import search


class MeanShape(Planner):
    name = "mean-shape"
    description = "baseline: candidates ranked by Ferrari-Canny quality (or the lift) on the posterior mean shape"
    BOUNDS = {"candidates": (1, 10_000), "angular_noise_deg": (0.0, 90.0)}

    def __init__(self, candidates: int = 100, angular_noise_deg: float = 10.0, quality: str = "force_closure"):
        if candidates < 1:
            raise ValueError("candidates must be at least 1")
        self.candidates = int(candidates)
        self.angular_noise_deg = float(angular_noise_deg)
        self.quality = check_quality(quality)

    def plan(self, problem: Problem, rng: np.random.Generator) -> Plan:
        return search(problem, rng, self.candidates, self.angular_noise_deg, self._score, setup=self._setup)

    def _setup(self, problem: Problem, rng):
        mass = MassBelief.of_mean_shape(problem.belief, problem.settings) if self.quality == "lift" else None
        return problem, problem.belief.mean_field, mass

    @staticmethod
    def _score(grasps, state):
        problem, mean, mass = state
        belief, settings = problem.belief, problem.settings
        c = find_contacts(mean, grasps[:, 0], grasps[:, 1], settings.jaw_width)
        closed, quality = plate_closure(c, settings.friction, belief.center_of_mass, belief.characteristic_length)
        if mass is None:
            return quality, np.zeros(len(grasps))
        # As P_L: the nearer plate may push the object before the other arrives
        # (harness.push), and a grasp out of force closure may be squeezed into it
        # (harness.squeeze).
        c, closed, settled, _ = push_and_squeeze(mean, grasps[:, 0], grasps[:, 1], 0, c, closed, settings.friction,
                                              settings.jaw_width, belief.characteristic_length)
        lift = mass.settled_margin(settled, closed | settled.squeezed, settings.friction, settings, belief.grid.cell)
        return lift, quality
