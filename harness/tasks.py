"""The tasks of an experiment: cells (scene x realisation) and physics batches.

A cell is one scene and one sensor realisation (one belief). Its cell task builds the
belief, runs every planner that has no plan in the ledger yet, judges each plan by the
analytic P_F, and returns the polygons of the posterior shape samples that the physics
trials use. Each plan's trials then run as fixed batches (``batch_size`` consecutive
trials of one plan and one shape source, in one freshly reset pybullet world), so which trials
share a world is fixed by the config, never by the number of workers.

Random streams (harness.seeding) are named by (seed, scene, realisation, purpose):
``sensor`` for the belief, ``planner``/label for each planner, and the evaluation streams
``shapes``, ``approach``, ``friction`` (posterior draws) and ``truth-approach``,
``truth-friction`` (true-shape trials), which do not depend on the planner. Physics trial
i on posterior samples uses shape sample i, approach deviates i and friction deviate i of
the analytic P_F's draws: every planner meets the same shapes and the same noise, and a
plan's trial i and its analytic draw i are the same situation.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from harness.config import ExperimentConfig, PlannerEntry
from harness.deadline import Overtime, deadline, hard_stop_s, is_overtime
from harness.scene import load_scene

NO_PLAN = "no_plan"              # trial outcome when the plan gave nothing to execute
EXECUTABLE = ("ok", "budget")    # plan statuses whose grasp is executed
HARNESS_STATUSES = ("raised", "invalid", "overtime")
SHAPES = ("posterior", "truth")



@lru_cache(maxsize=32)
def _scene(path: str):
    return load_scene(path)


def scene_of(config: ExperimentConfig, path: str):
    return _scene(path)


@lru_cache(maxsize=64)
def _settings(path: str, overrides_json: str, protocol):
    from harness.settings import resolve

    return resolve(_scene(path), json.loads(overrides_json), protocol)


def settings_of(config: ExperimentConfig, path: str):
    """The grasp settings of a scene in this experiment: the scene's, the config's
    overrides, and the lift of the config's physics protocol (resolved once per process)."""
    return _settings(path, json.dumps(config.settings, sort_keys=True), config.protocol())


@dataclass(frozen=True)
class CellResult:
    """What a cell task returns: plan and analytic rows for the planners it ran, the
    polygons of the posterior samples for the trials, and the trials' random deviates."""

    scene: str
    realisation: int
    plans: list
    analytic: list
    polygons: list
    approach: np.ndarray          # (posterior_trials, 2, 2)
    friction: np.ndarray          # (posterior_trials,)
    truth_approach: np.ndarray    # (truth_trials, 2, 2)
    truth_friction: np.ndarray    # (truth_trials,)
    seconds: float


def run_cell(config: ExperimentConfig, path: str, realisation: int, labels: tuple[str, ...]) -> CellResult:
    """Belief, plans of ``labels``, their analytic P_F, and the trials' shapes and noise,
    with one BLAS thread: the workers are the parallelism. On 2 cores, two workers with
    two BLAS threads each took 38.0-39.0 s for the 30 cells of make eval, one thread each
    31.4-34.1 s (four runs each); the plans and shapes are bit for bit the same."""
    from harness.gpis import single_threaded_blas

    with single_threaded_blas():
        return _cell(config, path, realisation, labels)


def _cell(config: ExperimentConfig, path: str, realisation: int, labels: tuple[str, ...]) -> CellResult:
    from harness.belief import build_belief
    from harness.physics.bodies import field_polygon
    from harness.quality import default_streams, draw_evaluation, evaluate_draws
    from harness.seeding import stream

    start = time.perf_counter()
    scene = scene_of(config, path)
    name = scene.name
    belief = build_belief(scene, stream(config.seed, name, realisation, "sensor")).prepare()
    settings = settings_of(config, path)
    n = max(config.analytic_draws, config.posterior_trials)
    draws = draw_evaluation(belief, n, *default_streams(config.seed, name, realisation))
    plans, analytic = [], []
    for entry in config.planners:
        if entry.label not in labels:
            continue
        row = _plan_row(config, entry, scene, belief, realisation, settings)
        plans.append(row)
        if row["executed"]:
            grasp = np.array([[row["g1x"], row["g1y"]], [row["g2x"], row["g2y"]]])
            outcomes = evaluate_draws(grasp, draws.first(config.analytic_draws), settings)
            est = outcomes.estimates[0]
            analytic.append({"scene": name, "realisation": realisation, "planner": entry.label,
                             "draws": est.samples, "p_f": est.p_f, "ci_low": est.ci_low, "ci_high": est.ci_high,
                             "ferrari_canny_mean": est.ferrari_canny_mean,
                             "failures": json.dumps(est.failures, sort_keys=True), "p_l": est.p_l,
                             "p_l_ci_low": est.p_l_ci_low, "p_l_ci_high": est.p_l_ci_high, "pivots": est.pivots,
                             "reasons": draw_reasons(outcomes.reason[0, :config.posterior_trials])})
    k = config.posterior_trials
    polygons = [field_polygon(f, belief.grid) for f in draws.shapes.values[:k]]
    truth_approach = stream(config.seed, name, realisation, "truth-approach").standard_normal(
        (config.truth_trials, 2, 2))
    truth_friction = stream(config.seed, name, realisation, "truth-friction").standard_normal(config.truth_trials)
    return CellResult(name, realisation, plans, analytic, polygons, draws.approach[:k].copy(),
                      draws.friction[:k].copy(), truth_approach, truth_friction, time.perf_counter() - start)


def draw_reasons(reason: np.ndarray) -> str:
    """The analytic verdicts of the draws that posterior trials 0, 1, ... share, as text
    for the ledger: one comma-separated name per draw ('lifted' or the failure reason)."""
    from harness.quality import FAILURE_REASONS

    return ",".join("lifted" if r < 0 else FAILURE_REASONS[r] for r in reason)


def _plan_row(config, entry: PlannerEntry, scene, belief, realisation, settings) -> dict:
    """Run one planner under the harness's checks; never raises for the planner's faults."""
    from harness.seeding import stream
    from planners.base import Problem
    from planners.registry import make_planner

    row = {"scene": scene.name, "realisation": realisation, "planner": entry.label, "planner_name": entry.name,
           "params": json.dumps(entry.params, sort_keys=True), "status": "error", "executed": 0, "message": "",
           "g1x": None, "g1y": None, "g2x": None, "g2y": None, "estimate": None, "plan_time_s": 0.0,
           "iterations": 0, "evaluations": 0, "trace": "[]"}
    budget = config.time_budget_s
    problem = Problem(belief, settings, time_budget_s=budget)
    rng = stream(config.seed, scene.name, realisation, "planner", entry.label)
    start = time.perf_counter()
    try:
        planner = make_planner(entry.name, entry.params)
        with deadline(hard_stop_s(budget)):
            plan = planner.plan(problem, rng)
    except Overtime:
        row.update(status="overtime", message=f"stopped after {time.perf_counter() - start:.1f} s "
                                              f"(budget {budget:g} s)", plan_time_s=time.perf_counter() - start)
        return row
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - a plugin's bug (even sys.exit) is an outcome
        row.update(status="raised", message=f"{type(exc).__name__}: {exc}"[:500],
                   plan_time_s=time.perf_counter() - start)
        return row
    elapsed = time.perf_counter() - start
    row.update(plan_time_s=elapsed, status=str(plan.status), message=str(plan.message or "")[:500],
               iterations=int(plan.iterations or 0), evaluations=int(plan.evaluations or 0),
               trace=json.dumps([[float(v) for v in t] for t in (plan.trace or ())]))
    estimate = plan.estimate
    row["estimate"] = float(estimate) if estimate is not None and math.isfinite(float(estimate)) else None
    grasp = plan.grasp
    if grasp is None:
        return row
    coords = np.asarray([grasp.g1, grasp.g2], dtype=float)
    if coords.shape == (2, 2) and np.isfinite(coords).all():
        row.update(g1x=coords[0, 0], g1y=coords[0, 1], g2x=coords[1, 0], g2y=coords[1, 1])
    problem_text = grasp.problem(scene.grid, settings.opening) if np.isfinite(coords).all() else \
        "non-finite coordinates"
    if problem_text:
        row.update(status="invalid", message=f"grasp rejected: {problem_text}")
    elif is_overtime(elapsed, budget):
        row.update(status="overtime", message=f"took {elapsed:.1f} s (budget {budget:g} s)")
    row["executed"] = int(row["status"] in EXECUTABLE)
    return row


@dataclass(frozen=True)
class Batch:
    """One physics task: consecutive trials ``indices`` of one plan on one shape source."""

    scene_path: str
    scene: str
    realisation: int
    planner: str
    shapes: str
    indices: tuple[int, ...]
    grasp: tuple
    polygons: list
    approach: np.ndarray
    friction: np.ndarray


_THREAD = threading.local()


def _runner(protocol):
    """This thread's pybullet client for ``protocol``, kept between batches (a connect
    costs about 25 ms). One per thread, as a Dask worker may run tasks in several. Each
    batch starts from a reset world, so its outcomes do not depend on what ran before
    (tested)."""
    from harness.physics.trial import MAX_BATCH, Runner

    runners = _THREAD.__dict__.setdefault("runners", {})
    if protocol not in runners:
        runners[protocol] = Runner(protocol, batch_size=MAX_BATCH)
    return runners[protocol]


def run_batch(config: ExperimentConfig, batch: Batch) -> list[dict]:
    """The trials of one batch in one freshly reset pybullet world; rows for the ledger."""
    from harness.physics.simulate import make_trials

    trials = make_trials(settings_of(config, batch.scene_path), np.asarray(batch.grasp), batch.polygons,
                         batch.approach, batch.friction)
    results = _runner(config.protocol()).run(trials)
    return [_trial_row(batch, i, r.outcome, r.steps, r.grip_width, r.closing_turn, r.rise, r.pivot)
            for i, r in zip(batch.indices, results, strict=True)]


def _trial_row(b: Batch, index: int, outcome: str, steps: int = 0, grip_width=None, closing_turn=None,
               rise=None, pivot=None) -> dict:

    def num(v):
        return None if v is None or not math.isfinite(v) else float(v)

    return {"scene": b.scene, "realisation": b.realisation, "planner": b.planner, "shapes": b.shapes,
            "trial": int(index), "outcome": outcome, "steps": int(steps), "grip_width": num(grip_width),
            "closing_turn": num(closing_turn), "rise": num(rise), "pivot": num(pivot)}


def batches_of(config: ExperimentConfig, path: str, cell: CellResult, plan: dict,
               done: set[tuple[str, str, int]]) -> tuple[list[Batch], list[dict]]:
    """A plan's missing trials: batches to simulate, and ``no_plan`` rows when the plan
    has nothing to execute (those trials count as failures of the planner)."""
    from harness.physics.simulate import truth_polygon

    batches, rows = [], []
    label = plan["planner"]
    grasp = ((plan["g1x"], plan["g1y"]), (plan["g2x"], plan["g2y"]))
    for shapes, count in (("posterior", config.posterior_trials), ("truth", config.truth_trials)):
        for lo in range(0, count, config.batch_size):
            indices = tuple(i for i in range(lo, min(count, lo + config.batch_size)))
            if all((label, shapes, i) in done for i in indices):
                continue
            key = Batch(path, cell.scene, cell.realisation, label, shapes, indices, grasp, [], None, None)
            if not plan["executed"]:
                rows.extend(_trial_row(key, i, NO_PLAN) for i in indices if (label, shapes, i) not in done)
                continue
            sl = slice(indices[0], indices[-1] + 1)
            if shapes == "posterior":
                polygons, approach, friction = cell.polygons[sl], cell.approach[sl], cell.friction[sl]
            else:
                polygons = [truth_polygon(scene_of(config, path))]
                approach, friction = cell.truth_approach[sl], cell.truth_friction[sl]
            batches.append(replace(key, polygons=polygons, approach=approach, friction=friction))
    return batches, rows
