"""The planner contract. A planner is one class in one module: it receives a Problem
(read-only) and a random generator, and returns a Plan.

Write a planner by subclassing :class:`Planner`:

- set the class attributes ``name`` (the registry key, e.g. ``"my-planner"``) and
  ``description`` (one line);
- give ``__init__`` only keyword parameters, each with a default, and store each one
  under its own name (``self.candidates = candidates``): that is how ``planners list``
  shows them and how ``--param KEY=VALUE`` sets them. The default's type is the
  parameter's type (an int parameter refuses 2.5 and true, a float one nan and inf);
  ``BOUNDS`` gives numeric parameters their inclusive ranges, checked before ``__init__``
  runs when a planner is made from a config or the command line;
- implement ``plan(problem, rng)`` (abstract here): use only ``rng`` for randomness, check
  ``problem.time_budget_s`` between units of work, and return a Plan whose status says
  what happened (never raise for a belief without a surface: return
  ``Plan.without_grasp("no_surface", ...)``). The problem is read-only: its arrays refuse
  writes (copy what you change). In an experiment the harness runs each plan in a process
  of its own and kills it at 1.5 x the budget + 1 s (harness.deadline);
- optionally, ``shape_samples()``: how many posterior shape samples ``plan`` holds at
  once, for the memory estimate made before a run.

Register it in your own package under the entry-point group ``gpis_harness.planners``
(see docs/planners.md) and check it with ``harness.testing.check_planner``.
"""

from __future__ import annotations

import inspect
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from harness.belief import Belief
from harness.grasp import Grasp
from harness.readonly import freeze
from harness.settings import GraspSettings, resolve

#: What a Plan's status may say.
STATUSES = ("ok", "budget", "no_surface", "no_candidate", "infeasible", "error")
#: What the built-in planners may optimise (their ``quality`` parameter): the paper's
#: planar force closure, or force closure and the lift (harness.lift).
QUALITIES = ("force_closure", "lift")


def check_quality(quality: str) -> str:
    """``quality`` if it is one of QUALITIES; ValueError otherwise."""
    if quality not in QUALITIES:
        raise ValueError(f"quality must be one of {', '.join(QUALITIES)}, got {quality!r}")
    return quality


@dataclass(frozen=True)
class Problem:
    """What a planner must solve: the shape belief, the grasp's settings (gripper, friction
    and its spread, approach noise sigma_g, the object's extrusion and the lift; see
    harness.settings.GraspSettings) and an optional time budget in seconds.

    Read-only: making a Problem makes every array reachable from it non-writeable (the
    belief's fields, its GP's fitted state, its observations, the scene's fields), so a
    write raises ValueError in the planner. In an experiment each plan also runs in a
    process of its own, where anything else it changes is its own copy."""

    belief: Belief
    settings: GraspSettings
    time_budget_s: float | None = None

    def __post_init__(self):
        freeze(self)

    @classmethod
    def for_belief(cls, belief: Belief, settings: GraspSettings | None = None,
                   time_budget_s: float | None = None) -> "Problem":
        """The problem of a belief with the given settings, by default its scene's."""
        return cls(belief, settings if settings is not None else resolve(belief.scene), time_budget_s)


@dataclass(frozen=True)
class Plan:
    """A planner's answer.

    grasp: the chosen grasp, or None. status: one of STATUSES ("ok"; "budget" when the
    time budget cut the search short and the best grasp so far is returned;
    "no_surface"; "no_candidate"; "infeasible"; "error", set by the harness when plan
    raised). estimate: the planner's own estimate of P_F (or P_L), or None. iterations and
    evaluations: the planner's units of work. seconds: time by phase. trace: tuples
    (seconds, evaluations, best value so far) for convergence plots. message: a note.
    """

    grasp: Grasp | None
    status: str
    estimate: float | None = None
    iterations: int = 0
    evaluations: int = 0
    seconds: dict = field(default_factory=dict)
    trace: tuple = ()
    message: str = ""

    @classmethod
    def without_grasp(cls, status: str, message: str, **stats) -> "Plan":
        return cls(None, status, message=message, **stats)


class Planner(ABC):
    """Base class of planners; see the module docstring for the contract."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    #: Inclusive ranges of numeric parameters, ``{"candidates": (1, 10_000)}``; None for an
    #: open end. planners.registry.make_planner refuses a value outside its range.
    BOUNDS: ClassVar[dict] = {}

    @abstractmethod
    def plan(self, problem: Problem, rng: np.random.Generator) -> Plan:
        """The grasp for ``problem``, using only ``rng`` for randomness."""

    @classmethod
    def parameters(cls) -> dict:
        """Keyword parameters of the constructor and their defaults."""
        sig = inspect.signature(cls.__init__)
        return {k: p.default for k, p in sig.parameters.items()
                if k != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)}

    def get_params(self) -> dict:
        """The parameters this planner was made with."""
        return {k: getattr(self, k) for k in self.parameters()}

    def shape_samples(self) -> int:
        """How many posterior shape samples ``plan`` holds at once (its pool of draws), for
        the memory estimate made before a run (harness.memory). Optional: 0 by default;
        a planner that holds many should say so, or a run that cannot hold them is
        refused only when its plan runs out of memory (its status is then 'crashed')."""
        return 0


class Stopwatch:
    """Elapsed time against an optional budget, and seconds by phase."""

    def __init__(self, budget: float | None):
        self.start = time.perf_counter()
        self.budget = budget
        self.phases: dict = {}
        self._mark = self.start

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def over_budget(self) -> bool:
        return self.budget is not None and self.elapsed() > self.budget

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.phases[phase] = self.phases.get(phase, 0.0) + now - self._mark
        self._mark = now
