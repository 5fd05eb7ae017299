"""Experiments: a config's cells and batches run (or resumed) into an output folder's
ledger. The config is validated in harness.config, the tasks are harness.tasks; this is
the main loop, the only writer of the ledger.
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from harness.config import ExperimentConfig
from harness.errors import InputError
from harness.manifest import environment
from harness.tasks import batches_of, run_batch, run_cell, settings_of


@dataclass
class RunStats:
    plans: int = 0
    trials: int = 0
    seconds: float = 0.0
    interrupted: bool = False
    errors: list = field(default_factory=list)


def run_experiment(config: ExperimentConfig, out_dir: Path, workers: int | None = None,
                   scheduler: str | None = None, fresh: bool = False, log=print,
                   plan_memory: float | None = None) -> RunStats:
    """Run (or resume) an experiment into ``out_dir``'s ledger; each plan's process may
    grow by ``plan_memory`` bytes (harness.memory). The caller holds the folder's lock
    (harness.outputs.folder_lock)."""
    from harness.executor import make_executor
    from harness.ledger import FILENAME, Ledger

    out_dir.mkdir(parents=True, exist_ok=True)
    stats = RunStats()
    start = time.perf_counter()
    key = config.hash
    executor = make_executor(workers, scheduler)  # before the run is recorded: a failed connection leaves no trace
    status = "interrupted"
    try:
        with Ledger(out_dir / FILENAME) as ledger:
            if fresh:
                ledger.forget(key)
            _check_planners(ledger, config, out_dir)
            run = ledger.start_run(key, config.name, config.as_dict(), environment())
            try:
                todo, counts = _work_left(ledger, config)
                n_plans, n_trials, done_plans, done_trials = counts
                per_plan = config.posterior_trials + config.truth_trials
                log(f"{config.name}: {len(config.scenes)} scenes x {config.realisations} realisations x "
                    f"{len(config.planners)} planners, {per_plan} trials per plan; config {key}; "
                    f"{executor.description}"
                    + (f"; resuming with {done_plans} plans and {done_trials} trials done"
                       if done_plans or done_trials else ""))
                bars = [_Progress("plans", n_plans, done_plans, 0, start, log),
                        _Progress("trials", n_trials, done_trials, 1, start, log)]
                try:
                    _drive(config, ledger, executor, todo, stats, bars, plan_memory)
                    status = "complete" if not stats.errors else "errors"
                except KeyboardInterrupt:
                    stats.interrupted = True
                finally:
                    for bar in bars:
                        bar.close()
            finally:
                try:
                    ledger.end_run(run, status)
                except sqlite3.Error:
                    if status != "interrupted":
                        raise  # the run finished but its end cannot be recorded: say so
                    # else the error that stopped the run (a full disk, say) is the one reported
    finally:
        executor.close(cancel=status == "interrupted")
    stats.seconds = time.perf_counter() - start
    for error in stats.errors:
        log(f"task failed: {error}")
    return stats


def adopt_plans(config: ExperimentConfig, out_dir: Path, source: ExperimentConfig, source_dir: Path) -> int:
    """Record in ``out_dir``'s ledger, under ``config``'s hash, the plans and their analytic
    rows that ``source_dir``'s ledger holds for ``source``, the same experiment in another
    engine; a run of ``config`` then resumes with them planned and simulates their trials
    only. A plan does not depend on the engine: planners never simulate, the analytic draws
    come from the seed alone, and each scene's grasp settings (the lift's protocol
    included) are checked to be the same in both, so these are the plans ``config`` would
    make (``bench engines`` finds make eval's 180 plans identical when each engine plans
    them). Rows already recorded stay; an adopted plan's ``plan_time_s`` is the source
    run's. Returns how many plans were new to ``out_dir``'s ledger. ValueError when the
    experiments differ in anything but the engine."""
    from harness.ledger import FILENAME, Ledger

    if replace(source.with_engine(config.engine), name=config.name) != config:
        raise ValueError(f"{source.name} and {config.name} differ in more than the engine")
    for path in config.scenes:
        if settings_of(config, path) != settings_of(source, path):
            raise ValueError(f"{path}: the grasp settings differ between the engines' protocols")
    with Ledger(Path(source_dir) / FILENAME, create=False) as ledger:
        plans, analytic = ledger.rows(source.hash, "plans"), ledger.rows(source.hash, "analytic")
    if not plans:
        return 0
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    with Ledger(Path(out_dir) / FILENAME) as ledger:
        known = {(r["scene"], r["realisation"], r["planner"]) for r in ledger.rows(config.hash, "plans")}
        ledger.add(config.hash, {"plans": plans, "analytic": analytic})
    return sum((r["scene"], r["realisation"], r["planner"]) not in known for r in plans)


def _check_planners(ledger, config: ExperimentConfig, out_dir: Path) -> None:
    """A label already recorded in this experiment must name the same planner with the
    same parameters: its rows are reused as they are (InputError otherwise, before any work)."""
    recorded = ledger.planner_entries(config.hash)
    for entry in config.planners:
        mine = (entry.name, json.dumps(entry.params, sort_keys=True))
        other = sorted(recorded.get(entry.label, set()) - {mine})
        if other:
            name, params = other[0]
            raise InputError(str(out_dir), f"planners.{entry.label}",
                             f"recorded here as {name} with parameters {params}, the config gives {entry.name} "
                             f"with {mine[1]}: give the planner another label, or start over with --fresh")


def _work_left(ledger, config: ExperimentConfig) -> tuple[list, tuple[int, int, int, int]]:
    """Cells with work left, as (path, realisation, labels to plan, plans already done,
    trials done), and the counts (plans, trials, plans done, trials done)."""
    key = config.hash
    todo = []
    n_plans = n_trials = done_plans = done_trials = 0
    per_plan = config.posterior_trials + config.truth_trials
    mine = {e.label for e in config.planners}  # rows of planners no longer in the config stay, unused
    for path, name, r in config.cells():
        plans = {label: row for label, row in ledger.plan_rows(key, name, r).items() if label in mine}
        trials = {t for t in ledger.done_trials(key, name, r) if t[0] in mine}
        labels = tuple(e.label for e in config.planners if e.label not in plans)
        n_plans += len(config.planners)
        n_trials += len(config.planners) * per_plan
        done_plans += len(config.planners) - len(labels)
        done_trials += len(trials)
        if labels or len(trials) < len(config.planners) * per_plan:
            todo.append((path, r, labels, plans, trials))
    return todo, (n_plans, n_trials, done_plans, done_trials)


def _drive(config: ExperimentConfig, ledger, executor, todo: list, stats: RunStats, bars: list,
           plan_memory: float | None) -> None:
    """Submit the cells, then each plan's batches as its cell returns; record every result."""
    key = config.hash
    for path, r, labels, _, _ in todo:
        executor.submit(run_cell, config, path, r, labels, plan_memory, tag=("cell", path, r))
    known = {(path, r): (plans, trials) for path, r, _, plans, trials in todo}
    while executor.pending:
        tag, future = executor.next_done()
        try:
            result = future.result()
        except Exception as exc:  # noqa: BLE001 - a task's failure is logged, the run goes on
            stats.errors.append(f"{tag[0]} {tag[1:]}: {type(exc).__name__}: {exc}")
            continue
        if tag[0] == "cell":
            _, path, r = tag
            plans, done = known[(path, r)]
            ledger.add(key, {"plans": result.plans, "analytic": result.analytic})
            stats.plans += len(result.plans)
            bars[0].update(len(result.plans))
            for row in list(plans.values()) + result.plans:
                batches, rows = batches_of(config, path, result, row, done)
                if rows:
                    ledger.add(key, {"trials": rows})
                    bars[1].update(len(rows))
                for batch in batches:
                    executor.submit(run_batch, config, batch, tag=("batch", len(batch.indices)))
        else:
            ledger.add(key, {"trials": result})
            stats.trials += len(result)
            bars[1].update(len(result))


class _Progress:
    """A tqdm bar on a terminal (counts, rate, time left); without one, a line when the
    phase completes."""

    def __init__(self, desc: str, total: int, initial: int, position: int, start: float, log):
        from tqdm import tqdm

        self.desc, self.total, self.n, self.start, self.log = desc, total, initial, start, log
        self.bar = tqdm(total=total, initial=initial, desc=desc, unit=desc[:-1], disable=None, position=position,
                        dynamic_ncols=True, smoothing=0.1)

    def update(self, n: int) -> None:
        self.n += n
        self.bar.update(n)
        if self.bar.disable and n and self.n >= self.total:
            self.log(f"{self.desc}: {self.n}/{self.total} done after {time.perf_counter() - self.start:.0f} s")

    def close(self) -> None:
        self.bar.close()
