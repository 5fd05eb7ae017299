"""The second engine: MuJoCo's trial against closed forms (the jaws' squeeze, the pad's
stiffness and torsion, the prism's mass), the calibration grasps on the rectangle,
determinism with any number of workers, the engine in configs, manifests and
cross-engine comparisons. The fidelity and agreement figures live in
``gpis-harness bench physics`` and ``bench engines`` (docs/physics.md, "MuJoCo")."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pandas as pd
import pytest

from harness.cli import main
from harness.physics import mujoco_engine as me
from harness.physics.bodies import principal_frame, prism_mass_properties
from harness.physics.simulate import make_trials, truth_polygon
from harness.physics.engines import make_runner
from harness.protocol import ENGINE_DEFAULTS, Protocol
from harness.scene import load_scene
from harness.settings import resolve

REPO = Path(__file__).resolve().parents[1]
MUJOCO = Protocol.of("mujoco")


def _rectangle_trials(g1, g2, n: int = 1, sigma_g: float | None = 0.0, seed: int = 0, **overrides):
    """Trials on the rectangle (0.06 m x 0.03 m); ``sigma_g`` None: the scene's."""
    scene = load_scene("rectangle")
    settings = resolve(scene, ({} if sigma_g is None else {"sigma_g": sigma_g}) | overrides)
    approach = np.random.default_rng(seed).standard_normal((n, 2, 2))
    return make_trials(settings, [g1, g2], [truth_polygon(scene)], approach)


def _closed_slot(trial) -> me._Slot:
    """A MuJoCo trial stepped until its jaws stall (the lift about to begin)."""
    slot = me._Slot(me.MujocoRunner(MUJOCO), trial)
    while slot.phase == "close" and slot.result is None:
        slot.before_step()
        mujoco.mj_step(slot.model, slot.data)
        slot.fresh = False
        slot.after_step()
    assert slot.result is None and slot.phase == "lift"
    return slot


def test_the_calibration_grasps_on_the_rectangle_in_mujoco():
    """As in Bullet (tests/test_physics_trial.py): through the centre under the scene's
    approach noise it succeeds at least 0.95 of the time (here every one of 20 trials);
    a grasp that misses is no_contact; jaws placed inside are approach_collision."""
    good = _rectangle_trials((-0.045, 0.0), (0.045, 0.0), n=20, sigma_g=None)
    miss = _rectangle_trials((-0.045, 0.03), (0.045, 0.03))
    inside = _rectangle_trials((-0.02, 0.0), (0.045, 0.0))
    with make_runner(MUJOCO) as runner:
        results = runner.run(good + miss + inside)
    assert [r.outcome for r in results[:20]] == ["success"] * 20
    assert results[20].outcome == "no_contact"
    assert results[21].outcome == "approach_collision"
    for r in results[:20]:
        assert abs(r.closing_turn) < 0.05
        assert r.rise == pytest.approx(MUJOCO.lift_height, abs=0.002)  # held: no creep while lifting and shaking
        assert r.pivot < 0.05  # approach noise holds it a little off its centre of mass


def test_the_jaws_squeeze_with_the_force_limit_and_the_pad_has_its_stiffness():
    """Stalled on the rectangle, each plate's contact forces add up to the gripper's force
    limit (the damper in its joint pulls nothing at rest), and the plates sink into the
    0.06 m wide faces as a 2 mm pad of about 1 MPa over a square centimetre would:
    k = E A / t = 5e4 N/m, 0.2 to 0.6 mm at 20 N (MuJoCo's soft contact is stiffer the
    deeper it goes, so the stated range is the pad's, not a fitted number)."""
    force = 20.0
    slot = _closed_slot(_rectangle_trials((-0.045, 0.0), (0.045, 0.0), force=force)[0])
    m, d = slot.model, slot.data
    normal = {jaw: 0.0 for jaw in slot.jaw_geoms}
    f = np.zeros(6)
    for k in range(d.ncon):
        c = d.contact[k]
        for jaw in slot.jaw_geoms:
            if jaw in (c.geom1, c.geom2):
                mujoco.mj_contactForce(m, d, k, f)
                normal[jaw] += f[0]
    for total in normal.values():
        assert total == pytest.approx(force, rel=0.03)
    sink = (0.06 - slot.grip_width) / 2
    assert 0.2e-3 < sink < 0.6e-3
    assert 1e4 < force / sink < 1e5


def test_the_model_carries_the_prism_and_the_pad_torsion():
    """The object's mass and principal inertia are the exact prism's (bodies.py's closed
    form); the plates' torsional coefficient is (2/3) mu PAD_RADIUS, a disc's under
    uniform pressure; jaw contacts have condim 4, the table's 3; the elliptic cone; the
    gripper's links weigh what Bullet's do."""
    scene = load_scene("marker")
    trial = make_trials(resolve(scene), [(0.03, -0.01), (0.02, 0.03)], [truth_polygon(scene)], np.zeros((1, 2, 2)))[0]
    slot = me._Slot(me.MujocoRunner(MUJOCO), trial)
    m = slot.model
    props = prism_mass_properties(trial.polygon, trial.thickness, trial.density)
    moments, _ = principal_frame(props.inertia)
    assert m.body_mass[slot.obj] == pytest.approx(props.mass, rel=1e-9)
    assert sorted(m.body_inertia[slot.obj]) == pytest.approx(sorted(moments), rel=1e-6)
    assert m.body_ipos[slot.obj] == pytest.approx(props.com, abs=1e-9)
    for plate in slot.jaw_geoms:
        mu, torsion, rolling = m.geom_friction[plate]
        assert mu == pytest.approx(trial.friction)
        assert torsion == pytest.approx(2 / 3 * trial.friction * me.PAD_RADIUS)
        assert rolling == 0.0
        assert m.geom_condim[plate] == me.JAW_CONDIM == 4
    assert m.geom_condim[m.geom("table").id] == me.TABLE_CONDIM == 3
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert m.opt.timestep == ENGINE_DEFAULTS["mujoco"]["time_step"]
    # The same gripper as Bullet's: the palm's and each plate's mass as pybullet loads
    # them from the gripper's URDF, and the plates' inertia. The palm's inertia is the
    # URDF's box in MuJoCo; pybullet computes its base's from the collision box grown by
    # its 1 mm margin on every side (4-21 % larger moments: docs/physics.md, "MuJoCo").
    import pybullet as pb

    from harness.physics.gripper import PALM_MASS, PALM_THICKNESS

    c = pb.connect(pb.DIRECT)
    try:
        grip = pb.loadURDF(trial.gripper.urdf, physicsClientId=c)
        bullet = [pb.getDynamicsInfo(grip, link, physicsClientId=c)[:3:2] for link in (-1, *trial.gripper.jaw_links)]
    finally:
        pb.disconnect(physicsClientId=c)
    bodies = [slot.layout.palm, *(int(m.geom_bodyid[g]) for g in slot.jaw_geoms)]
    for k, (body, (mass, inertia)) in enumerate(zip(bodies, bullet)):
        assert m.body_mass[body] == pytest.approx(mass, rel=1e-6)
        if k:
            assert m.body_inertia[body] == pytest.approx(inertia, rel=1e-6)
    g = trial.gripper
    box = [g.face_at_zero[1] * 2 + 2 * g.pad_thickness, max(g.pad_width, 0.02), PALM_THICKNESS]

    def moments(a, b, h):
        return sorted(PALM_MASS / 12 * np.array([b * b + h * h, a * a + h * h, a * a + b * b]))

    assert sorted(m.body_inertia[slot.layout.palm]) == pytest.approx(moments(*box), rel=1e-9)
    assert sorted(bullet[0][1]) == pytest.approx(moments(*(x + 0.002 for x in box)), rel=1e-6)


def test_the_palm_stands_at_its_target_while_the_jaws_hold_the_object_on_the_table():
    """The gripper's own weight does not pull the palm off its target (the weld carries
    the path, not the gripper's weight, as Bullet's base constraint does): once the jaws
    have closed on the rectangle at rest on the table, the palm's frame is within 1 um of
    the mocap target (with the gripper weighing on the weld it sags 0.1 mm and more)."""
    slot = _closed_slot(_rectangle_trials((-0.045, 0.0), (0.045, 0.0))[0])
    mujoco.mj_step(slot.model, slot.data, 50)
    mujoco.mj_kinematics(slot.model, slot.data)
    assert slot.data.xpos[slot.layout.palm] == pytest.approx(slot.mocap_pos, abs=1e-6)


def test_a_trial_is_the_same_alone_in_a_batch_and_twice():
    """One model per trial: a trial's row does not depend on the trials beside it, the
    batch size or what the runner ran before; bit for bit."""
    scene = load_scene("marker")
    from harness import pipeline

    inputs = pipeline.posterior_inputs(pipeline.open_cell(scene, resolve(scene), 3, 0, 6), 6)
    trials = make_trials(resolve(scene), [[0.033, -0.014], [0.022, 0.034]], inputs.polygons, inputs.approach)
    with make_runner(MUJOCO, batch_size=4) as runner:
        together = [repr(r.as_dict()) for r in runner.run(trials)]
        again = [repr(r.as_dict()) for r in runner.run(trials)]
    me.compiled.cache_clear()
    alone = [repr(make_runner(MUJOCO).run([t])[0].as_dict()) for t in reversed(trials)][::-1]
    assert together == again == alone
    assert {eval(r)["outcome"] for r in together} - {"approach_collision"}  # some were simulated


def test_a_process_keeps_as_many_compiled_models_as_built_bodies():
    """A least-recently-used cache smaller than the shapes a process cycles through
    misses on every trial: with 128 models and `bench physics`' 130 shapes, every pass
    compiled every shape again. The models' cache holds as many as the bodies' does, and
    the models' layouts (indices and spare data) as many as the models."""
    from harness.physics.bodies import recipe

    assert me.compiled.cache_info().maxsize >= recipe.cache_info().maxsize >= 130
    assert me._layout.cache_info().maxsize >= me.compiled.cache_info().maxsize


def test_a_model_lends_its_data_to_one_trial_at_a_time():
    """A finished trial leaves its MjData to the next trial of the same model, reset to
    the model's initial state (mj_resetData, as a new MjData is); a trial that starts
    while another holds the data gets data of its own. Rows are the same either way
    (test_a_trial_is_the_same_alone_in_a_batch_and_twice runs the same trials again on
    lent data)."""
    trial = _rectangle_trials((-0.045, 0.0), (0.045, 0.0))[0]
    runner = me.MujocoRunner(MUJOCO)
    first, second = me._Slot(runner, trial), me._Slot(runner, trial)
    assert first.layout is second.layout and first.data is not second.data
    first.layout.give(first.data)
    mujoco.mj_step(first.model, first.data)  # a state that the next trial must not see
    third = me._Slot(runner, trial)
    assert third.data is first.data
    assert third.data.time == 0.0 and np.array_equal(third.data.qpos, second.data.qpos)
    assert np.array_equal(third.data.qvel, second.data.qvel) and not third.data.qacc_warmstart.any()


def test_the_mujoco_engine_refuses_a_gripper_it_cannot_build():
    from dataclasses import replace

    trial = _rectangle_trials((-0.045, 0.0), (0.045, 0.0))[0]
    other = replace(trial, gripper=replace(trial.gripper, urdf="/robots/franka_hand.urdf"))
    with pytest.raises(ValueError, match="built-in parallel-jaw gripper"):
        make_runner(MUJOCO).run([other])
    # The built-in URDF driven another way (its jaws' joints read with the other sign, or
    # closing along y) is not the gripper MuJoCo builds either.
    for changed in ({"face_per_unit": (-1.0, 1.0)}, {"closing_axis": (0.0, 1.0)}):
        with pytest.raises(ValueError, match="built-in parallel-jaw gripper"):
            make_runner(MUJOCO).run([replace(trial, gripper=replace(trial.gripper, **changed))])


def test_the_engine_is_a_physics_setting(tmp_path, capsys):
    from harness.config import load_config

    head = 'scenes = ["rectangle"]\n[[planners]]\nname = "mean-shape"\n'
    plain, mj, bad = (tmp_path / f"{n}.toml" for n in ("plain", "mj", "bad"))
    plain.write_text(head)
    mj.write_text(head + '[physics]\nengine = "mujoco"\n')
    bad.write_text(head + '[physics]\nengine = "ode"\n')
    explicit = tmp_path / "explicit.toml"
    explicit.write_text(head + '[physics]\nengine = "pybullet"\n')
    a, b = load_config(plain), load_config(mj)
    assert a.physics == {} and a.protocol() == Protocol() and a.engine == "pybullet"
    assert load_config(explicit).hash == a.hash  # the default engine leaves configs as they were
    assert b.protocol() == Protocol.of("mujoco") and b.protocol().time_step == ENGINE_DEFAULTS["mujoco"]["time_step"]
    assert a.with_engine("mujoco").physics == b.physics and a.with_engine("mujoco").name == "plain-mujoco"
    assert main(["eval", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "physics.engine" in err and "'ode'" in err


@pytest.fixture(scope="module")
def quick_runs(tmp_path_factory):
    """experiments/quick.toml in MuJoCo with 1 and with 2 workers, and in pybullet."""
    tmp = tmp_path_factory.mktemp("engines")
    quick = str(REPO / "experiments" / "quick.toml")
    for name, extra in (("mj1", ["--engine", "mujoco", "--workers", "1"]),
                        ("mj2", ["--engine", "mujoco", "--workers", "2"]),
                        ("pb", ["--workers", "2"])):
        assert main(["eval", quick, "--out", str(tmp / name), *extra]) == 0
    return tmp


def test_mujoco_runs_quick_end_to_end_the_same_with_any_number_of_workers(quick_runs):
    keys = ["scene", "realisation", "planner", "shapes", "trial"]
    one, two = (pd.read_parquet(quick_runs / d / "trials.parquet").sort_values(keys).reset_index(drop=True)
                for d in ("mj1", "mj2"))
    assert len(one) == 128
    pd.testing.assert_frame_equal(one, two, check_exact=True)
    manifest = json.loads((quick_runs / "mj1" / "manifest.json").read_text())
    assert manifest["engine"] == {"name": "mujoco", "version": mujoco.__version__}
    assert manifest["config"]["physics"] == {"engine": "mujoco"}
    assert json.loads((quick_runs / "pb" / "manifest.json").read_text())["engine"]["name"] == "pybullet"
    for name in ("summary.csv", "calibration.csv", "comparisons.csv", "failures.csv", "summary.md"):
        assert (quick_runs / "mj1" / name).is_file()
    assert "Physics: mujoco" in (quick_runs / "mj1" / "summary.md").read_text()
    assert list((quick_runs / "mj1" / "figures").glob("*.png"))


def test_a_cross_engine_comparison_pairs_runs_that_differ_in_the_engine_alone(quick_runs, capsys):
    pb, mj = str(quick_runs / "pb"), str(quick_runs / "mj1")
    assert main(["compare", pb, mj, "--engines", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["differences"] == {"physics": [{}, {"engine": "mujoco"}]}
    assert out["trials"]["paired"] == 128
    assert all(p["identical"] == p["plans"] for p in out["plans"].values())  # the engine moves no plan
    assert main(["compare", mj, str(quick_runs / "mj2"), "--engines"]) == 2  # one engine twice
    assert "needs two engines" in capsys.readouterr().err


def test_a_cross_engine_comparison_refuses_any_other_difference(tmp_path, capsys):
    from test_compare import _config, _keys, _write_run

    outcomes = ["success"] * len(_keys())
    a = _write_run(tmp_path / "a", _config(), outcomes)
    b = _write_run(tmp_path / "b", _config(physics={"engine": "mujoco", "lift_height": 0.05}), outcomes)
    c = _write_run(tmp_path / "c", _config(physics={"engine": "mujoco"}, time_budget_s=99.0), outcomes)
    d = _write_run(tmp_path / "d", _config(physics={"engine": "mujoco"}, batch_size=64), outcomes)
    for other, field in ((b, "config.physics"), (c, "config.time_budget_s")):
        assert main(["compare", str(a), str(other), "--engines"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and field in err and "engine alone" in err
    assert main(["compare", str(a), str(d), "--engines"]) == 0  # batching changes no result
    assert main(["compare", str(a), str(b)]) == 0  # without --engines any physics change is paired


def test_a_cross_engine_comparison_refuses_scene_files_whose_content_differs(tmp_path, capsys):
    """Two runs may read their scenes from different folders (the ledger pairs them by the
    scene's name): a cross-engine comparison checks that the files say the same, by the
    config's content hash less the engine."""
    from test_compare import SCENES, _config, _keys, _write_run

    text = (Path(__file__).parents[1] / "scenes" / "rectangle.toml").read_text()
    folders = {}
    for copy, noise in (("one", "0.0005"), ("same", "0.0005"), ("noisier", "0.002")):
        folder = tmp_path / copy
        folder.mkdir()
        for name in SCENES:
            edited = text.replace('name = "rectangle"', f'name = "{name}"')
            (folder / f"{name}.toml").write_text(edited.replace("noise = 0.0005", f"noise = {noise}"))
        folders[copy] = [str(folder / f"{name}.toml") for name in SCENES]
    outcomes = ["success"] * len(_keys())
    a = _write_run(tmp_path / "a", _config(scenes=folders["one"]), outcomes)
    same = _write_run(tmp_path / "b", _config(scenes=folders["same"], physics={"engine": "mujoco"}), outcomes)
    noisier = _write_run(tmp_path / "c", _config(scenes=folders["noisier"], physics={"engine": "mujoco"}), outcomes)
    assert main(["compare", str(a), str(same), "--engines"]) == 0
    capsys.readouterr()
    assert main(["compare", str(a), str(noisier), "--engines"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "config.scenes" in err and "content differs" in err


def test_simulate_writes_mujoco_frames(tmp_path, capsys):
    frames = tmp_path / "frames"
    assert main(["simulate", "rectangle", "--grasp", "-0.045", "0", "0.045", "0", "--trials", "2",
                 "--engine", "mujoco", "--frames", str(frames), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["engine"] == "mujoco" and out["successes"] == 2
    assert sorted(p.name for p in frames.glob("*.png")) == ["1-placed.png", "2-closed.png", "3-lifted.png",
                                                             "4-shaken.png"]


def test_the_base_follows_the_protocols_path_in_mujoco():
    """The mocap target's path in MuJoCo is the protocol's motion (trial.motion) about the
    grasp (the lift up to the lift height, the shake's offsets and turns), as
    TrialMachine.before_step moves Bullet's base."""
    slot = _closed_slot(_rectangle_trials((-0.045, 0.01), (0.045, -0.01))[0])
    positions, turns = slot.paths["lift"]
    assert positions[-1][2] == pytest.approx(slot.base_z + MUJOCO.lift_height, abs=1e-12)
    assert positions[:, :2] == pytest.approx(np.tile(slot.centre, (len(positions), 1)))
    heading = 2 * np.arctan2(turns[:, 3], turns[:, 0])
    assert heading == pytest.approx(np.full(len(turns), slot.heading))
    shake, shake_turns = slot.paths["shake"]
    angle = 2 * np.arctan2(shake_turns[:, 3], shake_turns[:, 0]) - slot.heading
    a, b, turn = np.asarray(slot.motion.shake).T
    assert angle == pytest.approx(turn, abs=1e-12)
    offsets = np.hypot(shake[:, 0] - slot.centre[0], shake[:, 1] - slot.centre[1])
    assert offsets == pytest.approx(np.hypot(a, b), abs=1e-12)
    assert offsets.max() == pytest.approx(MUJOCO.shake_amplitude, rel=1e-3)
    assert math.isclose(shake[0, 2], slot.base_z + MUJOCO.lift_height)
    # Against the closed forms: the shake's offset follows the amplitude's sin^2 envelope
    # at the end of each step, its turn is in proportion to the offset along the first
    # axis, and the lift rises on the minimum-jerk profile.
    t = (np.arange(len(shake)) + 1) * MUJOCO.time_step
    envelope = MUJOCO.shake_amplitude * np.sin(np.pi * t / MUJOCO.shake_time) ** 2
    assert offsets == pytest.approx(envelope, abs=1e-12)
    assert angle == pytest.approx(MUJOCO.shake_turn * a / MUJOCO.shake_amplitude, abs=1e-12)
    tau = (np.arange(len(positions)) + 1) * MUJOCO.time_step / MUJOCO.lift_time
    rise = MUJOCO.lift_height * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
    assert positions[:, 2] - slot.base_z == pytest.approx(rise, abs=1e-12)


def test_the_study_rebuilds_a_disagreement_with_frames_and_traces(quick_runs, tmp_path):
    """A posterior trial marked as held by one engine and lost by the other is re-run in
    both from the run's config and plan: MuJoCo gives the run's own row for it (a trial's
    row does not depend on its batch), and each engine's folder gets the four frames and
    the trace, whose last check is where the re-run ended."""
    from harness.bench.engines_study import write_frames
    from harness.report import load

    mj = pd.read_parquet(quick_runs / "mj1" / "trials.parquet")
    picked = mj[mj.shapes == "posterior"].head(1)
    trials = picked.rename(columns={"outcome": "outcome_b"}).assign(outcome_a="slipped")
    out = write_frames(trials, load(quick_runs / "mj1"), tmp_path, count=1)
    assert len(out) == 1
    row = picked.iloc[0]
    assert out[0]["rerun"]["mujoco"]["outcome"] == row.outcome
    assert out[0]["rerun"]["mujoco"]["pivot"] == pytest.approx(row.pivot, abs=1e-12)
    for engine in ("pybullet", "mujoco"):
        folder = Path(out[0]["folder"]) / engine
        assert len(list(folder.glob("*.png"))) == 4
        trace = pd.read_csv(folder / "trace.csv")
        assert trace["pivot"].iloc[-1] == pytest.approx(out[0]["rerun"][engine]["pivot"], abs=1e-12)


def test_the_engines_study_reports_the_runs_own_counts(quick_runs, tmp_path):
    """bench engines' study of two runs: its trial agreement, per-planner success and
    plan count are the trials' own (recomputed here from the runs' parquet files), every
    comparison of the report appears under both engines, and the text prints."""
    from harness.bench.engines_study import format_lines, study

    res = study(quick_runs / "pb", quick_runs / "mj1", frames=tmp_path / "frames")
    keys = ["scene", "realisation", "planner", "shapes", "trial"]
    a, b = (pd.read_parquet(quick_runs / d / "trials.parquet") for d in ("pb", "mj1"))
    both = a.merge(b, on=keys, suffixes=("_a", "_b"))
    assert res["trials"] == len(both) == 128
    assert res["trial_agreement"]["all"] == pytest.approx((both.outcome_a == both.outcome_b).mean(), abs=1e-12)
    assert res["identical_plans"] == {"paired": 8, "same": 8}
    for p in res["planners"]:
        for k, run in enumerate((a, b)):
            post = run[(run.planner == p["planner"]) & (run.shapes == "posterior")]
            assert p["posterior"][k] == pytest.approx((post.outcome == "success").mean(), abs=1e-12)
    report = pd.read_csv(quick_runs / "pb" / "comparisons.csv")
    pairs = {(r.planner, r.versus) for r in report.itertuples()}
    assert {(c["planner"], c["versus"]) for c in res["comparisons"]} == pairs
    # Each comparison's change from one engine to the other, paired trial by trial: the
    # difference of the two differences on the same pairs, inside its own interval.
    for c in res["comparisons"]:
        assert c["shift"] == pytest.approx(c["difference"][1] - c["difference"][0], abs=1e-12)
        assert c["shift_ci"][0] <= c["shift"] <= c["shift_ci"][1]
    assert res["engines"] == ["pybullet", "mujoco"]
    text = "\n".join(format_lines(res))
    assert "pybullet 3.2.7 against mujoco" in text and "paired trials" in text and "(paired)" in text
    # With the bars of bench lift (as bench engines runs them): one row per bar in each engine.
    row = {"bar": "bar 18 x 3 x 3 cm", "points": [{"offset": 0.0}, {"offset": 0.004}], "p_l_at": 0.03,
           "success_at": 0.028, "error": 0.07, "model_turning_at": 0.03, "turning_at": None, "turning_error": None,
           "held_turn_median": None, "failures": {"slipped": 3}}
    bars = {"rows": [row], "trials_per_offset": 4, "analytic_draws": 50, "sigma_g": 0.0, "largest_error": 0.07,
            "largest_turning_error": None, "missing": 0}
    text = "\n".join(format_lines({**res, "lift": {"pybullet": bars, "mujoco": bars}}))
    assert text.count("bar 18 x 3 x 3 cm") == 2 and "the lift model's bars in mujoco:" in text


def _relabel(folder: Path, outcomes: dict, p_l: dict, moved: tuple | None = None) -> None:
    """Give a copied run's ledger these trial outcomes ({key: outcome}) and plans' P_L,
    and move the ``moved`` plan's first jaw by 1 mm."""
    import sqlite3

    with sqlite3.connect(folder / "ledger.sqlite") as db:
        if moved is not None:
            db.execute("UPDATE plans SET g1y = g1y + 0.001 WHERE scene = ? AND realisation = ? AND planner = ?",
                       moved)
        db.executemany("UPDATE trials SET outcome = ? WHERE scene = ? AND realisation = ? AND planner = ? "
                       "AND shapes = ? AND trial = ?", [(o, *k) for k, o in outcomes.items()])
        db.executemany("UPDATE analytic SET p_l = ? WHERE scene = ? AND realisation = ? AND planner = ?",
                       [(v, *k) for k, v in p_l.items()])


def test_the_engines_study_figures_are_the_trials_own_where_the_engines_part(quick_runs, tmp_path):
    """The study's every figure (cells and their rms difference, each planner's pooled
    success and Wilson interval, the rankings and Kendall's tau, the comparisons' verdicts,
    P_L's Spearman and Brier, trial agreement and the outcomes' cross-table) against the
    same numbers computed here from the trials, on copies of the quick runs whose
    outcomes were redrawn so that success varies by plan and the engines part on a fifth
    of the trials (the quick runs themselves succeed in every trial, where most of these
    figures cannot fail)."""
    import shutil

    from scipy import stats

    from harness.bench.engines_study import study
    from harness.quality import Z95

    dirs = {}
    for name in ("pb", "mj1"):
        dirs[name] = tmp_path / name
        shutil.copytree(quick_runs / name, dirs[name])
    keys = ["scene", "realisation", "planner", "shapes", "trial"]
    trials = pd.read_parquet(quick_runs / "pb" / "trials.parquet").sort_values(keys).reset_index(drop=True)
    plans = sorted(set(map(tuple, trials[["scene", "realisation", "planner"]].to_numpy())))
    rng = np.random.default_rng(11)
    rate = {k: 0.95 if k[2] == "gp-gpis-opt" else r for k, r in zip(plans, rng.uniform(0.2, 1.0, len(plans)))}
    p_l = {k: float(np.clip(rate[k] + rng.normal(0, 0.15), 0, 1)) for k in plans}
    win_a = np.array([rng.random() < rate[(r.scene, r.realisation, r.planner)] for r in trials.itertuples()])
    flip = rng.random(len(trials)) < 0.2
    # B: a fifth of the trials turned, one planner's posterior successes lost (its
    # comparisons' intervals then lie apart), and some failures another failure.
    flip |= win_a & (trials.planner == "gp-gpis-opt").to_numpy() & (trials.shapes == "posterior").to_numpy()
    a = np.where(win_a, "success", "slipped")
    b = np.where(flip, np.where(win_a, np.where(rng.random(len(trials)) < 0.5, "slipped", "dropped"), "success"), a)
    b = np.where(~flip & ~win_a & (rng.random(len(trials)) < 0.3), "dropped", b)
    rows = list(map(tuple, trials[keys].to_numpy()))
    _relabel(dirs["pb"], dict(zip(rows, a)), p_l)
    _relabel(dirs["mj1"], dict(zip(rows, b)), p_l, moved=plans[0])
    t = trials[keys].assign(a=a, b=b, sa=a == "success", sb=b == "success")
    assert 0 < t.sa.mean() < 1 and (t.a != t.b).any()

    res = study(dirs["pb"], dirs["mj1"])
    assert res["identical_plans"] == {"paired": 8, "same": 7}
    # Cells: each engine's success per scene and planner, and the rms of their differences.
    cell = t.groupby(["scene", "planner", "shapes"])[["sa", "sb"]].mean()
    for c in res["cells"]:
        for shapes in ("posterior", "truth"):
            assert c[shapes] == pytest.approx(list(cell.loc[(c["scene"], c["planner"], shapes)]), abs=1e-12)
    for shapes in ("posterior", "truth"):
        d = cell.xs(shapes, level="shapes")
        assert len(res["cells"]) == len(d) == 8
        assert res["cell_rms"][shapes] == pytest.approx(float(np.sqrt(((d.sa - d.sb) ** 2).mean())), abs=1e-12)
    assert res["cell_rms"]["posterior"] > 0.05
    # Each planner pooled over scenes, with the Wilson interval of its posterior trials.
    pooled = t.groupby(["planner", "shapes"])[["sa", "sb"]].agg(["sum", "count"])
    for p in res["planners"]:
        for k, col in enumerate(("sa", "sb")):
            post, truth = pooled.loc[(p["planner"], "posterior"), col], pooled.loc[(p["planner"], "truth"), col]
            assert p["posterior"][k] == pytest.approx(post["sum"] / post["count"], abs=1e-12)
            assert p["truth"][k] == pytest.approx(truth["sum"] / truth["count"], abs=1e-12)
            n, s = post["count"], post["sum"] / post["count"]
            centre, half = (s + Z95**2 / (2 * n)), Z95 * math.sqrt(s * (1 - s) / n + Z95**2 / (4 * n * n))
            assert p["posterior_ci"][k] == pytest.approx([(centre - half) / (1 + Z95**2 / n),
                                                          (centre + half) / (1 + Z95**2 / n)], abs=1e-9)
    # Rankings: per scene and pooled, each engine's order by posterior success, and
    # Kendall's tau between the engines' successes.
    post = t[t.shapes == "posterior"]
    for scene, r in res["ranking"].items():
        g = post if scene == "all" else post[post.scene == scene]
        rates = g.groupby("planner")[["sa", "sb"]].mean()
        tau = stats.kendalltau(rates.sa, rates.sb).statistic
        assert (r["tau"] is None and math.isnan(tau)) or r["tau"] == pytest.approx(tau, abs=1e-12)
        for k, col in enumerate(("sa", "sb")):
            order = list(rates[col].loc[r["order"][k]])
            assert sorted(r["order"][k]) == sorted(rates.index) and order == sorted(order, reverse=True)
    per_scene = [r["tau"] for s, r in res["ranking"].items() if s != "all" and r["tau"] is not None]
    assert res["kendall_tau_per_scene"] == {"mean": pytest.approx(float(np.mean(per_scene)), abs=1e-12),
                                            "min": pytest.approx(min(per_scene), abs=1e-12),
                                            "scenes": len(per_scene)}
    # Comparisons pooled over scenes: each engine's paired difference on the same trials,
    # the verdict its interval gives, its sign and whether the two intervals overlap.
    assert res["comparisons"]
    for c in res["comparisons"]:
        g = t if c["shapes"] == "all" else t[t.shapes == c["shapes"]]
        wide = g.pivot_table(index=["scene", "realisation", "shapes", "trial"], columns="planner",
                             values=["sa", "sb"], aggfunc="first")
        for k, col in enumerate(("sa", "sb")):
            direct = (wide[col][c["planner"]].astype(float) - wide[col][c["versus"]].astype(float)).mean()
            assert c["difference"][k] == pytest.approx(direct, abs=1e-12)
            lo, hi = c["ci"][k]
            assert c["verdict"][k] == ("+" if lo > 0 else "-" if hi < 0 else "0")
        assert c["same_sign"] == (np.sign(c["difference"][0]) == np.sign(c["difference"][1]))
        assert c["same_verdict"] == (c["verdict"][0] == c["verdict"][1])
        (la, ha), (lb, hb) = c["ci"]
        assert c["intervals_overlap"] == (max(la, lb) <= min(ha, hb))
    assert {c["verdict"][0] for c in res["comparisons"]} != {"0"}
    assert {c["intervals_overlap"] for c in res["comparisons"]} == {True, False}
    assert {c["same_sign"] for c in res["comparisons"]} == {True, False}
    # P_L against each engine: Spearman over plans, Brier over posterior trials.
    est = post.assign(p=[p_l[(r.scene, r.realisation, r.planner)] for r in post.itertuples()])
    for name, col in (("pybullet", "sa"), ("mujoco", "sb")):
        per_plan = est.groupby(["scene", "realisation", "planner"]).agg(p=("p", "first"), s=(col, "mean"))
        cal = res["calibration"][name]["p_l"]
        assert cal["spearman"] == pytest.approx(stats.spearmanr(per_plan.p, per_plan.s).statistic, abs=1e-12)
        assert cal["brier"] == pytest.approx(float(((est.p - est[col]) ** 2).mean()), abs=1e-12)
        assert cal["success_rate"] == pytest.approx(float(est[col].mean()), abs=1e-12)
        assert cal["mean_estimate"] == pytest.approx(float(per_plan.p.mean()), abs=1e-12)
    assert res["calibration"]["pybullet"]["p_l"]["brier"] != res["calibration"]["mujoco"]["p_l"]["brier"]
    # Trial by trial: the same outcome, the same success, and the cross-table's counts.
    for shapes, g in t.groupby("shapes"):
        assert res["trial_agreement"][shapes] == pytest.approx(float((g.a == g.b).mean()), abs=1e-12)
        assert res["success_agreement"][shapes] == pytest.approx(float((g.sa == g.sb).mean()), abs=1e-12)
    assert res["trial_agreement"]["all"] == pytest.approx(float((t.a == t.b).mean()), abs=1e-12)
    table = res["outcomes"]["table"]
    counts = t.groupby(["a", "b"]).size()
    assert {(ra, cb): n for ra, row in table.items() for cb, n in row.items() if n} == dict(counts)
    assert {("success", "dropped"), ("slipped", "success"), ("slipped", "dropped")} <= set(dict(counts))


def test_mujocos_runaway_check_reads_the_centre_of_mass_speed_as_bullets_does():
    """A free joint's linear velocity is its frame origin's (the polygon's origin), not the
    centre of mass's, which Bullet's base velocity gives. On a rectangle shifted 4 cm from
    the origin, a spin of 20 rad/s about the vertical through its centre of mass moves the
    origin at 0.8 m/s and the centre of mass not at all: the check reads 0; a translation
    of 0.3 m/s reads 0.3 (below and above a max_speed of 0.1 m/s)."""
    import shapely.affinity

    scene = load_scene("rectangle")
    settings = resolve(scene, {"sigma_g": 0.0})
    polygon = shapely.affinity.translate(truth_polygon(scene), xoff=0.04)
    trial = make_trials(settings, [(-0.005, 0.0), (0.085, 0.0)], [polygon], np.zeros((1, 2, 2)))[0]
    slot = me._Slot(me.MujocoRunner(replace(MUJOCO, max_speed=0.1)), trial)
    mujoco.mj_kinematics(slot.model, slot.data)
    com, origin = slot.data.xipos[slot.obj].copy(), slot.data.xpos[slot.obj].copy()
    assert np.linalg.norm((com - origin)[:2]) == pytest.approx(0.04, abs=1e-6)
    spin = np.array([0.0, 0.0, 20.0])  # world frame; the body's frame is the world's here (no turn yet)
    np.testing.assert_allclose(slot.data.xmat[slot.obj].reshape(3, 3), np.eye(3), atol=1e-12)
    slot.obj_velocity[:] = [*(-np.cross(spin, com - origin)), *spin]
    slot.fresh = False
    assert np.linalg.norm(slot.obj_velocity[:3]) == pytest.approx(0.8, rel=1e-6) and not slot.blew_up()
    slot.obj_velocity[:] = [0.3, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert slot.blew_up()


def test_mujocos_runaway_speeds_from_the_state_match_its_kinematics_on_a_turned_object():
    """The runaway check's speeds come from the free joint's state alone (its quaternion,
    the centre of mass in the body's frame), at every closing step; against the second
    formulation from MuJoCo's kinematics (the body's rotation matrix, the centre of mass
    and the origin in the world) on 50 random turns and velocities of the shifted
    rectangle: the same speed and spin within 1e-12 m/s."""
    import shapely.affinity

    scene = load_scene("rectangle")
    settings = resolve(scene, {"sigma_g": 0.0})
    polygon = shapely.affinity.translate(truth_polygon(scene), xoff=0.04, yoff=-0.01)
    trial = make_trials(settings, [(-0.005, 0.0), (0.085, 0.0)], [polygon], np.zeros((1, 2, 2)))[0]
    slot = me._Slot(me.MujocoRunner(MUJOCO), trial)
    rng = np.random.default_rng(4)
    for _ in range(50):
        turn = rng.normal(size=4)
        slot.obj_turn[:] = turn / np.linalg.norm(turn)
        slot.obj_velocity[:] = rng.normal(scale=(1, 1, 1, 20, 20, 20))
        mujoco.mj_kinematics(slot.model, slot.data)
        d = slot.data
        spin = d.xmat[slot.obj].reshape(3, 3) @ slot.obj_velocity[3:]
        velocity = slot.obj_velocity[:3] + np.cross(spin, d.xipos[slot.obj] - d.xpos[slot.obj])
        speed, size = slot.speeds()
        assert speed == pytest.approx(np.linalg.norm(velocity), abs=1e-12)
        assert size == pytest.approx(np.linalg.norm(spin), abs=1e-12)
        assert np.linalg.norm(d.xipos[slot.obj] - d.xpos[slot.obj]) > 0.03  # the centre of mass is off the origin


def test_without_early_stop_a_trial_keeps_its_first_failure_when_it_later_blows_up():
    """The naive reference runs every trial to the end (early_stop off) and records the
    first failure seen: an object lost in the lift that then diverges is 'slipped', not
    'unstable' (which replaced it before)."""
    trial = _rectangle_trials((-0.045, 0.0), (0.045, 0.0))[0]
    slot = me._Slot(me.MujocoRunner(MUJOCO, early_stop=False), trial)
    while slot.phase == "close" and slot.result is None:
        slot.before_step()
        mujoco.mj_step(slot.model, slot.data)
        slot.fresh = False
        slot.after_step()
    slot._fail("slipped")
    assert slot.result is None  # no early stop: it runs on
    slot.obj_velocity[0] = math.nan  # the state diverges
    while slot.result is None:
        slot.before_step()
        slot.fresh = False
        slot.after_step()
    assert slot.result.outcome == "slipped"
