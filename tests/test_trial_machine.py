"""The trial's state machine (harness.physics.trial.TrialMachine) on a scripted engine: each
rule of the outcome taxonomy (docs/physics.md, "One trial") decided from what the engine's
queries answer, with no simulation, so that both engines' verdicts rest on rules tested
apart from their physics."""

from __future__ import annotations

import math

import pytest
from shapely.geometry import box

from harness.physics.gripper import GripperAdapter
from harness.physics.trial import Trial, TrialMachine
from harness.protocol import Protocol

PROTOCOL = Protocol()
OPENING, SPEED = 0.1, 0.1
GRIPPER = GripperAdapter(urdf="unused", finger_joints=(0, 1), jaw_links=(0, 1), closing_axis=(1.0, 0.0),
                         face_at_zero=(-OPENING / 2, OPENING / 2), face_per_unit=(1.0, -1.0), depth=0.04,
                         pad_width=0.01, pad_thickness=0.005, force=20.0, closing_speed=SPEED)
TRIAL = Trial(box(-0.03, -0.015, 0.03, 0.015), (-0.05, 0.0), (0.05, 0.0), (1.0, 0.0), 0.03, 1000.0, 0.5, GRIPPER)
#: The jaws move for this many closing steps, then stand still.
STALL_AT = 10


class _Scripted(TrialMachine):
    """A trial whose engine answers from a script: ``near(phase, tick, distance)`` the
    jaws within ``distance`` of the object, ``on_table(phase, tick)``, ``blew_up(phase,
    tick)``; the jaws close at full speed, each for its ``stall_at`` steps, and stall
    ``width`` apart."""

    def __init__(self, near=None, on_table=None, blew_up=None, width=0.03, early_stop=True,
                 stall_at=(STALL_AT, STALL_AT)):
        super().__init__(0, TRIAL, PROTOCOL, early_stop)
        self.script_near = near or (lambda phase, tick, distance: 2)
        self.script_table = on_table or (lambda phase, tick: False)
        self.script_blew = blew_up or (lambda phase, tick: False)
        self.width, self.stall_at = width, stall_at
        self.start(OPENING, (0.0, 0.0), 0.0, 0.05)

    def move(self, x, y, z, heading):
        pass

    def jaw_states(self):
        q = 0.5 * (OPENING - self.width)  # each face's travel inwards
        return tuple((q, SPEED if self.steps < at else 0.0) for at in self.stall_at)

    def jaws_shut(self, states):
        return False

    def near_jaws(self, distance):
        return self.script_near(self.phase, self.tick, distance)

    def on_table(self):
        return self.script_table(self.phase, self.tick)

    def blew_up(self):
        return self.script_blew(self.phase, self.tick)

    def object_height_and_yaw(self):
        return 0.0, 0.0

    def relative_pose(self):
        return 1.0, 0.0, 0.0, 0.0

    def run(self):
        while self.result is None:
            self.before_step()
            self.after_step()
        return self.result


def _lost_in(phase: str, checks: int):
    """The object near neither jaw, at any distance asked, at the first ``checks`` checks
    of ``phase``; near both otherwise."""
    every = PROTOCOL.steps(PROTOCOL.check_interval)

    def near(now, tick, distance):
        return 0 if now == phase and tick <= checks * every else 2
    return near


def _lost_checks() -> int:
    return max(1, math.ceil(PROTOCOL.lost_time / (PROTOCOL.steps(PROTOCOL.check_interval) * PROTOCOL.time_step)))


def test_a_trial_held_by_both_jaws_off_the_table_to_the_end_succeeds():
    machine = _Scripted()
    result = machine.run()
    assert result.outcome == "success"
    assert result.grip_width == pytest.approx(0.03, abs=1e-12) and result.pivot == 0.0
    m = machine.motion
    assert result.steps == STALL_AT + PROTOCOL.steps(PROTOCOL.stall_time) - 1 + m.lift_steps + m.hold_steps \
        + m.shake_steps


def test_the_jaws_have_stalled_when_both_have_been_slow_for_the_stall_time():
    """One jaw stopped on the object while the other still closes is not a stall."""
    machine = _Scripted(stall_at=(STALL_AT, 3 * STALL_AT))
    result = machine.run()
    m = machine.motion
    assert result.outcome == "success"
    assert result.steps == 3 * STALL_AT + PROTOCOL.steps(PROTOCOL.stall_time) - 1 + m.lift_steps + m.hold_steps \
        + m.shake_steps


@pytest.mark.parametrize("width, near, why", [
    (0.0005, 2, "the jaws stalled closer than the held distance: nothing between them"),
    (0.03, 1, "one jaw touches the object when they stall"),
    (0.03, 0, "neither does"),
])
def test_jaws_that_stall_without_both_touching_the_object_are_no_contact(width, near, why):
    result = _Scripted(near=lambda phase, tick, distance: near, width=width).run()
    assert result.outcome == "no_contact", why


def test_an_object_away_from_both_jaws_for_the_lost_time_is_slipped_while_lifting_and_dropped_while_shaking():
    lost = _lost_checks()
    assert _Scripted(near=_lost_in("lift", lost)).run().outcome == "slipped"
    assert _Scripted(near=_lost_in("hold", lost)).run().outcome == "slipped"
    assert _Scripted(near=_lost_in("shake", lost)).run().outcome == "dropped"
    # One check fewer is not lost: the object came back to the jaws.
    assert _Scripted(near=_lost_in("lift", lost - 1)).run().outcome == "success"


@pytest.mark.parametrize("phase, outcome", [("hold", "slipped"), ("shake", "dropped")])
def test_at_the_end_of_the_hold_and_of_the_shake_the_object_must_touch_both_jaws_and_not_the_table(phase, outcome):
    """Still within the lost distance of a jaw, but touching one jaw only (or also
    resting on the table) when the phase ends, is not held."""
    m = _Scripted().motion
    end = {"hold": m.hold_steps, "shake": m.shake_steps}[phase]

    def one_jaw(now, tick, distance):
        return 1 if now == phase and tick >= end and distance <= PROTOCOL.held_distance else 2

    assert _Scripted(near=one_jaw).run().outcome == outcome
    on_table = _Scripted(on_table=lambda now, tick: now == phase and tick >= end)
    assert on_table.run().outcome == outcome


def test_a_simulation_that_blows_up_is_unstable_whenever_it_does():
    for phase in ("close", "lift", "shake"):
        result = _Scripted(blew_up=lambda now, tick, phase=phase: now == phase and tick >= 3).run()
        assert result.outcome == "unstable", phase
        assert math.isnan(result.rise) and math.isnan(result.pivot)


def test_without_early_stop_a_trial_runs_the_whole_protocol_and_keeps_its_first_failure():
    lost = _lost_checks()
    early = _Scripted(near=_lost_in("lift", lost)).run()
    full = _Scripted(near=_lost_in("lift", lost), early_stop=False)
    result = full.run()
    m = full.motion
    assert early.outcome == result.outcome == "slipped"
    assert early.steps < result.steps == STALL_AT + PROTOCOL.steps(PROTOCOL.stall_time) - 1 + m.lift_steps \
        + m.hold_steps + m.shake_steps
