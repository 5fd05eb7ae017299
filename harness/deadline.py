"""The time limits of a plan: when a plan counts as overtime, and the hard stop of a
planner that runs far past its budget."""

from __future__ import annotations

import signal
import threading

OVERTIME_SLACK = 1.5             # a plan may take this factor times its budget ...
OVERTIME_GRACE_S = 1.0           # ... plus this, before it counts as overtime
HARD_STOP_FACTOR = 3.0           # a planner still running at 3 x budget + 10 s is stopped
HARD_STOP_EXTRA_S = 10.0


def is_overtime(elapsed: float, budget: float) -> bool:
    """Whether a plan that took ``elapsed`` seconds overran its ``budget``."""
    return elapsed > OVERTIME_SLACK * budget + OVERTIME_GRACE_S


def hard_stop_s(budget: float) -> float:
    """Seconds after which a planner with ``budget`` is stopped."""
    return HARD_STOP_FACTOR * budget + HARD_STOP_EXTRA_S


class Overtime(Exception):
    """Raised inside a planner that reached its hard stop."""


class deadline:
    """Stop the planner (raise Overtime in it) after ``seconds``, where Unix timers allow
    (the main thread of a worker process); elsewhere the overtime is only recorded."""

    def __init__(self, seconds: float):
        self.seconds = seconds
        self.armed = hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()

    def __enter__(self):
        if self.armed:
            self.previous = signal.signal(signal.SIGALRM, self._fire)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)

    def __exit__(self, *exc):
        if self.armed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self.previous)

    @staticmethod
    def _fire(signum, frame):
        raise Overtime()
