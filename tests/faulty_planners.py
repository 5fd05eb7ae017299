"""Planners that break the contract. Those that fail in ``plan`` (the ways DESIGN.md
lists) are outcomes: the harness records each with its status and finishes the
experiment. Those that cannot be made (no ``plan``, a constructor that raises or exits,
parameters not stored) are bad input: one line and exit 2 before any work. Imported as
module:Class (by workers too)."""

from __future__ import annotations

import math
import sys
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


# -- planners that cannot be made ------------------------------------------------------------


class NotAPlanner:
    name = "test-not-a-planner"


class NoPlan(Planner):
    name = "test-no-plan"
    description = "forgets to implement plan"


class FailsToConstruct(Planner):
    name = "test-fails-to-construct"
    description = "its constructor raises"

    def __init__(self, model: str = "weights.bin"):
        raise RuntimeError(f"cannot open {model}")

    def plan(self, problem, rng):  # pragma: no cover - never made
        raise AssertionError


class ExitsInInit(FailsToConstruct):
    def __init__(self):
        sys.exit(4)


class ForgetsParameter(Planner):
    name = "test-forgets-parameter"
    description = "stores its parameter under another name"

    def __init__(self, candidates: int = 5):
        self.n = candidates

    def plan(self, problem, rng):  # pragma: no cover - never made by the registry
        return Plan(Grasp((-0.045, 0.0), (0.045, 0.0)), "ok")
