"""The regime sweep (harness.bench.regimes_study, `gpis-harness bench regimes`): its
objects are valid scenes of the size asked for, and its per-regime statistics agree with
the same numbers computed directly from the trials of a small sweep."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from harness.bench import regimes_study as rs
from harness.bench.regime_objects import FAMILIES, objects
from harness.report import load, retest_spearman
from harness.scene import load_scene

PLANNERS = [{"name": "mean-shape", "label": "mean-shape-lift", "params": {"quality": "lift", "candidates": 20}},
            {"name": "gp-gpis-opt", "label": "gp-gpis-opt-lift",
             "params": {"quality": "lift", "initialisations": 2, "screen": 10, "max_iterations": 5}},
            {"name": "gp-p", "label": "gp-p-lift", "params": {"quality": "lift", "candidates": 10, "samples": 30}}]
REGIMES = (rs.CENTRE, rs.REGIMES[1], rs.REGIMES[-2])  # centre, weak and a held-out regime
OBJECTS = objects(per_family=2, held_out_every=2, families=("tool", "letter"))


def test_objects_are_scenes_of_their_size(tmp_path):
    """Every object of the default sweep is a valid scene at each size the regimes use;
    its longest extent (the hull's diameter) is 0.7-1.25 times the size; the same object is written the same
    way twice; one in four is held out, in every family."""
    everything = objects()
    assert len(everything) == 24 and {o.family for o in everything} == set(FAMILIES)
    assert sum(o.held_out for o in everything) == 6
    assert [o.name for o in everything if o.held_out] == [f"{f}_3" for f in FAMILIES]
    for size, density in {(r.size, r.density) for r in rs.REGIMES}:
        for obj in everything:
            path = tmp_path / f"{obj.name}.toml"
            path.write_text(obj.scene_text(size, density))
            scene = load_scene(path)
            hull = np.asarray(scene.shape.convex_hull.exterior.coords)
            longest = np.linalg.norm(hull[:, None] - hull[None], axis=-1).max()
            assert 0.7 * size <= longest <= 1.25 * size, (obj.name, size, longest)
            assert scene.physics.density == density and scene.physics.thickness == pytest.approx(0.3 * size)
    again = objects()
    assert [o.scene_text(0.11, 1000.0) for o in again] == [o.scene_text(0.11, 1000.0) for o in everything]


def test_the_fresh_objects_are_other_shapes_all_held_out(tmp_path):
    """bench regimes --objects fresh: numbers 4-7 of each family, every one held out, none
    the same shape as a sweep object, each a valid scene of its size; the CLI's choices are
    the object sets."""
    from harness.bench.regime_objects import OBJECT_SETS, fresh_objects
    from harness.cli import build_parser

    fresh, sweep = fresh_objects(), objects()
    assert len(fresh) == 24 and all(o.held_out for o in fresh)
    assert sorted(o.name for o in fresh) == sorted(f"{f}_{k}" for f in FAMILIES for k in range(4, 8))
    assert not {repr(o.shape) for o in fresh} & {repr(o.shape) for o in sweep}  # the outlines' parameters
    for obj in fresh:
        path = tmp_path / f"{obj.name}.toml"
        path.write_text(obj.scene_text(0.11, 1000.0))
        hull = np.asarray(load_scene(path).shape.convex_hull.exterior.coords)
        assert 0.7 * 0.11 <= np.linalg.norm(hull[:, None] - hull[None], axis=-1).max() <= 1.25 * 0.11, obj.name
    args = build_parser().parse_args(["bench", "regimes", "--objects", "fresh"])
    assert args.objects == "fresh" and set(OBJECT_SETS) == {"sweep", "fresh"}
    assert rs.default_folder("fresh") != rs.default_folder("sweep") == Path("results/regimes")


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("regimes")
    result = rs.run(out, workers=2, regimes=REGIMES, objects=OBJECTS, planners=PLANNERS, posterior_trials=6,
                    truth_trials=2, analytic_draws=60, log=lambda line: None)
    return out, result


def _direct(out, regime: str, scenes) -> dict:
    """The statistics of one regime's part, computed here from the ledger's rows."""
    data = load(out / "pybullet" / regime)
    plans = data["plans"][data["plans"].scene.isin(scenes) & (data["plans"].executed == 1)]
    trials = data["trials"][data["trials"].scene.isin(scenes)]
    post = trials[trials.shapes == "posterior"].assign(s=lambda t: (t.outcome == "success").astype(float))
    rate = post.groupby(["scene", "planner"]).s.mean()
    est = plans.merge(data["analytic"], on=["scene", "realisation", "planner"]).set_index(["scene", "planner"]).p_l
    est, rate_ = est.align(rate, join="inner")
    brier = float(((est.reindex(pd.MultiIndex.from_frame(post[["scene", "planner"]])).to_numpy()
                    - post.s.to_numpy()) ** 2).mean())
    wide = post.pivot_table(index=["scene", "trial"], columns="planner", values="s")
    varied = est.nunique() > 1 and rate_.nunique() > 1
    return {"p_l_spearman": stats.spearmanr(est, rate_).statistic if varied else math.nan, "p_l_brier": brier,
            "diff": {p: float((wide[p] - wide["mean-shape-lift"]).mean()) for p in rs.LIFT_PLANNERS},
            "share": float((rate < 0.9).mean()), "success": float(post.s.mean())}


def test_regime_rows_match_the_trials(sweep):
    """Spearman, Brier, the share of plans below 0.9, success and the paired differences
    of every row equal the same statistics computed directly from the trials (to 1e-9);
    each part holds the objects it should; each interval holds its difference."""
    out, result = sweep
    rows = pd.DataFrame(result["rows"])
    assert set(rows.regime) == {r.name for r in REGIMES}
    held = {o.name for o in OBJECTS if o.held_out}
    spearmans = 0
    for r in result["rows"]:
        regime = next(g for g in REGIMES if g.name == r["regime"])
        names = {o.name for o in OBJECTS}
        scenes = {"all": names, "design": names - held,
                  "held_out": names if regime.held_out else held}[r["part"]]
        assert r["objects"] == len(scenes)
        direct = _direct(out, r["regime"], scenes)
        if not math.isnan(direct["p_l_spearman"]):
            spearmans += 1
            assert r["p_l_spearman"] == pytest.approx(direct["p_l_spearman"], abs=1e-9)
        assert r["p_l_brier"] == pytest.approx(direct["p_l_brier"], abs=1e-9)
        assert r["share_below_0_9"] == pytest.approx(direct["share"], abs=1e-12)
        assert r["success_rate"] == pytest.approx(direct["success"], abs=1e-12)
        assert r["varies"] == (direct["share"] >= rs.VARIES_SHARE)
        for p in rs.LIFT_PLANNERS:
            assert r[f"diff:{p}"] == pytest.approx(direct["diff"][p], abs=1e-12)
            assert r[f"diff_low:{p}"] <= r[f"diff:{p}"] + 1e-12 <= r[f"diff_high:{p}"] + 2e-12
    assert spearmans >= 2  # the comparison ran on rows where both P_L and success vary
    assert not {"design"} & set(rows[rows.regime_held_out].part)


def test_pooled_difference_is_the_trial_weighted_mean(sweep):
    """The difference pooled over the sweep is the mean over every paired posterior trial
    of every regime, computed here from the ledgers (each regime's pairs counted from its
    trials, not assumed), and so the per-regime differences weighted by those pairs."""
    out, result = sweep
    rows = pd.DataFrame(result["rows"]).set_index(["regime", "part"])
    names = {o.name for o in OBJECTS}
    for p in rs.LIFT_PLANNERS:
        paired, weights = [], []
        for regime in REGIMES:
            post = load(out / "pybullet" / regime.name)["trials"].query("shapes == 'posterior'")
            wide = post.assign(s=(post.outcome == "success").astype(float)).pivot_table(
                index=["scene", "trial"], columns="planner", values="s")
            diff = (wide[p] - wide["mean-shape-lift"]).dropna()
            assert set(diff.index.get_level_values("scene")) == names
            paired.append(diff.to_numpy())
            weights.append((rows.loc[(regime.name, "all"), f"diff:{p}"], len(diff)))
        every = np.concatenate(paired)
        pooled = result["pooled"]["pybullet"]["all"][p]
        assert pooled["pairs"] == len(every) == sum(n for _, n in weights)
        assert pooled["difference"] == pytest.approx(float(every.mean()), abs=1e-12)
        weighted = sum(d * n for d, n in weights) / sum(n for _, n in weights)
        assert pooled["difference"] == pytest.approx(weighted, abs=1e-12)
        assert pooled["ci_low"] <= pooled["difference"] <= pooled["ci_high"]
    assert any(result["pooled"]["pybullet"]["all"][p]["difference"] != 0 for p in rs.LIFT_PLANNERS)


def test_outputs_and_the_command_line(sweep, tmp_path):
    """regimes.csv and the regime map are written; a second run resumes (no new trial)
    and gives the same rows; a bad --engines is one line and exit code 2."""
    out, result = sweep
    assert (out / "regimes.csv").is_file() and (out / "regime_map.png").stat().st_size > 10_000
    again = rs.run(out, workers=1, regimes=REGIMES, objects=OBJECTS, planners=PLANNERS, posterior_trials=6,
                   truth_trials=2, analytic_draws=60, log=lambda line: None)
    pd.testing.assert_frame_equal(pd.DataFrame(again["rows"]), pd.DataFrame(result["rows"]))
    text = "\n".join(rs.format_lines(result))  # a part of the sweep says which regimes it pooled
    assert "pooled over centre, weak, weak-slippery-noisy (design)" in text and "over the sweep" not in text
    whole = {**result, "regimes": [{"name": r.name} for r in rs.REGIMES]}
    assert "pooled over the sweep (design)" in "\n".join(rs.format_lines(whole))
    bad = subprocess.run([sys.executable, "-m", "harness", "bench", "regimes", "--engines", "bullet",
                          "--out", str(tmp_path / "x")], capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "--engines" in bad.stderr


def test_plans_stopped_at_their_budget_are_counted_and_reported(sweep):
    """A plan that stopped at its time budget depends on how fast the machine ran it: each
    row counts its part's such plans (none in the tiny sweep, whose plans finish on their
    own), and the text report names the regimes and parts that have any."""
    out, result = sweep
    assert all(r["budget_stops"] == 0 for r in result["rows"])
    assert "stopped at their time budget" not in "\n".join(rs.format_lines(result))
    regime = REGIMES[0]
    data = load(out / "pybullet" / regime.name)
    plans = data["plans"]
    stopped = plans.index[plans.scene == plans.scene.iloc[0]][:2]
    data["plans"].loc[stopped, "status"] = "budget"
    names = sorted(plans.scene.unique())
    row = rs._regime_row(data, names)
    assert row["budget_stops"] == 2
    assert rs._regime_row(data, [n for n in names if n != plans.scene.iloc[0]])["budget_stops"] == 0
    rows = [dict(r, budget_stops=2) if r["regime"] == regime.name and r["part"] == "all" else r
            for r in result["rows"]]
    rows.append({**rows[0], "regime": regime.name, "part": "design", "budget_stops": 2})
    line = [t for t in rs.format_lines({**result, "rows": rows}) if "stopped at their time budget" in t]
    assert len(line) == 1 and line[0].endswith(f": {regime.name} design 2")  # the 'all' part is not repeated


def test_verdict_rows_agree_with_the_draws_judged_again(sweep):
    """verdicts.csv: per engine, regime and part, the trials of each verdict sum to the
    part's posterior trials, and each verdict's count and success equal those found by
    judging every trial's own draw again (harness.explain.trial_draws: the cells opened
    anew, not the ledger's verdicts), to 1e-12."""
    from harness.explain import trial_draws

    out, result = sweep
    table = pd.read_csv(out / "verdicts.csv")
    assert len(table) == len(result["verdicts"]) and set(table.engine) == {"pybullet"}
    held = {o.name for o in OBJECTS if o.held_out}
    names = {o.name for o in OBJECTS}
    for regime in REGIMES:
        draws = trial_draws(out / "pybullet" / regime.name)
        for part, g in table[table.regime == regime.name].groupby("part"):
            scenes = {"all": names, "design": names - held, "held_out": names if regime.held_out else held}[part]
            mine = draws[draws.scene.isin(scenes)]
            assert g.trials.sum() == len(mine) == len(scenes) * len(PLANNERS) * 6
            direct = mine.assign(s=mine.outcome == "success").groupby("verdict").s.agg(["size", "mean"])
            got = g.set_index("verdict")
            assert set(got.index) == set(direct.index)
            for v in direct.index:
                assert got.loc[v, "trials"] == direct.loc[v, "size"]
                assert got.loc[v, "success"] == pytest.approx(direct.loc[v, "mean"], abs=1e-12)
            shares = [c for c in g.columns if c.startswith("share:")] + ["success"]
            assert np.allclose(g[shares].fillna(0).sum(axis=1), 1.0, atol=1e-12)


def _posterior(rates: np.ndarray, n: int, rng) -> pd.DataFrame:
    """Posterior trials of len(rates) plans, n each, success drawn at each plan's rate."""
    wins = rng.random((len(rates), n)) < rates[:, None]
    return pd.DataFrame({"scene": np.repeat([f"s{k}" for k in range(len(rates))], n), "realisation": 0,
                         "planner": "p", "outcome": np.where(wins.ravel(), "success", "slipped")})


def test_the_brier_floor_is_the_expected_score_of_the_true_rates():
    """Simulated: plans with known success rates, 24 trials each; the floor estimated from
    the trials averages, over 400 repetitions, to the expected Brier score of the true
    rates, mean p (1 - p) (within 0.002; the plug-in s (1 - s) is low by a factor 23/24)."""
    rng = np.random.default_rng(5)
    rates = rng.uniform(0.3, 1.0, 60)
    floors = [rs.brier_floor(_posterior(rates, 24, rng)) for _ in range(400)]
    assert np.mean(floors) == pytest.approx(np.mean(rates * (1 - rates)), abs=0.002)
    assert rs.brier_floor(_posterior(np.array([1.0, 0.0]), 24, rng)) == 0.0


def test_the_retest_spearman_is_what_a_second_run_of_the_trials_reaches():
    """Simulated: plans with known success rates, 24 trials each; the split-half estimate
    from one run averages, over 60 repetitions, to the Spearman between two independent
    runs of the same plans (simulated beside it): within 0.03 where success varies much
    (rates 0.3-1: about 0.8), within 0.06 where it barely does (0.9-1: about 0.3, far
    below the 0.7 target; there one run's Spearman spreads by +-0.12, so the two means
    differ by about 0.02 by chance, and halves of 12 trials are coarse). The plans' true
    rates as the estimate reach about its square root, within the same tolerances."""
    rng = np.random.default_rng(8)
    for low, expected_range, tolerance in ((0.3, (0.65, 0.95), 0.03), (0.9, (0.1, 0.45), 0.06)):
        rates = rng.uniform(low, 1.0, 80)
        estimated, actual, perfect = [], [], []
        for _ in range(60):
            first, second = _posterior(rates, 24, rng), _posterior(rates, 24, rng)
            estimated.append(retest_spearman(first, repeats=16))
            a, b = (run.assign(s=run.outcome == "success").groupby("scene").s.mean() for run in (first, second))
            actual.append(stats.spearmanr(a, b).statistic)
            perfect.append(stats.spearmanr(rates, a.reindex([f"s{k}" for k in range(len(rates))])).statistic)
        assert np.mean(estimated) == pytest.approx(np.mean(actual), abs=tolerance)
        # the true rates as the estimate reach about its square root
        assert np.sqrt(np.mean(estimated)) == pytest.approx(np.mean(perfect), abs=tolerance)
        assert expected_range[0] < np.mean(actual) < expected_range[1]
    assert math.isnan(retest_spearman(_posterior(np.array([1.0, 1.0, 1.0]), 24, rng)))  # never varies


def test_calibration_gives_each_planner_the_retest_of_its_own_trials():
    """calibration.csv's retest_spearman: per planner the statistic of that planner's
    trials, for 'all' of every trial, the same for P_F's and P_L's rows."""
    from harness.report import ALL, calibration

    rng = np.random.default_rng(9)
    runs = []
    for planner in ("a", "b"):
        post = _posterior(rng.uniform(0.3, 1.0, 12), 24, rng).assign(planner=planner, shapes="posterior")
        runs.append(post)
    trials = pd.concat(runs, ignore_index=True)
    plans = trials[["scene", "realisation", "planner"]].drop_duplicates().assign(executed=1)
    analytic = plans.drop(columns="executed").assign(p_f=rng.random(len(plans)), p_l=rng.random(len(plans)))
    cal, _ = calibration({"plans": plans, "analytic": analytic, "trials": trials})
    for planner, part in (("a", runs[0]), ("b", runs[1]), (ALL, trials)):
        rows = cal[cal.planner == planner]
        assert len(rows) == 2 and rows.retest_spearman.nunique() == 1
        assert rows.retest_spearman.iloc[0] == pytest.approx(retest_spearman(part), abs=1e-12)
    assert cal.retest_spearman.iloc[0] > 0.5  # 12 plans at rates 0.3-1, 24 trials each: a measurable ranking


def test_the_engine_yardstick_scores_one_run_by_the_others_rates_at_the_same_grasps():
    """The same trials in both runs: Spearman 1 and the Brier score of each plan's own rate,
    mean s (1 - s) over trials (closed form); a plan executed at another grasp in the other
    run is left out."""
    rng = np.random.default_rng(6)
    post = _posterior(np.linspace(0.2, 1.0, 12), 20, rng)
    plans = pd.DataFrame({"scene": [f"s{k}" for k in range(12)], "realisation": 0, "planner": "p",
                          "g1x": 0.0, "g1y": 0.0, "g2x": 0.05, "g2y": 0.0})
    s = (post.outcome == "success").groupby(post.scene).mean()
    got = rs.engine_yardstick(post, post, plans, plans)
    assert got["engine_spearman"] == pytest.approx(1.0)
    assert got["engine_brier"] == pytest.approx(float((s * (1 - s)).mean()), abs=1e-12)
    moved = plans.assign(g1x=np.where(plans.scene == "s0", 0.01, 0.0))
    rest = post[post.scene != "s0"]
    s_rest = s.drop("s0")
    assert rs.engine_yardstick(post, post, plans, moved)["engine_brier"] == pytest.approx(
        float((s_rest * (1 - s_rest)).mean()), abs=1e-12)
    assert rs.engine_yardstick(rest, rest, plans, plans)["engine_brier"] == pytest.approx(
        float((s_rest * (1 - s_rest)).mean()), abs=1e-12)


def test_a_second_engine_adopts_the_first_engines_plans(sweep, tmp_path):
    """MuJoCo's run of a regime adopts the plans pybullet made of it (no plan made again)
    and gives the rows of a MuJoCo run that planned for itself: every plan, analytic row
    and trial the same. Experiments that differ in more than the engine are refused."""
    from harness.config import parse_config
    from harness.experiment import adopt_plans

    out, _ = sweep
    weak, lines = REGIMES[1], []
    kwargs = dict(regimes=(weak,), objects=OBJECTS, planners=PLANNERS, posterior_trials=6, truth_trials=2,
                  analytic_draws=60)
    rs.run(out, engines=("pybullet", "mujoco"), workers=1, log=lines.append, **kwargs)
    assert any("plans of the pybullet run adopted" in line for line in lines)
    assert any(line.startswith(f"mujoco {weak.name}: 0 plans and ") for line in lines)  # nothing planned again
    rs.run(tmp_path, engines=("mujoco",), workers=1, log=lambda line: None, **kwargs)
    adopted, own = load(out / "mujoco" / weak.name), load(tmp_path / "mujoco" / weak.name)
    keys = ["scene", "realisation", "planner"]
    for table, drop in (("plans", ["plan_time_s", "trace"]), ("analytic", []),
                        ("trials", [])):
        a, b = (d[table].drop(columns=drop).sort_values(keys + (["shapes", "trial"] if table == "trials" else []))
                .reset_index(drop=True) for d in (adopted, own))
        assert len(a) > 0
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    scenes = rs.write_objects(out, (weak,), OBJECTS)[weak.objects_key]
    doc = rs.regime_config(weak, scenes, "mujoco", PLANNERS, 6, 2, 60)
    config = parse_config(doc, source="test", base_dir=out, default_name=doc["name"])
    other = parse_config({**rs.regime_config(weak, scenes, "pybullet", PLANNERS, 6, 2, 60), "seed": 1},
                         source="test", base_dir=out, default_name=doc["name"])
    with pytest.raises(ValueError, match="more than the engine"):
        adopt_plans(config, tmp_path / "x", other, out / "pybullet" / weak.name)


def test_a_part_of_the_sweep_runs_the_named_regimes_in_the_sweeps_order(monkeypatch, capsys):
    """bench regimes --regimes: the named regimes, in the sweep's order whatever the order
    given, reach the run (the same Regime values the whole sweep uses, so a later full run
    resumes them); an unknown or empty list is one line naming the sweep's regimes and
    exit code 2, before any folder is made."""
    from harness.cli import main

    assert [r.name for r in rs.regimes_named(["slippery", "weak"])] == ["weak", "slippery"]
    assert rs.regimes_named(["firm-heavy"]) == (rs.REGIMES[-1],)
    with pytest.raises(ValueError, match="unknown regimes bogus, nope; the sweep's are centre, weak"):
        rs.regimes_named(["weak", "nope", "bogus"])
    seen = {}

    def fake_run(out, engines, workers, scheduler, regimes, objects, log):
        seen.update(out=out, regimes=regimes, objects=len(objects))
        return {"rows": [], "verdicts": [], "pooled": {}}

    monkeypatch.setattr(rs, "run", fake_run)
    rs.benchmark(rs.Settings(out=Path("unused"), regimes=("large-heavy", "centre")))
    assert seen["regimes"] == (rs.CENTRE, rs.REGIMES[8]) and rs.REGIMES[8].name == "large-heavy"
    rs.benchmark(rs.Settings(out=Path("unused")))
    assert seen["regimes"] == rs.REGIMES and seen["objects"] == 24
    for bad in ("weak,nope", ","):
        assert main(["bench", "regimes", "--regimes", bad, "--out", "never-made"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--regimes" in err[0] and "centre, weak, strong" in err[0]
    assert not Path("never-made").exists()


def test_regimes_that_share_draws_are_resampled_together():
    """Every regime runs at the sweep's seed on objects of the same names, so trial i of an
    object shares its random draws across regimes. The pooled interval resamples those
    trials together: two regimes with the same outcomes trial for trial (draws that decide
    everything) pool to the very interval of one, where resampling them apart would narrow
    it by about sqrt(2); a single regime's interval is the report's within-plan bootstrap,
    bit for bit."""
    from harness.report import _paired, paired_difference, row_groups

    rng = np.random.default_rng(7)
    rows = []
    for scene in ("a", "b", "c"):
        for realisation in range(2):
            for planner, rate in (("gp-gpis-opt-lift", 0.8), (rs.BASELINE_LIFT, 0.6)):
                for trial in range(24):
                    rows.append({"scene": scene, "realisation": realisation, "planner": planner,
                                 "shapes": "posterior", "trial": trial,
                                 "outcome": "success" if rng.random() < rate else "slipped"})
    one = pd.DataFrame(rows).assign(regime="weak")
    single = rs._difference(one, "gp-gpis-opt-lift", rs.BASELINE_LIFT)
    m = _paired(one.assign(scene="weak/" + one.scene), "gp-gpis-opt-lift", rs.BASELINE_LIFT, "posterior")
    report = paired_difference((m.a - m.b).to_numpy(), row_groups(m, ["scene", "realisation"]),
                               np.random.default_rng(np.random.SeedSequence([0, 0x5EE9])))
    assert (single["ci_low"], single["ci_high"]) == (report["ci_low"], report["ci_high"])
    twice = rs._difference(pd.concat([one, one.assign(regime="strong")], ignore_index=True),
                           "gp-gpis-opt-lift", rs.BASELINE_LIFT)
    assert twice["pairs"] == 2 * single["pairs"] and twice["difference"] == pytest.approx(single["difference"])
    assert (twice["ci_low"], twice["ci_high"]) == (pytest.approx(single["ci_low"]), pytest.approx(single["ci_high"]))
    apart = rs._difference(pd.concat([one, one.assign(regime="strong", scene="x" + one.scene)], ignore_index=True),
                           "gp-gpis-opt-lift", rs.BASELINE_LIFT)  # other names: other draws, resampled apart
    ratio = (apart["ci_high"] - apart["ci_low"]) / (single["ci_high"] - single["ci_low"])
    assert ratio == pytest.approx(1 / math.sqrt(2), rel=0.15)
