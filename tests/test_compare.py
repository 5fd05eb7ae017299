"""`gpis-harness compare`: the paired comparison of two runs, checked against the trials'
own counts, McNemar's exact p in closed form, the bootstrap interval's normal
approximation, and the pairing rules."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from harness.cli import main
from harness.compare import compare, config_differences
from harness.ledger import FILENAME, Ledger

SCENES = ("alpha", "beta")
PLANNERS = ("mean-shape", "gp-p")
POSTERIOR, TRUTH = 400, 200


def _config(**changes) -> dict:
    config = {"name": "synthetic", "source": "synthetic.toml", "seed": 0, "realisations": 2,
              "scenes": [f"/nowhere/{s}.toml" for s in SCENES],
              "planners": [{"label": p, "name": p, "params": {}} for p in PLANNERS],
              "analytic_draws": 100, "posterior_trials": POSTERIOR, "truth_trials": TRUTH,
              "time_budget_s": 10.0, "settings": {}, "physics": {},
              "batch_size": 16}
    return {**config, **changes}


def _keys():
    """(scene, realisation, planner, shapes, trial) of every trial, in a fixed order."""
    return [(s, r, p, shapes, i) for s in SCENES for r in range(2) for p in PLANNERS
            for shapes, n in (("posterior", POSTERIOR), ("truth", TRUTH)) for i in range(n)]


def _write_run(folder: Path, config: dict, outcomes: list[str], moved_plan: bool = False,
               failed_plan: bool = False) -> Path:
    """A results folder whose ledger holds one experiment with these trial outcomes (and,
    with ``failed_plan``, its last plan failed: no grasp)."""
    folder.mkdir()
    plans = [{"scene": s, "realisation": r, "planner": p, "planner_name": p, "params": "{}", "status": "ok",
              "executed": 1, "message": "", "g1x": -0.03, "g1y": 0.0, "g2x": 0.03, "g2y": 0.0, "estimate": 0.5,
              "plan_time_s": 0.1, "iterations": 1, "evaluations": 1, "trace": "[]"}
             for s in SCENES for r in range(2) for p in PLANNERS]
    if moved_plan:
        plans[0]["g1y"] = 0.001
    if failed_plan:
        plans[-1].update(status="error", executed=0, g1x=math.nan, g1y=math.nan, g2x=math.nan, g2y=math.nan)
    trials = [{"scene": s, "realisation": r, "planner": p, "shapes": shapes, "trial": i, "outcome": o,
               "steps": 1, "grip_width": None, "closing_turn": None, "rise": None, "pivot": None}
              for (s, r, p, shapes, i), o in zip(_keys(), outcomes)]
    with Ledger(folder / FILENAME) as ledger:
        run = ledger.start_run("h" + config["name"], config["name"], config, {})
        ledger.add("h" + config["name"], {"plans": plans, "trials": trials})
        ledger.end_run(run, "complete")
    return folder


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """Run A: success with a probability that depends on the planner; run B: A with a known
    set of trials turned (success <-> slipped), more of them towards success."""
    tmp = tmp_path_factory.mktemp("compare")
    rng = np.random.default_rng(5)
    keys = _keys()
    rate = np.array([0.8 if k[2] == "mean-shape" else 0.6 for k in keys])
    a = np.where(rng.random(len(keys)) < rate, "success", "slipped")
    turn = rng.random(len(keys)) < np.where(a == "success", 0.04, 0.12)
    b = np.where(turn, np.where(a == "success", "slipped", "success"), a)
    # Dropped in both: the same failure is agreement, a different failure is not.
    b[:3] = a[:3] = "dropped"
    a[3], b[3] = "slipped", "dropped"
    dir_a = _write_run(tmp / "a", _config(), list(a))
    dir_b = _write_run(tmp / "b", _config(name="finer", physics={"solver_iterations": 100}, time_budget_s=99.0),
                       list(b), moved_plan=True)
    return dir_a, dir_b, keys, a, b


def _mcnemar_closed_form(k: int, n: int) -> float:
    """Two-sided exact binomial test of k of n at 1/2: twice the smaller tail, at most 1."""
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(min(k, n - k) + 1)) / 2 ** n
    return min(1.0, 2 * tail)


def test_cells_are_the_trials_own_counts(two_runs):
    dir_a, dir_b, keys, a, b = two_runs
    result = compare(dir_a, dir_b)
    cells = result["cells"]
    assert result["trials"] == {"a": len(keys), "b": len(keys), "paired": len(keys)}
    per_cell = []
    for scene in SCENES:
        for planner in PLANNERS:
            for shapes in ("posterior", "truth"):
                mask = np.array([k[0] == scene and k[2] == planner and k[3] == shapes for k in keys])
                sa, sb = a[mask] == "success", b[mask] == "success"
                row = cells[(cells.scene == scene) & (cells.planner == planner) & (cells.shapes == shapes)].iloc[0]
                only_a, only_b = int((sa & ~sb).sum()), int((~sa & sb).sum())
                assert row.pairs == mask.sum()
                assert (row.only_a, row.only_b) == (only_a, only_b)
                assert row.success_a == pytest.approx(sa.mean(), abs=1e-12)
                assert row.difference == pytest.approx((only_b - only_a) / mask.sum(), abs=1e-12)
                assert row.agreement == pytest.approx((a[mask] == b[mask]).mean(), abs=1e-12)
                assert row.mcnemar_p == pytest.approx(_mcnemar_closed_form(only_a, only_a + only_b), rel=1e-9)
                per_cell.append(row.difference)
    per_cell = np.array(per_cell)
    assert result["spread"]["cells"] == 8
    assert result["spread"]["rms"] == pytest.approx(np.sqrt(np.mean(per_cell ** 2)), abs=1e-12)
    assert result["spread"]["max"] == pytest.approx(per_cell[np.argmax(np.abs(per_cell))], abs=1e-12)
    # The largest change is the largest in size, with its sign: the same cell, negated, from B to A.
    back = compare(dir_b, dir_a)["spread"]
    assert (back["max"], back["max_at"]) == (pytest.approx(-result["spread"]["max"], abs=1e-12),
                                             result["spread"]["max_at"])
    overall = cells[(cells.scene == "all") & (cells.planner == "all") & (cells.shapes == "all")].iloc[0]
    assert overall.difference == pytest.approx((b == "success").mean() - (a == "success").mean(), abs=1e-12)
    # Trials 0-3: dropped in both agrees; dropped in B only where A slipped does not.
    assert overall.agreement == pytest.approx((a == b).mean(), abs=1e-12)


def test_bootstrap_interval_matches_the_normal_approximation(two_runs):
    """Over 4,800 pairs the bootstrap's 95 % interval is the mean +- 1.96 standard errors
    of the paired differences (within 15 %: the bootstrap's own noise at 2,000 resamples
    and the within-plan resampling, which removes the between-plan part of the spread)."""
    dir_a, dir_b, _, a, b = two_runs
    overall = compare(dir_a, dir_b)["cells"].query("scene == 'all' and planner == 'all' and shapes == 'all'").iloc[0]
    d = (b == "success").astype(float) - (a == "success").astype(float)
    half = 1.96 * d.std(ddof=1) / math.sqrt(len(d))
    assert overall.ci_low < overall.difference < overall.ci_high
    assert (overall.ci_high - overall.ci_low) / 2 == pytest.approx(half, rel=0.15)


def _rate(keys, outcomes, planner: str, shapes: str) -> float:
    mask = np.array([k[2] == planner and shapes in (k[3], "all") for k in keys])
    return float((outcomes[mask] == "success").mean())


def test_planner_shifts_are_the_differences_of_differences(two_runs):
    dir_a, dir_b, keys, a, b = two_runs
    shifts = compare(dir_a, dir_b)["planner_shifts"]
    assert list(zip(shifts.planner, shifts.versus, shifts.shapes)) == [("gp-p", "mean-shape", "posterior"),
                                                                     ("gp-p", "mean-shape", "truth"),
                                                                     ("gp-p", "mean-shape", "all")]
    for row in shifts.itertuples():
        da, db = (_rate(keys, x, "gp-p", row.shapes) - _rate(keys, x, "mean-shape", row.shapes) for x in (a, b))
        assert row.difference_a == pytest.approx(da, abs=1e-12)
        assert row.difference_b == pytest.approx(db, abs=1e-12)
        assert row.shift == pytest.approx(db - da, abs=1e-12)
        assert row.shift_ci_low < row.shift < row.shift_ci_high
        # The bootstrap's interval against the normal approximation of the paired shifts
        # (per pair (scene, realisation, shapes, trial): B's difference less A's), within
        # 15 % as for the differences above.
        pairs = [(k[0], k[1], k[3], k[4]) for k in keys if k[2] == "gp-p" and row.shapes in (k[3], "all")]
        index = {k: j for j, k in enumerate(keys)}
        d = np.array([sum((1.0 if x[index[(s, r, pl, sh, i)]] == "success" else 0.0) * sign * side
                          for x, side in ((b, 1.0), (a, -1.0)) for pl, sign in (("gp-p", 1.0), ("mean-shape", -1.0)))
                      for s, r, sh, i in pairs])
        assert len(d) == row.pairs and d.mean() == pytest.approx(row.shift, abs=1e-12)
        half = 1.96 * d.std(ddof=1) / math.sqrt(len(d))
        assert (row.shift_ci_high - row.shift_ci_low) / 2 == pytest.approx(half, rel=0.15)


def test_what_differs_and_which_plans_moved(two_runs):
    dir_a, dir_b, *_ = two_runs
    result = compare(dir_a, dir_b)
    # The name changes no result; the physics and the time budget per plan may.
    assert result["differences"] == {"physics": [{}, {"solver_iterations": 100}], "time_budget_s": [10.0, 99.0]}
    assert result["plans"] == {"mean-shape": {"plans": 4, "identical": 3}, "gp-p": {"plans": 4, "identical": 4}}
    diffs = config_differences(_config(), _config(scenes=["/x/alpha.toml", "/x/gamma.toml"],
                                                  planners=[{"label": "mean-shape", "name": "mean-shape",
                                                             "params": {"candidates": 5}}]))
    assert diffs["scenes"] == [["beta"], ["gamma"]]
    assert diffs["planners.gp-p"][1] is None
    assert diffs["planners.mean-shape"][1]["params"] == {"candidates": 5}


def test_a_plan_that_failed_in_both_runs_is_the_same_plan(two_runs, tmp_path):
    """Plans are identical when their grasps and statuses are: a planner that returned no
    grasp in both runs (NaN coordinates) planned alike; one that failed in one run only
    did not."""
    _, _, _, a, _ = two_runs
    both = [_write_run(tmp_path / name, _config(), list(a), failed_plan=True) for name in ("x", "y")]
    once = _write_run(tmp_path / "z", _config(), list(a))
    assert compare(*both)["plans"]["gp-p"] == {"plans": 4, "identical": 4}
    assert compare(both[0], once)["plans"]["gp-p"] == {"plans": 4, "identical": 3}


def test_command_line_prints_the_tables_and_json(two_runs, capsys):
    dir_a, dir_b, keys, a, b = two_runs
    assert main(["compare", str(dir_a), str(dir_b)]) == 0
    text = capsys.readouterr().out
    assert "physics: {} -> {'solver_iterations': 100}" in text and "B - A [95% CI]" in text
    assert f"Paired trials: {len(keys)}" in text and "mean-shape 3/4" in text
    assert main(["compare", str(dir_a), str(dir_b), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["outcomes"]["success"]["success"] == int(((a == "success") & (b == "success")).sum())
    assert len(out["cells"]) == 8 + 2 * 3 + 3


def test_runs_that_drew_differently_are_refused_in_one_line(two_runs, tmp_path, capsys):
    dir_a, _, _, a, _ = two_runs
    other = _write_run(tmp_path / "seed1", _config(seed=1), list(a))
    assert main(["compare", str(dir_a), str(other)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "config.seed" in err and "not paired" in err
    # Other grasp settings (here the approach noise's size) execute other grasps from the same deviates.
    other = _write_run(tmp_path / "sigma", _config(settings={"sigma_g": 0.002}), list(a))
    assert main(["compare", str(dir_a), str(other)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "config.settings" in err and "not paired" in err
    assert main(["compare", str(dir_a), str(tmp_path / "missing")]) == 2
    assert "no such results folder" in capsys.readouterr().err
