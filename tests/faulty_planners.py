"""Planners that break the contract in the ways DESIGN.md lists; the harness must record
each with its status and finish the experiment. Imported by workers as module:Class."""

from __future__ import annotations

import math
import time

from harness.grasp import Grasp
from planners.base import Plan, Planner


class Raises(Planner):
    name = "test-raises"

    def plan(self, problem, rng):
        raise RuntimeError("deliberate failure")


class ReturnsNaN(Planner):
    name = "test-nan"

    def plan(self, problem, rng):
        return Plan(Grasp((math.nan, 0.0), (0.05, 0.0)), "ok", estimate=math.nan)


class OutsideGrid(Planner):
    name = "test-outside"

    def plan(self, problem, rng):
        return Plan(Grasp((5.0, 5.0), (5.05, 5.0)), "ok")


class Sleeps(Planner):
    name = "test-sleeps"

    def __init__(self, seconds: float = 3.0):
        self.seconds = seconds

    def plan(self, problem, rng):
        time.sleep(self.seconds)
        return Plan(Grasp((-0.045, 0.0), (0.045, 0.0)), "ok")
