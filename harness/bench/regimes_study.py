"""P_L and the planners across physical regimes (``gpis-harness bench regimes``).

A regime is one physical setting: the gripper's force limit, the jaws' friction, the
approach noise, and the objects' size and density. The sweep runs one experiment per
regime (the planners of make eval, on the procedural objects of
:mod:`harness.bench.regime_objects`), each an ordinary, resumable eval run in
``OUT/ENGINE/REGIME`` whose scenes are files written to ``OUT/objects``, and reports per
regime: the analytic P_F's and P_L's Spearman (over plans), Brier (over trials) and mean
estimate against physical success; each planner's pooled success; the paired
differences of the lift planners against mean-shape-lift.

The regimes are one axis at a time around a centre (the library's gripper and friction,
medium objects), from a weak gripper (5 N) to a strong one (40 N), slippery jaws (0.2)
to grippy ones (0.8), precise approaches (1 mm) to noisy ones (5 mm), small light
objects to large heavy ones; and two regimes that mix the axes at values the others do
not use, held out. One object in four of each family is held out too. Held-out objects
and regimes are never looked at while the lift model is changed (docs/lift.md); the
tables report them apart ('design': design objects in design regimes; 'held_out': the
held-out objects in every regime, and every object in the held-out regimes).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from harness.bench.common import jsonable
from harness.bench.regime_objects import objects as regime_objects

#: Trials per plan and analytic draws. 24 objects x 24 posterior trials give 576 trials
#: per planner and regime (a Wilson interval of about +-0.03 at 0.85); the paired
#: differences are narrower. 500 draws put the analytic estimates' own standard error
#: below 0.023, small against their spread across plans.
POSTERIOR_TRIALS = 24
TRUTH_TRIALS = 8
ANALYTIC_DRAWS = 500
#: Per plan: a cap, not a target. A plan that stops at its budget (status 'budget')
#: depends on how fast the machine ran it. On this 2-core machine the sweep's longest plan
#: took 20.3 s with little beside it, but 5 of its 1,584 plans stopped at a 30 s budget
#: when it ran beside other jobs (gp-p-lift, 31-34 s; docs/lift.md, "Across regimes").
TIME_BUDGET_S = 120.0
#: "Success varies" in a regime when at least this share of its plans succeed on fewer
#: than SUCCESS_VARIES_BELOW of their posterior trials (below it, every planner nearly
#: always succeeds and a ranking of plans has little to rank).
VARIES_SHARE = 0.1
SUCCESS_VARIES_BELOW = 0.9
#: The targets of P_L (issue "P_L and the planners across physical regimes").
SPEARMAN_TARGET = 0.7
BRIER_TARGET = 0.10
BASELINE_LIFT = "mean-shape-lift"
LIFT_PLANNERS = ("gp-gpis-opt-lift", "gp-p-lift")


@dataclass(frozen=True)
class Regime:
    """A physical setting of the sweep."""

    name: str
    force: float       # N, each jaw's force limit (gripper.force)
    friction: float    # jaw-object Coulomb friction
    sigma_g: float     # m, approach noise per jaw start
    size: float        # m, the objects' longest extent
    density: float     # kg/m^3
    held_out: bool = False

    @property
    def objects_key(self) -> str:
        return f"{100 * self.size:g}cm-{self.density:g}"


#: The centre: the library's gripper, friction and approach noise; objects of 11 cm at
#: 1000 kg/m^3 (33-180 g; the library holds 50-450 g).
CENTRE = Regime("centre", 20.0, 0.5, 0.0025, 0.11, 1000.0)
REGIMES = (
    CENTRE,
    Regime("weak", 5.0, 0.5, 0.0025, 0.11, 1000.0),
    Regime("strong", 40.0, 0.5, 0.0025, 0.11, 1000.0),
    Regime("slippery", 20.0, 0.2, 0.0025, 0.11, 1000.0),
    Regime("grippy", 20.0, 0.8, 0.0025, 0.11, 1000.0),
    Regime("precise", 20.0, 0.5, 0.001, 0.11, 1000.0),
    Regime("noisy", 20.0, 0.5, 0.005, 0.11, 1000.0),
    Regime("small-light", 20.0, 0.5, 0.0025, 0.08, 400.0),     # 5-28 g
    Regime("large-heavy", 20.0, 0.5, 0.0025, 0.15, 2000.0),    # 170-910 g
    # Held out: the axes mixed, at values no design regime uses.
    Regime("weak-slippery-noisy", 8.0, 0.3, 0.004, 0.11, 1000.0, held_out=True),
    Regime("firm-heavy", 30.0, 0.65, 0.0015, 0.13, 1500.0, held_out=True),
)


def regime_config(regime: Regime, scenes: list[Path], engine: str = "pybullet", planners: list | None = None,
                  posterior_trials: int = POSTERIOR_TRIALS, truth_trials: int = TRUTH_TRIALS,
                  analytic_draws: int = ANALYTIC_DRAWS) -> dict:
    """The experiment config (as a parsed TOML document) of one regime."""
    doc = {"name": f"regime-{regime.name}", "seed": 0, "scenes": [str(s) for s in scenes], "realisations": 1,
           "evaluation": {"analytic_draws": analytic_draws, "posterior_trials": posterior_trials,
                          "truth_trials": truth_trials, "sigma_g": regime.sigma_g, "friction": regime.friction,
                          "time_budget_s": TIME_BUDGET_S},
           "gripper": {"force": regime.force},
           "planners": planners if planners is not None else _default_planners()}
    if engine != "pybullet":
        doc["physics"] = {"engine": engine}
    return doc


def _default_planners() -> list:
    """make eval's planners (experiments/default.toml)."""
    import tomllib

    with open(Path(__file__).resolve().parents[2] / "experiments" / "default.toml", "rb") as f:
        return tomllib.load(f)["planners"]


def write_objects(out: Path, regimes=REGIMES, objects=None) -> dict[str, list[Path]]:
    """Write each object's scene file at each (size, density) the regimes use; returns
    the paths per objects_key."""
    written = {}
    for regime in regimes:
        if regime.objects_key in written:
            continue
        folder = Path(out) / "objects" / regime.objects_key
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for obj in objects or regime_objects():
            path = folder / f"{obj.name}.toml"
            text = obj.scene_text(regime.size, regime.density)
            if not path.exists() or path.read_text() != text:
                path.write_text(text)
            paths.append(path)
        written[regime.objects_key] = paths
    return written


@dataclass(frozen=True)
class Settings:
    """The folder of the runs, objects and tables (None: :func:`default_folder` of the
    object set); the engines; worker processes per run (None: one per core); a Dask
    scheduler (None: local processes); the object set
    (:data:`~harness.bench.regime_objects.OBJECT_SETS`: 'sweep', the 24 objects the model
    and planners were settled on, six of them held out; 'fresh', 24 others of the same
    families, all held out); the names of the regimes to run (None: every one of
    :data:`REGIMES`)."""

    out: Path | None = None
    engines: tuple = ("pybullet",)
    workers: int | None = None
    scheduler: str | None = None
    objects: str = "sweep"
    regimes: tuple | None = None


def default_folder(object_set: str) -> Path:
    """Each object set's own folder (their runs differ in their scenes, so they never share
    a ledger): results/regimes for the sweep, results/regimes-NAME for another set."""
    return Path("results/regimes" if object_set == "sweep" else f"results/regimes-{object_set}")


def benchmark(settings: Settings = Settings(), log=print) -> dict:
    """Run (or resume) every regime in each engine, then :func:`study`."""
    from harness.bench.regime_objects import OBJECT_SETS

    out = Path(settings.out) if settings.out is not None else default_folder(settings.objects)
    regimes = REGIMES if settings.regimes is None else regimes_named(settings.regimes)
    result = run(out=out, engines=settings.engines, workers=settings.workers, scheduler=settings.scheduler,
                 regimes=regimes, objects=OBJECT_SETS[settings.objects](), log=log)
    return {**result, "object_set": settings.objects}


def regimes_named(names) -> tuple:
    """The regimes of :data:`REGIMES` with these names, in the sweep's order (a part of
    the sweep: each regime's run is the one the whole sweep makes, so a later run of every
    regime into the same folder resumes it). Raises ValueError naming the unknown ones."""
    names = set(names)
    unknown = sorted(names - {r.name for r in REGIMES})
    known = ", ".join(r.name for r in REGIMES)
    if not names:
        raise ValueError(f"no regime given; the sweep's are {known}")
    if unknown:
        raise ValueError(f"unknown regime{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                         f"the sweep's are {known}")
    return tuple(r for r in REGIMES if r.name in names)


def run(out: Path = default_folder("sweep"), engines=("pybullet",), workers: int | None = None,
        scheduler: str | None = None, regimes=REGIMES, objects=None, planners: list | None = None,
        posterior_trials: int = POSTERIOR_TRIALS, truth_trials: int = TRUTH_TRIALS,
        analytic_draws: int = ANALYTIC_DRAWS, log=print) -> dict:
    """Run (or resume) every regime's experiment in each engine, then :func:`study`.
    ``objects``: the sweep's objects (default :func:`regime_objects.objects`). The engines
    after the first adopt the plans the first made of each regime
    (:func:`harness.experiment.adopt_plans`: the same plans, made once) and simulate them."""
    from harness.config import parse_config
    from harness.experiment import adopt_plans, run_experiment
    from harness.ledger import FILENAME
    from harness.memory import check_config
    from harness.outputs import command_line, folder_lock, output_folder
    from harness.report import write_report

    out = Path(out)
    objects = objects or regime_objects()
    scenes = write_objects(out, regimes, objects)
    workers = workers or os.cpu_count() or 1  # as eval: the local pool's, or the cluster's memory check
    for engine in engines:
        for regime in regimes:
            folder = output_folder(out / engine / regime.name)
            doc = regime_config(regime, scenes[regime.objects_key], engine, planners, posterior_trials,
                                truth_trials, analytic_draws)
            config = parse_config(doc, source=f"bench regimes: {regime.name}", base_dir=out,
                                  default_name=doc["name"])
            plan_memory = check_config(config, workers, None)
            with folder_lock(folder, command_line()):
                first = out / engines[0] / regime.name
                if engine != engines[0] and (first / FILENAME).is_file():
                    # The regime's plans, made in the first engine, are this engine's too.
                    source = replace(config.with_engine(engines[0]), name=config.name)
                    adopted = adopt_plans(config, folder, source, first)
                    if adopted:
                        log(f"{engine} {regime.name}: {adopted} plans of the {engines[0]} run adopted")
                stats = run_experiment(config, folder, workers=workers, scheduler=scheduler, log=log,
                                       plan_memory=plan_memory)
                if stats.interrupted:
                    raise KeyboardInterrupt
                log(f"{engine} {regime.name}: {stats.plans} plans and {stats.trials} trials in {stats.seconds:.0f} s")
                write_report(folder, figures=False)
    result = study(out, engines, regimes, objects)
    (out / "regimes.json").write_text(json.dumps(result, indent=1, default=jsonable) + "\n")
    rows = pd.DataFrame(result["rows"])
    rows.to_csv(out / "regimes.csv", index=False)
    pd.DataFrame(result["verdicts"]).to_csv(out / "verdicts.csv", index=False)
    result["figure"] = str(regime_map(rows, out / "regime_map.png"))
    return result


def study(out: Path, engines=("pybullet",), regimes=REGIMES, objects=None) -> dict:
    """Per engine, regime and part (design, held_out, all): the calibration of P_F and
    P_L, each planner's success and the lift planners' paired differences; three
    yardsticks for P_L, the Brier score's floor (:func:`brier_floor`), the Spearman the
    trials measured again would reach (:func:`harness.report.retest_spearman`) and,
    with two engines, the other engine's success per plan as the estimate
    (:func:`engine_yardstick`); per verdict of the model on each posterior trial's own
    draw, how often the physics succeeded (:func:`verdict_rows`); and the differences
    pooled over the sweep."""
    from harness.report import load, restricted

    objects = objects or regime_objects()
    held = {o.name for o in objects if o.held_out}
    rows, verdicts, pooled = [], [], {}
    loaded = {(engine, regime.name): load(Path(out) / engine / regime.name)
              for engine in engines for regime in regimes}
    for engine in engines:
        runs = {}
        for regime in regimes:
            data = loaded[engine, regime.name]
            runs[regime.name] = data
            names = sorted(data["plans"].scene.unique())
            parts = {"all": names}
            if regime.held_out:
                parts["held_out"] = names
            else:
                parts["design"] = [n for n in names if n not in held]
                parts["held_out"] = [n for n in names if n in held]
            for part, scenes in parts.items():
                if not scenes:
                    continue
                row = {"engine": engine, "regime": regime.name, "part": part, "regime_held_out": regime.held_out,
                       **_regime_row(data, scenes)}
                others = [e for e in engines if e != engine]
                if others:  # the first other engine's physics as the estimate
                    mine, theirs = (restricted(loaded[e, regime.name], scenes) for e in (engine, others[0]))
                    row.update(engine_yardstick(mine["trials"][mine["trials"].shapes == "posterior"],
                                                theirs["trials"][theirs["trials"].shapes == "posterior"],
                                                mine["plans"], theirs["plans"]))
                rows.append({**row, **{k: v for k, v in asdict(regime).items() if k not in ("name", "held_out")}})
                verdicts.extend({"engine": engine, "regime": regime.name, "part": part, **v}
                                for v in verdict_rows(data, scenes))
        pooled[engine] = _pooled(runs, regimes, held)
    return {"rows": rows, "verdicts": verdicts, "pooled": pooled, "regimes": [asdict(r) for r in regimes],
            "objects": {"design": sorted(o.name for o in objects if not o.held_out), "held_out": sorted(held)},
            "targets": {"spearman": SPEARMAN_TARGET, "brier": BRIER_TARGET, "varies_share": VARIES_SHARE,
                        "success_varies_below": SUCCESS_VARIES_BELOW}}


def _regime_row(data: dict, scenes: list[str]) -> dict:
    from harness.report import ALL, calibration, restricted

    part = restricted(data, scenes)
    row = {"objects": len(scenes)}
    post = part["trials"][part["trials"].shapes == "posterior"]
    per_plan = post.assign(s=post.outcome == "success").groupby(["scene", "realisation", "planner"]).s.mean()
    row["plans"] = len(per_plan)
    row["share_below_0_9"] = float((per_plan < SUCCESS_VARIES_BELOW).mean()) if len(per_plan) else math.nan
    row["varies"] = bool(row["share_below_0_9"] >= VARIES_SHARE)
    cal = calibration(part)[0]
    for r in cal[cal.planner == ALL].itertuples():
        row.update({f"{r.metric}_spearman": r.spearman, f"{r.metric}_brier": r.brier,
                    f"{r.metric}_mean": r.mean_estimate, "retest_spearman": r.retest_spearman})
    row["success_rate"] = float((post.outcome == "success").mean()) if len(post) else math.nan
    row["budget_stops"] = int((part["plans"].status == "budget").sum())
    row["brier_floor"] = brier_floor(post)
    won = part["trials"].assign(s=part["trials"].outcome == "success")
    rates = won.groupby(["shapes", "planner"], sort=False).s.mean()
    for planner in dict.fromkeys(won.planner):
        row[f"success:{planner}"] = float(rates.get(("posterior", planner), math.nan))
        row[f"truth:{planner}"] = float(rates.get(("truth", planner), math.nan))
    for planner in LIFT_PLANNERS:
        d = _difference(part["trials"], planner, BASELINE_LIFT)
        row.update({f"diff:{planner}": d["difference"], f"diff_low:{planner}": d["ci_low"],
                    f"diff_high:{planner}": d["ci_high"]})
    row["p_l_holds"] = bool(row.get("p_l_spearman", math.nan) >= SPEARMAN_TARGET
                            and row.get("p_l_brier", math.nan) <= BRIER_TARGET)
    return row


def verdict_rows(data: dict, scenes: list[str]) -> list[dict]:
    """Per verdict of the model on each posterior trial's own draw (the ledger's: 'lifted',
    'lifted_turned' or the first reason P_L fails, harness.report.reasons), over these
    scenes' trials of every planner: how many trials, and the share the physics lifted
    (``success``) and lost by each outcome (``share:OUTCOME``). Where the model's verdict
    and the physics part (a failure that succeeds, a lifted draw that does not) is where
    P_L's errors come from (docs/lift.md, "What keeps it from the targets")."""
    from harness.report import ALL, reasons, restricted

    table = reasons(restricted(data, scenes))
    if table.empty:
        return []
    table = table[table.planner == ALL].drop(columns="planner")
    outcomes = [c for c in table.columns if c != "analytic"]
    out = []
    for r in table.to_dict("records"):
        n = sum(r[c] for c in outcomes)
        out.append({"verdict": r["analytic"], "trials": int(n),
                    **{(c if c == "success" else f"share:{c}"): r[c] / n for c in outcomes}})
    return out


def brier_floor(post: pd.DataFrame) -> float:
    """The Brier score, over these posterior trials, of the estimate that gives each plan
    its true success rate: the least any per-plan estimate (P_L's, or any other) can
    score in expectation. Estimated without bias from the trials, n / (n - 1) s (1 - s)
    per plan of n trials with success rate s, weighted by n (plans of one trial give
    no estimate and are left out)."""
    from harness.report import plan_rates

    g = plan_rates(post)
    g = g[g["count"] > 1]
    if g.empty:
        return math.nan
    s = g["sum"] / g["count"]
    return float((g["count"] ** 2 / (g["count"] - 1) * s * (1 - s)).sum() / g["count"].sum())


def engine_yardstick(post: pd.DataFrame, other: pd.DataFrame, plans: pd.DataFrame,
                     other_plans: pd.DataFrame) -> dict:
    """The other engine's success rate of each plan as the estimate of this engine's
    trials (Spearman over plans, Brier over trials, as P_L's): how well the physics of
    one simulator predicts the other's, a yardstick for P_L. Only plans executed at the
    same grasp in both runs count (the plans do not depend on the engine)."""
    from harness.report import brier_score, plan_rates

    key = ["scene", "realisation", "planner"]
    grasp = ["g1x", "g1y", "g2x", "g2y"]
    same = plans[key + grasp].merge(other_plans[key + grasp], on=key, suffixes=("", "_o"))
    same = same[np.isclose(same[grasp].to_numpy(), same[[g + "_o" for g in grasp]].to_numpy()).all(axis=1)]
    mine, theirs = plan_rates(post), plan_rates(other)
    g = mine.merge(theirs, left_index=True, right_index=True, suffixes=("", "_o"))
    g = g.join(same.set_index(key)[[]], how="inner")
    if len(g) < 3:
        return {"engine_spearman": math.nan, "engine_brier": math.nan}
    forecast, success = g["sum_o"] / g["count_o"], g["sum"] / g["count"]
    varied = forecast.nunique() > 1 and success.nunique() > 1
    return {"engine_spearman": float(stats.spearmanr(forecast, success).statistic) if varied else math.nan,
            "engine_brier": brier_score(forecast, g["sum"], g["count"])}


def _difference(trials: pd.DataFrame, a: str, b: str, seed: int = 0) -> dict:
    """Paired success difference a - b on posterior samples with the report's bootstrap
    interval: pairs resampled within each plan's trials, so the interval is conditional on
    the plans. ``trials`` may hold several regimes (a 'regime' column). Every regime runs
    at the sweep's seed on objects of the same names, and a cell's random streams are
    keyed by seed, scene name and realisation (harness.pipeline.open_cell), so trial i of
    an object meets the same approach, friction and pressure deviates, and shape samples
    drawn from the same numbers, in every regime: those trials are resampled together (one
    draw of trial indices per object and realisation, applied to every regime). Resampling
    each regime's plans on their own treated them as independent and gave pooled intervals
    too narrow; for a single regime the two are the same, bit for bit."""
    from harness.report import _paired, linked_difference

    if "regime" not in trials.columns:
        trials = trials.assign(regime="")
    m = _paired(trials.assign(scene=trials.regime + "/" + trials.scene), a, b, "posterior")
    if m.empty:
        return {"pairs": 0, "difference": math.nan, "ci_low": math.nan, "ci_high": math.nan}
    parts = m.scene.str.split("/", n=1, expand=True)
    frame = m.assign(regime=parts[0], scene=parts[1], d=(m.a - m.b).astype(float))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5EE9]))
    return linked_difference(frame, ["scene", "realisation"], "regime", rng)


def _pooled(runs: dict, regimes, held: set) -> dict:
    """The lift planners' paired differences over every regime (posterior samples), on
    the design part and on the held-out part."""
    frames = {"design": [], "held_out": [], "all": []}
    for regime in regimes:
        t = runs[regime.name]["trials"].assign(regime=regime.name)
        frames["all"].append(t)
        out_mask = t.scene.isin(held) | regime.held_out
        frames["held_out"].append(t[out_mask])
        frames["design"].append(t[~out_mask])
    return {part: {planner: _difference(pd.concat(f, ignore_index=True), planner, BASELINE_LIFT)
                   for planner in LIFT_PLANNERS} for part, f in frames.items()}


def regime_map(rows: pd.DataFrame, path: Path) -> Path:
    """The regime map: per regime (rows), P_L's Spearman and Brier against their targets
    and their yardsticks (the Brier floor and the trials' retest Spearman; the other
    engine's success as the estimate, when the sweep ran in both), and the lift
    planners' paired differences against mean-shape-lift, for the design and held-out
    parts of each engine."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    engines = list(dict.fromkeys(rows.engine))
    regimes = list(dict.fromkeys(rows.regime))
    fig, axes = plt.subplots(len(engines), 3, figsize=(13, 0.45 * len(regimes) * len(engines) + 1.6),
                             squeeze=False, sharey=True)
    y = np.arange(len(regimes))
    for e, engine in enumerate(engines):
        for part, dy, colour in (("design", -0.18, "tab:blue"), ("held_out", 0.18, "tab:orange")):
            g = rows[(rows.engine == engine) & (rows.part == part)].set_index("regime").reindex(regimes)
            faded = np.where(g.varies.fillna(False).astype(bool), 1.0, 0.35)
            for ax, col, target, marks in (
                    (axes[e, 0], "p_l_spearman", SPEARMAN_TARGET, (("engine_spearman", "|", "the other engine"),
                                                                   ("retest_spearman", "x", "retest"))),
                    (axes[e, 1], "p_l_brier", BRIER_TARGET, (("engine_brier", "|", "the other engine"),
                                                             ("brier_floor", "x", "floor")))):
                ax.barh(y + dy, g[col], height=0.34, color=colour, alpha=0.8, label=part.replace("_", " "))
                for k, a in enumerate(faded):
                    if a < 1:
                        ax.barh(y[k] + dy, g[col].iloc[k], height=0.34, color="white", alpha=0.6)
                for mark_col, marker, label in marks:  # the yardsticks, where the sweep has them
                    if mark_col in g and g[mark_col].notna().any():
                        ax.plot(g[mark_col], y + dy, marker, color="k", ms=7, mew=1.2,
                                label=label if part == "design" else None)
                ax.axvline(target, color="k", lw=1, ls="--")
            for planner, marker in zip(LIFT_PLANNERS, ("o", "s")):
                d = g[f"diff:{planner}"]
                err = np.vstack([d - g[f"diff_low:{planner}"], g[f"diff_high:{planner}"] - d])
                axes[e, 2].errorbar(d, y + dy + (0.06 if marker == "s" else -0.06), xerr=err, fmt=marker,
                                    color=colour, ms=4, lw=1,
                                    label=f"{planner} ({part.replace('_', ' ')})")
        axes[e, 2].axvline(0, color="k", lw=1)
        axes[e, 0].set_title(f"{engine}: P_L Spearman (target >= {SPEARMAN_TARGET})", fontsize=9)
        axes[e, 1].set_title(f"{engine}: P_L Brier (target <= {BRIER_TARGET})", fontsize=9)
        axes[e, 2].set_title(f"{engine}: success - {BASELINE_LIFT} (paired, 95 %)", fontsize=9)
    axes[0, 0].set_yticks(y, [r + (" *" if rows[rows.regime == r].regime_held_out.any() else "") for r in regimes],
                          fontsize=8)
    for ax in axes[:, 0]:  # the shared labels, the same size in every engine's row
        ax.tick_params(axis="y", labelsize=8)
    axes[0, 0].invert_yaxis()
    axes[0, 0].legend(fontsize=7, loc="lower left")
    axes[0, 2].legend(fontsize=6, loc="lower left")
    fig.text(0.01, 0.005, "* held-out regime; faded bars: success does not vary (fewer than a tenth of the "
             "plans below 0.9); |: the other engine's success per plan as the estimate; x: the trials measured "
             "again (Spearman) and the Brier score's floor", fontsize=7)
    fig.tight_layout(rect=(0, 0.02, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def format_lines(res: dict) -> list[str]:
    """The per-regime table (P_L and the lift planners' differences) as text."""
    lines = [] if "object_set" not in res else [f"objects: {res['object_set']} ({len(res['objects']['design'])} "
                                                 f"design, {len(res['objects']['held_out'])} held out)"]
    for engine in dict.fromkeys(r["engine"] for r in res["rows"]):
        lines.append(f"{engine}: regime, part, plans, share of plans below 0.9, P_F Spearman/Brier, "
                     f"P_L Spearman/Brier/mean, the Brier floor, the Spearman of the trials measured again (retest), "
                     f"the other engine's success as the estimate "
                     f"(Spearman/Brier), success, gp-gpis-opt-lift and gp-p-lift - {BASELINE_LIFT}")
        lines.append(f"{'regime':<22}{'part':<10}{'plans':>6}{'<0.9':>6}{'P_F rho':>9}{'Brier':>7}"
                     f"{'P_L rho':>9}{'Brier':>7}{'mean':>6}{'floor':>7}{'retest':>7}{'eng rho':>8}{'Brier':>7}"
                     f"{'succ':>6}  "
                     f"{'opt-lift diff [95%]':<24}{'gp-p-lift diff [95%]':<24}")
        for r in res["rows"]:
            if r["engine"] != engine:
                continue
            diffs = "".join(f"{r[f'diff:{p}']:+.3f} [{r[f'diff_low:{p}']:+.3f},{r[f'diff_high:{p}']:+.3f}]  "
                            for p in LIFT_PLANNERS)
            name = r["regime"] + ("*" if r["regime_held_out"] else "")
            lines.append(f"{name:<22}{r['part']:<10}{r['plans']:>6}{r['share_below_0_9']:>6.2f}"
                         f"{r.get('p_f_spearman', math.nan):>9.2f}{r.get('p_f_brier', math.nan):>7.3f}"
                         f"{r.get('p_l_spearman', math.nan):>9.2f}{r.get('p_l_brier', math.nan):>7.3f}"
                         f"{r.get('p_l_mean', math.nan):>6.2f}{r.get('brier_floor', math.nan):>7.3f}"
                         f"{r.get('retest_spearman', math.nan):>7.2f}"
                         f"{r.get('engine_spearman', math.nan):>8.2f}{r.get('engine_brier', math.nan):>7.3f}"
                         f"{r['success_rate']:>6.2f}  {diffs}")
        ran = [r["name"] for r in res.get("regimes", [])]
        scope = "the sweep" if len(ran) in (0, len(REGIMES)) else ", ".join(ran)
        for part, d in res["pooled"][engine].items():
            lines.append(f"pooled over {scope} ({part}): " + "; ".join(
                f"{p} {v['difference']:+.3f} [{v['ci_low']:+.3f}, {v['ci_high']:+.3f}]" for p, v in d.items()))
        stops = [f"{r['regime']} {r['part']} {r['budget_stops']}" for r in res["rows"]
                 if r["engine"] == engine and r["part"] != "all" and r.get("budget_stops")]
        if stops:
            lines.append("plans that stopped at their time budget (their grasps depend on how fast the machine ran "
                         "them; a larger time_budget_s removes that): " + ", ".join(stops))
    if "figure" in res:
        lines.append(f"regime map: {res['figure']}")
    return lines
