"""The planner conformance kit: ``check_planner(PlannerClass)`` runs a planner on small
scenes and checks the contract of planners/base.py. Plugin authors call it in their own
tests; the built-in planners pass it."""

from __future__ import annotations

import math
import time

import numpy as np

from harness import isolation
from harness.belief import Belief, build_belief
from harness.errors import describe
from harness.gpis import GPIS
from harness.grasp import load_kernels
from harness.readonly import InputsChanged, changes, fingerprint
from harness.scene import load_scene
from harness.seeding import stream
from harness.sensor import NORMAL, Observations


def check_planner(planner_class, scenes=("disk", "rectangle"), seeds=(0, 1), time_budget: float = 1.0,
                  slack: float = 1.5, params: dict | None = None) -> dict:
    """Check a planner class against the contract; raise AssertionError saying what is
    wrong, or return a short report (plan times by scene and seed).

    Checks: the class has a name and a one-line description, implements ``plan``, its
    BOUNDS name parameters and hold their defaults, every constructor parameter has a
    default and is stored under its own name; on every scene and seed,
    ``plan`` returns a Plan with a known status and a grasp that is finite, inside the
    grid and no wider than the opening; the same seed gives the same grasp; the plan
    changes nothing it was given (no write into the problem's read-only arrays, nothing
    reachable from the problem changed: harness.readonly); with a time budget the plan
    returns within the budget plus ``slack`` seconds (it runs in a process of its own,
    killed then); on a belief with no surface the plan's status is "no_surface" (not an
    exception).
    """
    from planners.base import STATUSES, Plan, Planner, Problem
    from planners.registry import class_problem, parameter_value

    name = getattr(planner_class, "name", "")
    _require(isinstance(planner_class, type) and issubclass(planner_class, Planner),
             f"{planner_class!r} is not a subclass of planners.base.Planner")
    _require(isinstance(name, str) and name, "the class needs a non-empty string `name`")
    description = getattr(planner_class, "description", "")
    _require(isinstance(description, str) and description and "\n" not in description,
             f"{name}: `description` must be one line")
    problem = class_problem(planner_class)
    _require(problem is None, f"{name}: {problem}")
    defaults = planner_class.parameters()
    missing = [k for k, v in defaults.items() if v is _EMPTY]
    _require(not missing, f"{name}: every constructor parameter needs a default: {missing}")
    for key, default in defaults.items():
        try:
            parameter_value(planner_class, key, default)
        except ValueError as exc:
            raise AssertionError(f"{name}: the default of {key} is refused: {exc}") from None
    planner = planner_class(**(params or {}))
    unstored = [k for k in defaults if not hasattr(planner, k)]
    _require(not unstored, f"{name}: store each parameter under its own name (in __init__, "
             f"self.<name> = <name>); not stored: {', '.join(unstored)}")

    load_kernels()  # loaded before the forks, as pipeline.plan does: no budget pays for it
    report = {}
    for scene_name in scenes:
        scene = load_scene(scene_name)
        belief = build_belief(scene, stream(0, "conformance", scene_name, "sensor")).prepare()
        problem = Problem.for_belief(belief)
        # First, in a process of its own, killed at budget + slack, as an experiment kills
        # a planner at its deadline (harness.deadline): a planner that ignores its budget
        # fails here instead of hanging the checks that follow.
        budgeted = Problem.for_belief(belief, time_budget_s=time_budget)
        where = f"{name} on {scene_name} with a time budget"
        outcome = isolation.call(_budgeted_plan, planner, budgeted, stream(99, "conformance", scene_name, name),
                                 where, deadline_s=time_budget + slack)
        _require(outcome.kind != "overtime", f"{where}: ignores its deadline: still planning {outcome.seconds:.1f} s "
                 f"after it started, with a budget of {time_budget:g} s (allowed slack {slack:g} s); killed")
        _require(outcome.kind == "returned", outcome.message.removeprefix("AssertionError: ") if
                 outcome.message.startswith("AssertionError: ") else f"{where}: {outcome.message}")

        for seed in seeds:
            where = f"{name} on {scene_name}, seed {seed}"
            start = time.perf_counter()
            plan = _plan_untouched(planner, problem, stream(seed, "conformance", scene_name, name), where)
            report[(scene_name, seed)] = time.perf_counter() - start
            _check_plan(plan, problem, where, Plan, STATUSES)
            _require(plan.status == "ok", f"{where}: status {plan.status!r}, expected 'ok' ({plan.message})")
            again = _plan_untouched(planner_class(**(params or {})), problem,
                                    stream(seed, "conformance", scene_name, name), where)
            _require(again.grasp == plan.grasp, f"{name} on {scene_name}: the same seed gave different grasps "
                     f"({plan.grasp} and {again.grasp})")

    empty = Problem.for_belief(_belief_without_surface(load_scene(scenes[0])))
    try:
        plan = _plan_untouched(planner, empty, stream(0, "conformance", "empty", name), f"{name} with no surface")
    except AssertionError:
        raise
    except Exception as exc:  # the contract: say so in the Plan instead
        raise AssertionError(f"{name}: raised {type(exc).__name__} on a belief with no surface: {exc}") from None
    _require(isinstance(plan, Plan) and plan.status == "no_surface" and plan.grasp is None,
             f"{name}: a belief with no surface must give a Plan with status 'no_surface' and no grasp, "
             f"got {getattr(plan, 'status', plan)!r}")
    return report


_EMPTY = __import__("inspect").Parameter.empty


def _plan_untouched(planner, problem, rng, where: str):
    """``planner.plan(problem, rng)``, failing (AssertionError) when the plan wrote into
    its inputs: a write into a read-only array, or anything reachable from the problem
    changed (harness.readonly: its arrays' bytes, its numbers, its objects)."""
    before = fingerprint(problem)
    try:
        plan = planner.plan(problem, rng)
    except ValueError as exc:
        if "read-only" in str(exc):
            raise AssertionError(f"{where}: writes into its inputs ({describe(exc)}); the problem is read-only: "
                                 "copy what you change") from None
        raise
    changed = changes(before, fingerprint(problem))
    _require(not changed, f"{where}: {InputsChanged(changed)}" if changed else "")
    return plan


def _budgeted_plan(planner, problem, rng, where: str) -> None:
    """The budgeted check, in its own process: plan (untouched inputs), then check the plan."""
    from planners.base import STATUSES, Plan

    _check_plan(_plan_untouched(planner, problem, rng, where), problem, where, Plan, STATUSES)


def _require(condition, message: str) -> None:
    if not condition:
        raise AssertionError(message)


def _check_plan(plan, problem, where: str, plan_type, statuses) -> None:
    _require(isinstance(plan, plan_type), f"{where}: plan() must return a Plan, got {type(plan).__name__}")
    _require(plan.status in statuses, f"{where}: unknown status {plan.status!r} (known: {', '.join(statuses)})")
    if plan.status in ("ok", "budget"):
        _require(plan.grasp is not None, f"{where}: status {plan.status!r} without a grasp")
    if plan.grasp is not None:
        g = plan.grasp.array
        _require(np.all(np.isfinite(g)), f"{where}: grasp has non-finite coordinates {g.tolist()}")
        problem_text = plan.grasp.problem(problem.belief.grid, problem.settings.opening)
        _require(problem_text is None, f"{where}: invalid grasp: {problem_text}")
    _require(plan.estimate is None or (math.isfinite(plan.estimate)),
             f"{where}: estimate must be a finite number or None")
    _require(all(len(t) == 3 for t in plan.trace), f"{where}: trace entries are (seconds, evaluations, best)")


def _belief_without_surface(scene) -> Belief:
    """A belief of ``scene`` whose posterior mean is outside everywhere: every cell read
    the truncation distance ("nothing there"), and the prior mean agrees."""
    points = scene.grid.points
    n = len(points)
    values = np.full(n, scene.truncation)
    obs = Observations(points=points.copy(), values=values, noise_var=np.full(n, scene.sensor.noise**2),
                       gradients=np.full((n, 2), np.nan), gradient_noise_var=np.full((n, 2), np.nan),
                       cells=np.column_stack([np.arange(n) % scene.grid.size, np.arange(n) // scene.grid.size]),
                       kind=np.full(n, NORMAL, dtype=np.int8))
    s = scene.gpis
    active = np.arange(0, n, 7)
    gp = GPIS(lengthscale=s.lengthscale, scale=s.scale, prior_mean=scene.truncation)
    gp.fit(points[active], values[active], obs.noise_var[active])
    return Belief(scene, obs, gp, active)
