"""The report's P_L columns on a synthetic ledger: pooled P_F and P_L in the summary,
calibration per metric (Brier over trials and Spearman over plans, against a direct
computation), the analytic verdicts against the physical outcomes, and the planner
comparisons a config with lift variants gets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from harness.ledger import FILENAME, Ledger
from harness.report import (budget_note, calibration, comparison_pairs, comparisons, leaderboard, leaderboard_table,
                            load, reasons, summary)

SCENES = ("alpha", "beta")
PLANNERS = ("mean-shape", "gp-p")
POSTERIOR, TRUTH, DRAWS = 40, 10, 200


def _config() -> dict:
    return {"name": "synthetic", "source": "synthetic.toml", "seed": 0, "realisations": 3,
            "scenes": [f"/nowhere/{s}.toml" for s in SCENES],
            "planners": [{"label": p, "name": p, "params": {}} for p in PLANNERS],
            "analytic_draws": DRAWS, "posterior_trials": POSTERIOR, "truth_trials": TRUTH, "time_budget_s": 10.0,
            "settings": {}, "physics": {}, "batch_size": 16}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Plans whose P_L sets their trials' success rate (P_F does not), and per-draw
    verdicts that say 'lifted' exactly for the successful trials but for a known few."""
    folder = tmp_path_factory.mktemp("report")
    rng = np.random.default_rng(11)
    plans, analytic, trials = [], [], []
    for s in SCENES:
        for r in range(3):
            for p in PLANNERS:
                p_l = float(rng.uniform(0.1, 0.95))
                p_f = float(rng.uniform(0.9, 1.0))
                success = rng.random(POSTERIOR) < p_l
                verdicts = np.where(success, "lifted", "weight_torque")
                verdicts[:2] = ["friction_cone", "lifted"]
                plans.append({"scene": s, "realisation": r, "planner": p, "planner_name": p, "params": "{}",
                              "status": "ok", "executed": 1, "message": "", "g1x": -0.03, "g1y": 0.0, "g2x": 0.03,
                              "g2y": 0.0, "estimate": 0.5, "plan_time_s": 0.1, "iterations": 1, "evaluations": 1,
                              "trace": "[]"})
                analytic.append({"scene": s, "realisation": r, "planner": p, "draws": DRAWS, "p_f": p_f,
                                 "ci_low": p_f - 0.01, "ci_high": min(1.0, p_f + 0.01), "ferrari_canny_mean": 0.1,
                                 "failures": "{}", "p_l": round(p_l * DRAWS) / DRAWS, "p_l_ci_low": 0.0,
                                 "p_l_ci_high": 1.0, "pivots": 0, "reasons": ",".join(verdicts)})
                for i in range(POSTERIOR):
                    trials.append({"scene": s, "realisation": r, "planner": p, "shapes": "posterior", "trial": i,
                                   "outcome": "success" if success[i] else "slipped", "steps": 1,
                                   "grip_width": None, "closing_turn": None, "rise": None, "pivot": None})
                for i in range(TRUTH):
                    trials.append({"scene": s, "realisation": r, "planner": p, "shapes": "truth", "trial": i,
                                   "outcome": "success", "steps": 1, "grip_width": None, "closing_turn": None,
                                   "rise": None, "pivot": None})
    with Ledger(folder / FILENAME) as ledger:
        number = ledger.start_run("h", "synthetic", _config(), {})
        ledger.add("h", {"plans": plans, "analytic": analytic, "trials": trials})
        ledger.end_run(number, "complete")
    return load(folder)


def test_the_summary_pools_p_l_over_the_plans_draws(run):
    s = summary(run)
    a = run["analytic"]
    for planner in PLANNERS:
        row = s[(s.scene == "all") & (s.planner == planner)].iloc[0]
        mine = a[a.planner == planner]
        assert row.p_l == pytest.approx((mine.p_l * DRAWS).sum() / (DRAWS * len(mine)), abs=1e-12)
        # The interval is Wilson's over the pooled draws (scipy's implementation).
        wilson = stats.binomtest(round((mine.p_l * DRAWS).sum()), DRAWS * len(mine)).proportion_ci(method="wilson")
        assert (row.p_l_ci_low, row.p_l_ci_high) == (pytest.approx(wilson.low, abs=1e-9),
                                                     pytest.approx(wilson.high, abs=1e-9))
        assert row.p_l_ci_low < row.p_l < row.p_l_ci_high


def test_a_plan_that_failed_counts_as_p_f_and_p_l_zero_over_the_configs_draws(run):
    """A planner that returned no grasp (executed 0, no analytic row, no trials) still counts
    in its pooled P_F and P_L, at 0 over the experiment's analytic draws, so a planner
    that fails often is not ranked on its successes alone."""
    key = ("beta", 1, "gp-p")
    at = lambda frame: (frame.scene == key[0]) & (frame.realisation == key[1]) & (frame.planner == key[2])  # noqa: E731
    plans = run["plans"].copy()
    plans.loc[at(plans), "executed"] = 0
    failed = {**run, "plans": plans, "analytic": run["analytic"][~at(run["analytic"])],
              "trials": run["trials"][~at(run["trials"])]}
    row = summary(failed)
    row = row[(row.scene == "all") & (row.planner == "gp-p")].iloc[0]
    mine = failed["analytic"][failed["analytic"].planner == "gp-p"]
    for metric in ("p_f", "p_l"):
        expected = (mine[metric] * DRAWS).round().sum() / (DRAWS * (len(mine) + 1))  # each plan k of DRAWS
        assert row[metric] == pytest.approx(expected, abs=1e-12)
    assert row.plans_ok == f"{len(mine)}/{len(mine) + 1}" and not row.complete


def test_calibration_gives_brier_and_spearman_per_metric_as_computed_directly(run):
    """Over trials (the Brier score, the success rate) and over plans (Spearman), computed
    directly; also with plans of unequal trial counts (a run stopped part way), where the
    success pooled over trials is not the mean of the plans' rates."""
    uneven = run["trials"]
    uneven = uneven[~((uneven.realisation == 0) & (uneven.shapes == "posterior") & (uneven.trial >= 10))]
    for data in (run, {**run, "trials": uneven}):
        table, bins = calibration(data)
        assert set(table.metric) == {"p_f", "p_l"} and set(bins.metric) == {"p_f", "p_l"}
        post = data["trials"][data["trials"].shapes == "posterior"]
        joined = post.merge(data["analytic"], on=["scene", "realisation", "planner"])
        won = (joined.outcome == "success").astype(float)
        rate = joined.assign(s=won).groupby(["scene", "realisation", "planner"]).agg(
            s=("s", "mean"), p_f=("p_f", "first"), p_l=("p_l", "first"))
        for metric in ("p_f", "p_l"):
            row = table[(table.metric == metric) & (table.planner == "all")].iloc[0]
            assert row.brier == pytest.approx(((joined[metric] - won) ** 2).mean(), abs=1e-12)
            assert row.spearman == pytest.approx(stats.spearmanr(rate[metric], rate.s).statistic, abs=1e-12)
            assert row.success_rate == pytest.approx(won.mean(), abs=1e-12)
        p_l, p_f = (table[(table.metric == m) & (table.planner == "all")].iloc[0] for m in ("p_l", "p_f"))
        assert p_l.spearman > 0.8 and p_l.brier < p_f.brier  # the synthetic success follows P_L, not P_F
    assert abs(won.mean() - rate.s.mean()) > 1e-3  # the uneven run tells the two rates apart


def test_the_verdicts_of_the_draws_meet_their_trials_outcomes(run):
    table = reasons(run)
    overall = table[table.planner == "all"].drop(columns="planner").set_index("analytic")
    n_plans = len(SCENES) * 3 * len(PLANNERS)
    assert overall.loc["friction_cone"].sum() == n_plans  # draw 0 of every plan
    # Draws 2.. say 'lifted' exactly for the successes; draw 1 says 'lifted' whatever happened.
    post = run["trials"][run["trials"].shapes == "posterior"]
    assert overall.loc["lifted", "success"] == (post[post.trial >= 1].outcome == "success").sum()
    assert overall.loc["weight_torque", "slipped"] == (post[post.trial >= 2].outcome == "slipped").sum()
    assert overall.to_numpy().sum() == len(post)
    assert list(table.planner.unique()) == ["all", *PLANNERS]


def test_lifted_draws_the_weight_turned_get_their_own_row_before_the_failures(run):
    """Draw 1 of every plan relabelled 'lifted_turned' (harness.pipeline.verdict_label):
    its trials leave the 'lifted' row for a row of their own, between 'lifted' and the
    failure reasons; nothing else moves."""
    before = reasons(run)
    data = dict(run)
    data["analytic"] = run["analytic"].assign(
        reasons=[",".join("lifted_turned" if i == 1 else v for i, v in enumerate(r.split(",")))
                 for r in run["analytic"].reasons])
    table = reasons(data)
    overall = table[table.planner == "all"].drop(columns="planner").set_index("analytic")
    was = before[before.planner == "all"].drop(columns="planner").set_index("analytic")
    post = run["trials"][run["trials"].shapes == "posterior"]
    draw1 = post[post.trial == 1].outcome.value_counts()
    assert list(overall.index) == ["lifted", "lifted_turned", "friction_cone", "weight_torque"]
    for outcome, n in draw1.items():
        assert overall.loc["lifted_turned", outcome] == n
        assert overall.loc["lifted", outcome] == was.loc["lifted", outcome] - n
    assert (overall.loc["weight_torque"] == was.loc["weight_torque"]).all()


def test_a_drawn_verdict_is_labelled_by_its_reason_and_whether_the_weight_turned_it():
    from harness.pipeline import verdict_label
    from harness.quality import FAILURE_REASONS

    assert verdict_label(-1, False) == "lifted" and verdict_label(-1, True) == "lifted_turned"
    for k, name in enumerate(FAILURE_REASONS):
        assert verdict_label(k, True) == name == verdict_label(k, False)


def test_the_leaderboard_ranks_by_posterior_success_with_wilson_intervals_and_paired_differences(run):
    """Against direct computations: the order by pooled posterior success, the Wilson
    interval from its closed form, the difference against the best as the mean of the
    paired differences on the same trials, McNemar's p as the exact binomial test of the
    discordant pairs, and a bootstrap interval around the difference."""
    board = leaderboard(run)
    post = run["trials"][run["trials"].shapes == "posterior"]
    won = post.assign(s=post.outcome == "success")
    rates = won.groupby("planner").s.mean().sort_values(ascending=False)
    assert list(board.planner) == list(rates.index) and list(board["rank"]) == [1, 2]
    z = stats.norm.ppf(0.975)
    for r in board.itertuples():
        k, n = int(won[won.planner == r.planner].s.sum()), int((won.planner == r.planner).sum())
        centre = (k + z * z / 2) / (n + z * z)
        half = z * np.sqrt(k * (n - k) / n + z * z / 4) / (n + z * z)
        assert (r.trials, r.success_rate) == (n, pytest.approx(k / n, abs=1e-12))
        assert (r.success_ci_low, r.success_ci_high) == (pytest.approx(centre - half, abs=1e-9),
                                                         pytest.approx(centre + half, abs=1e-9))
    best, second = board.iloc[0], board.iloc[1]
    assert best.difference_vs_best == 0 and best.mcnemar_p == 1
    keys = ["scene", "realisation", "trial"]
    pairs = won[won.planner == second.planner][keys + ["s"]].merge(won[won.planner == best.planner][keys + ["s"]],
                                                                     on=keys)
    a, b = pairs.s_x.astype(int).to_numpy(), pairs.s_y.astype(int).to_numpy()
    assert second.difference_vs_best == pytest.approx((a - b).mean(), abs=1e-12)
    n10, n01 = int(((a == 1) & (b == 0)).sum()), int(((a == 0) & (b == 1)).sum())
    assert (second.only_planner, second.only_best) == (n10, n01)
    assert second.mcnemar_p == pytest.approx(stats.binomtest(n10, n10 + n01, 0.5).pvalue, abs=1e-12)
    assert second.difference_ci_low < second.difference_vs_best < second.difference_ci_high
    table = leaderboard_table(board)
    assert table["vs best (paired)"].iloc[0] == "best" and table["McNemar p"].iloc[0] == "–"


def test_plans_stopped_at_their_budget_are_counted_per_planner_in_a_note(run):
    """No note when every plan finished on its own; with some 'budget' plans, the note
    counts them (of all plans) per planner, since their grasps depend on the machine."""
    assert budget_note(run) is None
    plans = run["plans"].copy()
    plans.loc[plans.index[[0, 2, 3]], "status"] = "budget"
    stopped = plans.loc[plans.index[[0, 2, 3]], "planner"].value_counts()
    note = budget_note({**run, "plans": plans})
    assert note.startswith(f"3 of {len(plans)} plans stopped at their time budget (")
    assert ", ".join(f"{p} {n}" for p, n in stopped.sort_index().items()) in note
    # Plans killed at their deadline or by their memory limit depend on the machine too.
    plans.loc[plans.index[[5]], "status"] = "overtime"
    plans.loc[plans.index[[6]], "status"] = "crashed"
    killed = plans.loc[plans.index[[5, 6]], "planner"].value_counts()
    note = budget_note({**run, "plans": plans})
    assert note.startswith(f"3 of {len(plans)} plans stopped at their time budget (")
    assert (f"; 2 of {len(plans)} plans were killed past their deadline or by their memory limit ("
            + ", ".join(f"{p} {n}" for p, n in killed.sort_index().items()) + ")") in note


def test_lift_variants_are_compared_with_their_own_baseline_and_with_the_paper_quality():
    planners = [("mean-shape", "mean-shape", {}), ("gp-p", "gp-p", {}), ("gp-gpis-opt", "gp-gpis-opt", {}),
                ("mean-shape-lift", "mean-shape", {"quality": "lift"}), ("gp-p-lift", "gp-p", {"quality": "lift"}),
                ("gp-gpis-opt-lift", "gp-gpis-opt", {"quality": "lift"})]
    config = {"scenes": [], "realisations": 1,
              "planners": [{"label": lab, "name": name, "params": params} for lab, name, params in planners]}
    assert comparison_pairs(config) == [
        ("gp-p", "mean-shape"), ("gp-gpis-opt", "mean-shape"), ("gp-p-lift", "mean-shape-lift"),
        ("gp-gpis-opt-lift", "mean-shape-lift"), ("gp-gpis-opt", "gp-p"), ("gp-gpis-opt-lift", "gp-p-lift"),
        ("mean-shape-lift", "mean-shape"), ("gp-p-lift", "gp-p"), ("gp-gpis-opt-lift", "gp-gpis-opt")]


def test_comparisons_pool_both_shape_sources(run):
    comp = comparisons(run)
    pooled = comp[(comp.scene == "all") & (comp.shapes == "all")].iloc[0]
    post = comp[(comp.scene == "all") & (comp.shapes == "posterior")].iloc[0]
    truth = comp[(comp.scene == "all") & (comp.shapes == "truth")].iloc[0]
    assert pooled.pairs == post.pairs + truth.pairs
    assert pooled.difference == pytest.approx((post.difference * post.pairs + truth.difference * truth.pairs)
                                              / pooled.pairs, abs=1e-12)
    assert pooled.ci_low <= pooled.difference <= pooled.ci_high


def test_calibration_splits_by_regime_and_the_parts_pool_back():
    """The committed reference run (rectangle at friction 0.5, marker at 0.45) spans two
    regimes: each regime's P_L Brier is the direct mean over its trials, and the two,
    weighted by their trials, give the pooled Brier (a second formulation); a run whose
    scenes share one regime is not split."""
    from pathlib import Path

    from harness.report import calibration_by_regime, scene_regimes

    root = Path(__file__).resolve().parents[1]
    run = load(root / "results" / "reference")
    # The stored config names the scene files where the reference was made: use this clone's.
    run["config"] = {**run["config"], "scenes": [str(root / "scenes" / Path(s).name) for s in run["config"]["scenes"]]}
    regimes = scene_regimes(run["config"])
    assert regimes == {"rectangle": "force 20 N, friction 0.5, sigma_g 2.5 mm",
                       "marker": "force 20 N, friction 0.45, sigma_g 2.5 mm"}
    table, bins = calibration_by_regime(run)
    rows = table[(table.metric == "p_l") & (table.planner == "all")].set_index("regime")
    assert set(rows.index) == set(regimes.values()) and set(bins.regime) == set(regimes.values())
    post = run["trials"][run["trials"].shapes == "posterior"].merge(run["analytic"],
                                                                   on=["scene", "realisation", "planner"])
    won = (post.outcome == "success").astype(float)
    sq = (post.p_l - won) ** 2
    for scene, label in regimes.items():
        assert rows.loc[label, "brier"] == pytest.approx(sq[post.scene == scene].mean(), abs=1e-12)
    counts = post.scene.map(regimes).value_counts()
    pooled = sum(rows.loc[label, "brier"] * counts[label] for label in counts.index) / counts.sum()
    whole = calibration(run)[0]
    assert pooled == pytest.approx(whole[(whole.metric == "p_l") & (whole.planner == "all")].brier.iloc[0], abs=1e-12)
    one = {**run, "config": {**run["config"], "scenes": [s for s in run["config"]["scenes"] if "rectangle" in s]}}
    assert calibration_by_regime(one)[0].empty


def test_rank_shares_decompose_spearmans_shortfall_exactly_ties_included():
    """rho = 1 - sum((z_f - z_s)^2) / (2 (n - 1)) with z the standardised average ranks:
    against scipy's Spearman on data with ties (a second formulation) to 1e-12; the shares
    sum to 1; in a perfect ranking with two plans swapped the whole shortfall is theirs,
    half each; constant success gives NaN."""
    from harness.report import rank_shares

    rng = np.random.default_rng(3)
    for _ in range(20):
        n = int(rng.integers(5, 60))
        forecast = np.round(rng.random(n), 1)  # ties
        success = np.clip(forecast + rng.normal(0, 0.2, n), 0, 1).round(1)
        shares, rho = rank_shares(forecast, success)
        assert rho == pytest.approx(stats.spearmanr(forecast, success).statistic, abs=1e-12)
        assert shares.sum() == pytest.approx(1.0, abs=1e-12) and (shares >= 0).all()
    forecast = np.arange(10.0)
    success = forecast.copy()
    success[[3, 7]] = success[[7, 3]]
    shares, rho = rank_shares(forecast, success)
    assert shares[3] == pytest.approx(0.5) and shares[7] == pytest.approx(0.5)
    assert np.delete(shares, [3, 7]) == pytest.approx(0.0)
    assert np.isnan(rank_shares(forecast, np.ones(10))[0]).all()


def test_the_plan_table_gives_each_executed_plan_and_its_share_of_the_ranking_error():
    """calibration_plans.csv's table on the committed reference run: one row per executed
    plan, its success the share of its posterior trials that succeeded (counted directly);
    every plan succeeds there, so the shares are undefined (NaN); with one trial of one plan
    lost, the P_L shares are rank_shares of the plans' P_L and success and sum to 1, and the
    rho that decomposes is calibration.csv's pooled Spearman."""
    from pathlib import Path

    from harness.report import plan_calibration, rank_shares

    root = Path(__file__).resolve().parents[1]
    run = load(root / "results" / "reference")
    table = plan_calibration(run)
    executed = run["plans"][run["plans"].executed == 1]
    assert len(table) == len(executed)
    post = run["trials"][run["trials"].shapes == "posterior"]
    for row in table.itertuples():
        mine = post[(post.scene == row.scene) & (post.realisation == row.realisation) & (post.planner == row.planner)]
        assert row.trials == len(mine) and row.success_rate == pytest.approx((mine.outcome == "success").mean())
    assert (table.success_rate == 1.0).all() and table.p_l_rank_share.isna().all()
    trials = run["trials"].copy()
    lost = trials.index[(trials.shapes == "posterior") & (trials.scene == "marker") & (trials.planner == "gp-p")][0]
    trials.loc[lost, "outcome"] = "slipped"
    changed = {**run, "trials": trials}
    table = plan_calibration(changed)
    shares, rho = rank_shares(table.p_l, table.success_rate)
    assert table.p_l_rank_share.to_numpy() == pytest.approx(shares) and shares.sum() == pytest.approx(1.0)
    pooled = calibration(changed)[0]
    assert rho == pytest.approx(pooled[(pooled.metric == "p_l") & (pooled.planner == "all")].spearman.iloc[0])


@pytest.mark.parametrize(("change", "field"), [
    ("config = '{}'", "runs.config.seed"),
    ("config = '[1, 2]'", "runs.config"),
    ("config = json_remove(config, '$.scenes')", "runs.config.scenes"),
    ("config = json_set(config, '$.posterior_trials', 'a')", "runs.config.posterior_trials"),
    ("config = json_set(config, '$.planners', json('[{\"name\": \"gp-p\"}]'))", "runs.config.planners"),
    ("config = json_set(config, '$.physics', json('[1]'))", "runs.config.physics"),
    ("environment = '[]'", "runs.environment"),
])
def test_a_stored_run_of_the_wrong_structure_is_one_line(tmp_path, capsys, change, field):
    """The ledger checks its columns' types; the JSON of a run's config and environment is
    checked on reading: a folder whose stored run has another structure (edited, or written
    by something else) is one line naming the field for report and compare, exit 2."""
    import shutil
    import sqlite3

    from harness.cli import main

    reference = Path(__file__).resolve().parent.parent / "results" / "reference"
    good, bad = tmp_path / "good", tmp_path / "bad"
    for folder in (good, bad):
        shutil.copytree(reference, folder, ignore=shutil.ignore_patterns("figures", "*.lock"))
    with sqlite3.connect(bad / "ledger.sqlite") as db:
        db.execute(f"UPDATE runs SET {change}")
    for argv in (["report", str(bad), "--no-figures"], ["compare", str(good), str(bad)]):
        assert main(argv) == 2, argv
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"gpis-harness: error: {bad / 'ledger.sqlite'}: {field}: "), \
            lines
    assert main(["report", str(good), "--no-figures"]) == 0  # the untouched copy reads as ever


def test_the_tables_do_not_depend_on_the_order_the_trials_were_recorded_in(run, tmp_path):
    """Workers record trial batches in the order they finish; the report reads them in the
    order of their key, so a ledger whose rows went in shuffled gives the same tables (the
    bootstrap intervals and the retest pick trials by position). SQLite's planner reads
    them through the key's index today even without the ledger's ORDER BY; the ORDER BY
    makes that a contract, and this test keeps it one."""
    rng = np.random.default_rng(3)
    folder = tmp_path / "shuffled"
    folder.mkdir()
    rows = {name: run[name].to_dict("records") for name in ("plans", "analytic", "trials")}
    for name in rows:
        rows[name] = [rows[name][k] for k in rng.permutation(len(rows[name]))]
    for row in rows["trials"]:
        row.update({k: None for k in ("grip_width", "closing_turn", "rise", "pivot") if row[k] != row[k]})
    with Ledger(folder / FILENAME) as ledger:
        number = ledger.start_run("h", "synthetic", _config(), {})
        for start in range(0, len(rows["trials"]), 50):  # in several transactions, as batches are
            ledger.add("h", {"trials": rows["trials"][start:start + 50]})
        ledger.add("h", {"plans": rows["plans"], "analytic": rows["analytic"]})
        ledger.end_run(number, "complete")
    shuffled = load(folder)
    assert shuffled["trials"].equals(run["trials"])
    pd.testing.assert_frame_equal(comparisons(shuffled), comparisons(run))
    pd.testing.assert_frame_equal(calibration(shuffled)[0], calibration(run)[0])
    pd.testing.assert_frame_equal(leaderboard(shuffled), leaderboard(run))


def test_a_reliability_bin_holds_the_estimates_at_its_lower_edge(run):
    """Bins of a tenth, [k/10, (k+1)/10): an estimate of exactly 0.3, 0.6 or 0.7 (60 of 200
    draws, say) is in the bin it opens (with edges from linspace, 0.3 fell below)."""
    analytic = run["analytic"].copy()
    for k, value in enumerate((0.3, 0.6, 0.7)):
        analytic.loc[analytic.index[k], "p_l"] = value
    _, bins = calibration({**run, "analytic": analytic})
    p_l = bins[bins.metric == "p_l"]
    # Each plan's bin counted in decimal arithmetic, where 0.3 is 0.3.
    from collections import Counter
    from decimal import Decimal

    expected = Counter(min(int(Decimal(repr(v)) * 10), 9) for v in analytic.p_l)
    assert {round(low * 10): n for low, n in zip(p_l.bin_low, p_l.plans) if n} == dict(expected)
    for value in (0.3, 0.6, 0.7):
        assert p_l[p_l.bin_low == value].bin_high.iloc[0] == pytest.approx(value + 0.1, abs=1e-12)


def test_the_bootstrap_of_a_small_plan_has_the_unbiased_variance():
    """Resampling a plan's n trials gives their mean the variance (n - 1)/n s^2/n; the
    rescaled values (Rao and Wu) give s^2/n, the unbiased variance of the mean, which a
    plan of 4 true-shape trials falls short of by a quarter otherwise. Checked on the
    bootstrap's own replicates (2,000: the variance within 10 %, its Monte-Carlo error
    about 3 %), with the mean kept."""
    from harness.report import BOOTSTRAP, _bootstrap_means, rescaled

    d = np.array([1.0, 0.0, 0.0, -1.0, 1.0, 1.0, 0.0, 1.0])  # two plans of 4 trials
    groups = [np.arange(4), np.arange(4, 8)]
    boot = _bootstrap_means(d, groups, np.random.default_rng(1))
    assert len(boot) == BOOTSTRAP
    unbiased = sum(d[g].var(ddof=1) * len(g) for g in groups) / len(d) ** 2  # var of the pooled mean
    assert boot.var() == pytest.approx(unbiased, rel=0.10)
    assert boot.var() > 1.15 * sum(d[g].var(ddof=0) * len(g) for g in groups) / len(d) ** 2  # not the biased one
    for g in groups:
        assert rescaled(d[g]).mean() == pytest.approx(d[g].mean(), abs=1e-15)
    assert rescaled(np.array([0.5])).tolist() == [0.5]


def test_another_planner_in_the_report_leaves_the_others_intervals_as_they_were(run):
    """Each interval draws its bootstrap from a stream of its own (seed, the pair, the
    shape source, the scene): a planner added to an experiment, a plugin under development
    say, listed before the others, leaves the baselines' comparisons bit for bit (with one
    stream for the whole table, its pairs took the others' random numbers)."""
    extra = run["trials"][run["trials"].planner == "gp-p"].assign(planner="extra")
    extra.loc[extra.index[::3], "outcome"] = "dropped"
    config = dict(run["config"])
    config["planners"] = [config["planners"][0], {"label": "extra", "name": "gp-p", "params": {"x": 1}},
                          *config["planners"][1:]]
    more = {**run, "config": config, "trials": pd.concat([run["trials"], extra], ignore_index=True),
            "plans": pd.concat([run["plans"], run["plans"][run["plans"].planner == "gp-p"].assign(planner="extra")]),
            "analytic": pd.concat([run["analytic"],
                                   run["analytic"][run["analytic"].planner == "gp-p"].assign(planner="extra")])}
    before, after = comparisons(run), comparisons(more)
    assert set(after.planner) == {"gp-p", "extra"}
    kept = after[(after.planner == "gp-p") & (after.versus == "mean-shape")].reset_index(drop=True)
    pd.testing.assert_frame_equal(kept, before.reset_index(drop=True))
    assert (kept.ci_high > kept.ci_low).any()  # real intervals, not all of zero width
