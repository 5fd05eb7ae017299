"""The time limits of a plan: when a plan counts as overtime, and the deadline at which
the harness kills a planner that is still running (from outside its process, so that
no ``except`` in the planner can swallow it)."""

from __future__ import annotations

OVERTIME_SLACK = 1.5             # a plan may take this factor times its budget ...
OVERTIME_GRACE_S = 1.0           # ... plus this, before it counts as overtime


def is_overtime(elapsed: float, budget: float) -> bool:
    """Whether a plan that took ``elapsed`` seconds overran its ``budget``."""
    return elapsed > deadline_s(budget)


def deadline_s(budget: float) -> float:
    """Seconds after which a planner with ``budget`` is overtime, and is killed if it
    is still running: its plan would not be executed anyway."""
    return OVERTIME_SLACK * budget + OVERTIME_GRACE_S
