"""Which verdicts survive a change of simulator (``gpis-harness bench engines``).

make eval's experiment (experiments/default.toml) runs once per engine, into
``OUT/pybullet`` and ``OUT/mujoco`` (each resumable, like eval). The two runs differ in
the engine alone, so every plan, shape sample, approach draw and friction draw is the
same, and trial i of a plan in one run is trial i of it in the other
(:func:`harness.compare.check_engines_only`). The study sets the runs side by side:

- per cell (scene, planner, shape source) success in each engine and the rms of the
  differences; each planner's pooled success in each;
- the planners' ranking per scene and pooled, and Kendall's tau between the engines;
- every pooled paired comparison of the default report, under each engine: its sign,
  whether its 95 % interval excludes 0, whether the two intervals overlap;
- the analytic P_F's and P_L's Spearman and Brier against each engine's success;
- trial by trial: the share of equal outcomes and the cross-table of outcomes;
- the lift model's bar sweeps (``bench lift``) in each engine;
- frames and traces from both engines of a few trials on which they disagree.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from harness.bench.common import jsonable
from harness.protocol import ENGINES

#: make eval's experiment.
CONFIG = "experiments/default.toml"
#: Trials on which the engines disagree whose frames the study writes, per direction.
FRAMED = 2


@dataclass(frozen=True)
class Settings:
    """The folder of the two runs, their frames and study.json; worker processes per run
    (None: one per core)."""

    out: Path = Path("results/engines")
    workers: int | None = None


def benchmark(settings: Settings = Settings(), log=print) -> dict:
    """Run (or resume) make eval's experiment in each engine and set them side by side."""
    return run(out=Path(settings.out), workers=settings.workers, log=log)


def run(config_path: str = CONFIG, out: Path = Path("results/engines"), workers: int | None = None,
        lift_trials: int = 16, log=print) -> dict:
    """Run (or resume) the experiment in each engine, then :func:`study`."""
    from harness.config import load_config
    from harness.experiment import run_experiment
    from harness.memory import check_config
    from harness.outputs import command_line, folder_lock, output_folder
    from harness.report import write_report

    config = load_config(config_path)
    workers = workers or os.cpu_count() or 1
    folders = {}
    for engine in ENGINES:
        folder = output_folder(Path(out) / engine)
        engine_config = config.with_engine(engine)
        plan_memory = check_config(engine_config, workers, None)
        with folder_lock(folder, command_line()):
            stats = run_experiment(engine_config, folder, workers=workers, log=log, plan_memory=plan_memory)
            if stats.interrupted:
                raise KeyboardInterrupt
            log(f"{engine}: {stats.plans} plans and {stats.trials} trials in {stats.seconds:.0f} s")
            write_report(folder, figures=True)
        folders[engine] = folder
    result = study(folders[ENGINES[0]], folders[ENGINES[1]], frames=Path(out) / "frames")
    from harness.bench.lift_study import validate

    result["lift"] = {engine: validate(trials=lift_trials, engine=engine) for engine in ENGINES}
    (Path(out) / "study.json").write_text(json.dumps(result, indent=1, default=jsonable) + "\n")
    return result


def study(dir_a: Path, dir_b: Path, frames: Path | None = None) -> dict:
    """The agreement of two runs that differ in the engine alone (A: pybullet, B: MuJoCo)."""
    from harness.compare import compare
    from harness.report import ALL, calibration, comparisons, engine_of, load, summary

    paired = compare(dir_a, dir_b, engines=True)  # refuses runs that differ in more than the engine
    a, b = load(Path(dir_a)), load(Path(dir_b))
    names = [engine_of(a)["name"], engine_of(b)["name"]]
    sa, sb = summary(a), summary(b)
    both = sa.merge(sb, on=["scene", "planner"], suffixes=("_a", "_b"))
    cells = both[both.scene != ALL]
    rms = {shapes: float(np.sqrt(((cells[f"{col}_a"] - cells[f"{col}_b"]) ** 2).mean()))
           for shapes, col in (("posterior", "success_rate"), ("truth", "truth_success_rate"))}
    pooled = both[both.scene == ALL]
    planners = [{"planner": r.planner, "posterior": [r.success_rate_a, r.success_rate_b],
                 "truth": [r.truth_success_rate_a, r.truth_success_rate_b],
                 "posterior_ci": [[r.success_ci_low_a, r.success_ci_high_a], [r.success_ci_low_b, r.success_ci_high_b]]}
                for r in pooled.itertuples()]
    ranking = {}
    for scene, g in both.groupby("scene", sort=False):
        tau = stats.kendalltau(g.success_rate_a, g.success_rate_b).statistic
        ranking[scene] = {"tau": None if tau is None or math.isnan(tau) else float(tau),
                          "order": [list(g.sort_values(f"success_rate_{k}", ascending=False, kind="stable").planner)
                                    for k in "ab"]}
    taus = [v["tau"] for s, v in ranking.items() if s != ALL and v["tau"] is not None]
    ca, cb = (comparisons(x, seed=int(x["config"]["seed"])) for x in (a, b))
    keys = ["scene", "shapes", "planner", "versus"]
    cmp = ca.merge(cb, on=keys, suffixes=("_a", "_b"))
    cmp = cmp[cmp.scene == ALL]
    # Whether the intervals overlap is no test of a change (the runs are paired trial by
    # trial); compare's planner shifts are: the change of each difference from A to B, with
    # its paired bootstrap interval.
    shifts = paired["planner_shifts"].set_index(["planner", "versus", "shapes"])
    verdicts = []
    for r in cmp.itertuples():
        sig = [_verdict(r.ci_low_a, r.ci_high_a), _verdict(r.ci_low_b, r.ci_high_b)]
        key = (r.planner, r.versus, r.shapes)
        shift = shifts.loc[key] if key in shifts.index else None
        verdicts.append({"planner": r.planner, "versus": r.versus, "shapes": r.shapes,
                         "difference": [r.difference_a, r.difference_b],
                         "ci": [[r.ci_low_a, r.ci_high_a], [r.ci_low_b, r.ci_high_b]],
                         "verdict": sig, "same_sign": bool(np.sign(r.difference_a) == np.sign(r.difference_b)),
                         "same_verdict": sig[0] == sig[1],
                         "intervals_overlap": bool(r.ci_low_a <= r.ci_high_b and r.ci_low_b <= r.ci_high_a),
                         "shift": None if shift is None else float(shift["shift"]),
                         "shift_ci": None if shift is None else [float(shift["shift_ci_low"]),
                                                                 float(shift["shift_ci_high"])]})
    cal = {}
    for name, run in zip(names, (a, b)):
        table = calibration(run)[0]
        table = table[table.planner == ALL]
        cal[name] = {r.metric: {"spearman": r.spearman, "brier": r.brier, "mean_estimate": r.mean_estimate,
                                "success_rate": r.success_rate, "plans": r.plans} for r in table.itertuples()}
    trials = a["trials"][["scene", "realisation", "planner", "shapes", "trial", "outcome"]].merge(
        b["trials"][["scene", "realisation", "planner", "shapes", "trial", "outcome"]],
        on=["scene", "realisation", "planner", "shapes", "trial"], suffixes=("_a", "_b"))
    agreement = {shapes: float((g.outcome_a == g.outcome_b).mean()) for shapes, g in trials.groupby("shapes")}
    agreement["all"] = float((trials.outcome_a == trials.outcome_b).mean())
    success = {shapes: float(((g.outcome_a == "success") == (g.outcome_b == "success")).mean())
               for shapes, g in trials.groupby("shapes")}
    result = {
        "engines": names, "versions": [engine_of(a)["version"], engine_of(b)["version"]],
        "dirs": [str(dir_a), str(dir_b)], "trials": len(trials),
        "identical_plans": {"paired": sum(v["plans"] for v in paired["plans"].values()),
                            "same": sum(v["identical"] for v in paired["plans"].values())},
        "cells": [{"scene": r.scene, "planner": r.planner, "posterior": [r.success_rate_a, r.success_rate_b],
                   "truth": [r.truth_success_rate_a, r.truth_success_rate_b]} for r in cells.itertuples()],
        "cell_rms": rms, "planners": planners, "ranking": ranking,
        "kendall_tau_per_scene": {"mean": float(np.mean(taus)) if taus else None, "min": min(taus) if taus else None,
                                  "scenes": len(taus)},
        "comparisons": verdicts, "calibration": cal,
        "trial_agreement": agreement, "success_agreement": success,
        "outcomes": {"rows": names[0], "columns": names[1],
                     "table": pd.crosstab(trials.outcome_a, trials.outcome_b).to_dict(orient="index")},
    }
    if frames is not None:
        result["frames"] = write_frames(trials, a, frames)
    return result


def _verdict(lo: float, hi: float) -> str:
    """'+' or '-' when the interval excludes 0 on that side, '0' when it holds 0."""
    return "+" if lo > 0 else "-" if hi < 0 else "0"


def write_frames(trials: pd.DataFrame, run: dict, folder: Path, count: int = FRAMED) -> list[dict]:
    """Frames and traces (trace.csv, harness.physics.trace) from both engines of the first
    ``count`` posterior trials held in one engine and lost in the other (each way): the
    trial rebuilt from the run's config and plan exactly as eval ran it (harness.pipeline)."""
    from harness import pipeline
    from harness.config import ExperimentConfig
    from harness.physics.simulate import make_trials
    from harness.physics.engines import make_runner
    from harness.physics.trace import Tracer
    from harness.protocol import Protocol
    from harness.scene import load_scene
    from harness.settings import resolve

    config = ExperimentConfig.from_dict(run["config"])
    paths = dict(zip(config.scene_names, config.scenes))
    plans = run["plans"].set_index(["scene", "realisation", "planner"])
    out = []
    for held_in in ("a", "b"):
        other = "b" if held_in == "a" else "a"
        picked = trials[(trials.shapes == "posterior") & (trials[f"outcome_{held_in}"] == "success")
                        & (trials[f"outcome_{other}"] != "success")].head(count)
        for r in picked.itertuples():
            scene = load_scene(paths[r.scene])
            settings = resolve(scene, config.settings, config.protocol())
            cell = pipeline.open_cell(scene, settings, config.seed, r.realisation,
                                      pipeline.cell_draws(config.analytic_draws, config.posterior_trials))
            inputs = pipeline.posterior_inputs(cell, config.posterior_trials, config.protocol().body_refinement)
            inputs = inputs.part(slice(r.trial, r.trial + 1))
            grasp = pipeline.planned_grasp(plans.loc[(r.scene, r.realisation, r.planner)].to_dict())
            trial = make_trials(settings, grasp, inputs.polygons, inputs.approach, inputs.friction)
            where = Path(folder) / f"{r.scene}-r{r.realisation}-{r.planner}-posterior-{r.trial}"
            seen = {}
            for engine in ENGINES:
                tracer = Tracer()
                with make_runner(Protocol.of(engine)) as runner:
                    seen[engine] = runner.run(trial, frames=where / engine, trace=tracer)[0].as_dict()
                tracer.write(where / engine / "trace.csv")
            out.append({"trial": where.name, "folder": str(where), "recorded": [r.outcome_a, r.outcome_b],
                        "rerun": seen})
    return out


def format_lines(res: dict) -> list[str]:
    """The study as text: the tables of docs/physics.md, "Two engines"."""
    a, b = res["engines"]
    lines = [f"engines: {a} {res['versions'][0]} against {b} {res['versions'][1]}, {res['trials']} paired trials, "
             f"{res['identical_plans']['same']} of {res['identical_plans']['paired']} plans identical",
             f"per cell (scene x planner): rms difference in success {res['cell_rms']['posterior']:.3f} on posterior "
             f"samples, {res['cell_rms']['truth']:.3f} on the true shape",
             f"{'planner':<20} {'posterior ' + a:>18} {'posterior ' + b:>18} {'truth ' + a:>14} {'truth ' + b:>14}"]
    for p in res["planners"]:
        lines.append(f"{p['planner']:<20} {p['posterior'][0]:>18.3f} {p['posterior'][1]:>18.3f} "
                     f"{p['truth'][0]:>14.3f} {p['truth'][1]:>14.3f}")
    tau = res["kendall_tau_per_scene"]
    pooled = res["ranking"].get("all", {})
    lines.append(f"ranking (posterior success): Kendall's tau pooled {_num(pooled.get('tau'))}; per scene mean "
                 f"{_num(tau['mean'])}, min {_num(tau['min'])} over {tau['scenes']} scenes")
    lines.append(f"pooled order in {a}: {' > '.join(pooled.get('order', [[]])[0])}")
    lines.append(f"pooled order in {b}: {' > '.join(pooled.get('order', [[], []])[1])}")
    lines.append(f"paired comparisons (pooled over scenes): difference [95% CI] in {a} | in {b}; verdict")
    for c in res["comparisons"]:
        (da, db), ((la, ha), (lb, hb)) = c["difference"], c["ci"]
        mark = ("same verdict" if c["same_verdict"] else "verdict changes") + (
            "" if c["intervals_overlap"] else ", intervals apart")
        if c.get("shift") is not None:
            (sl, sh) = c["shift_ci"]
            mark += f"; change {c['shift']:+.3f} [{sl:+.3f}, {sh:+.3f}] (paired)"
        lines.append(f"  {c['planner']} vs {c['versus']} ({c['shapes']}): {da:+.3f} [{la:+.3f}, {ha:+.3f}] | "
                     f"{db:+.3f} [{lb:+.3f}, {hb:+.3f}]; {mark}")
    for name, cal in res["calibration"].items():
        lines.append(f"{name}: " + "; ".join(f"{m.upper()} Spearman {_num(v['spearman'])}, Brier {v['brier']:.3f}, "
                                             f"mean {v['mean_estimate']:.3f} against success {v['success_rate']:.3f}"
                                             for m, v in cal.items()))
    ag = res["trial_agreement"]
    lines.append(f"trial by trial: same outcome {ag['all']:.3f} (posterior {ag.get('posterior', math.nan):.3f}, "
                 f"true shape {ag.get('truth', math.nan):.3f}); same success or failure "
                 + ", ".join(f"{k} {v:.3f}" for k, v in res["success_agreement"].items()))
    table = pd.DataFrame(res["outcomes"]["table"]).T.fillna(0).astype(int)
    lines.append(f"outcomes (rows {a}, columns {b}):")
    lines += ["  " + line for line in table.to_string().splitlines()]
    for f in res.get("frames", []):
        lines.append(f"frames of {f['trial']}: recorded {f['recorded'][0]} / {f['recorded'][1]}, in {f['folder']}")
    if "lift" in res:
        from harness.bench.lift_study import _bar_lines

        for name, lift in res["lift"].items():
            lines += ["", f"the lift model's bars in {name}:", *_bar_lines(lift)]
    return lines


def _num(v) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.3f}"
