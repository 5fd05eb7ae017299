"""Each posterior trial beside the lift model's view of its own draw (``gpis-harness
report DIR --draws`` writes it to ``draws.csv``): why P_L said what it did about the
trial that the physics then ran.

Posterior trial i of a plan runs on evaluation draw i of its cell: shape sample i,
approach deviates i, friction deviate i (harness.pipeline). The ledger keeps each
trial's verdict (the analytic rows' ``reasons``) but not the model's quantities behind
it, so this module opens each cell again exactly as the experiment opened it (the same
seed, realisation, settings and number of draws, :func:`harness.pipeline.cell_draws`:
the GP's shape samples depend on how many are drawn) and judges each executed plan on
the first posterior-trials draws with the lift model's quantities kept
(:data:`harness.quality.LIFT_INPUTS`) and how the plates settled it on the table
(:data:`harness.quality.SETTLE_INPUTS`, ``settled`` as its name). Every row's verdict is checked against the one
the ledger recorded during the run (runs recorded before the ledger kept verdicts are
not checked); a mismatch (a scene file changed since the run, another version of the
model, or, from a script, numeric code paths other than the run's: a draw on a knife
edge follows the last bit of the shape sampler's products) is refused, not written, with
the cause named when it is the code paths.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from harness.errors import InputError

#: The table's columns before the lift model's quantities (harness.quality.LIFT_INPUTS).
KEYS = ("scene", "realisation", "planner", "trial", "outcome", "pivot", "verdict")


def trial_draws(out_dir: Path, data: dict | None = None) -> pd.DataFrame:
    """One row per posterior trial of the latest experiment in ``out_dir``: its keys, its
    outcome and the angle it turned in the gripper (``pivot``, rad), its draw's verdict
    (harness.pipeline.verdict_label), the lift model's quantities on that draw (NaN
    where the plates were not in force closure) and how the plates settled it (the push's
    and the squeeze's turns, the slide, and ``settled``: one of harness.quality.SETTLED).
    Raises InputError when a verdict recomputed here is not the one the ledger recorded."""
    from harness import pipeline
    from harness.config import ExperimentConfig
    from harness.gpis import single_threaded_blas
    from harness.quality import LIFT_INPUTS, SETTLE_INPUTS, SETTLED, evaluate_draws
    from harness.report import load
    from harness.tasks import scene_of, settings_of

    data = data if data is not None else load(out_dir)
    config = ExperimentConfig.from_dict(data["config"])
    paths = dict(zip(config.scene_names, config.scenes))
    trials = data["trials"]
    post = trials[trials.shapes == "posterior"].set_index(["scene", "realisation", "planner", "trial"]).sort_index()
    recorded = data["analytic"].set_index(["scene", "realisation", "planner"])["reasons"]
    plans = data["plans"]
    plans = plans[plans.executed.astype(bool)]
    n = config.posterior_trials
    rows = []
    for (name, realisation), cell_plans in plans.groupby(["scene", "realisation"], sort=True):
        path = paths.get(name)
        if path is None or not Path(path).is_file():
            raise InputError(str(out_dir), "config.scenes",
                             f"scene '{name}' is not at {path}: cannot draw its cell again")
        settings = settings_of(config, path)
        cell = pipeline.open_cell(scene_of(config, path), settings, config.seed, int(realisation),
                                  pipeline.cell_draws(config.analytic_draws, n))
        draws = cell.draws.first(n)
        for plan in cell_plans.to_dict("records"):
            with single_threaded_blas():  # as eval judged it (harness.pipeline.judge)
                out = evaluate_draws(pipeline.planned_grasp(plan), draws, settings, lift_inputs=True)
            verdicts = [pipeline.verdict_label(r, t) for r, t in zip(out.reason[0], out.pivots[0])]
            key = (name, realisation, plan["planner"])
            ledger = recorded.get(key)
            ledger = ledger.split(",") if isinstance(ledger, str) and ledger else []  # older ledgers: none
            if ledger and _reasons(verdicts[:len(ledger)]) != _reasons(ledger):
                raise InputError(str(out_dir), "analytic.reasons",
                                 f"{name} realisation {realisation} {plan['planner']}: the verdicts drawn again "
                                 f"differ from the ledger's ({_why_different(data)})")
            for k in range(n):
                trial = post.loc[key + (k,)] if key + (k,) in post.index else None
                rows.append((name, realisation, plan["planner"], k,
                             None if trial is None else trial.outcome, np.nan if trial is None else trial.pivot,
                             verdicts[k], *(float(out.lift_inputs[q][0, k]) for q in LIFT_INPUTS),
                             *(float(out.lift_inputs[q][0, k]) for q in SETTLE_INPUTS[:-1]),
                             SETTLED[int(out.lift_inputs["settled"][0, k])]))
    return pd.DataFrame(rows, columns=[*KEYS, *LIFT_INPUTS, *SETTLE_INPUTS])


def _why_different(data: dict) -> str:
    """Why a cell drawn again may judge a draw otherwise than the run did: the run's
    numeric code paths (harness.provenance.CODE_PATHS, recorded in its environment) when
    this process's differ (a draw on a knife edge follows the last bit of the shape
    sampler's products), else a changed scene file or model."""
    from harness.provenance import CODE_PATHS

    recorded = (data.get("environment", {}).get("reproducibility") or {}).get("code_paths")
    here = {name: os.environ.get(name) for name in CODE_PATHS}
    if recorded is not None and recorded != here:
        return (f"the run's numeric code paths were {recorded}, this process's are {here}: set them before "
                "numpy is imported, as the gpis-harness command does (docs/experiments.md, 'Pinned code paths')")
    return "a scene or the model changed since the run"


def _reasons(labels: list[str]) -> list[str]:
    """Verdicts as ledgers written before the 'lifted_turned' label recorded them."""
    return ["lifted" if v == "lifted_turned" else v for v in labels]


def write_draws(out_dir: Path) -> Path:
    """``draws.csv`` in ``out_dir`` (:func:`trial_draws`), written atomically."""
    from harness.outputs import write_atomic

    table = trial_draws(out_dir)
    return write_atomic(Path(out_dir) / "draws.csv", lambda tmp: table.to_csv(tmp, index=False))
