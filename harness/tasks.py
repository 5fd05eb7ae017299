"""The tasks of an experiment: cells (scene x realisation) and physics batches.

A cell is one scene and one sensor realisation (one belief). Its cell task runs the
cell's pipeline (harness.pipeline: the belief, every planner that has no plan in the
ledger yet, each in a process of its own, and the analytic judging of each plan) and
returns the polygons of the posterior shape samples that the physics trials use. Each
plan's trials then run as fixed batches (``batch_size`` consecutive trials of one plan
and one shape source, in one freshly reset pybullet world), so which trials share a
world is fixed by the config, never by the number of workers.

Physics trial i on posterior samples uses shape sample i, approach deviates i and
friction deviate i of the analytic P_F's draws: every planner meets the same shapes and
the same noise, and a plan's trial i and its analytic draw i are the same situation.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from harness.config import ExperimentConfig
from harness.pipeline import TrialInputs
from harness.scene import load_scene

NO_PLAN = "no_plan"              # trial outcome when the plan gave nothing to execute
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
    """What a cell task returns: plan and analytic rows for the planners it ran, and the
    inputs of its posterior and true-shape trials (harness.pipeline.TrialInputs)."""

    scene: str
    realisation: int
    plans: list
    analytic: list
    posterior: TrialInputs
    truth: TrialInputs
    seconds: float


def run_cell(config: ExperimentConfig, path: str, realisation: int, labels: tuple[str, ...],
             plan_memory: float | None = None) -> CellResult:
    """Belief, plans of ``labels`` (each plan's process may grow by ``plan_memory``
    bytes), their analytic P_F, and the trials' shapes and noise, with one BLAS thread:
    the workers are the parallelism. On 2 cores, two workers with two BLAS threads each
    took 38.0-39.0 s for the 30 cells of make eval, one thread each 31.4-34.1 s (four runs
    each); the plans and shapes are bit for bit the same."""
    from harness.gpis import single_threaded_blas

    with single_threaded_blas():
        return _cell(config, path, realisation, labels, plan_memory)


def _cell(config: ExperimentConfig, path: str, realisation: int, labels: tuple[str, ...],
          plan_memory: float | None) -> CellResult:
    from harness import pipeline

    start = time.perf_counter()
    scene = scene_of(config, path)
    cell = pipeline.open_cell(scene, settings_of(config, path), config.seed, realisation,
                              pipeline.cell_draws(config.analytic_draws, config.posterior_trials))
    plans, analytic = [], []
    for entry in config.planners:
        if entry.label not in labels:
            continue
        row, _ = pipeline.plan(cell, entry.label, entry.name, entry.params, config.time_budget_s, plan_memory)
        plans.append(row)
        if row["executed"]:
            analytic.append(pipeline.analytic_row(cell, row, config.analytic_draws, config.posterior_trials))
    return CellResult(scene.name, realisation, plans, analytic,
                      pipeline.posterior_inputs(cell, config.posterior_trials, config.protocol().body_refinement),
                      pipeline.truth_inputs(scene, config.seed, realisation, config.truth_trials),
                      time.perf_counter() - start)


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
    """This thread's runner for ``protocol`` (its engine), kept between batches (a
    pybullet connect costs about 25 ms). One per thread, as a Dask worker may run tasks
    in several. Each batch starts from a reset world (pybullet) or from a model of its
    own per trial (MuJoCo), so its outcomes do not depend on what ran before (tested)."""
    from harness.physics.engines import make_runner
    from harness.physics.trial import MAX_BATCH

    runners = _THREAD.__dict__.setdefault("runners", {})
    if protocol not in runners:
        runners[protocol] = make_runner(protocol, batch_size=MAX_BATCH)
    return runners[protocol]


def run_batch(config: ExperimentConfig, batch: Batch) -> list[dict]:
    """The trials of one batch in the config's engine; rows for the ledger."""
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
            part = (cell.posterior if shapes == "posterior" else cell.truth).part(slice(indices[0], indices[-1] + 1))
            batches.append(replace(key, polygons=part.polygons, approach=part.approach, friction=part.friction))
    return batches, rows
