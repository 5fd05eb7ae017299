"""One cell's pipeline, behind every front door: ``eval``'s cell tasks and the ``plan``,
``quality`` and ``simulate`` commands all build the belief, its evaluation draws, each
plan (in a process of its own, harness.isolation), the analytic judging and the trials'
inputs here, so what a command prints is what ``eval`` records for that cell.

A cell is (seed, scene, realisation). Its random streams (harness.seeding) are named by
purpose: ``sensor`` for the belief, ``planner`` + label for each planner, the evaluation
streams ``shapes``, ``approach``, ``friction``, ``pressure`` (posterior draws; posterior
trial i uses draw i) and ``truth-approach``, ``truth-friction`` (true-shape trials).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass

import numpy as np

from harness import isolation
from harness.belief import Belief
from harness.deadline import deadline_s, is_overtime
from harness.protocol import Protocol
from harness.quality import EvaluationDraws, evaluate_draws
from harness.scene import Scene
from harness.settings import GraspSettings

#: Plan statuses whose grasp is executed and judged.
EXECUTABLE = ("ok", "budget")
#: Statuses the harness gives a plan: the planner raised an Exception, its grasp cannot be
#: executed, it ran past its deadline, or its process crashed (a BaseException, an exit,
#: a signal, memory).
HARNESS_STATUSES = ("raised", "invalid", "overtime", "crashed")
#: Evaluation draws of the single-shot commands (eval's default analytic_draws).
DRAWS = 1000


@dataclass(frozen=True)
class Cell:
    """A cell's scene and settings, its belief (prepared) and its
    evaluation draws (shared by every planner: common random numbers)."""

    seed: int
    realisation: int
    scene: Scene
    settings: GraspSettings
    belief: Belief
    draws: EvaluationDraws


def cell_draws(analytic_draws: int, posterior_trials: int) -> int:
    """How many paired evaluation draws an experiment's cell draws: the analytic
    estimate's and the posterior trials' (trial i runs on draw i), whichever is more.
    Code that opens an experiment's cell again to look at its trials must draw exactly
    this many: the GP's shape samples depend on how many are drawn (the approach,
    friction and pressure deviates do not), so a cell drawn with another count pairs
    trial i with another shape sample."""
    return max(analytic_draws, posterior_trials)


def open_cell(scene: Scene, settings: GraspSettings, seed: int, realisation: int, draws: int) -> Cell:
    """Observe the scene with the cell's sensor stream, fit the belief (its grid fields,
    mean shape and centre of mass computed now) and draw ``draws`` paired evaluation
    draws."""
    from harness.belief import build_belief
    from harness.gpis import single_threaded_blas
    from harness.quality import default_streams, draw_evaluation
    from harness.seeding import stream

    # One BLAS thread, as in eval's cell tasks (harness.tasks.run_cell): the GP's fit (its
    # Cholesky factor) differs in its last bits with the thread count, so a command that
    # opens a cell must use the same one to print what eval records.
    with single_threaded_blas():
        belief = build_belief(scene, stream(seed, scene.name, realisation, "sensor")).prepare()
        evaluation = draw_evaluation(belief, draws, *default_streams(seed, scene.name, realisation))
    return Cell(seed, realisation, scene, settings, belief, evaluation)


def plan(cell: Cell, label: str, name: str, params: dict, budget: float | None,
         memory_bytes: float | None = None) -> tuple[dict, str]:
    """The ledger's plan row of planner ``name`` (labelled ``label``, with ``params``) on
    the cell, and the planner's traceback when it raised or crashed ("" otherwise). The
    planner is made and run in a process of its own (harness.isolation): its writes, its
    crash and its memory (``memory_bytes`` beyond the caller's) stay there, and it is
    killed at its deadline (harness.deadline) when it has a ``budget``. Never raises for
    the planner's faults; they are the row's status."""
    from harness.gpis import single_threaded_blas
    from harness.grasp import load_kernels
    from harness.seeding import stream
    from planners.base import Problem
    from planners.registry import builtins

    row = {"scene": cell.scene.name, "realisation": cell.realisation, "planner": label, "planner_name": name,
           "params": json.dumps(params, sort_keys=True), "status": "error", "executed": 0, "message": "",
           "g1x": None, "g1y": None, "g2x": None, "g2y": None, "estimate": None, "plan_time_s": 0.0,
           "iterations": 0, "evaluations": 0, "trace": "[]"}
    problem = Problem(cell.belief, cell.settings, time_budget_s=budget)
    rng = stream(cell.seed, cell.scene.name, cell.realisation, "planner", label)
    builtins()  # imported here once, not in every plan's process; plugins load there only
    load_kernels()  # the compiled contact search, loaded once here: no plan's budget pays for it
    with single_threaded_blas():  # the plan's process inherits it, as in eval's cell tasks
        outcome = isolation.call(_plan_in_child, name, params, problem, rng,
                                 deadline_s=None if budget is None else deadline_s(budget), memory_bytes=memory_bytes)
    if outcome.kind != "returned":
        row.update(status=outcome.kind, message=outcome.message[:500], plan_time_s=outcome.seconds)
        return row, outcome.traceback
    result = outcome.value
    elapsed = result["plan_time_s"]
    row.update(plan_time_s=elapsed, status=result["status"], message=result["message"][:500],
               iterations=result["iterations"], evaluations=result["evaluations"], trace=json.dumps(result["trace"]))
    estimate = result["estimate"]
    row["estimate"] = estimate if estimate is not None and math.isfinite(estimate) else None
    if result["grasp"] is None:
        return row, ""
    coords = np.asarray(result["grasp"], dtype=float)
    problem_text = _grasp_problem(coords, cell)
    if np.isfinite(coords).all():
        row.update(g1x=coords[0, 0], g1y=coords[0, 1], g2x=coords[1, 0], g2y=coords[1, 1])
    if problem_text:
        row.update(status="invalid", message=f"grasp rejected: {problem_text}")
    elif budget is not None and is_overtime(elapsed, budget):
        row.update(status="overtime", message=f"took {elapsed:.1f} s (budget {budget:g} s)")
    row["executed"] = int(row["status"] in EXECUTABLE)
    return row, ""


def _plan_in_child(name: str, params: dict, problem, rng) -> dict:
    """Make the planner and plan, in the isolated process; the Plan as JSON-ready values.
    A Plan that cannot be read so, or a problem changed by the planner (a replaced array,
    an attribute set with object.__setattr__; harness.readonly), is the planner's fault:
    an Exception, 'raised'."""
    from harness.readonly import InputsChanged, changes, fingerprint
    from planners.base import STATUSES, Plan
    from planners.registry import make_planner

    planner = make_planner(name, params)
    before = fingerprint(problem, contents=False)
    start = time.perf_counter()
    plan = planner.plan(problem, rng)
    elapsed = time.perf_counter() - start
    changed = changes(before, fingerprint(problem, contents=False))
    if changed:  # only this process's copy changed; the planner's fault all the same
        raise InputsChanged(changed)
    if not isinstance(plan, Plan):
        raise TypeError(f"plan() returned {type(plan).__name__}, not a Plan")
    if plan.status not in STATUSES:
        raise ValueError(f"plan() returned the unknown status {plan.status!r} (known: {', '.join(STATUSES)})")
    grasp = None
    if plan.grasp is not None:
        grasp = np.asarray([plan.grasp.g1, plan.grasp.g2], dtype=float)
        if grasp.shape != (2, 2):
            raise ValueError(f"plan() returned a grasp of shape {grasp.shape}, not two points")
        grasp = grasp.tolist()
    estimate = None if plan.estimate is None else float(plan.estimate)
    return {"status": plan.status, "message": str(plan.message or ""), "grasp": grasp, "estimate": estimate,
            "iterations": int(plan.iterations or 0), "evaluations": int(plan.evaluations or 0),
            "trace": [[float(v) for v in t] for t in (plan.trace or ())], "plan_time_s": elapsed}


def _grasp_problem(coords: np.ndarray, cell: Cell) -> str | None:
    """Why a planned grasp cannot be executed (non-finite, off the grid, wider than the
    opening), or None."""
    from harness.grasp import Grasp

    if not np.isfinite(coords).all():
        return "non-finite coordinates"
    return Grasp(tuple(coords[0]), tuple(coords[1])).problem(cell.scene.grid, cell.settings.opening)


def judge(cell: Cell, grasp, draws: int):
    """The analytic verdicts (harness.quality.DrawOutcomes) of one grasp ((2, 2) jaw
    starts or a Grasp) on the cell's first ``draws`` evaluation draws (with one BLAS
    thread, as :func:`open_cell`)."""
    from harness.gpis import single_threaded_blas

    with single_threaded_blas():
        return evaluate_draws(grasp, cell.draws.first(draws), cell.settings)


def planned_grasp(row: dict) -> np.ndarray:
    """A plan row's grasp as (2, 2) jaw starts."""
    return np.array([[row["g1x"], row["g1y"]], [row["g2x"], row["g2y"]]], dtype=float)


def verdict_label(reason: int, turned: bool) -> str:
    """A draw's analytic verdict as the ledger stores it: ``lifted`` (the plates hold it
    level), ``lifted_turned`` (the weight turned it in the plates and it is still lifted:
    over the regime sweep such draws failed up to four times in five where nothing
    stopped the turn, docs/lift.md) or the first reason it fails P_L
    (harness.quality.FAILURE_REASONS)."""
    from harness.quality import FAILURE_REASONS, LIFTED_VERDICTS

    if reason >= 0:
        return FAILURE_REASONS[reason]
    return LIFTED_VERDICTS[int(bool(turned))]


def analytic_row(cell: Cell, row: dict, draws: int, reasons: int) -> dict:
    """The ledger's analytic row of an executed plan: P_F, P_L, their intervals and the
    failures over the first ``draws`` draws, and the verdicts of the first ``reasons``
    draws (those the posterior trials share; :func:`verdict_label`), judged on as many of
    the cell's draws as that takes when they are more than ``draws``."""
    grasp = planned_grasp(row)
    outcomes = judge(cell, grasp, draws)
    est = outcomes.estimates[0]
    drawn = outcomes if reasons <= draws else judge(cell, grasp, reasons)
    verdicts = ",".join(verdict_label(r, turned)
                        for r, turned in zip(drawn.reason[0, :reasons], drawn.pivots[0, :reasons]))
    return {"scene": cell.scene.name, "realisation": cell.realisation, "planner": row["planner"],
            "draws": est.samples, "p_f": est.p_f, "ci_low": est.ci_low, "ci_high": est.ci_high,
            "ferrari_canny_mean": est.ferrari_canny_mean, "failures": json.dumps(est.failures, sort_keys=True),
            "p_l": est.p_l, "p_l_ci_low": est.p_l_ci_low, "p_l_ci_high": est.p_l_ci_high, "pivots": est.pivots,
            "reasons": verdicts}


@dataclass(frozen=True)
class TrialInputs:
    """What the trials of one shape source share with the analytic draws: the polygons
    (one per trial, or the one true shape) and the standard-normal approach (n, 2, 2) and
    friction (n,) deviates."""

    polygons: list
    approach: np.ndarray
    friction: np.ndarray

    def part(self, trials: slice) -> "TrialInputs":
        """The inputs of some of the trials (one shared polygon stays shared)."""
        polygons = self.polygons if len(self.polygons) == 1 else self.polygons[trials]
        return TrialInputs(polygons, self.approach[trials], self.friction[trials])


def posterior_inputs(cell: Cell, trials: int, refinement: int = Protocol.body_refinement) -> TrialInputs:
    """Posterior trial i: shape sample i (its body outlined on cells ``refinement`` times
    finer than the belief's, the protocol's ``body_refinement``), approach and friction
    deviates i of the cell's evaluation draws."""
    from harness.physics.bodies import field_polygon

    values = cell.draws.shapes.values[:trials]
    return TrialInputs([field_polygon(f, cell.belief.grid, refinement) for f in values],
                       cell.draws.approach[:trials].copy(),
                       cell.draws.friction[:trials].copy())


def truth_inputs(scene: Scene, seed: int, realisation: int, trials: int) -> TrialInputs:
    """True-shape trials: the true outline, and deviates from the truth streams."""
    from harness.physics.simulate import truth_polygon
    from harness.seeding import stream

    approach = stream(seed, scene.name, realisation, "truth-approach").standard_normal((trials, 2, 2))
    friction = stream(seed, scene.name, realisation, "truth-friction").standard_normal(trials)
    return TrialInputs([truth_polygon(scene)], approach, friction)
