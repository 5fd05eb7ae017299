"""Physics trials, whatever the engine: one trial's inputs and result, the outcomes and
their taxonomy, the geometric checks made before simulating, the base's motion after
the jaws stall, and the engine-neutral state machine (:class:`TrialMachine`).

A trial: the object (a polygon extruded to a prism) lies on the table; the open jaws
are placed around it at the executed jaw starts (after approach noise), just above the
table; a jaw whose pad footprint overlaps the object gives ``approach_collision``
without simulating. The jaws close under a force limit until they stall; if they do
not then both touch the object the outcome is ``no_contact``. The gripper lifts,
holds, and shakes; losing the object while lifting or holding is ``slipped``, while
shaking ``dropped``; NaN or runaway velocities are ``unstable``. Otherwise the trial is
a ``success``. See docs/physics.md for every constant.

Two engines run this protocol: pybullet (:mod:`harness.physics.bullet`, the default)
and MuJoCo (:mod:`harness.physics.mujoco_engine`). Each decides every outcome by the
rules above, with the same protocol constants; only how contact is simulated differs.
Trials are run in the order given, in batches fixed by that order, never by the
number of workers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import Polygon

from harness.physics.gripper import GripperAdapter
from harness.protocol import Protocol

OUTCOMES = ("success", "approach_collision", "no_contact", "slipped", "dropped", "unstable", "empty_shape")
FAILURES = OUTCOMES[1:]

#: Most trials in one batch (one world in pybullet).
MAX_BATCH = 64


@dataclass(frozen=True)
class Trial:
    """One trial's inputs: the object's outline (world x, y; empty for a sample with no
    inside region), the executed jaw starts g1 and g2, the closing direction (g1 to g2,
    or the planned direction when noise made them coincide), the prism's thickness,
    density and jaw-object friction, and the gripper."""

    polygon: Polygon
    g1: tuple[float, float]
    g2: tuple[float, float]
    axis: tuple[float, float]
    thickness: float
    density: float
    friction: float
    gripper: GripperAdapter


@dataclass(frozen=True)
class TrialResult:
    """A trial's outcome and what the simulation measured: steps simulated (of the
    trial's own step: Bullet runs light objects at a finer one, harness.physics.bullet),
    the jaw separation when the jaws stalled, the object's turn about the vertical while the
    jaws closed (radians; the flat plates aligning it), its final rise (m, of the centre
    of mass), and how far it turned in the gripper after the jaws stalled (radians; a
    heavy object held far from its centre of mass pivots about the grasp axis)."""

    outcome: str
    steps: int = 0
    grip_width: float = math.nan
    closing_turn: float = math.nan
    rise: float = math.nan
    pivot: float = math.nan

    def as_dict(self) -> dict:
        return {"outcome": self.outcome, "steps": self.steps, "grip_width": self.grip_width,
                "closing_turn": self.closing_turn, "rise": self.rise, "pivot": self.pivot}


def pad_footprints(trial: Trial) -> list[Polygon]:
    """The two jaw pads' footprints on the table at the start (world frame)."""
    u = np.asarray(trial.axis, dtype=float)
    v = np.array([-u[1], u[0]])
    half_w, t = 0.5 * trial.gripper.pad_width, trial.gripper.pad_thickness
    pads = []
    for start, outward in ((np.asarray(trial.g1), -u), (np.asarray(trial.g2), u)):
        corners = [start + a * half_w * v + b * t * outward for a, b in ((-1, 0), (1, 0), (1, 1), (-1, 1))]
        pads.append(Polygon(corners))
    return pads


def approach_blocked(trial: Trial) -> bool:
    """Whether a jaw pad would come down on the object (overlap of positive area). A pad
    that does not meet the object at all (most pads) is told by the cheap predicate."""
    return any(shapely.intersects(pad, trial.polygon) and shapely.intersection(pad, trial.polygon).area > 0.0
               for pad in pad_footprints(trial))


def free_travel(trial: Trial) -> float:
    """How far both jaws can close together before either plate touches the object: the
    gap between each plate's face and the object within the plate's width, the smaller
    of the two (infinite when nothing lies between the plates)."""
    u = np.asarray(trial.axis, dtype=float)
    v = np.array([-u[1], u[0]])
    g1, g2 = np.asarray(trial.g1, dtype=float), np.asarray(trial.g2, dtype=float)
    width = float(_along(g2 - g1, u))
    half = 0.5 * trial.gripper.pad_width
    strip = Polygon([g1 - half * v, g2 - half * v, g2 + half * v, g1 + half * v])
    between = shapely.intersection(strip, trial.polygon)
    if between.is_empty or between.area <= 0.0:
        return math.inf
    along = _along(shapely.get_coordinates(between), u) - float(_along(g1, u))
    return max(0.0, min(float(along.min()), width - float(along.max())))


def _along(points: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Coordinates of points (..., 2) along u, elementwise: a BLAS dot product's last
    bits depend on the host's kernel, and these numbers reach Bullet."""
    return points[..., 0] * u[0] + points[..., 1] * u[1]


def minimum_jerk(u: float) -> float:
    u = min(max(u, 0.0), 1.0)
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


@dataclass(frozen=True)
class Motion:
    """A protocol's phase lengths (steps) and the base's motion at each step after the
    jaws stall, computed once per protocol instead of once per trial and step: the
    lift's rise, and the shake's in-plane offsets (along and across the closing axis)
    and turn."""

    lift_steps: int
    hold_steps: int
    shake_steps: int
    rise: tuple[float, ...]
    shake: tuple[tuple[float, float, float], ...]


@lru_cache(maxsize=8)
def motion(p: Protocol) -> Motion:
    lift, hold, shake = p.steps(p.lift_time), p.steps(p.hold_time), p.steps(p.shake_time)
    rise = tuple(p.lift_height * minimum_jerk((k + 1) / lift) for k in range(lift))
    w = 2 * math.pi * p.shake_frequency
    offsets = []
    for k in range(shake):
        t = (k + 1) * p.time_step
        envelope = math.sin(math.pi * min(t / p.shake_time, 1.0)) ** 2
        offsets.append((p.shake_amplitude * envelope * math.sin(w * t), p.shake_amplitude * envelope * math.cos(w * t),
                        p.shake_turn * envelope * math.sin(w * t)))
    return Motion(lift, hold, shake, rise, tuple(offsets))


def yaw(quaternion) -> float:
    x, y, z, w = quaternion
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


#: With skip_free_travel, the closing jaws start this far short of the first contact (m),
#: time enough to reach the closing speed (in under a step) before touching.
SKIP_MARGIN = 0.002

#: The jaws' lower edges start this far above the table (m).
TABLE_GAP = 0.001


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def skipped_travel(trial: Trial, protocol: Protocol) -> float:
    """How far each jaw starts closer to the object than its executed start (m): with
    ``skip_free_travel`` both jaws start SKIP_MARGIN short of the first contact, which
    they would have reached at the same moment, with nothing yet touched."""
    if not protocol.skip_free_travel:
        return 0.0
    return max(0.0, min(free_travel(trial), 0.5 * math.dist(trial.g1, trial.g2)) - SKIP_MARGIN)


class BatchRunner:
    """What every engine's runner shares: the protocol, the batch size (1 to MAX_BATCH),
    early stopping (a trial ends as soon as its outcome is decided; without it every
    simulated trial runs the whole protocol, the naive reference), the context manager,
    and :meth:`run`, which hands the trials to the engine's ``_run_batch`` in batches
    fixed by their order."""

    def __init__(self, protocol: Protocol, batch_size: int = 16, early_stop: bool = True):
        if not 1 <= batch_size <= MAX_BATCH:
            raise ValueError(f"batch_size must be 1 to {MAX_BATCH}")
        self.protocol = protocol
        self.batch_size = batch_size
        self.early_stop = early_stop

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release what the engine holds (nothing by default)."""

    def run(self, trials, frames: Path | None = None, progress=None, trace=None) -> list[TrialResult]:
        """Outcomes of the trials, in order. ``frames``: a folder for PNG snapshots of
        each phase of the first trial; ``trace``: a harness.physics.trace.Tracer that
        records the first trial. ``progress`` is called with each batch's size."""
        results: list[TrialResult] = []
        for start in range(0, len(trials), self.batch_size):
            batch = trials[start:start + self.batch_size]
            results.extend(self._run_batch(batch, Path(frames) if frames is not None and start == 0 else None,
                                           trace if start == 0 else None))
            if progress:
                progress(len(batch))
        return results

    def _run_batch(self, batch, frames: Path | None, trace=None) -> list[TrialResult]:
        """The batch's results; ``frames``: where the first trial's snapshots go, if
        anywhere; ``trace``: the first trial's tracer, if any."""
        raise NotImplementedError


def prechecked(trial: Trial) -> TrialResult | None:
    """The outcome of a trial decided without simulating: ``empty_shape`` for a sample
    with no inside region, ``approach_collision`` when a jaw pad comes down on the
    object; None when the trial must be simulated."""
    if trial.polygon.is_empty:
        return TrialResult("empty_shape")
    if approach_blocked(trial):
        return TrialResult("approach_collision")
    return None


class TrialMachine:
    """One trial's state machine, the same in every engine: the phases (close, lift,
    hold, shake), the checks that end them and the outcome each failure gets. An engine
    subclasses it with the queries below, builds the trial's bodies, then calls
    :meth:`start`; it calls :meth:`before_step` and :meth:`after_step` around each step
    of its world until ``result`` is set."""

    def __init__(self, index: int, trial: Trial, protocol: Protocol, early_stop: bool):
        self.index, self.trial, self.protocol, self.early_stop = index, trial, protocol, early_stop
        self.result: TrialResult | None = None
        self.phase = "close"
        self.tick = 0               # steps since this phase began
        self.phase_steps = 0        # how long this phase lasts (lift, hold, shake; closing ends by itself)
        self.steps = 0
        self.failure: str | None = None  # first failure seen when not stopping early
        self.quiet = 0              # checks in a row with the object lost / steps with stalled jaws
        self.grip_width = math.nan
        self.closing_turn = math.nan
        self.grip_pose = None       # the object's orientation in the gripper when the jaws stalled
        self.tracer = None          # a harness.physics.trace.Tracer recording this trial, or None

    # -- what an engine provides -----------------------------------------------------

    def move(self, x: float, y: float, z: float, heading: float) -> None:
        """Drive the gripper's base to (x, y, z) turned ``heading`` about the vertical."""
        raise NotImplementedError

    def jaw_states(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Each finger joint's (position, velocity)."""
        raise NotImplementedError

    def jaws_shut(self, states) -> bool:
        """Whether both finger joints have reached their closing limits."""
        raise NotImplementedError

    def near_jaws(self, distance: float) -> int:
        """How many of the two jaws are within ``distance`` of the object (m)."""
        raise NotImplementedError

    def on_table(self) -> bool:
        """Whether the object touches the table."""
        raise NotImplementedError

    def blew_up(self) -> bool:
        """NaN anywhere, or the object faster than max_speed or spinning faster than max_spin."""
        raise NotImplementedError

    def object_height_and_yaw(self) -> tuple[float, float]:
        """The height of the object's centre of mass and its turn about the vertical."""
        raise NotImplementedError

    def relative_pose(self) -> tuple[float, float, float, float]:
        """The object's orientation in the gripper's frame (a unit quaternion)."""
        raise NotImplementedError

    def snapshot(self, name: str) -> None:
        """A frame of the trial named ``name``, when frames are being recorded."""

    def poses(self):
        """For a trace (harness.physics.trace): the gripper's and the object's frames in
        the world, (gripper position (3,), rotation (3, 3), object position, rotation)."""
        raise NotImplementedError

    def jaw_contacts(self):
        """For a trace: per jaw, (contact points, their total normal force (N), their
        pressure centre (3,) in the world or None without points)."""
        raise NotImplementedError

    # -- the protocol ------------------------------------------------------------------

    def start(self, width: float, centre: tuple[float, float], heading: float, base_z: float) -> None:
        """Begin closing, the jaws ``width`` apart around ``centre`` with the base at
        ``base_z``, turned ``heading``."""
        p, g = self.protocol, self.trial.gripper
        self.centre, self.heading, self.base_z = centre, heading, base_z
        self.heading_cos_sin = (math.cos(heading), math.sin(heading))
        self.start_z, self.start_yaw = self.object_height_and_yaw()
        self.stall_steps = p.steps(p.stall_time)
        self.slow_speed = p.stall_fraction * g.closing_speed  # a jaw slower than this is stalling
        self.close_steps = p.steps(0.5 * width / g.closing_speed + p.closing_slack)
        self.check_steps = p.steps(p.check_interval)
        self.lost_checks = max(1, int(math.ceil(p.lost_time / (self.check_steps * p.time_step))))
        self.motion = motion(p)
        self.snapshot("1-placed")

    def undecided_steps(self) -> int:
        """How many of the next steps decide nothing (the step after them may): an
        engine may run them without calling :meth:`after_step` if it calls
        :meth:`ticked` for them. 0 while closing, where every step is checked."""
        if self.phase == "close" or self.result is not None:
            return 0
        c = self.check_steps
        return max(0, min(c - self.tick % c, self.phase_steps - self.tick) - 1)

    def ticked(self, steps: int) -> None:
        """Count ``steps`` steps run without :meth:`after_step` (see :meth:`undecided_steps`)."""
        self.tick += steps
        self.steps += steps

    def before_step(self) -> None:
        if self.phase == "lift":
            self.move(self.centre[0], self.centre[1], self.base_z + self.motion.rise[self.tick], self.heading)
        elif self.phase == "shake":
            a, b, turn = self.motion.shake[self.tick]
            ch, sh = self.heading_cos_sin
            self.move(self.centre[0] + a * ch - b * sh, self.centre[1] + a * sh + b * ch,
                      self.base_z + self.protocol.lift_height, self.heading + turn)

    def after_step(self) -> None:
        self.tick += 1
        self.steps += 1
        if self.phase == "close":
            self._after_closing_step()
        elif self.tick % self.check_steps == 0 or self.tick >= self.phase_steps:
            if self.blew_up():  # a trial that failed already (no early stop) keeps its first failure
                return self._finish(self.failure or "unstable")
            if self.near_jaws(self.protocol.lost_distance) == 0:
                self.quiet += 1
                if self.quiet >= self.lost_checks:
                    self._fail("slipped" if self.phase in ("lift", "hold") else "dropped")
            else:
                self.quiet = 0
            if self.result is None and self.tick >= self.phase_steps:
                self._end_phase()
            if self.tracer is not None:
                self.tracer.record(self)

    def _after_closing_step(self) -> None:
        g, p = self.trial.gripper, self.protocol
        states = self.jaw_states()
        (q0, v0), (q1, v1) = states
        slow_speed, (f0, f1) = self.slow_speed, g.face_per_unit  # the jaws' faces' speeds: joint speed x face per unit
        slow = abs(v0 * f0) < slow_speed and abs(v1 * f1) < slow_speed
        shut = self.jaws_shut(states)
        self.quiet = self.quiet + 1 if slow else 0
        if self.blew_up():
            return self._finish(self.failure or "unstable")
        if not (shut or (self.quiet >= self.stall_steps and self.tick > 2) or self.tick >= self.close_steps):
            return
        faces = [g.face_at_zero[j] + g.face_per_unit[j] * s[0] for j, s in enumerate(states)]
        self.grip_width = faces[1] - faces[0]
        if not math.isfinite(self.grip_width):  # a jaw diverged: any NaN is a blow-up
            return self._finish(self.failure or "unstable")
        self.closing_turn = wrap(self.object_height_and_yaw()[1] - self.start_yaw)
        self.snapshot("2-closed")
        self.grip_pose = self.relative_pose()
        if self.tracer is not None:
            self.tracer.record(self)
        if self.grip_width < p.held_distance or self.near_jaws(p.held_distance) < 2:
            self._fail("no_contact")
        if self.result is None:
            self._begin("lift")

    def _end_phase(self) -> None:
        held = self.near_jaws(self.protocol.held_distance) == 2 and not self.on_table()
        if self.phase == "lift":
            self._begin("hold")
        elif self.phase == "hold":
            self.snapshot("3-lifted")
            if held:
                self._begin("shake")
            else:
                self._fail("slipped")
                if self.result is None:
                    self._begin("shake")
        else:
            self.snapshot("4-shaken")
            if not held:
                self._fail("dropped")
            self._finish(self.failure or "success")

    def _begin(self, phase: str) -> None:
        self.phase, self.tick, self.quiet = phase, 0, 0
        m = self.motion
        self.phase_steps = {"lift": m.lift_steps, "hold": m.hold_steps, "shake": m.shake_steps}[phase]

    def _fail(self, outcome: str) -> None:
        """Record a failure: the trial ends now with early stopping, else at the end of
        the protocol with the first failure seen."""
        if self.failure is None:
            self.failure = outcome
            self.snapshot(f"lost-{outcome}")
        if self.early_stop:
            self._finish(outcome)

    def _finish(self, outcome: str) -> None:
        stable = outcome != "unstable"
        self.result = TrialResult(outcome, self.steps, self.grip_width, self.closing_turn,
                                  self._rise() if stable else math.nan, self._pivot() if stable else math.nan)

    def _pivot(self) -> float:
        """How far (rad) the object has turned in the gripper since the jaws stalled."""
        if self.grip_pose is None:
            return math.nan
        now = self.relative_pose()
        dot = abs(sum(a * b for a, b in zip(now, self.grip_pose)))
        return 2.0 * math.acos(min(1.0, dot))

    def _rise(self) -> float:
        return self.object_height_and_yaw()[0] - self.start_z
