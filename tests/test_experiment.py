"""Experiments end to end: config validation, eval and report on a tiny experiment,
independence from workers and executor, resume after kill -9, faulty planners."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness.cli import main
from harness.config import load_config
from harness.protocol import Protocol
from harness.report import SUMMARY_COLUMNS

ROOT = Path(__file__).resolve().parent.parent
TIMING = ["plan_time_median_s"]

TINY = """
name = "tiny"
seed = 3
scenes = ["rectangle"]
realisations = 2

[evaluation]
analytic_draws = 100
posterior_trials = 6
truth_trials = 2
time_budget_s = 20.0

[physics]
batch_size = 4

[[planners]]
name = "mean-shape"
params = { candidates = 20 }

[[planners]]
name = "gp-p"
params = { candidates = 20, samples = 100 }

[[planners]]
name = "gp-gpis-opt"
label = "opt"
params = { initialisations = 3, screen = 20, rerank_samples = 50 }
"""


def _write(tmp_path: Path, text: str, name: str = "tiny.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _eval(config: Path, out: Path, *extra: str) -> int:
    return main(["eval", str(config), "--out", str(out), *extra])


def _tables(out: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    summary = pd.read_csv(out / "summary.csv").drop(columns=TIMING)
    trials = pd.read_parquet(out / "trials.parquet").sort_values(
        ["scene", "realisation", "planner", "shapes", "trial"]).reset_index(drop=True)
    return summary, trials


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("tiny")
    config = _write(tmp, TINY)
    out = tmp / "out"
    assert _eval(config, out, "--workers", "2") == 0
    return config, out


def test_eval_writes_every_table_and_figure(tiny_run, capsys):
    config, out = tiny_run
    for name in ("summary.csv", "summary.md", "summary.tex", "trials.parquet", "plans.parquet", "manifest.json",
                 "comparisons.csv", "calibration.csv", "figures/success.png", "figures/failures.png",
                 "figures/calibration.png", "figures/grasps-rectangle.png"):
        assert (out / name).is_file(), name
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary.columns[:len(SUMMARY_COLUMNS)]) == SUMMARY_COLUMNS
    assert summary.complete.all()
    # Every expected trial is there once: 2 realisations x 3 planners x (6 + 2).
    trials = pd.read_parquet(out / "trials.parquet")
    assert len(trials) == 2 * 3 * 8
    assert not trials.duplicated(["scene", "realisation", "planner", "shapes", "trial"]).any()
    # The summary's rates are the trials' own counts, and Wilson intervals bracket them.
    post = trials[(trials.planner == "gp-p") & (trials.shapes == "posterior") & (trials.scene == "rectangle")]
    row = summary[(summary.scene == "rectangle") & (summary.planner == "gp-p")].iloc[0]
    assert row.n_trials == 12
    assert row.success_rate == pytest.approx((post.outcome == "success").mean(), abs=1e-12)
    wilson = stats.binomtest(int((post.outcome == "success").sum()), len(post)).proportion_ci(method="wilson")
    assert (row.success_ci_low, row.success_ci_high) == (pytest.approx(wilson.low, abs=1e-9),
                                                         pytest.approx(wilson.high, abs=1e-9))
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["config_hash"] == load_config(config).hash and manifest["packages"]["pybullet"]
    tex = (out / "summary.tex").read_text()
    assert r"\toprule" in tex and r"\textbf{" in tex
    # The outcome table lists the planners in the config's order, as the summary does, and
    # its counts are the trials' own.
    fails = pd.read_csv(out / "failures.csv")
    assert list(fails.planner) == ["mean-shape", "mean-shape", "gp-p", "gp-p", "opt", "opt"]
    assert list(fails.shapes) == ["posterior", "truth"] * 3
    counts = trials.groupby(["planner", "shapes"]).size()
    outcome_columns = [c for c in fails.columns if c not in ("planner", "shapes")]
    expected_counts = [counts[p, s] for p, s in zip(fails.planner, fails.shapes)]
    assert all(fails[outcome_columns].sum(axis=1).to_numpy() == expected_counts)
    # With benchmark data in the folder, the report adds the convergence and runtime figures.
    bench = {"convergence": [{"seed": 0, "gp-p": [[0.1, 10, 0.5], [0.2, 20, 0.7]], "gp-gpis-opt": [[0.05, 1, 0.6]]}],
             "scp_s_per_init": {"25": 0.02, "50": 0.02}, "gpp_s_per_candidate": {"25": 0.01, "50": 0.02},
             "rows": [{"M": 25, "p_f_s": 0.01}, {"M": 50, "p_f_s": 0.01}]}
    (out / "bench-planning.json").write_text(json.dumps(bench))
    assert main(["report", str(out)]) == 0
    assert (out / "figures" / "convergence.png").is_file() and (out / "figures" / "runtime.png").is_file()


def test_pairing_same_shapes_and_noise_for_every_planner(tmp_path):
    """Common random numbers: a plan's trial i uses shape sample i and noise draw i, the
    same for every planner. Two labels of one planner that plans the same grasp on every
    belief must then get the same trial rows, bit for bit (steps, grip width, turns), while
    the trials of one plan differ among themselves (the draws do vary from trial to trial)."""
    text = TINY.replace("realisations = 2", "realisations = 1")
    text = text[:text.index("[[planners]]")] + "".join(
        f'[[planners]]\nname = "edge_planners:Fixed"\nlabel = "{label}"\n\n' for label in ("fixed-a", "fixed-b"))
    text += '[[planners]]\nname = "mean-shape"\nparams = { candidates = 20 }\n'
    out = tmp_path / "out"
    assert _eval(_write(tmp_path, text), out, "--workers", "2") == 0
    trials = pd.read_parquet(out / "trials.parquet")
    columns = ["outcome", "steps", "grip_width", "closing_turn", "rise", "pivot"]
    a, b = (trials[trials.planner == label].sort_values(["shapes", "trial"]).reset_index(drop=True)
            for label in ("fixed-a", "fixed-b"))
    assert len(a) == len(b) == 8
    pd.testing.assert_frame_equal(a[["shapes", "trial", *columns]], b[["shapes", "trial", *columns]])
    posterior = a[a.shapes == "posterior"]
    assert posterior.steps.nunique() > 1 and posterior.grip_width.nunique() > 1  # not one situation six times
    # Each is compared with the baseline (mean-shape) on the same pairs: the same rows.
    comp = pd.read_csv(out / "comparisons.csv")
    rows_a, rows_b = (comp[comp.planner == label].drop(columns="planner").reset_index(drop=True)
                      for label in ("fixed-a", "fixed-b"))
    assert len(rows_a) == 6
    pd.testing.assert_frame_equal(rows_a, rows_b)
    # The paired difference is McNemar's discordant counts over the pairs (some nonzero here).
    assert (comp.only_planner + comp.only_versus).sum() > 0
    for row in comp.itertuples():
        assert row.difference == pytest.approx((row.only_planner - row.only_versus) / row.pairs, abs=1e-12)


def test_the_config_hash_covers_the_outline_files_a_scene_reads(tmp_path):
    """An outline CSV is part of its scene: editing it changes the experiment's hash (a
    resume would otherwise mix rows of two shapes), rewriting it the same does not, and a
    config whose scenes read no file hashes as before (no 'outline_files' entry)."""
    (tmp_path / "shapes").mkdir()
    csv = tmp_path / "shapes" / "box.csv"
    csv.write_text("x,y\n0,0\n6,0\n6,3\n0,3\n")
    (tmp_path / "box.toml").write_text('[grid]\nsize = 40\nextent = 0.2\n[shape]\ntype = "outline"\n'
                                        'path = "shapes/box.csv"\nscale = 0.01\n')
    config = _write(tmp_path, 'scenes = ["box.toml", "disk"]\n[[planners]]\nname = "mean-shape"\n', "c.toml")
    first = load_config(config)
    assert set(first.content()["outline_files"]) == {"box"}
    assert first.content()["outline_files"]["box"].keys() == {"shapes/box.csv"}
    before = first.hash  # the hash reads the files when asked: keep this one's
    csv.write_text("x,y\n0,0\n6,0\n6,3\n0,3\n")
    assert load_config(config).hash == before
    csv.write_text("x,y\n0,0\n6,0\n6,3.5\n0,3\n")
    assert load_config(config).hash != before
    plain = load_config(_write(tmp_path, 'scenes = ["disk"]\n[[planners]]\nname = "mean-shape"\n', "d.toml"))
    assert "outline_files" not in plain.content()


def test_results_do_not_depend_on_workers_or_executor(tiny_run, tmp_path):
    config, out2 = tiny_run
    reference = _tables(out2)
    for extra in (["--workers", "1"], ["--workers", "2", "--scheduler", "local"]):
        out = tmp_path / extra[-1]
        assert _eval(config, out, *extra, "--no-report") == 0
        assert main(["report", str(out), "--no-figures"]) == 0
        summary, trials = _tables(out)
        pd.testing.assert_frame_equal(summary, reference[0])
        pd.testing.assert_frame_equal(trials, reference[1])


def test_a_planner_added_to_a_finished_run_is_the_only_one_planned_and_simulated(tiny_run, tmp_path, capsys):
    """The config hash leaves the planners out: the tiny experiment run first without
    gp-gpis-opt, then with it into the same folder, plans and simulates gp-gpis-opt alone
    (the others' plan rows are not rewritten) and gives the tables of the whole run at
    once; the same label with other parameters is one line and exit 2."""
    config, reference_out = tiny_run
    reference = _tables(reference_out)
    opt = TINY[TINY.index("[[planners]]\nname = \"gp-gpis-opt\""):]
    first = _write(tmp_path, TINY.replace(opt, ""), "first.toml")
    out = tmp_path / "out"
    assert _eval(first, out, "--workers", "2", "--no-report") == 0
    with closing(sqlite3.connect(out / "ledger.sqlite")) as db:
        before = db.execute("SELECT planner, scene, realisation, plan_time_s FROM plans").fetchall()
        trials_before = db.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    assert {row[0] for row in before} == {"mean-shape", "gp-p"} and trials_before == 2 * 2 * (6 + 2)
    capsys.readouterr()
    assert _eval(config, out, "--workers", "2") == 0
    assert "resuming with 4 plans and 32 trials done" in capsys.readouterr().err
    with closing(sqlite3.connect(out / "ledger.sqlite")) as db:
        after = db.execute("SELECT planner, scene, realisation, plan_time_s FROM plans "
                           "WHERE planner != 'opt'").fetchall()
    assert sorted(after) == sorted(before)
    summary, trials = _tables(out)
    pd.testing.assert_frame_equal(summary, reference[0])
    pd.testing.assert_frame_equal(trials, reference[1])
    # The report of the first config again: its two planners only.
    assert _eval(first, out, "--workers", "1") == 0
    assert set(pd.read_csv(out / "summary.csv").planner) == {"mean-shape", "gp-p"}
    changed = _write(tmp_path, TINY.replace("initialisations = 3", "initialisations = 4"), "changed.toml")
    capsys.readouterr()
    assert _eval(changed, out, "--workers", "1") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "planners.opt" in err[0] and "another label" in err[0]


def _ledger_trials(ledger: Path) -> int:
    """Trial rows in a ledger that another process is writing (-1 before it has any)."""
    if not ledger.exists():
        return -1
    try:
        with closing(sqlite3.connect(ledger, timeout=5)) as db:
            return db.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    except sqlite3.OperationalError:  # the tables are being created
        return -1


def test_resume_after_kill_gives_the_uninterrupted_tables(tiny_run, tmp_path):
    config, reference_out = tiny_run
    reference = _tables(reference_out)
    total = len(reference[1])
    out = tmp_path / "killed"
    ledger = out / "ledger.sqlite"
    command = [sys.executable, "-m", "harness", "eval", str(config), "--out", str(out), "--workers", "2",
               "--no-report"]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    # Three random moments, chosen by progress rather than by the clock (a process's
    # start-up time varies from machine to machine): as soon as the ledger holds at least
    # 0 (planning may still run), then more trial rows, never the last batch.
    moments = np.sort(np.random.default_rng(5).integers(0, total * 3 // 4, size=3))
    counts = []
    for moment in moments:
        proc = subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        deadline = time.monotonic() + 300
        while _ledger_trials(ledger) < moment and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed"
        os.killpg(proc.pid, signal.SIGKILL)  # the main process and its workers, as a crash would
        proc.wait()
        counts.append(_ledger_trials(ledger))
    assert counts == sorted(counts) and 0 <= counts[0] < total  # killed mid-run, nothing lost
    assert subprocess.run(command, cwd=ROOT, env=env, capture_output=True, check=False).returncode == 0
    assert main(["report", str(out), "--no-figures"]) == 0
    summary, trials = _tables(out)
    pd.testing.assert_frame_equal(summary, reference[0])
    pd.testing.assert_frame_equal(trials, reference[1])


def test_faulty_planners_are_recorded_and_the_run_completes(tmp_path):
    # Fewer analytic draws than posterior trials: P_F uses the first 4 of the 6 paired draws.
    text = TINY.replace("realisations = 2", "realisations = 1").replace("time_budget_s = 20.0",
                                                                       "time_budget_s = 0.5")
    text = text.replace("analytic_draws = 100", "analytic_draws = 4")
    text = text[:text.index("[[planners]]")] + "".join(
        f'[[planners]]\nname = "faulty_planners:{cls}"\nlabel = "{label}"\n\n'
        for cls, label in (("Raises", "raises"), ("ReturnsNaN", "nan"), ("OutsideGrid", "outside"),
                           ("Sleeps", "sleeps")))
    text += '[[planners]]\nname = "mean-shape"\nparams = { candidates = 20 }\n'
    out = tmp_path / "out"
    assert _eval(_write(tmp_path, text), out, "--workers", "1") == 0
    plans = pd.read_parquet(out / "plans.parquet").set_index("planner")
    assert plans.loc["raises", "status"] == "raised" and "deliberate failure" in plans.loc["raises", "message"]
    assert plans.loc["nan", "status"] == "invalid"
    assert plans.loc["outside", "status"] == "invalid"
    assert plans.loc["sleeps", "status"] == "overtime"
    assert plans.loc["mean-shape", "status"] == "ok"
    trials = pd.read_parquet(out / "trials.parquet")
    failed = trials[trials.planner != "mean-shape"]
    assert len(failed) == 4 * 8 and (failed.outcome == "no_plan").all()
    summary = pd.read_csv(out / "summary.csv")
    assert summary.complete.all()
    assert (summary[summary.planner != "mean-shape"].success_rate == 0).all()
    assert len(plans) == 5
    with sqlite3.connect(out / "ledger.sqlite") as db:  # only mean-shape's plan was judged, on 4 draws
        assert db.execute("SELECT planner, draws FROM analytic").fetchall() == [("mean-shape", 4)]


BAD_CONFIGS = [
    ("seed = -1", "seed"),
    ("seed = 1\nscenes = []", "scenes"),
    ('scenes = ["no_such_scene"]', "scenes[0]"),
    ("realisations = 0", "realisations"),
    ('[[planners]]\nname = "no-such-planner"', "planners[0].name"),
    ('[[planners]]\nname = "gp-p"\nparams = { candidates = "many" }', "planners[0].params.candidates"),
    ('[[planners]]\nname = "gp-p"\nparams = { wings = 2 }', "planners[0].params.wings"),
    ('[evaluation]\nposterior_trials = 1.5\n[[planners]]\nname = "gp-p"', "evaluation.posterior_trials"),
    ('[physics]\ntime_step = 0.5\n[[planners]]\nname = "gp-p"', "physics.time_step"),
    ('[physics]\ntime_step = 1e-300\n[[planners]]\nname = "gp-p"', "physics.time_step"),
    ('[physics]\nlift_time = 1e300\n[[planners]]\nname = "gp-p"', "physics.lift_time"),
    ('[physics]\nshake_frequency = 1e6\n[[planners]]\nname = "gp-p"', "physics.shake_frequency"),
    ('[gripper]\nclosing_speed = 1e-300\n[[planners]]\nname = "gp-p"', "gripper.closing_speed"),
    ('name = "run\\u0000x"\n[[planners]]\nname = "gp-p"', "name"),
    ('[[planners]]\nname = "gp-p"\nlabel = "all"', "planners[0].label"),
    ('scenes = ["foo**/*.toml"]\n[[planners]]\nname = "gp-p"', "scenes[0]"),
    ('[physics]\ncone_friction = 0\n[[planners]]\nname = "gp-p"', "physics.cone_friction"),
    ('[physics]\ntable_hull = "yes"\n[[planners]]\nname = "gp-p"', "physics.table_hull"),
    ('[physics]\nconvex_clipping = 1\n[[planners]]\nname = "gp-p"', "physics.convex_clipping"),
    ('[physics]\nbody_refinement = 0\n[[planners]]\nname = "gp-p"', "physics.body_refinement"),
    ('[physics]\nbody_refinement = 2.5\n[[planners]]\nname = "gp-p"', "physics.body_refinement"),
    ('[physics]\nengine = "mujoco"\nconvex_clipping = true\n[[planners]]\nname = "gp-p"', "physics.convex_clipping"),
    ('[physics]\nengine = "mujoco"\npad_stiffness = 2e4\npad_damping = 90\n[[planners]]\nname = "gp-p"',
     "physics.pad_stiffness"),
    ('[physics]\npad_stiffness = -1.0\n[[planners]]\nname = "gp-p"', "physics.pad_stiffness"),
    ('[physics]\npad_stiffness = 2e4\npad_damping = 0\n[[planners]]\nname = "gp-p"', "physics.pad_damping"),
    ('colour = "red"\n[[planners]]\nname = "gp-p"', "colour"),
    ('[[planners]]\nname = "gp-p"\n[[planners]]\nname = "gp-p"', "planners[1].label"),
    ('[gripper]\nopening = 0\n[[planners]]\nname = "gp-p"', "gripper.opening"),
    ("this is not toml", None),
]


@pytest.mark.parametrize(("text", "field"), BAD_CONFIGS)
def test_bad_configs_get_one_line_naming_the_field(tmp_path, capsys, text, field):
    if "scenes" not in text:  # a config must name its scenes
        text = 'scenes = ["disk"]\n' + text
    path = _write(tmp_path, text, "bad.toml")
    assert _eval(path, tmp_path / "out") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"gpis-harness: error: {path}"), err
    if field:
        assert f": {field}:" in err, err
    assert not (tmp_path / "out").exists()  # nothing started


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value) if np.isfinite(value) else ("nan" if value != value else ("inf" if value > 0 else "-inf"))
    if isinstance(value, str):
        return json.dumps(value)
    return "[" + ", ".join(_toml_value(v) for v in value) + "]"


_values = st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
                    st.text(max_size=12), st.lists(st.integers(-3, 3) | st.text(max_size=5), max_size=3))
_counts, _small = st.integers(1, 64), st.floats(0.0005, 0.05)
# Values each key may well hold, so that many fuzzed configs load (and then must run).
_plausible = {"seed": _counts, "realisations": _counts, "name": st.text("abc-_", min_size=1, max_size=8),
              "evaluation.analytic_draws": _counts, "evaluation.posterior_trials": _counts,
              "evaluation.truth_trials": _counts, "evaluation.sigma_g": _small,
              "evaluation.friction": st.floats(0.05, 1.5), "evaluation.time_budget_s": st.floats(0.1, 100.0),
              "physics.time_step": st.floats(1e-4, 0.01), "physics.solver_iterations": _counts,
              "physics.batch_size": _counts, "physics.cone_friction": st.booleans(),
              "physics.table_hull": st.booleans(), "physics.body_refinement": st.integers(1, 4),
              "gripper.opening": st.floats(0.02, 0.2), "gripper.force": st.floats(0.5, 100.0),
              "gripper.sigma_g": _small, "evaluation.load_factor": st.floats(0.5, 3.0),
              "planners.name": st.sampled_from(["gp-p", "mean-shape", "gp-gpis-opt"]),
              "planners.params.candidates": _counts}
_keys = st.sampled_from([*_plausible, "scenes", "bogus"])
_changes = _keys.flatmap(lambda key: st.tuples(st.just(key), st.one_of(*[_plausible.get(key, _values)] * 3, _values)))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=st.lists(_changes, min_size=1, max_size=3).map(dict))
def test_fuzzed_configs_run_or_get_one_line(tmp_path, capsys, changes):
    """Whatever a config holds, loading it either fails with one line naming the file (exit
    2 at the command line) or gives a config that runs: its physics protocol, every
    scene's grasp settings and every planner are made from it without an error. The base
    config names a scene, so that most of the fuzzed ones load."""
    tables: dict = {"": {"scenes": ["rectangle"]}, "evaluation": {}, "physics": {}, "gripper": {}}
    planner = {"name": "gp-p"}
    for key, value in changes.items():
        if key.startswith("planners."):
            planner[key.split(".", 1)[1]] = value
        elif "." in key:
            table, field = key.split(".")
            tables[table][field] = value
        else:
            tables[""][key] = value
    lines = [f"{k} = {_toml_value(v)}" for k, v in tables[""].items()]
    for table in ("evaluation", "physics", "gripper"):
        lines += [f"[{table}]"] + [f"{k} = {_toml_value(v)}" for k, v in tables[table].items()]
    params = {k.split(".", 1)[1]: v for k, v in planner.items() if k.startswith("params.")}
    lines += ["[[planners]]", f"name = {_toml_value(planner['name'])}"]
    if params:
        lines.append("params = { " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in params.items()) + " }")
    path = tmp_path / "fuzz.toml"
    path.write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    try:
        config = load_config(path)
    except Exception as exc:  # noqa: BLE001 - the assertion is on the kind of error
        from harness.errors import InputError

        assert isinstance(exc, InputError), f"{type(exc).__name__}: {exc}"
        assert "\n" not in str(exc) and str(exc).startswith(str(path))
        return
    from harness.tasks import settings_of
    from planners.registry import make_planner

    config.protocol()
    for scene in config.scenes:
        settings_of(config, scene)
    for entry in config.planners:
        make_planner(entry.name, entry.params)


def test_corrupt_or_foreign_ledger_is_one_line_exit_2(tmp_path, capsys):
    config = _write(tmp_path, TINY)
    for name, make in (("garbage", lambda p: p.write_bytes(b"this is not sqlite" * 100)),
                       ("foreign", lambda p: sqlite3.connect(p).execute("CREATE TABLE t (x)").connection.commit())):
        out = tmp_path / name
        out.mkdir()
        make(out / "ledger.sqlite")
        assert _eval(config, out) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "ledger.sqlite" in err, err
        assert main(["report", str(out)]) == 2
        assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_a_cell_plans_with_one_blas_thread_and_the_same_results(tmp_path, monkeypatch):
    """The workers are the parallelism: inside a cell BLAS runs one thread, whether the cell
    is eval's task (run_cell) or opened directly, as the single-shot commands (plan,
    quality, simulate, report --draws) open it, so that they print what eval records (the
    GP's fit differs in its last bits with the thread count); the process's own threads
    are back afterwards, and the plan and the trials' shapes are the same bit for bit."""
    from threadpoolctl import threadpool_info

    import harness.belief
    from harness.tasks import _cell, run_cell

    def blas_threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    outside = blas_threads()
    seen = []
    real = harness.belief.build_belief

    def spy(*args, **kwargs):
        seen.append(blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(harness.belief, "build_belief", spy)
    config = load_config(_write(tmp_path, TINY))
    path, labels = config.scenes[0], ("mean-shape",)
    limited, free = run_cell(config, path, 0, labels), _cell(config, path, 0, labels, None)
    assert seen == [{1}, {1}]
    assert blas_threads() == outside
    keys = ("g1x", "g1y", "g2x", "g2y", "estimate")
    assert [limited.plans[0][k] for k in keys] == [free.plans[0][k] for k in keys]
    assert all(a.equals_exact(b, 0.0) for a, b in zip(limited.posterior.polygons, free.posterior.polygons, strict=True))


def test_physics_overrides_reach_the_protocol(tmp_path):
    head = 'scenes = ["disk"]\n'
    text = head + '[physics]\ncone_friction = false\nsolver_iterations = 80\n[[planners]]\nname = "gp-p"'
    path = _write(tmp_path, text, "pyramid.toml")
    protocol = load_config(path).protocol()
    assert (protocol.cone_friction, protocol.solver_iterations) == (False, 80)
    assert load_config(_write(tmp_path, head + '[[planners]]\nname = "gp-p"', "cone.toml")).protocol().cone_friction
    flipped = str(not Protocol().table_hull).lower()
    path = _write(tmp_path, head + f'[physics]\ntable_hull = {flipped}\n[[planners]]\nname = "gp-p"', "foot.toml")
    assert load_config(path).protocol().table_hull is not Protocol().table_hull
    flipped = str(not Protocol().convex_clipping).lower()
    path = _write(tmp_path, head + f'[physics]\nconvex_clipping = {flipped}\n[[planners]]\nname = "gp-p"', "sat.toml")
    assert load_config(path).protocol().convex_clipping is not Protocol().convex_clipping
    rigid = _write(tmp_path, head + '[physics]\npad_stiffness = 0\n[[planners]]\nname = "gp-p"', "rigid.toml")
    assert (load_config(rigid).protocol().pad_stiffness, Protocol().pad_stiffness) == (0.0, 2e4)
    soft = _write(tmp_path, head + '[physics]\npad_stiffness = 1e4\npad_damping = 60\n[[planners]]\nname = "gp-p"',
                  "soft.toml")
    assert (load_config(soft).protocol().pad_stiffness, load_config(soft).protocol().pad_damping) == (1e4, 60.0)
    # the pads are in the hash though the config does not name them (rows made with rigid
    # pads are never resumed into a ledger of compliant ones), in Bullet's runs alone
    plain = load_config(_write(tmp_path, head + '[[planners]]\nname = "gp-p"', "plain.toml"))
    assert plain.content()["pads"] == [2e4, 90.0] and load_config(rigid).hash != plain.hash
    assert "pads" not in plain.with_engine("mujoco").content()
    path = _write(tmp_path, head + '[physics]\nbody_refinement = 1\n[[planners]]\nname = "gp-p"', "coarse.toml")
    assert (Protocol().body_refinement, load_config(path).protocol().body_refinement) == (2, 1)
    # the default refinement is in the hash though the config does not name it, so rows
    # made with another are never resumed into one ledger
    default = load_config(_write(tmp_path, head + '[[planners]]\nname = "gp-p"', "default.toml"))
    explicit = _write(tmp_path, head + '[physics]\nbody_refinement = 2\n[[planners]]\nname = "gp-p"', "two.toml")
    assert default.content()["body_refinement"] == 2 and load_config(path).hash != default.hash
    assert load_config(explicit).content()["body_refinement"] == 2


def test_compare_pairs_two_runs_that_differ_in_physics_only(tiny_run, tmp_path, capsys):
    """The documented check of a result's numerical robustness: the same experiment with
    twice the solver iterations plans the same grasps and pairs every trial; a run
    compared with itself changes nothing."""
    from harness.compare import compare

    _, out = tiny_run
    finer = tmp_path / "finer"
    config = _write(tmp_path, TINY.replace("batch_size = 4", "batch_size = 4\nsolver_iterations = 100"))
    assert _eval(config, finer, "--workers", "2", "--no-report") == 0
    result = compare(out, finer)
    assert result["differences"] == {"physics": [{}, {"solver_iterations": 100}]}
    assert result["plans"] == {label: {"plans": 2, "identical": 2} for label in ("mean-shape", "gp-p", "opt")}
    assert result["trials"] == {"a": 48, "b": 48, "paired": 48}
    same = compare(out, out)["cells"]
    assert (same.difference == 0).all() and (same.agreement == 1).all() and (same.mcnemar_p == 1).all()
    assert main(["compare", str(out), str(finer)]) == 0
    assert "solver_iterations" in capsys.readouterr().out


def test_report_draws_sets_each_posterior_trial_beside_its_own_draws_lift_model(tiny_run, capsys):
    """`report --draws`: one row per posterior trial, its outcome the ledger's, its
    verdict the one the ledger recorded during the run, and the lift model's quantities
    on that draw consistent with the verdict by the model's own rules (docs/lift.md):
    a lifted draw is level exactly when its lever sum reaches the demand (the lift's peak
    demand where a plate presses with its edge), and turned and still lifted only where
    its levers stop the turn short of the table (lever sum >= demand x clear_cos) and no
    plate presses with its edge; the weight is the prism's (density x thickness x g x the
    sample's area, about the rectangle's)."""
    from harness.report import load
    from harness.scene import load_scene
    from harness.settings import GRAVITY

    _, out = tiny_run
    assert main(["report", str(out), "--no-figures", "--draws"]) == 0
    assert "draws.csv" in capsys.readouterr().err
    table = pd.read_csv(out / "draws.csv")
    data = load(out)
    post = data["trials"][data["trials"].shapes == "posterior"]
    assert len(table) == len(post) == 2 * 3 * 6
    merged = table.merge(post, on=["scene", "realisation", "planner", "trial"], suffixes=("", "_ledger"))
    assert len(merged) == len(table) and (merged.outcome == merged.outcome_ledger).all()
    recorded = {(r.scene, r.realisation, r.planner): r.reasons.split(",") for r in data["analytic"].itertuples()}
    assert all(r.verdict == recorded[(r.scene, r.realisation, r.planner)][r.trial] for r in table.itertuples())
    lifted = table[table.verdict.isin(["lifted", "lifted_turned"])]
    assert len(lifted) > 0
    needed = np.where(lifted.edge > 0, lifted.peak_demand, lifted.demand)
    assert ((lifted.lever_sum >= needed) == (lifted.verdict == "lifted")).all()
    turned = lifted[lifted.verdict == "lifted_turned"]
    assert (turned.lever_sum >= turned.demand * turned.clear_cos).all() and (turned.edge == 0).all()
    scene = load_scene("rectangle")
    prism = scene.physics.density * scene.physics.thickness * GRAVITY * scene.shape.area
    assert lifted.weight.median() == pytest.approx(prism, rel=0.05)
    planar = table[~table.verdict.isin(["lifted", "lifted_turned", "weight_slip", "weight_torque"])]
    assert planar[["weight", "demand"]].isna().all().all()


def test_report_draws_refuses_verdicts_that_are_not_the_ledgers(tiny_run):
    """Drawn again, a cell must give each trial the verdict the run recorded; where it
    does not (here the ledger's first verdict is altered, as a changed scene file or
    model would), trial_draws refuses with one line instead of writing other draws."""
    from harness.errors import InputError
    from harness.explain import trial_draws
    from harness.report import load

    _, out = tiny_run
    data = load(out)
    first = data["analytic"].index[0]
    labels = data["analytic"].at[first, "reasons"].split(",")
    labels[0] = "missed" if labels[0] != "missed" else "lifted"
    data["analytic"].at[first, "reasons"] = ",".join(labels)
    with pytest.raises(InputError, match="analytic.reasons.*a scene or the model changed"):
        trial_draws(out, data)
    # A run made under other numeric code paths (a script that imported numpy before
    # setting them) is told so, not that its model changed.
    recorded = data["environment"]["reproducibility"]
    recorded["code_paths"] = {name: "elsewhere" for name in recorded["code_paths"]}
    with pytest.raises(InputError, match="numeric code paths were .*elsewhere"):
        trial_draws(out, data)
    gone = load(out)
    gone["config"]["scenes"] = [str(out / "moved.toml") for _ in gone["config"]["scenes"]]
    with pytest.raises(InputError, match="cannot draw its cell again"):
        trial_draws(out, gone)
