"""Tables and statistics from an experiment's ledger (``gpis-harness report DIR``).

Per scene and planner: trials, physical success on posterior samples and on the true
shape (Wilson 95 % intervals), analytic P_F and P_L (pooled over the realisations' draws,
Wilson), mean Ferrari-Canny, median plan time, and whether every expected row is present.
Paired comparisons use the common random numbers: trial i of two planners on the same
cell met the same shape and the same approach noise. Calibration compares each plan's
analytic P_F and P_L with its physical success, and the analytic verdict of each draw
with the outcome of the posterior trial that shares it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from harness.config import ExperimentConfig, stored_scene_names
from harness.errors import InputError
from harness.ledger import FILENAME, Ledger
from harness.outputs import write_atomic, write_text
from harness.quality import wilson_interval

BOOTSTRAP = 2000
BASELINE = "mean-shape"
ALL = "all"
SUMMARY_COLUMNS = ["scene", "planner", "n_trials", "success_rate", "success_ci_low", "success_ci_high",
                   "truth_success_rate", "truth_ci_low", "truth_ci_high", "p_f", "p_f_ci_low", "p_f_ci_high",
                   "p_l", "p_l_ci_low", "p_l_ci_high", "ferrari_canny_mean", "plan_time_median_s", "plans_ok",
                   "complete"]
#: The analytic metrics calibrated against physical success.
METRICS = ("p_f", "p_l")
RELIABILITY_BINS = 10


def load(out_dir: Path, config_hash: str | None = None) -> dict:
    """The latest experiment in ``out_dir``'s ledger as DataFrames plus its config."""
    path = Path(out_dir) / FILENAME
    if not Path(out_dir).is_dir():
        raise InputError(str(out_dir), None, "no such results folder")
    with Ledger(path, create=False) as ledger:
        key = config_hash or ledger.latest_hash()
        runs = ledger.runs()
        runs = runs[runs.config_hash == key]
        out = {"hash": key, "runs": runs, "config": json.loads(runs.iloc[-1].config),
               "environment": json.loads(runs.iloc[-1].environment)}
        _check_stored(out["config"], out["environment"], path)
        labels = {p["label"] for p in out["config"]["planners"]}
        for table in ("plans", "analytic", "trials"):
            rows = ledger.table(key, table)
            # The latest config's planners: an experiment's ledger may hold the rows of a
            # planner a later config dropped (the config hash does not cover the planners).
            out[table] = rows[rows.planner.isin(labels)].reset_index(drop=True)
    return out


def _check_stored(config, environment, path: Path) -> None:
    """The stored run's config and environment have the structure the tables read (the
    ledger checks its columns' types, not what the JSON inside them holds); one line
    naming the field otherwise."""

    def bad(field: str, what: str) -> InputError:
        return InputError(str(path), f"runs.{field}", f"{what}: not a run this version can read")

    if not isinstance(config, dict):
        raise bad("config", f"a {type(config).__name__}, not a table")
    if not isinstance(environment, dict):
        raise bad("environment", f"a {type(environment).__name__}, not a table")
    for key in ("seed", "realisations", "analytic_draws", "posterior_trials", "truth_trials"):
        value = config.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise bad(f"config.{key}", f"{value!r} is not a count")
    scenes, planners = config.get("scenes"), config.get("planners")
    if not isinstance(scenes, list) or not all(isinstance(x, str) for x in scenes):
        raise bad("config.scenes", "not a list of scene files")
    if not isinstance(planners, list) or not all(isinstance(x, dict) and isinstance(x.get("label"), str)
                                                  and isinstance(x.get("name"), str) for x in planners):
        raise bad("config.planners", "not a list of planner entries with a label and a name")
    for key in ("physics", "settings"):
        if not isinstance(config.get(key) or {}, dict):
            raise bad(f"config.{key}", "not a table")


def expected(config: dict) -> tuple[list[str], list[str], int]:
    """The scene names, planner labels and realisations a complete run has."""
    scenes = list(stored_scene_names(config))
    planners = [p["label"] for p in config["planners"]]
    return scenes, planners, config["realisations"]


def summary(data: dict) -> pd.DataFrame:
    """One row per scene and planner, then one 'all' row per planner (pooled)."""
    config, plans, analytic, trials = data["config"], data["plans"], data["analytic"], data["trials"]
    scenes, planners, realisations = expected(config)
    per_plan = config["posterior_trials"] + config["truth_trials"]
    rows = []
    for scene in scenes + [ALL]:
        for planner in planners:
            sel = (lambda df: df[(df.planner == planner) & ((df.scene == scene) if scene != ALL else True)])
            t, p, a = sel(trials), sel(plans), sel(analytic)
            n_scenes = len(scenes) if scene == ALL else 1
            post, truth = t[t.shapes == "posterior"], t[t.shapes == "truth"]
            k, n = int((post.outcome == "success").sum()), len(post)
            kt, nt = int((truth.outcome == "success").sum()), len(truth)
            # Plans with nothing executed count as P_F and P_L 0 over the same number of draws.
            draws = int(config["analytic_draws"]) * int((p.executed == 0).sum()) + int(a.draws.sum())
            pooled = {m: _pooled(a[m], a.draws, draws) for m in METRICS}
            lo, hi = wilson_interval(k, n) if n else (np.nan, np.nan)
            tlo, thi = wilson_interval(kt, nt) if nt else (np.nan, np.nan)
            fc = (a.ferrari_canny_mean.sum() / len(p)) if len(p) else np.nan
            rows.append({
                "scene": scene, "planner": planner, "n_trials": n,
                "success_rate": k / n if n else np.nan, "success_ci_low": float(lo), "success_ci_high": float(hi),
                "truth_success_rate": kt / nt if nt else np.nan, "truth_ci_low": float(tlo),
                "truth_ci_high": float(thi),
                **{f"{m}{suffix}": v for m in METRICS for suffix, v in zip(("", "_ci_low", "_ci_high"), pooled[m])},
                "ferrari_canny_mean": fc, "plan_time_median_s": float(p.plan_time_s.median()) if len(p) else np.nan,
                "plans_ok": f"{int(p.executed.sum())}/{realisations * n_scenes}",
                "complete": bool(len(p) == realisations * n_scenes and len(t) == realisations * n_scenes * per_plan),
            })
    return pd.DataFrame(rows, columns=SUMMARY_COLUMNS)


def _pooled(estimates: pd.Series, draws: pd.Series, total: int) -> tuple[float, float, float]:
    """A metric pooled over plans (estimate x draws successes out of ``total`` draws) with
    its Wilson interval; NaN when a plan has no estimate (a ledger written before P_L)."""
    if not total or estimates.isna().any():
        return np.nan, np.nan, np.nan
    successes = float((estimates * draws).round().sum())
    lo, hi = wilson_interval(successes, total)
    return successes / total, float(lo), float(hi)


def _paired(trials: pd.DataFrame, a: str, b: str, shapes: str) -> pd.DataFrame:
    keys = ["scene", "realisation", "trial"]
    ta = trials[(trials.planner == a) & (trials.shapes == shapes)][keys + ["outcome"]]
    tb = trials[(trials.planner == b) & (trials.shapes == shapes)][keys + ["outcome"]]
    m = ta.merge(tb, on=keys, suffixes=("_a", "_b"))
    m["a"] = (m.outcome_a == "success").astype(int)
    m["b"] = (m.outcome_b == "success").astype(int)
    return m


def comparison_pairs(config: dict) -> list[tuple[str, str]]:
    """The planner comparisons a report shows (labels, in the config's order): each planner
    against every mean-shape entry that optimises the same quality, every gp-gpis-opt
    entry against every gp-p entry of the same quality, and each entry that optimises the
    lift against the entry of the same planner and parameters that does not. A planner
    without a ``quality`` parameter counts as force closure."""
    planners = expected(config)[1]
    entries = {p["label"]: p for p in config["planners"]}
    names = {lab: entries[lab]["name"] for lab in planners}
    quality = {lab: entries[lab]["params"].get("quality", "force_closure") for lab in planners}
    pairs: list[tuple[str, str]] = []

    def add(a, b):
        if a != b and (a, b) not in pairs and (b, a) not in pairs:
            pairs.append((a, b))

    for base in (lab for lab in planners if names[lab] == BASELINE):
        for lab in planners:
            if quality[lab] == quality[base]:
                add(lab, base)
    for opt in (lab for lab in planners if names[lab] == "gp-gpis-opt"):
        for gp in (lab for lab in planners if names[lab] == "gp-p" and quality[lab] == quality[opt]):
            add(opt, gp)
    for lab in (lab for lab in planners if quality[lab] == "lift"):
        plain = {k: v for k, v in entries[lab]["params"].items() if k != "quality"}
        for other in planners:
            other_params = {k: v for k, v in entries[other]["params"].items() if k != "quality"}
            if names[other] == names[lab] and quality[other] == "force_closure" and other_params == plain:
                add(lab, other)
    return pairs


def paired_difference(d: np.ndarray, groups: list[np.ndarray], rng: np.random.Generator) -> dict:
    """Mean of the paired differences ``d`` with a bootstrap 95 % interval that resamples
    pairs within each group (index arrays into d), so it is conditional on what the groups
    share (their plans)."""
    boot = _bootstrap_means(d, groups, rng)
    return {"pairs": len(d), "difference": float(d.mean()), "ci_low": float(np.percentile(boot, 2.5)),
            "ci_high": float(np.percentile(boot, 97.5))}


def linked_difference(frame: pd.DataFrame, cell: list[str], member: str, rng: np.random.Generator) -> dict:
    """Mean of the paired differences ``frame.d`` with a bootstrap 95 % interval, where the
    rows of one ``cell`` (its keys) and one ``trial`` index share their random draws across
    ``member``s: the planners of one cell meet the same shape sample and noise in trial i,
    and so do a sweep's regimes on one object. Each cell's trials are resampled with one
    draw of trial indices, applied to every member (as :func:`paired_difference` resamples
    a plan's trials, which it equals bit for bit when each cell has one member); resampling
    the members apart would treat shared draws as independent and narrow the interval."""
    wide = frame.pivot_table(index=[*cell, "trial"], columns=member, values="d", aggfunc="first")
    values = wide.to_numpy(dtype=float)
    present = ~np.isnan(values)
    sums, counts = np.zeros(BOOTSTRAP), np.zeros(BOOTSTRAP)
    cells = pd.Series(np.arange(len(wide)), index=wide.index.droplevel("trial"))
    for _, rows in cells.groupby(level=list(range(len(cell))), sort=True):
        rows = rows.to_numpy()
        # Each member's trials in the cell, rescaled as a stratum over the trials it has (a
        # member the cell lacks, or a trial it lacks, counts 0 and is not counted).
        have = present[rows]
        scaled = rescaled(values[rows], have)
        picks = rng.integers(0, len(rows), size=(BOOTSTRAP, len(rows)))
        sums += scaled[picks].sum(axis=(1, 2))
        counts += have[picks].sum(axis=(1, 2))
    boot = sums / counts
    return {"pairs": int(present.sum()), "difference": float(frame.d.mean()),
            "ci_low": float(np.percentile(boot, 2.5)), "ci_high": float(np.percentile(boot, 97.5))}


def mcnemar(a: np.ndarray, b: np.ndarray) -> tuple[int, int, float]:
    """Discordant pairs of two 0/1 outcome arrays (a only, b only) and McNemar's exact p."""
    only_a, only_b = int(((a == 1) & (b == 0)).sum()), int(((a == 0) & (b == 1)).sum())
    p = stats.binomtest(only_a, only_a + only_b, 0.5).pvalue if only_a + only_b else 1.0
    return only_a, only_b, float(p)


def row_groups(frame: pd.DataFrame, keys: list[str]) -> list[np.ndarray]:
    """Row positions of ``frame`` grouped by ``keys`` (for :func:`paired_difference`: the
    trials of one plan, by (scene, realisation), adding planner or shapes where a frame
    mixes them)."""
    return [g.index.to_numpy() for _, g in frame.reset_index(drop=True).groupby(keys)]


def comparisons(data: dict, seed: int = 0) -> pd.DataFrame:
    """The pairs of :func:`comparison_pairs`, on posterior samples, on the true shape and
    pooled over both ('all'): success difference (a - b) on the same trials, a paired
    bootstrap 95 % interval (trials resampled in pairs within each plan's trials of one
    shape source, so the interval is conditional on the plans), and McNemar's exact p on
    the discordant pairs."""
    from harness.seeding import stream

    config, trials = data["config"], data["trials"]
    scenes = expected(config)[0]
    rows = []
    for a, b in comparison_pairs(config):
        by_source = {shapes: _paired(trials, a, b, shapes).assign(shapes=shapes) for shapes in ("posterior", "truth")}
        by_source[ALL] = pd.concat(by_source.values(), ignore_index=True)
        for shapes, m in by_source.items():
            for scene in scenes + [ALL]:
                s = m if scene == ALL else m[m.scene == scene]
                if s.empty:
                    continue
                groups = row_groups(s, ["shapes", "scene", "realisation"])
                # Each interval its own stream: another planner in the report, or one more
                # pair, leaves this pair's interval as it was.
                rng = stream(seed, "bootstrap", "comparison", a, b, shapes, scene)
                diff = paired_difference((s.a - s.b).to_numpy(), groups, rng)
                n10, n01, p = mcnemar(s.a.to_numpy(), s.b.to_numpy())
                rows.append({"scene": scene, "shapes": shapes, "planner": a, "versus": b, **diff,
                             "only_planner": n10, "only_versus": n01, "mcnemar_p": p})
    return pd.DataFrame(rows)


LEADERBOARD_COLUMNS = ["rank", "planner", "trials", "success_rate", "success_ci_low", "success_ci_high",
                       "difference_vs_best", "difference_ci_low", "difference_ci_high", "only_planner", "only_best",
                       "mcnemar_p", "truth_trials", "truth_success_rate", "truth_ci_low", "truth_ci_high", "p_l",
                       "p_l_ci_low", "p_l_ci_high", "plan_time_median_s"]


def leaderboard(data: dict, seed: int = 0) -> pd.DataFrame:
    """The planners ranked by pooled success on posterior samples (ties: on the true
    shape), each with its Wilson 95 % interval; the paired difference against the best on
    the same posterior trials, with the report's bootstrap interval (pairs resampled
    within each plan) and McNemar's exact p; success on the true shape; the analytic P_L
    pooled over the plans' draws; the median plan time. The rank is 1 + the number of
    planners with a strictly higher posterior success (none for a planner without
    trials, listed last)."""
    s = summary(data)
    pooled = s[s.scene == ALL].sort_values(["success_rate", "truth_success_rate"], ascending=False, kind="stable")
    if pooled.empty or pooled.success_rate.isna().all():
        return pd.DataFrame(columns=LEADERBOARD_COLUMNS)
    from harness.seeding import stream

    trials = data["trials"]
    best = pooled.planner.iloc[0]
    rows = []
    for r in pooled.itertuples():
        m = _paired(trials, r.planner, best, "posterior")
        if r.planner == best or m.empty:
            diff = {"difference": 0.0 if r.planner == best else np.nan, "ci_low": np.nan, "ci_high": np.nan}
            n10 = n01 = 0
            p = 1.0 if r.planner == best else np.nan
        else:
            rng = stream(seed, "bootstrap", "leaderboard", r.planner, best)  # its own, as in comparisons
            diff = paired_difference((m.a - m.b).to_numpy(), row_groups(m, ["scene", "realisation"]), rng)
            n10, n01, p = mcnemar(m.a.to_numpy(), m.b.to_numpy())
        truth = trials[(trials.planner == r.planner) & (trials.shapes == "truth")]
        rank = int(1 + (pooled.success_rate > r.success_rate).sum()) if pd.notna(r.success_rate) else None
        rows.append({"rank": rank, "planner": r.planner,
                     "trials": r.n_trials, "success_rate": r.success_rate, "success_ci_low": r.success_ci_low,
                     "success_ci_high": r.success_ci_high, "difference_vs_best": diff["difference"],
                     "difference_ci_low": diff["ci_low"], "difference_ci_high": diff["ci_high"],
                     "only_planner": n10, "only_best": n01, "mcnemar_p": p, "truth_trials": len(truth),
                     "truth_success_rate": r.truth_success_rate, "truth_ci_low": r.truth_ci_low,
                     "truth_ci_high": r.truth_ci_high, "p_l": r.p_l, "p_l_ci_low": r.p_l_ci_low,
                     "p_l_ci_high": r.p_l_ci_high, "plan_time_median_s": r.plan_time_median_s})
    return pd.DataFrame(rows, columns=LEADERBOARD_COLUMNS).astype({"rank": "Int64"})


def leaderboard_table(board: pd.DataFrame) -> pd.DataFrame:
    """The leaderboard as a paper table: rates and differences with their intervals in one cell."""
    best = board.planner.iloc[0] if len(board) else None

    def difference(r):
        if r.planner == best:
            return "best"
        if pd.isna(r.difference_vs_best):
            return "–"
        return f"{r.difference_vs_best:+.3f} [{r.difference_ci_low:+.3f}, {r.difference_ci_high:+.3f}]"

    return pd.DataFrame({
        "rank": board["rank"].map(lambda v: "–" if pd.isna(v) else str(v)), "planner": board.planner,
        "trials": board.trials,
        "success (posterior)": [_fmt_rate(*v) for v in zip(board.success_rate, board.success_ci_low,
                                                           board.success_ci_high)],
        "vs best (paired)": [difference(r) for r in board.itertuples()],
        "McNemar p": [("–" if r.planner == best or pd.isna(r.mcnemar_p) else f"{r.mcnemar_p:.2g}")
                      for r in board.itertuples()],
        "success (true shape)": [_fmt_rate(*v) for v in zip(board.truth_success_rate, board.truth_ci_low,
                                                            board.truth_ci_high)],
        "analytic P_L": [_fmt_rate(*v) for v in zip(board.p_l, board.p_l_ci_low, board.p_l_ci_high)],
        "plan time (s)": board.plan_time_median_s.map(lambda v: "–" if pd.isna(v) else f"{v:.2f}"),
    })


def _bootstrap_means(d: np.ndarray, groups: list[np.ndarray], rng: np.random.Generator) -> np.ndarray:
    total = np.zeros(BOOTSTRAP)
    for g in groups:
        picks = rng.integers(0, len(g), size=(BOOTSTRAP, len(g)))
        total += rescaled(d[g])[picks].sum(axis=1)
    return total / len(d)


def rescaled(x: np.ndarray, have: np.ndarray | None = None) -> np.ndarray:
    """A stratum's values for the bootstrap, their deviations from the stratum's mean
    stretched by sqrt(n / (n - 1)) (Rao and Wu 1988, the rescaling bootstrap): resampling n
    values with replacement gives their mean the variance (n - 1) / n s^2 / n, short of the
    unbiased s^2 / n by a factor that matters for small strata (a plan's 4 true-shape
    trials: intervals 13 % too narrow). The mean is kept; a stratum of one is left as it is.
    ``x`` (n,) is one stratum, or (n, k) k strata side by side (linked_difference's
    members), each over the rows ``have`` marks (the others come back as 0)."""
    if have is None:
        have = np.ones(x.shape, dtype=bool)
    n = have.sum(axis=0)
    mean = np.where(have, x, 0.0).sum(axis=0) / np.maximum(n, 1)
    factor = np.sqrt(np.where(n > 1, n / np.maximum(n - 1, 1), 1.0))
    return np.where(have, mean + factor * (x - mean), 0.0)


def plan_rates(post: pd.DataFrame) -> pd.DataFrame:
    """Per plan (scene, realisation, planner): its trials' successes ("sum") and count."""
    return (post.assign(s=(post.outcome == "success").astype(float))
            .groupby(["scene", "realisation", "planner"]).s.agg(["sum", "count"]))


def brier_score(forecast, wins, count) -> float:
    """The Brier score over trials of per-plan forecasts: each plan's ``count`` trials,
    ``wins`` of them successes, all forecast at its ``forecast``."""
    return float(((forecast ** 2) * (count - wins) + ((1 - forecast) ** 2) * wins).sum() / count.sum())


#: Random splits of each plan's trials that :func:`retest_spearman` averages over.
RETEST_SPLITS = 64


def retest_spearman(post: pd.DataFrame, repeats: int = RETEST_SPLITS, seed: int = 0) -> float:
    """How well the plans' success, measured again with as many trials, would rank this
    measurement: each plan's posterior trials split at random into two halves, the
    Spearman over plans between the halves' success rates (averaged over ``repeats``
    splits, drawn from ``seed``), stepped up to the full count by Spearman-Brown,
    2 r / (1 + r). A yardstick for an estimate's Spearman set by the trials' own noise,
    as the Brier score's floor is for its Brier score: a perfect estimate (each plan's
    true success rate) ranks the measured rates at about the square root of it (a
    measurement correlates with its true value as the square root of its test-retest
    correlation; tested), so below about 0.49 no estimate can reach a Spearman of 0.7.
    NaN with fewer than three plans of two trials or more, or where the halves never vary."""
    won = post.assign(s=(post.outcome == "success").to_numpy())
    groups = [g.to_numpy() for _, g in won.groupby(["scene", "realisation", "planner"]).s if len(g) > 1]
    if len(groups) < 3:
        return math.nan
    rng = np.random.default_rng(seed)
    rhos = []
    for _ in range(repeats):
        halves = np.empty((len(groups), 2))
        for k, outcomes in enumerate(groups):
            order = rng.permutation(len(outcomes))
            half = len(outcomes) // 2
            halves[k] = outcomes[order[:half]].mean(), outcomes[order[half:]].mean()
        if np.ptp(halves[:, 0]) > 0 and np.ptp(halves[:, 1]) > 0:
            rhos.append(stats.spearmanr(halves[:, 0], halves[:, 1]).statistic)
    if not rhos:
        return math.nan
    r = float(np.mean(rhos))
    return 2.0 * r / (1.0 + r) if r > -1.0 else math.nan


def _plans_with_rates(data: dict) -> pd.DataFrame:
    """The executed plans with their analytic estimates and their posterior trials'
    successes (``sum``) and count."""
    plans = data["plans"][data["plans"].executed == 1]
    rate = plan_rates(data["trials"][data["trials"].shapes == "posterior"]).reset_index()
    return plans.merge(data["analytic"], on=["scene", "realisation", "planner"]).merge(
        rate, on=["scene", "realisation", "planner"])


def rank_shares(forecast, success) -> tuple[np.ndarray, float]:
    """Each plan's share of the shortfall of Spearman's rho from 1, and rho. Spearman's rho
    is Pearson's correlation of the average ranks, so with z the ranks standardised (sample
    standard deviation) rho = 1 - sum((z_forecast - z_success)^2) / (2 (n - 1)) exactly,
    ties included: a plan's share is its squared difference over their sum. NaN shares
    (and rho) where either side is constant or there are fewer than three plans."""
    f, s = np.asarray(forecast, dtype=float), np.asarray(success, dtype=float)
    n = len(f)
    if n < 3 or np.ptp(f) == 0 or np.ptp(s) == 0:
        return np.full(n, np.nan), float("nan")
    z = [(r - r.mean()) / r.std(ddof=1) for r in (stats.rankdata(f), stats.rankdata(s))]
    squared = (z[0] - z[1]) ** 2
    total = squared.sum()
    shares = squared / total if total > 0 else np.zeros(n)
    return shares, float(1.0 - total / (2 * (n - 1)))


def plan_calibration(data: dict) -> pd.DataFrame:
    """Per executed plan: its analytic P_F and P_L, its posterior trials and their success,
    and per metric the plan's share of the pooled Spearman's shortfall from 1
    (:func:`rank_shares`): which plans cost the ranking of calibration.csv's 'all' row."""
    per_plan = _plans_with_rates(data)
    out = per_plan[["scene", "realisation", "planner", *METRICS]].copy()
    out["trials"] = per_plan["count"].astype(int)
    out["success_rate"] = per_plan["sum"] / per_plan["count"]
    for metric in METRICS:
        known = per_plan[metric].notna().to_numpy()
        shares = np.full(len(out), np.nan)
        shares[known] = rank_shares(per_plan.loc[known, metric], out.loc[known, "success_rate"])[0]
        out[f"{metric}_rank_share"] = shares
    return out.sort_values(["scene", "realisation", "planner"]).reset_index(drop=True)


def calibration(data: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per plan: analytic P_F and P_L against success on posterior samples. Returns the
    table per metric and planner (and 'all': Brier score over trials, each trial's
    forecast its plan's estimate; Spearman over plans; beside it the Spearman the same
    plans' trials measured again would reach, :func:`retest_spearman`, whose square root
    is about what a perfect estimate reaches) and the reliability bins per metric;
    :func:`plan_calibration` gives the plans themselves."""
    post = data["trials"][data["trials"].shapes == "posterior"]
    per_plan = _plans_with_rates(data)
    rows, bins = [], []
    edges = np.arange(RELIABILITY_BINS + 1) / RELIABILITY_BINS  # exact tenths: 0.3 opens its own bin
    key = ["scene", "realisation", "planner"]
    plan_of = pd.MultiIndex.from_frame(post[key])
    retests = {}  # per set of plans: P_F's and P_L's rows of a planner share it
    for metric in METRICS:
        known = per_plan[per_plan[metric].notna()]
        for planner, g in list(known.groupby("planner")) + [(ALL, known)]:
            if g.empty:
                continue
            forecast = g[metric]
            brier = brier_score(forecast, g["sum"], g["count"])
            success = g["sum"] / g["count"]
            varied = len(g) > 2 and forecast.nunique() > 1 and success.nunique() > 1  # else undefined
            rho = stats.spearmanr(forecast, success).statistic if varied else np.nan
            these = tuple(map(tuple, g[key].to_numpy()))
            if these not in retests:  # these plans' trials
                retests[these] = retest_spearman(post[plan_of.isin(pd.MultiIndex.from_tuples(these, names=key))])
            retest = retests[these]
            rows.append({"metric": metric, "planner": planner, "plans": len(g), "brier": brier, "spearman": float(rho),
                         "retest_spearman": retest, "mean_estimate": float(forecast.mean()),
                         "success_rate": float(g["sum"].sum() / g["count"].sum())})
        which = np.clip(np.digitize(known[metric], edges[1:-1]), 0, RELIABILITY_BINS - 1)
        for k in range(RELIABILITY_BINS):
            g = known[which == k]
            if g.empty:
                continue
            s, n = float(g["sum"].sum()), float(g["count"].sum())
            lo, hi = wilson_interval(s, n)
            bins.append({"metric": metric, "bin_low": edges[k], "bin_high": edges[k + 1], "plans": len(g),
                         "trials": int(n), "mean_estimate": float(g[metric].mean()), "success_rate": s / n,
                         "ci_low": float(lo), "ci_high": float(hi)})
    return pd.DataFrame(rows), pd.DataFrame(bins)


#: The grasp settings that make a regime (harness.settings.GraspSettings): the gripper's
#: force, the jaws' friction and its spread, and the approach noise. Objects (their size,
#: thickness, density) vary within a regime, as over a library.
REGIME_KEYS = ("force", "friction", "friction_spread", "sigma_g")


def scene_regimes(config: dict) -> dict[str, str]:
    """Each scene's regime: the REGIME_KEYS of its grasp settings as resolved in this
    experiment (the scene's own, or the config's overrides), as a label."""
    from harness.tasks import settings_of

    cfg = ExperimentConfig.from_dict(config)
    out = {}
    for name, path in zip(cfg.scene_names, cfg.scenes):
        s = settings_of(cfg, path)
        out[name] = (f"force {s.force:g} N, friction {s.friction:g}"
                     + (f" (spread {s.friction_spread:g})" if s.friction_spread else "")
                     + f", sigma_g {1000 * s.sigma_g:g} mm")
    return out


def restricted(data: dict, scenes) -> dict:
    """The run ``data`` (:func:`load`) with its plans, analytic rows and trials restricted
    to ``scenes`` (the config unchanged)."""
    keep = set(scenes)
    return {**data, **{t: data[t][data[t].scene.isin(keep)] for t in ("plans", "analytic", "trials")}}


def calibration_by_regime(data: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """:func:`calibration` over each regime's plans apart (scene_regimes), as two tables
    with a ``regime`` column; empty when every scene shares one regime."""
    try:
        regime = scene_regimes(data["config"])
    except InputError:  # a scene file that moved or changed since the run: no split
        return pd.DataFrame(), pd.DataFrame()
    if len(set(regime.values())) < 2:
        return pd.DataFrame(), pd.DataFrame()
    tables, bins = [], []
    for label in dict.fromkeys(regime.values()):
        part = restricted(data, [s for s, r in regime.items() if r == label])
        if part["plans"].empty:
            continue
        cal, b = calibration(part)
        tables.append(cal.assign(regime=label))
        bins.append(b.assign(regime=label))
    order = lambda frame: frame[["regime", *[c for c in frame.columns if c != "regime"]]]  # noqa: E731
    return (order(pd.concat(tables, ignore_index=True)) if tables else pd.DataFrame(),
            order(pd.concat(bins, ignore_index=True)) if bins else pd.DataFrame())


def reasons(data: dict) -> pd.DataFrame:
    """The analytic verdict of each posterior trial's draw ('lifted', 'lifted_turned' or
    the first failure reason: harness.pipeline.verdict_label) against the trial's
    physical outcome: counts per planner and for 'all'."""
    from harness.quality import FAILURE_REASONS, LIFTED_VERDICTS

    analytic = data["analytic"].dropna(subset=["reasons"])
    post = data["trials"][data["trials"].shapes == "posterior"]
    keys = ["scene", "realisation", "planner", "trial"]
    verdicts = pd.DataFrame([(r.scene, r.realisation, r.planner, i, v) for r in analytic.itertuples()
                             for i, v in enumerate(r.reasons.split(",") if r.reasons else [])],
                            columns=keys + ["analytic"])
    paired = post[keys + ["outcome"]].merge(verdicts, on=keys)
    if paired.empty:
        return pd.DataFrame()
    order = [*LIFTED_VERDICTS, *FAILURE_REASONS]
    tables = []
    for planner, g in [(ALL, paired)] + list(paired.groupby("planner", sort=False)):
        t = pd.crosstab(g.analytic, g.outcome).reindex([v for v in order if v in set(g.analytic)])
        tables.append(t.reset_index().assign(planner=planner))
    table = pd.concat(tables, ignore_index=True).fillna(0)
    outcomes = [c for c in table.columns if c not in ("planner", "analytic")]
    table[outcomes] = table[outcomes].astype(int)
    labels = [ALL] + expected(data["config"])[1]
    table = table.sort_values("planner", key=lambda c: c.map({p: k for k, p in enumerate(labels)}), kind="stable")
    return table[["planner", "analytic", *outcomes]].reset_index(drop=True)


def failures(data: dict) -> pd.DataFrame:
    """Trial outcomes by planner and shape source (counts), planners in the config's
    order (as in the summary), posterior samples before the true shape."""
    t = data["trials"]
    table = t.groupby(["planner", "shapes", "outcome"]).size().unstack("outcome", fill_value=0).reset_index()
    order = {label: k for k, label in enumerate(expected(data["config"])[1])}
    return table.sort_values(["planner", "shapes"], key=lambda c: c.map(order) if c.name == "planner" else c,
                             kind="stable").reset_index(drop=True)


# ---------------------------------------------------------------------------
# Writing


def _fmt_rate(rate, lo, hi) -> str:
    return "–" if pd.isna(rate) else f"{rate:.2f} [{lo:.2f}, {hi:.2f}]"


def display_table(s: pd.DataFrame) -> pd.DataFrame:
    """The summary as a paper table: rates with their intervals in one cell."""
    return pd.DataFrame({
        "scene": s.scene, "planner": s.planner, "trials": s.n_trials,
        "success (posterior)": [_fmt_rate(*v) for v in zip(s.success_rate, s.success_ci_low, s.success_ci_high)],
        "success (true shape)": [_fmt_rate(*v) for v in zip(s.truth_success_rate, s.truth_ci_low,
                                                             s.truth_ci_high)],
        "analytic P_F": [_fmt_rate(*v) for v in zip(s.p_f, s.p_f_ci_low, s.p_f_ci_high)],
        "analytic P_L": [_fmt_rate(*v) for v in zip(s.p_l, s.p_l_ci_low, s.p_l_ci_high)],
        "Ferrari-Canny": s.ferrari_canny_mean.map(lambda v: "–" if pd.isna(v) else f"{v:.3f}"),
        "plan time (s)": s.plan_time_median_s.map(lambda v: "–" if pd.isna(v) else f"{v:.2f}"),
        "plans": s.plans_ok, "complete": s.complete.map({True: "yes", False: "NO"}),
    })


def engine_of(data: dict) -> dict:
    """The physics engine a run's trials were simulated in, and its version as the run
    recorded it."""
    name = (data["config"].get("physics") or {}).get("engine", "pybullet")
    return {"name": name, "version": (data["environment"].get("packages") or {}).get(name)}


def _tex(text) -> str:
    """A table cell as LaTeX text."""
    return str(text).replace("_", r"\_").replace("%", r"\%").replace("–", "--")


def _latex(s: pd.DataFrame) -> str:
    """booktabs table; the best posterior success per scene in bold."""
    shown = display_table(s).drop(columns=["complete"])
    best = s.groupby("scene").success_rate.transform("max")
    lines = [r"\begin{tabular}{ll" + "r" * (shown.shape[1] - 2) + "}", r"\toprule",
             " & ".join(_tex(c) for c in shown.columns) + r" \\", r"\midrule"]
    previous = None
    for i, row in shown.iterrows():
        if previous is not None and row.scene != previous:
            lines.append(r"\midrule")
        previous = row.scene
        cells = [_tex(v) for v in row]
        if not pd.isna(s.success_rate[i]) and s.success_rate[i] == best[i]:
            cells[3] = r"\textbf{" + cells[3] + "}"
        lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", ""]
    return "\n".join(lines)


def write_report(out_dir: Path, figures: bool = True) -> dict:
    """Write every table and figure of the latest experiment in ``out_dir``; returns the
    summary and comparisons for printing."""
    out_dir = Path(out_dir)
    data = load(out_dir)
    s = summary(data)
    comp = comparisons(data, seed=int(data["config"]["seed"]))
    cal, bins = calibration(data)
    fails = failures(data)
    verdicts = reasons(data)
    by_regime, regime_bins = calibration_by_regime(data)
    board = leaderboard(data, seed=int(data["config"]["seed"]))
    tables = [("summary", s), ("comparisons", comp), ("calibration", cal),
              ("calibration_plans", plan_calibration(data)), ("reliability", bins), ("failures", fails),
              ("reasons", verdicts), ("leaderboard", board)]
    if not by_regime.empty:
        tables += [("calibration_by_regime", by_regime), ("reliability_by_regime", regime_bins)]
    for name, frame in tables:
        write_atomic(out_dir / f"{name}.csv", lambda tmp, frame=frame: frame.to_csv(tmp, index=False))
    engine = engine_of(data)
    engine_line = f"Physics: {engine['name']} {engine['version'] or ''}".rstrip()
    budget = budget_note(data)
    md = ["# " + data["config"]["name"], "", engine_line + " (docs/physics.md).", "",
          *([f"**{budget}**", ""] if budget else []), display_table(s).to_markdown(index=False), ""]
    if not comp.empty:
        shown = comp.copy()
        shown["difference [95% CI]"] = [f"{d:+.3f} [{lo:+.3f}, {hi:+.3f}]"
                                        for d, lo, hi in zip(shown.difference, shown.ci_low, shown.ci_high)]
        shown["McNemar p"] = shown.mcnemar_p.map(lambda p: f"{p:.3g}")
        columns = ["planner", "versus", "pairs", "difference [95% CI]", "McNemar p"]
        md += ["## Paired comparisons over all scenes (success difference)", "",
               shown[shown.scene == ALL][["shapes", *columns]].to_markdown(index=False), "",
               "## Paired comparisons per scene (posterior samples)", "",
               shown[(shown.shapes == "posterior") & (shown.scene != ALL)][["scene", *columns]]
               .to_markdown(index=False)]
    md += ["", "## Calibration of analytic P_F and P_L against physical success", "",
           cal.to_markdown(index=False, floatfmt=".3f") if not cal.empty else "(no executed plans)", ""]
    if not by_regime.empty:
        md += ["### Per regime (the scenes' force, friction and approach noise)", "",
               by_regime[by_regime.planner == ALL].drop(columns="planner").to_markdown(index=False, floatfmt=".3f"),
               ""]
    md += [
           "## Trial outcomes", "", fails.to_markdown(index=False), "",
           "## Analytic verdict of each posterior trial's draw against its physical outcome (all planners)", "",
           (verdicts[verdicts.planner == ALL].drop(columns="planner").to_markdown(index=False)
            if not verdicts.empty else "(no analytic verdicts)"), ""]
    write_text(out_dir / "summary.md", "\n".join(md))
    write_text(out_dir / "summary.tex", _latex(s))
    write_text(out_dir / "leaderboard.md",
               "\n".join([f"# {data['config']['name']}: leaderboard", "",
                          f"{engine_line}. Ranked by success on posterior samples (Wilson 95 % intervals); "
                          "'vs best': the paired difference on the same posterior trials (bootstrap 95 % "
                          "interval, pairs resampled within each plan) and McNemar's exact p.", "",
                          *([f"**{budget}**", ""] if budget else []),
                          leaderboard_table(board).to_markdown(index=False), ""]))
    write_text(out_dir / "leaderboard.tex", _leaderboard_latex(board))
    for table in ("trials", "plans"):
        write_atomic(out_dir / f"{table}.parquet", lambda tmp, table=table: data[table].to_parquet(tmp, index=False))
    runs = data["runs"]
    manifest = {"config": data["config"], "config_hash": data["hash"], "engine": engine, **data["environment"],
                "started": runs.started.iloc[0], "ended": runs.ended.iloc[-1],
                "invocations": [{"started": r.started, "ended": r.ended, "status": r.status,
                                 "git_commit": json.loads(r.environment).get("git_commit")}
                                for r in runs.itertuples()]}
    write_text(out_dir / "manifest.json", json.dumps(manifest, indent=2, default=str) + "\n")
    if figures:
        _figures(out_dir, data, s, bins, fails, regime_bins, board)
    return {"summary": s, "comparisons": comp, "calibration": cal, "leaderboard": board, "budget_note": budget}


def budget_note(data: dict) -> str | None:
    """A line for the report when plans stopped at their time budget (status 'budget'), or
    were killed past their deadline ('overtime') or by their memory limit or a signal
    ('crashed'): such a plan's grasp, or its having none, depends on how fast the machine
    ran it and on how much memory each worker had, so its rows may differ with other
    workers or on another machine (docs/experiments.md, "Reproducible across machines");
    None when no plan did."""
    plans = data["plans"]
    parts = []
    for statuses, what in ((("budget",), "stopped at their time budget"),
                           (("overtime", "crashed"), "were killed past their deadline or by their memory limit")):
        stopped = plans[plans.status.isin(statuses)]
        if len(stopped):
            counts = ", ".join(f"{p} {n}" for p, n in stopped.planner.value_counts().sort_index().items())
            parts.append(f"{len(stopped)} of {len(plans)} plans {what} ({counts})")
    if not parts:
        return None
    return ("; ".join(parts) + ": their grasps depend on this machine's speed, memory and load, so their rows may "
            "differ with other workers or on another machine; a larger time_budget_s removes that for planners "
            "that finish on their own.")


def _leaderboard_latex(board: pd.DataFrame) -> str:
    """booktabs table of the leaderboard; the best planner's row in bold."""
    shown = leaderboard_table(board)
    lines = [r"\begin{tabular}{rl" + "r" * (shown.shape[1] - 2) + "}", r"\toprule",
             " & ".join(_tex(c) for c in shown.columns) + r" \\", r"\midrule"]
    for _, row in shown.iterrows():
        cells = [_tex(v) for v in row]
        if row["rank"] == "1":
            cells = [r"\textbf{" + c + "}" for c in cells]
        lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", ""]
    return "\n".join(lines)


def _figures(out_dir, data, summary, bins, fails, regime_bins=None, board=None) -> list:
    """Write the report's PNGs into ``out_dir/figures``; returns their paths."""
    import matplotlib.pyplot as plt

    from harness import plots
    from harness.belief import build_belief
    from harness.seeding import stream
    from harness.tasks import scene_of, settings_of

    folder = Path(out_dir) / "figures"
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise InputError(str(folder), None, "is not a folder of this run's (a symbolic link or a file); remove it")
    folder.mkdir(exist_ok=True)
    written = []

    def save(fig, name):
        try:
            written.append(write_atomic(folder / name, lambda tmp: fig.savefig(tmp, dpi=110, format="png")))
        finally:
            plt.close(fig)

    per_scene = summary[summary.scene != "all"]
    save(plots.success_figure(per_scene), "success.png")
    if not fails.empty:
        save(plots.failures_figure(fails), "failures.png")
    save(plots.calibration_figure(bins), "calibration.png")
    if board is not None and not board.empty:
        save(plots.leaderboard_figure(board), "leaderboard.png")
    if regime_bins is not None and not regime_bins.empty:
        save(plots.calibration_by_regime_figure(regime_bins), "calibration-by-regime.png")
    bench_file = Path(out_dir) / "bench-planning.json"
    study = None
    if bench_file.is_file():  # written by: gpis-harness bench planning --json > DIR/bench-planning.json
        bench = json.loads(bench_file.read_text())
        if bench.get("convergence"):
            save(plots.convergence_figure(bench), "convergence.png")
        save(plots.runtime_figure(bench), "runtime.png")
        study = bench.get("bandit")
    bandit_file = Path(out_dir) / "bench-bandit.json"
    if bandit_file.is_file():  # written by: gpis-harness bench bandit --json > DIR/bench-bandit.json
        study = json.loads(bandit_file.read_text())
    if study and study.get("runs"):
        save(plots.bandit_figure(study), "bandit.png")
    config = ExperimentConfig.from_dict(data["config"])
    plans = data["plans"]
    for path in config.scenes:
        scene = scene_of(config, path)
        belief = build_belief(scene, stream(config.seed, scene.name, 0, "sensor"))
        rows = plans[(plans.scene == scene.name) & (plans.realisation == 0)].set_index("planner")
        grasps = {}
        for entry in config.planners:
            row = rows.loc[entry.label] if entry.label in rows.index else None
            ok = row is not None and pd.notna(row.g1x)  # a plan without a grasp reads as NaN or None
            grasps[entry.label] = ((row.g1x, row.g1y), (row.g2x, row.g2y)) if ok else None
        fig = plots.grasps_figure(belief, grasps, stream(config.seed, scene.name, 0, "blur"),
                                  settings_of(config, path).jaw_width,
                                  title=f"{scene.name}, realisation 0: GPIS-Blur and the planners' grasps\n"
                                        "blue dashed: true shape; bars: jaw plates at their start points")
        save(fig, f"grasps-{scene.name}.png")
    return written
