"""Planners at the edges of what the harness accepts (imported as module:Class)."""

from __future__ import annotations

from harness.grasp import Grasp
from planners.base import Plan, Planner

#: A grasp across the disk scene exactly as wide as its 0.10 m opening, up to rounding:
#: math.dist gives 0.10000000000000002.
ROUNDED = ((-0.05, 0.0), (0.05000000000000002, 0.0))
#: One micrometre wider than the opening: a real excess.
TOO_WIDE = ((-0.05, 0.0), (0.050001, 0.0))


class WideByRounding(Planner):
    name = "test-wide-by-rounding"

    def plan(self, problem, rng):
        return Plan(Grasp(*ROUNDED), "ok")


class WiderThanOpening(Planner):
    name = "test-wider-than-opening"

    def plan(self, problem, rng):
        return Plan(Grasp(*TOO_WIDE), "ok")


class ExitsInPlan(Planner):
    name = "test-exits-in-plan"

    def plan(self, problem, rng):
        raise SystemExit(3)


class Fixed(Planner):
    """The same grasp on every belief, whatever its label: across the rectangle's middle,
    a little off its centre (``Sleeps`` in faulty_planners plans through the centre)."""

    name = "test-fixed"

    def plan(self, problem, rng):
        return Plan(Grasp((-0.045, 0.004), (0.045, -0.002)), "ok")
