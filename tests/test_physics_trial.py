"""Physics trials: the approach check against the rectangle's closed form, the
calibration grasps, the unstable outcome, the friction law, and determinism. The large counts live in
``gpis-harness bench physics``."""

from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import pybullet as pb
import pytest

from harness.canonical import canonical
from harness.physics.simulate import make_trials, truth_polygon
from harness.physics.engines import make_runner
from harness.physics.trial import Trial, approach_blocked, free_travel
from harness.protocol import Protocol
from harness.scene import load_scene
from harness.settings import resolve


def _rectangle_trial(g1, g2, scene=None) -> Trial:
    scene = scene or load_scene("rectangle")
    settings = resolve(scene, {"sigma_g": 0.0})
    return make_trials(settings, [g1, g2], [truth_polygon(scene)], np.zeros((1, 2, 2)))[0]


def test_approach_collision_matches_the_rectangle_closed_form():
    # The pads reach PLATE_THICKNESS outwards from g and jaw_width / 2 to either side.
    rng = np.random.default_rng(5)
    for _ in range(200):
        x1, x2 = -rng.uniform(0.0, 0.05), rng.uniform(0.0, 0.05)
        y = rng.uniform(-0.03, 0.03)
        blocked = approach_blocked(_rectangle_trial((x1, y), (x2, y)))
        overlaps_y = abs(y) < 0.015 + 0.005
        expected = overlaps_y and (x1 > -0.03 or x2 < 0.03)
        assert blocked == expected, (x1, x2, y)


def test_free_travel_matches_the_rectangle_closed_form():
    # The 0.06 m x 0.03 m rectangle: a plate at x1 < -0.03 first meets the face x = -0.03,
    # unless its width misses the rectangle (|y| >= 0.015 + jaw_width / 2).
    rng = np.random.default_rng(6)
    half_pad = 0.5 * _rectangle_trial((-0.05, 0.0), (0.05, 0.0)).gripper.pad_width
    for _ in range(200):
        # On the canonical grid, as a trial executes them (make_trials rounds the plan).
        x1, x2 = canonical([-rng.uniform(0.03, 0.05), rng.uniform(0.03, 0.05)])
        y = canonical(rng.uniform(-0.025, 0.025))
        travel = free_travel(_rectangle_trial((x1, y), (x2, y)))
        if abs(y) < 0.015 + half_pad - 1e-9:
            assert travel == pytest.approx(min(-0.03 - x1, x2 - 0.03), abs=1e-12), (x1, x2, y)
        else:
            assert travel == math.inf


def test_the_calibration_grasps_on_the_rectangle():
    scene = load_scene("rectangle")
    good = _rectangle_trial((-0.045, 0.0), (0.045, 0.0), scene)
    miss = _rectangle_trial((-0.045, 0.03), (0.045, 0.03), scene)
    inside = _rectangle_trial((-0.02, 0.0), (0.045, 0.0), scene)
    with make_runner() as runner:
        results = runner.run([good] * 6 + [miss, inside])
    assert [r.outcome for r in results[:6]] == ["success"] * 6  # >= 98 % of 6 is all of them
    assert results[6].outcome == "no_contact"
    assert results[7].outcome == "approach_collision"
    for r in results[:6]:
        assert r.grip_width == pytest.approx(0.06, abs=5e-4)   # the jaws stall on the true faces
        assert abs(r.closing_turn) < 0.01                      # a square-on grasp does not turn it
        assert r.rise == pytest.approx(Protocol().lift_height, abs=0.005)


def test_a_blown_up_simulation_is_recorded_as_unstable():
    trial = _rectangle_trial((-0.045, 0.0), (0.045, 0.0))
    with make_runner(Protocol(max_speed=-1.0)) as runner:  # any motion counts as runaway
        assert runner.run([trial])[0].outcome == "unstable"


def test_a_jaw_that_diverged_while_closing_is_unstable_not_a_missed_grasp():
    """A NaN jaw position when the closing ends (the object's state still finite, so the
    runaway check passes) made a NaN grip width, which passed the grip-width test and
    ended `no_contact`; any NaN is `unstable` (docs/physics.md). MuJoCo's slot, its first
    jaw set to NaN at the closing's last step."""
    import harness.physics.mujoco_engine as me

    trial = _rectangle_trial((-0.045, 0.0), (0.045, 0.0))
    slot = me._Slot(me.MujocoRunner(Protocol.of("mujoco")), trial)
    slot.tick = slot.close_steps
    slot._after_closing_step()
    # Finite jaws still 2 mm off the walls (the skipped travel): the grip-width test passes
    # and the held test fails, the path a NaN width took before.
    assert slot.result.outcome == "no_contact" and slot.result.grip_width == pytest.approx(0.064, abs=1e-6)
    slot = me._Slot(me.MujocoRunner(Protocol.of("mujoco")), trial)
    slot.data.qpos[slot.finger_qpos[0]] = math.nan
    slot.tick = slot.close_steps
    assert not slot.blew_up()
    slot._after_closing_step()
    assert slot.result is not None and slot.result.outcome == "unstable"


def _pushed_distance(cone_friction: bool, angle: float, seconds: float = 0.25) -> float:
    """How far a 100 g box on the trials' table slides in ``seconds`` under a constant
    horizontal push at ``angle`` (rad) of 1.3 times its friction limit (friction as for a
    trial's object: the box carries 1, the table 0.5)."""
    protocol = Protocol(cone_friction=cone_friction)
    mass, mu = 0.1, protocol.table_friction
    push = 1.3 * mu * mass * 9.81 * np.array([math.cos(angle), math.sin(angle), 0.0])
    with make_runner(protocol) as runner:
        runner._reset_world()
        c = runner.client
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[0.03, 0.03, 0.01], physicsClientId=c)
        box = pb.createMultiBody(mass, shape, basePosition=[0, 0, 0.01], physicsClientId=c)
        pb.changeDynamics(box, -1, lateralFriction=1.0, frictionAnchor=1, physicsClientId=c)
        for _ in range(protocol.steps(seconds)):
            centre = pb.getBasePositionAndOrientation(box, physicsClientId=c)[0]
            pb.applyExternalForce(box, -1, push, centre, pb.WORLD_FRAME, physicsClientId=c)
            pb.stepSimulation(physicsClientId=c)
        x, y, _ = pb.getBasePositionAndOrientation(box, physicsClientId=c)[0]
    return math.hypot(x, y)


def test_friction_is_the_coulomb_cone_unless_the_protocol_asks_for_the_pyramid():
    """Coulomb: the push leaves 0.3 mu g of acceleration in any direction, so the box
    slides 0.15 mu g t^2 (46 mm in 0.25 s) along an axis and along the diagonal alike.
    Bullet's pyramid bounds the two friction directions separately: along an axis it
    agrees, but on the diagonal each component of the push (0.92 of the limit) is held."""
    closed_form = 0.15 * Protocol().table_friction * 9.81 * 0.25 ** 2
    assert _pushed_distance(True, 0.0) == pytest.approx(closed_form, rel=0.05)
    assert _pushed_distance(True, math.pi / 4) == pytest.approx(closed_form, rel=0.05)
    assert _pushed_distance(False, 0.0) == pytest.approx(closed_form, rel=0.05)
    assert _pushed_distance(False, math.pi / 4) < 0.002


def test_the_same_seed_gives_the_same_trials_and_outcomes():
    from harness import pipeline

    scene = load_scene("marker")
    grasp = [[0.033, -0.014], [0.022, 0.034]]

    def run_once():
        inputs = pipeline.posterior_inputs(pipeline.open_cell(scene, resolve(scene), 3, 0, 5), 5)
        trials = make_trials(resolve(scene), grasp, inputs.polygons, inputs.approach)
        with make_runner(batch_size=3) as runner:  # two batches: a world reset in between
            return trials, [repr(r.as_dict()) for r in runner.run(trials)]

    (trials_a, results_a), (trials_b, results_b) = run_once(), run_once()
    assert [t.polygon.wkb for t in trials_a] == [t.polygon.wkb for t in trials_b]
    assert [t.g1 + t.g2 for t in trials_a] == [t.g1 + t.g2 for t in trials_b]
    assert results_a == results_b  # bit for bit: outcomes, steps, grip widths, turns


def test_a_batch_does_not_depend_on_what_its_runner_ran_before():
    """Workers keep one client for many batches; each batch starts from a reset world,
    so its outcomes are the same bit for bit as in a fresh client."""
    scene = load_scene("rectangle")
    batch = [_rectangle_trial((-0.045, y), (0.045, y), scene) for y in (0.0, 0.01)]
    before = [_rectangle_trial((x, -0.02), (0.04, 0.02), scene) for x in (-0.045, -0.04)]
    with make_runner() as fresh:
        alone = [repr(r.as_dict()) for r in fresh.run(batch)]
    with make_runner() as used:
        used.run(before)
        after = [repr(r.as_dict()) for r in used.run(batch)]
    assert after == alone


@pytest.mark.parametrize("factor", [1, 4])
def test_the_precomputed_base_motion_matches_the_protocols_closed_forms(factor):
    """The lift follows the minimum-jerk profile to the full height; the shake runs one
    circle of the amplitude under the sin^2 envelope, with the turn in phase with it."""
    from harness.physics.trial import motion as _motion

    p = Protocol().finer(factor)
    m = _motion(p)
    assert (m.lift_steps, m.hold_steps, m.shake_steps) == (192 * factor, 48 * factor, 240 * factor)
    assert m.rise[-1] == pytest.approx(p.lift_height, abs=1e-15)
    half = m.lift_steps // 2 - 1  # the step ending at half the lift time: half the height, by symmetry
    assert m.rise[half] == pytest.approx(0.5 * p.lift_height, abs=1e-15)
    assert all(b > a for a, b in zip(m.rise, m.rise[1:]))
    for k in (0, m.shake_steps // 4, m.shake_steps // 2, m.shake_steps - 1):
        t = (k + 1) * p.time_step
        envelope = math.sin(math.pi * t / p.shake_time) ** 2
        a, b, turn = m.shake[k]
        assert math.hypot(a, b) == pytest.approx(p.shake_amplitude * envelope, abs=1e-15)
        assert turn == pytest.approx(p.shake_turn * a / p.shake_amplitude, abs=1e-15)
    peak = max(math.hypot(a, b) for a, b, _ in m.shake)
    assert peak == pytest.approx(p.shake_amplitude, rel=1e-4)


def test_the_contact_manifold_shortcut_of_the_lost_check_changes_no_result(monkeypatch):
    """The lost checks skip the closest-points query when the contact manifold already
    proves both jaws near. On the fidelity study's hard trial set (the first
    candidates as drawn, on the true shapes and posterior samples of every library
    scene, held and slipped trials among them) every result is the same bit for bit as with
    the query at every check, while the query runs far less often."""
    from harness.physics import bullet as trial_module
    from harness.bench.physics_study import library_trials

    trials = library_trials(grasps_per_scene=2, ranked=False).trials
    queries = []
    original = pb.getClosestPoints

    def counted(*args, **kwargs):
        queries.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(trial_module.pb, "getClosestPoints", counted)
    with make_runner() as runner:
        shortcut = runner.run(trials)
    with_shortcut = len(queries)
    monkeypatch.setattr(trial_module, "NEAR_SLACK", 1.0)  # no manifold point can prove a jaw near
    queries.clear()
    with make_runner() as runner:
        queried = runner.run(trials)
    assert [repr(r.as_dict()) for r in shortcut] == [repr(r.as_dict()) for r in queried]
    outcomes = {r.outcome for r in shortcut}
    assert {"success", "slipped"} <= outcomes, outcomes
    assert 0 < with_shortcut < 0.3 * len(queries), (with_shortcut, len(queries))


def test_contact_clipping_holds_the_swinging_hang_bar_as_a_four_times_finer_step_does():
    """bench lift's heavy hang bar (400 g at 10 N, the weight turns it) at two lengths whose
    hang clears the lifted table by about 5 cm, 8 trials each: at a four times finer step
    Bullet holds at least 15 of the 16 (docs/physics.md, "A heavy object swinging on the
    plates"), and so does the design's step with contact clipping. The design's step
    without clipping holds 13 of them (it shakes swinging bars out: docs/lift.md, "Hang
    bars"), so clipping flags that did not reach pybullet would fail this."""
    from harness.bench.lift_study import HANG_BARS, _exact_draws

    hang = HANG_BARS[0]
    trials = []
    for length in (0.075, 0.08):
        bar = hang.bar(length)
        scene = bar.scene()
        settings, approach, _ = _exact_draws(scene, 8, 3, "clipping test")
        trials += make_trials(settings, bar.grasp(hang.offset(length)), [truth_polygon(scene)], approach)
    for protocol in (Protocol().finer(4), Protocol(convex_clipping=True)):
        with make_runner(protocol) as runner:
            outcomes = [r.outcome for r in runner.run(trials)]
        assert outcomes.count("success") >= 15, (protocol.time_step, protocol.convex_clipping, outcomes)


def test_the_interleaved_timing_runs_every_trial_in_both_engines_as_a_plain_run_does():
    """bench physics' interleaved timing: each round runs every trial in both engines,
    block by block in turn, with the bodies built; its results are those of a plain run
    of each engine (blocks of Bullet's batch size keep Bullet's batches), and it times
    every round of each engine."""
    from harness.bench.physics_study import interleaved, library_trials

    trials = library_trials(grasps_per_scene=2, ranked=False).trials[:32]
    protocols = (Protocol(), Protocol.of("mujoco"))
    seconds, results = interleaved(trials, protocols, rounds=2, block=16)
    assert seconds.shape == (2, 2) and (seconds > 0).all()
    for protocol, got in zip(protocols, results):
        with make_runner(protocol) as runner:
            plain = runner.run(trials)
        assert [repr(r.as_dict()) for r in got] == [repr(r.as_dict()) for r in plain]
    assert {r.outcome for r in results[1]} - {"approach_collision", "empty_shape"}  # some were simulated


def _light_bar_trials(density: float, n: int = 2) -> list[Trial]:
    """A bar 8 cm long, 6 mm wide and 2.4 cm thick (11.5 cm^3), gripped across its middle
    by the library's gripper (20 N, 50 g plates), with millimetre approach offsets."""
    from shapely.geometry import box

    gripper = _rectangle_trial((-0.045, 0.0), (0.045, 0.0)).gripper
    bar = box(-0.04, -0.003, 0.04, 0.003)
    offsets = np.random.default_rng(11).normal(0.0, 0.001, (n, 2, 2))
    trials = []
    for k in range(n):
        g1, g2 = np.array([0.0, -0.03]) + offsets[k, 0], np.array([0.0, 0.03]) + offsets[k, 1]
        axis = (g2 - g1) / math.hypot(*(g2 - g1))
        trials.append(Trial(bar, tuple(g1), tuple(g2), tuple(axis), 0.024, density, 0.5, gripper))
    return trials


def test_a_light_object_is_classed_by_its_mass_against_a_jaws_mass_read_from_the_urdf():
    """The built-in gripper's URDF gives each plate PLATE_MASS; a bar of 11.52 cm^3 is light
    below 0.3 x 50 g = 15 g, so at 1300 kg/m^3 (14.98 g) and not at 1303 (15.01 g)."""
    from harness.physics import bullet
    from harness.physics.gripper import PLATE_MASS

    with make_runner(Protocol()) as runner:
        assert runner.jaw_mass(_light_bar_trials(1000.0, 1)[0].gripper) == pytest.approx(PLATE_MASS, rel=1e-9)
        limit = bullet.LIGHT_FRACTION * PLATE_MASS / 11.52e-6
        assert runner.is_light(_light_bar_trials(limit * 0.999, 1)[0])
        assert not runner.is_light(_light_bar_trials(limit * 1.001, 1)[0])


def test_a_light_thin_bar_is_held_at_the_finer_step_bullets_solver_needs(monkeypatch):
    """The 3.5 g thin bar (300 kg/m^3, 0.07 of a plate's mass): at the design's step
    Bullet's rigid plates press into it and close past it (`no_contact`, the control: the
    rule switched off, rigid pads); the runner runs it LIGHT_REFINE times finer, where it
    is held, as MuJoCo holds it at its own step (docs/physics.md, "Light objects").
    Compliant pads (the default) hold it at the design's step too."""
    from harness.physics import bullet

    trials = _light_bar_trials(300.0)
    steps, run_world = [], bullet.BulletRunner._run_world

    def spy(self, batch, slots, protocol, *args, **kwargs):
        steps.append(protocol.time_step)
        return run_world(self, batch, slots, protocol, *args, **kwargs)

    monkeypatch.setattr(bullet.BulletRunner, "_run_world", spy)
    with make_runner(Protocol()) as runner:
        assert [r.outcome for r in runner.run(trials)] == ["success"] * 2
    assert steps == [Protocol().time_step / bullet.LIGHT_REFINE]  # one world, the finer step
    with make_runner(Protocol.of("mujoco")) as runner:
        assert [r.outcome for r in runner.run(trials)] == ["success"] * 2
    monkeypatch.setattr(bullet, "LIGHT_FRACTION", 0.0)
    with make_runner(Protocol(pad_stiffness=0.0)) as runner:
        assert [r.outcome for r in runner.run(trials)] == ["no_contact"] * 2
    with make_runner(Protocol()) as runner:
        assert [r.outcome for r in runner.run(trials)] == ["success"] * 2


def test_a_batchs_light_objects_run_apart_without_changing_the_others():
    """A light bar between two trials of the rectangle: the rectangle's trials give, bit for
    bit, their rows of a batch whose middle trial is not simulated (an empty sample: the
    same world, the same slots), and the light bar its own run's outcome."""
    from dataclasses import replace

    from shapely.geometry import Polygon

    rect = [_rectangle_trial((-0.045, 0.0), (0.045, 0.0)), _rectangle_trial((-0.045, 0.004), (0.045, 0.004))]
    light = _light_bar_trials(300.0, 1)[0]
    with make_runner(Protocol()) as runner:
        mixed = runner.run([rect[0], light, rect[1]])
        without = runner.run([rect[0], replace(light, polygon=Polygon()), rect[1]])
        light_alone = runner.run([light])
    assert without[1].outcome == "empty_shape"
    assert repr(mixed[0].as_dict()) == repr(without[0].as_dict())
    assert repr(mixed[2].as_dict()) == repr(without[2].as_dict())
    assert mixed[1].outcome == light_alone[0].outcome == "success"


def test_a_compliant_pad_sinks_as_a_linear_spring():
    """`pad_stiffness` makes each contact point of Bullet's pads a spring (and damper):
    a 3 cm bar gripped across its centre then closes the jaws further than rigid
    contacts do, by the force over the stiffness. A linear spring sinks four times as far
    under four times the force and a quarter as far four times as stiff (within 15 %);
    on the bar's flat face the plate meets it as two points would, F / (2 k) a plate
    (within 20 %: 0.5 mm at 20 N and 2e4 N/m, as MuJoCo's pad sinks, tested there);
    rigid contacts sink less than 0.1 mm."""
    from harness.bench.lift_study import Bar, _exact_draws

    def sink(force: float, stiffness: float) -> float:
        bar = Bar(0.12, 1000.0, 0.5, force)
        scene = bar.scene()
        settings, approach, _ = _exact_draws(scene, 1, 0, "pad sink")
        trial = make_trials(settings, bar.grasp(0.0), [truth_polygon(scene)], np.zeros_like(approach))[0]
        protocol = Protocol(pad_stiffness=stiffness, pad_damping=2.0 * math.sqrt(stiffness * 0.1) if stiffness else 0.0)
        with make_runner(protocol) as runner:
            result = runner.run([trial])[0]
        assert result.outcome == "success"
        return 0.5 * (bar.width - result.grip_width)

    assert sink(20.0, 0.0) < 1e-4
    base = sink(20.0, 2e4)
    assert base == pytest.approx(20.0 / (2 * 2e4), rel=0.2)
    assert sink(5.0, 2e4) == pytest.approx(base / 4, rel=0.15)
    assert sink(20.0, 8e4) == pytest.approx(base / 4, rel=0.15)


def test_compliant_pads_turn_a_bar_where_a_uniformly_pressed_pad_does():
    """A bar gripped across its faces at offset d from its centre of mass turns once its
    weight's torque m g d passes the plates' torsional friction 2 mu F r, r the mean
    distance from the patch's centre under a uniform pressure (the 1 cm x (h - 1 mm)
    patch, integrated here on a grid): d* = 40.4 mm for the 18 x 3 x 3 cm bar of 162 g at
    8 N and mu 0.5. With compliant pads (the default) Bullet turns (more than 0.3 rad) at
    most one of 8 trials at 0.8 d* and at least 7 of 8 at 1.2 d* (docs/physics.md, "A
    compliant pad in Bullet"); rigid pads, whose point contacts give short levers, turn
    at least half of them already at 0.8 d*."""
    from harness.bench.lift_study import Bar, _exact_draws

    bar = Bar(0.18, 1000.0, 0.5, 8.0)
    w, h = 0.01, bar.thickness - 0.001
    x, z = np.meshgrid(np.linspace(-w / 2, w / 2, 201), np.linspace(-h / 2, h / 2, 401))
    d_star = 2 * bar.friction * bar.force * float(np.hypot(x, z).mean()) / (bar.mass * 9.81)
    assert d_star == pytest.approx(0.0404, abs=5e-4)
    scene = bar.scene()
    settings, approach, _ = _exact_draws(scene, 8, 0, "pad onset")

    def turned(factor: float, protocol: Protocol) -> int:
        trials = make_trials(settings, bar.grasp(factor * d_star), [truth_polygon(scene)], approach)
        with make_runner(protocol) as runner:
            return sum(r.pivot > 0.3 for r in runner.run(trials))

    assert turned(0.8, Protocol()) <= 1
    assert turned(1.2, Protocol()) >= 7
    assert turned(0.8, Protocol(pad_stiffness=0.0)) >= 4


@contextmanager
def _placed(engine: str, trial, protocol=None):
    """A trial's slot in a world of its own, placed and not yet stepped; the runner
    closed (its pybullet client disconnected) afterwards."""
    import harness.physics.bullet as bullet
    import harness.physics.mujoco_engine as me

    protocol = protocol or Protocol.of(engine)
    with make_runner(protocol) as runner:
        if engine == "mujoco":
            yield me._Slot(runner, trial)
        else:
            runner._reset_world(protocol)
            yield bullet._Slot(runner, 0, trial, (0.0, 0.0), protocol, None)


def _set(slot, jaws=None, velocity=None, lift=None, turn=None) -> None:
    """Put a slot's jaws (joint positions), the object's velocity (linear, angular) or its
    pose (raised by ``lift``, MuJoCo's turned by ``turn`` about the world's y axis through
    its frame's origin) where a query can read them."""
    if hasattr(slot, "data"):  # MuJoCo
        d = slot.data
        if jaws is not None:
            for k in range(2):
                d.qpos[slot.finger_qpos[k]] = jaws[k]
        if velocity is not None:
            slot.obj_velocity[:] = velocity
        if lift is not None or turn is not None:
            slot.obj_position[2] += lift or 0.0
            a = 0.5 * (turn or 0.0)
            slot.obj_turn[:] = (math.cos(a), 0.0, math.sin(a), 0.0)
        slot.fresh = False
        return
    c = slot.runner.client
    if jaws is not None:
        for joint, q in zip(slot.trial.gripper.finger_joints, jaws):
            pb.resetJointState(slot.grip, joint, q, physicsClientId=c)
    if velocity is not None:
        pb.resetBaseVelocity(slot.obj, velocity[:3], velocity[3:], physicsClientId=c)
    if lift is not None:
        (x, y, z), orn = pb.getBasePositionAndOrientation(slot.obj, physicsClientId=c)
        pb.resetBasePositionAndOrientation(slot.obj, (x, y, z + lift), orn, physicsClientId=c)
    pb.performCollisionDetection(physicsClientId=c)


@pytest.mark.parametrize("engine", ["pybullet", "mujoco"])
def test_each_engine_answers_the_machines_questions_on_placed_states(engine):
    """The queries that decide a trial's outcome, asked of states set by hand (the
    rectangle, 3 cm thick, placed for a grasp across its long faces): the jaws are shut
    only when both stand at their limits; a jaw on its face is near the object and one 1
    cm off it is not, whether the other touches or not (Bullet's contact manifold proves
    one jaw near, not both); the object's height is its centre of mass's,
    half the thickness above the table at rest; it touches the table at rest and not 2 mm
    above it (the held distance is 1 mm); a speed or a spin past the protocol's limit, with
    the other at rest, is a blown-up simulation and 0.9 of either is not."""
    trial = _rectangle_trial((0.0, -0.045), (0.0, 0.045))
    protocol = Protocol.of(engine)
    with _placed(engine, trial, protocol) as slot:
        _ask_placed(slot, trial, protocol)


def _ask_placed(slot, trial, protocol) -> None:
    limits = slot.limits
    _set(slot, jaws=limits)
    assert slot.jaws_shut(slot.jaw_states())
    for k in range(2):
        _set(slot, jaws=[limits[j] if j == k else 0.5 * limits[j] for j in range(2)])
        assert not slot.jaws_shut(slot.jaw_states())
    # Jaws at the long faces (1.5 cm either side of the grasp centre), one pressing 0.1
    # mm into its face, the other on its face or 1 cm off it.
    g = trial.gripper
    for off, near in ((0.0, 2), (0.01, 1)):
        _set(slot, jaws=[g.joint_position(0, -0.0149), g.joint_position(1, 0.015 + off)])
        assert [slot.near_jaws(protocol.held_distance), slot.near_jaws(0.005)] == [near, near]
    assert slot.object_height_and_yaw()[0] == pytest.approx(0.5 * trial.thickness, abs=2e-4)
    assert slot.on_table()
    _set(slot, lift=0.002)
    assert not slot.on_table()
    for limit, velocity in ((protocol.max_speed, (1.0, 0, 0, 0, 0, 0)), (protocol.max_spin, (0, 0, 0, 0, 0, 1.0))):
        for factor, blown in ((1.1, True), (0.9, False)):
            _set(slot, velocity=np.array(velocity) * limit * factor)
            assert slot.blew_up() == blown
    _set(slot, velocity=np.zeros(6))
    assert not slot.blew_up()


def test_mujocos_table_contact_is_any_piece_of_an_object_without_a_foot():
    """Without the foot (``table_hull = False``) every convex piece may meet the table: an
    L (a 10 x 1 cm bar and a 1 x 2 cm stub on its end: two pieces, the bar and the
    bar's last centimetre with the stub), tilted 0.1 rad about the y axis so that the
    bar's other end lies on the table and the stub's piece stands 9 mm above it and more,
    touches the table; raised 2 mm, it does not."""
    from shapely.geometry import Polygon

    from harness.physics.bodies import convex_pieces

    shape = Polygon([(-0.05, -0.005), (0.05, -0.005), (0.05, 0.025), (0.04, 0.025), (0.04, 0.005), (-0.05, 0.005)])
    assert [p.bounds[0] for p in convex_pieces(shape)] == pytest.approx([-0.05, 0.04])
    scene = load_scene("rectangle")
    settings = resolve(scene, {"sigma_g": 0.0})
    trial = make_trials(settings, [(0.0, -0.03), (0.0, 0.03)], [shape], np.zeros((1, 2, 2)))[0]
    with _placed("mujoco", trial, replace(Protocol.of("mujoco"), table_hull=False)) as slot:
        _set(slot, lift=0.05 * math.sin(0.1), turn=-0.1)  # the bar's end at x = -5 cm on the table
        assert slot.on_table()
        _set(slot, lift=0.002)
        assert not slot.on_table()


def test_in_bullet_the_foot_alone_meets_the_table_and_the_gripper_never_does():
    """The rectangle at rest on the table touches it through its foot (every contact
    point's link on the object is the foot's), and the gripper lowered 3 mm, its plates 2
    mm into the table, has no contact with it (docs/physics.md, "The foot")."""
    trial = _rectangle_trial((0.0, -0.045), (0.0, 0.045))
    with _placed("pybullet", trial) as slot:
        c, table = slot.runner.client, slot.runner.table
        pb.performCollisionDetection(physicsClientId=c)
        points = pb.getContactPoints(slot.obj, table, physicsClientId=c)
        assert slot.foot is not None and points and {p[3] for p in points} == {slot.foot}
        (x, y, z), orn = pb.getBasePositionAndOrientation(slot.grip, physicsClientId=c)
        pb.resetBasePositionAndOrientation(slot.grip, (x, y, z - 0.003), orn, physicsClientId=c)
        pb.performCollisionDetection(physicsClientId=c)
        assert pb.getClosestPoints(slot.grip, table, 0.0, physicsClientId=c)  # the plates are in the table
        assert not pb.getContactPoints(slot.grip, table, physicsClientId=c)
