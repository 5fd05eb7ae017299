"""A trial's trace (harness.physics.trace, ``simulate --trace``): it changes no result,
it has a row at the end of closing and at every contact check, and on the rectangle held
through its centre it reads what a held object must give: each jaw's contact forces
adding up to the gripper's force limit, the grip point staying put in the jaws, and the
turn and rise of the trial's own result at its last check."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from harness.cli import main
from harness.physics.engines import make_runner
from harness.physics.simulate import make_trials, truth_polygon
from harness.physics.trace import COLUMNS, Tracer, pressure_centre
from harness.protocol import ENGINES, Protocol
from harness.scene import load_scene
from harness.settings import resolve


def _rectangle_trials(n: int = 2):
    """The rectangle (6 x 3 cm) gripped through its centre across its 3 cm width, under
    the scene's approach noise."""
    scene = load_scene("rectangle")
    approach = np.random.default_rng(3).standard_normal((n, 2, 2))
    return resolve(scene), make_trials(resolve(scene), [(0.0, -0.03), (0.0, 0.03)], [truth_polygon(scene)],
                                       approach)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_trace_changes_no_result_and_reads_a_held_object(engine):
    settings, trials = _rectangle_trials()
    protocol = Protocol.of(engine)
    with make_runner(protocol) as runner:
        plain = runner.run(trials)
    tracer = Tracer()
    with make_runner(protocol) as runner:
        traced = runner.run(trials, trace=tracer)
    assert traced == plain  # bit for bit: tracing only reads the engine's state
    assert plain[0].outcome == "success"
    rows = tracer.rows
    assert set(rows[0]) == set(COLUMNS)
    # One row when the jaws stall, then one at every check: the phases in order, a check
    # every check_interval within a phase and one at each phase's end.
    phases = [r["phase"] for r in rows]
    assert phases[0] == "close" and phases[1:] == sorted(phases[1:], key=["lift", "hold", "shake"].index)
    check = protocol.steps(protocol.check_interval)
    steps = np.diff([r["step"] for r in rows if r["phase"] == "lift"])
    assert set(steps[:-1].tolist()) == {check} and 1 <= steps[-1] <= check
    # The last check is where the trial ended: its turn and rise are the result's.
    assert rows[-1]["pivot"] == plain[0].pivot and rows[-1]["rise"] == plain[0].rise
    held = [r for r in rows if r["phase"] != "close"]
    for r in held:
        for jaw in (1, 2):
            # Each jaw's contact points carry the force limit (20 N): within 3 % while the
            # object is lifted and held, within 10 % in the shake, whose acceleration along
            # the closing axis the two jaws' drives share unevenly (Bullet: 18.8-20.5 N).
            assert r[f"jaw{jaw}_points"] >= 1
            tolerance = 0.10 if r["phase"] == "shake" else 0.03
            assert r[f"jaw{jaw}_force"] == pytest.approx(settings.force, rel=tolerance)
        # The grip point stays where the jaws took it: along the plates and up within
        # 0.5 mm (across the jaws the pair may drift with the object in the shake).
        assert abs(r["slide_along"]) < 5e-4 and abs(r["slide_up"]) < 5e-4
        assert r["jaws_near"] == 2
    assert held[-1]["rise"] == pytest.approx(protocol.lift_height, abs=0.002) and not held[-1]["on_table"]
    # "On the table" means the same in both engines: touching within about the held
    # distance (1 mm). MuJoCo measures the distance; Bullet reads its contact manifold,
    # which keeps a convex foot's points on the plane up to about 0.8 mm. Lifted level
    # through its centre, the rectangle is on the table at every check below 0.5 mm of
    # rise and off it at every check above 1.5 mm, and it passes through both bands.
    low = [r["on_table"] for r in rows if r["rise"] < 0.0005]
    high = [r["on_table"] for r in rows if r["rise"] > 0.0015]
    assert low and all(low) and high and not any(high)


def test_the_pressure_centre_weighs_points_by_their_force():
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.03]])
    assert pressure_centre(points, [3.0, 1.0]) == pytest.approx([0.0, 0.0, 0.0075])
    assert pressure_centre(points, [0.0, 0.0]) == pytest.approx([0.0, 0.0, 0.015])
    assert pressure_centre(np.zeros((0, 3)), []) is None


def test_simulate_writes_the_trace_as_csv(tmp_path, capsys):
    out = tmp_path / "trace.csv"
    assert main(["simulate", "rectangle", "--grasp", "0", "-0.03", "0", "0.03", "--trials", "1", "--shapes",
                 "truth", "--engine", "mujoco", "--trace", str(out)]) == 0
    assert "trace in" in capsys.readouterr().out
    with open(out) as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS and len(rows) > 60
    assert rows[0]["phase"] == "close" and rows[-1]["phase"] == "shake"
    # Jaws placed inside the rectangle: decided before simulating, the trace has no rows.
    assert main(["simulate", "rectangle", "--grasp", "0", "-0.01", "0", "0.03", "--trials", "1", "--shapes",
                 "truth", "--sigma-g", "0", "--trace", str(out)]) == 0
    assert "ended approach_collision before its jaws closed" in capsys.readouterr().out
    with open(out) as f:
        assert list(csv.DictReader(f)) == [] and f.seek(0) == 0 and f.readline().strip() == ",".join(COLUMNS)


@pytest.mark.parametrize("engine", ENGINES)
def test_the_slide_of_an_object_too_heavy_for_the_grip_is_its_fall_behind_the_jaws(engine):
    """At 0.1 N the plates' friction (2 mu N = 0.1 N) cannot carry the rectangle's 0.21 N:
    it stays on the table while the jaws rise. Its grip point then slides down the
    plates (a point of the object carried into the gripper's frame) by as much as the
    gripper has risen less the object's own rise (heights in the world): within 0.5 mm
    at every check of the lift. The gripper follows the lift's minimum-jerk profile
    (harness.physics.trial.motion) a few milliseconds behind: within 4 mm of it (Bullet's
    base constraint 3.2 mm behind at the profile's peak speed, 0.47 m/s: about 7 ms)."""
    from harness.physics.trial import motion

    scene = load_scene("rectangle")
    settings = resolve(scene, {"force": 0.1, "sigma_g": 0.0})
    trial = make_trials(settings, [(0.0, -0.03), (0.0, 0.03)], [truth_polygon(scene)], np.zeros((1, 2, 2)))
    protocol = Protocol.of(engine)
    tracer = Tracer()
    with make_runner(protocol) as runner:
        result = runner.run(trial, trace=tracer)[0]
    assert result.outcome == "slipped"
    rise = motion(protocol).rise
    close = tracer.rows[0]["step"]
    lift = [r for r in tracer.rows if r["phase"] == "lift"]
    assert len(lift) >= 3
    for r in lift:
        assert r["slide_up"] == pytest.approx(r["rise"] - r["gripper_rise"], abs=5e-4)
        assert r["gripper_rise"] == pytest.approx(rise[r["step"] - close - 1], abs=4e-3)
    assert lift[-1]["slide_up"] < -0.005  # it did fall behind
