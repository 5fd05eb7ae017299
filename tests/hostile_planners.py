"""Planners that misbehave the ways a plugin under development does (issue 30): each plans
like mean-shape, and before or after that writes into its inputs, ends its own process,
raises what an ``except Exception`` does not catch, ignores its deadline or eats
memory. Beside them in one experiment, the built-in planners must give what they give
alone. Imported as module:Class (by workers too)."""

from __future__ import annotations

import os
import signal
import time

import numpy as np

from planners.mean_shape import MeanShape


class Deliberate(BaseException):
    """A BaseException that is neither SystemExit nor KeyboardInterrupt."""


class _Hostile(MeanShape):
    description = "plans like mean-shape, then misbehaves"
    BOUNDS = {"candidates": (1, 10_000)}

    def __init__(self, candidates: int = 20):
        super().__init__(candidates=candidates)

    def plan(self, problem, rng):
        plan = super().plan(problem, rng)
        self.misbehave(problem)
        return plan

    def misbehave(self, problem):  # pragma: no cover - overridden
        raise NotImplementedError


class WritesVariance(_Hostile):
    name = "hostile-writes-variance"

    def misbehave(self, problem):
        problem.belief.var[...] *= 4


class ScalesGP(_Hostile):
    name = "hostile-scales-gp"

    def misbehave(self, problem):
        for value in vars(problem.belief.gp).values():
            if isinstance(value, np.ndarray) and value.dtype.kind == "f":
                value *= 1.5


class ReplacesGP(_Hostile):
    """Rebinds the GP's fitted factor instead of writing into it: no array refuses that."""

    name = "hostile-replaces-gp"

    def misbehave(self, problem):
        problem.belief.gp.L_ = problem.belief.gp.L_ * 1.5


class SetsSettings(_Hostile):
    name = "hostile-sets-settings"

    def misbehave(self, problem):
        object.__setattr__(problem.settings, "friction", 0.05)
        object.__setattr__(problem.settings, "sigma_g", 0.01)


class Exits(_Hostile):
    name = "hostile-exits"

    def misbehave(self, problem):
        os._exit(1)


class KillsItself(_Hostile):
    name = "hostile-kills-itself"

    def misbehave(self, problem):
        os.kill(os.getpid(), signal.SIGKILL)


class RaisesKeyboardInterrupt(_Hostile):
    name = "hostile-keyboard-interrupt"

    def misbehave(self, problem):
        raise KeyboardInterrupt


class RaisesBaseException(_Hostile):
    name = "hostile-base-exception"

    def misbehave(self, problem):
        raise Deliberate("not an Exception")


class SleepsUnderExcept(_Hostile):
    """A retry loop that swallows whatever an Exception is: a timer's exception too."""

    name = "hostile-sleeps"

    def misbehave(self, problem):
        while True:
            try:
                time.sleep(0.05)
            except Exception:  # noqa: BLE001 - the point of this plugin
                pass


class EatsMemory(_Hostile):
    """Fills 3 GiB: more than a worker's budget in the tests (eval --memory-budget 1), far
    less than the machine's memory, so only the per-process limit stops it."""

    name = "hostile-eats-memory"

    def misbehave(self, problem):
        np.ones(3 * 2**30 // 8)


class Polite(_Hostile):
    """Misbehaves in no way: mean-shape under another name."""

    name = "hostile-polite"

    def misbehave(self, problem):
        pass
