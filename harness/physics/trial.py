"""Physics trials in pybullet: one trial's state machine, and the runner that steps
a batch of trials together in one pybullet world.

A trial: the object (a polygon extruded to a prism) lies on the table; the open jaws
are placed around it at the executed jaw starts (after approach noise), just above the
table; a jaw whose pad footprint overlaps the object gives ``approach_collision``
without simulating. The jaws close under position control with a force limit until
they stall; if they do not then both touch the object the outcome is ``no_contact``.
The gripper lifts, holds, and shakes; losing the object while lifting or holding is
``slipped``, while shaking ``dropped``; NaN or runaway velocities are ``unstable``.
Otherwise the trial is a ``success``. See docs/physics.md for every constant.

Batching: the runner puts up to ``batch_size`` trials in one world, each in its own
slot (bodies ``SLOT_SPACING`` apart), steps them together and removes a trial's bodies
as soon as its outcome is decided. Which trials share a world and in which slot is
fixed by their order in the list, never by the number of workers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pybullet as pb
import shapely
from shapely.geometry import Polygon

from harness.physics.bodies import create_body
from harness.physics.gripper import GripperAdapter
from harness.protocol import Protocol

OUTCOMES = ("success", "approach_collision", "no_contact", "slipped", "dropped", "unstable", "empty_shape")
FAILURES = OUTCOMES[1:]

#: Distance between neighbouring slots of a batch (m): far beyond any object, gripper,
#: shake and fall, so trials in one world never touch.
SLOT_SPACING = 2.0
#: Most trials in one world.
MAX_BATCH = 64
#: The floating base's constraint may apply up to this force (N).
BASE_FORCE = 2000.0


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
    """A trial's outcome and what the simulation measured: steps simulated, the jaw
    separation when the jaws stalled, the object's turn about the vertical while the
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
    """Whether a jaw pad would come down on the object (overlap of positive area)."""
    return any(shapely.intersection(pad, trial.polygon).area > 0.0 for pad in pad_footprints(trial))


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


class Runner:
    """Runs trials in batches in one pybullet client, kept for the runner's life (one
    per worker process). ``early_stop`` ends a trial as soon as its outcome is decided;
    without it every simulated trial runs the whole protocol (the naive reference)."""

    def __init__(self, protocol: Protocol | None = None, batch_size: int = 16, early_stop: bool = True):
        if not 1 <= batch_size <= MAX_BATCH:
            raise ValueError(f"batch_size must be 1 to {MAX_BATCH}")
        self.protocol = protocol or Protocol()
        self.batch_size = batch_size
        self.early_stop = early_stop
        self._client: int | None = None

    def __enter__(self) -> "Runner":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._client is not None:
            pb.disconnect(physicsClientId=self._client)
            self._client = None

    @property
    def client(self) -> int:
        if self._client is None:
            self._client = pb.connect(pb.DIRECT)
        return self._client

    def run(self, trials: Sequence[Trial], frames: Path | None = None,
            progress: Callable[[int], None] | None = None) -> list[TrialResult]:
        """Outcomes of the trials, in order. ``frames``: a folder for PNG snapshots of
        each phase of the first trial. ``progress`` is called with each batch's size."""
        results: list[TrialResult] = []
        for start in range(0, len(trials), self.batch_size):
            batch = trials[start:start + self.batch_size]
            camera = _Camera(Path(frames), self.client) if frames is not None and start == 0 else None
            results.extend(self._run_batch(batch, camera))
            if progress:
                progress(len(batch))
        return results

    # -- one world ---------------------------------------------------------------------

    def _reset_world(self) -> None:
        c, p = self.client, self.protocol
        pb.resetSimulation(physicsClientId=c)
        pb.setPhysicsEngineParameter(fixedTimeStep=p.time_step, numSolverIterations=p.solver_iterations,
                                     numSubSteps=0, deterministicOverlappingPairs=1,
                                     enableConeFriction=int(p.cone_friction), physicsClientId=c)
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        self.table = pb.createMultiBody(0, plane, physicsClientId=c)
        pb.changeDynamics(self.table, -1, lateralFriction=p.table_friction, physicsClientId=c)

    def _run_batch(self, batch: Sequence[Trial], camera: "_Camera | None") -> list[TrialResult]:
        self._reset_world()
        if camera is not None:
            camera.add_table()
        results: list[TrialResult | None] = [None] * len(batch)
        active: list[_Slot] = []
        for k, trial in enumerate(batch):
            if trial.polygon.is_empty:
                results[k] = TrialResult("empty_shape")
            elif approach_blocked(trial):
                results[k] = TrialResult("approach_collision")
                if camera is not None and k == 0:
                    camera.snapshot_footprint(trial)
            else:
                active.append(_Slot(self, k, trial, (k * SLOT_SPACING, 0.0),
                                    camera if k == 0 else None))
        c = self.client
        while active:
            for slot in active:
                slot.before_step()
            pb.stepSimulation(physicsClientId=c)
            decided = False
            for slot in active:
                slot.after_step()
                decided = decided or slot.result is not None
            if decided:
                for slot in active:
                    if slot.result is not None:
                        slot.remove()
                        results[slot.index] = slot.result
                active = [s for s in active if s.result is None]
        return results  # type: ignore[return-value]


def _minimum_jerk(u: float) -> float:
    u = min(max(u, 0.0), 1.0)
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


@dataclass(frozen=True)
class _Motion:
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
def _motion(p: Protocol) -> _Motion:
    lift, hold, shake = p.steps(p.lift_time), p.steps(p.hold_time), p.steps(p.shake_time)
    rise = tuple(p.lift_height * _minimum_jerk((k + 1) / lift) for k in range(lift))
    w = 2 * math.pi * p.shake_frequency
    offsets = []
    for k in range(shake):
        t = (k + 1) * p.time_step
        envelope = math.sin(math.pi * min(t / p.shake_time, 1.0)) ** 2
        offsets.append((p.shake_amplitude * envelope * math.sin(w * t), p.shake_amplitude * envelope * math.cos(w * t),
                        p.shake_turn * envelope * math.sin(w * t)))
    return _Motion(lift, hold, shake, rise, tuple(offsets))


def _yaw(quaternion) -> float:
    x, y, z, w = quaternion
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


@dataclass
class _Slot:
    """One trial's bodies and state machine in a batch world."""

    runner: Runner
    index: int
    trial: Trial
    origin: tuple[float, float]
    camera: "_Camera | None"
    result: TrialResult | None = None
    phase: str = "close"
    tick: int = 0               # steps since this phase began
    phase_steps: int = 0        # how long this phase lasts (lift, hold, shake; closing ends by itself)
    steps: int = 0
    failure: str | None = None  # first failure seen when not stopping early
    quiet: int = 0              # checks in a row with the object lost / steps with stalled jaws
    grip_width: float = math.nan
    closing_turn: float = math.nan
    limits: tuple = field(default_factory=tuple)
    grip_pose: tuple | None = None  # the object's orientation in the gripper when the jaws stalled

    def __post_init__(self):
        c, t, g = self.runner.client, self.trial, self.trial.gripper
        p = self.runner.protocol
        ox, oy = self.origin
        body = create_body(c, t.polygon, t.thickness, t.density, 1.0, origin=self.origin,
                           visual=self.camera is not None, foot=p.table_hull)
        self.obj, self.foot = body.body_id, body.foot
        for link in range(-1, pb.getNumJoints(self.obj, physicsClientId=c)):
            pb.changeDynamics(self.obj, link, frictionAnchor=int(p.friction_anchor), physicsClientId=c)
        g1, g2 = np.asarray(t.g1), np.asarray(t.g2)
        centre = 0.5 * (g1 + g2)
        width = math.dist(t.g1, t.g2)  # not np.linalg.norm: a BLAS dot product (see _along)
        heading = math.atan2(t.axis[1], t.axis[0]) - math.atan2(g.closing_axis[1], g.closing_axis[0])
        self.centre = (centre[0] + ox, centre[1] + oy)
        self.heading = heading
        self.heading_cos_sin = (math.cos(heading), math.sin(heading))
        self.base_z = g.depth + _TABLE_GAP
        self.orientation = pb.getQuaternionFromEuler([0, 0, heading])
        self.grip = pb.loadURDF(g.urdf, [self.centre[0], self.centre[1], self.base_z], self.orientation,
                                physicsClientId=c)
        for link in range(-1, pb.getNumJoints(self.grip, physicsClientId=c)):
            pb.changeDynamics(self.grip, link, lateralFriction=t.friction, frictionAnchor=int(p.friction_anchor),
                              physicsClientId=c)
            pb.setCollisionFilterPair(self.grip, self.runner.table, link, -1, 0, physicsClientId=c)
            if self.foot is not None:
                pb.setCollisionFilterPair(self.obj, self.grip, self.foot, link, 0, physicsClientId=c)
        if self.foot is not None:  # the foot alone meets the table, and nothing else
            pb.setCollisionFilterPair(self.obj, self.runner.table, -1, -1, 0, physicsClientId=c)
        # Free travel is skipped: both jaws start SKIP_MARGIN short of the first contact,
        # which they would have reached at the same moment, with nothing yet touched.
        skip = max(0.0, min(free_travel(t), 0.5 * width) - SKIP_MARGIN) if p.skip_free_travel else 0.0
        width -= 2 * skip
        limits = []
        for jaw, joint in enumerate(g.finger_joints):
            q0 = g.joint_position(jaw, (-0.5 if jaw == 0 else 0.5) * width)
            info = pb.getJointInfo(self.grip, joint, physicsClientId=c)
            closes_up = (g.face_per_unit[jaw] > 0) == (jaw == 0)
            limits.append(info[9] if closes_up else info[8])
            pb.resetJointState(self.grip, joint, q0, physicsClientId=c)
            pb.setJointMotorControl2(self.grip, joint, pb.POSITION_CONTROL, targetPosition=limits[-1],
                                     force=g.force, maxVelocity=g.closing_speed, physicsClientId=c)
        self.limits = tuple(limits)
        inertial = pb.getDynamicsInfo(self.grip, -1, physicsClientId=c)[3:5]
        self.pivot, self.pivot_orn = pb.invertTransform(*inertial)
        self.constraint = pb.createConstraint(self.grip, -1, -1, -1, pb.JOINT_FIXED, [0, 0, 0],
                                              self.pivot, [self.centre[0], self.centre[1], self.base_z],
                                              self.pivot_orn, self.orientation, physicsClientId=c)
        pb.changeConstraint(self.constraint, maxForce=BASE_FORCE, physicsClientId=c)
        self.start_z, self.start_yaw = self._object_height_and_yaw()
        self.stall_steps = p.steps(p.stall_time)
        self.close_steps = p.steps(0.5 * width / g.closing_speed + p.closing_slack)
        self.check_steps = p.steps(p.check_interval)
        self.lost_checks = max(1, int(math.ceil(p.lost_time / (self.check_steps * p.time_step))))
        self.motion = _motion(p)
        if self.camera is not None:
            self.camera.snapshot("1-placed", self)

    # -- per step ---------------------------------------------------------------------

    def before_step(self) -> None:
        if self.phase == "lift":
            self._move(self.centre[0], self.centre[1], self.base_z + self.motion.rise[self.tick], self.orientation)
        elif self.phase == "shake":
            a, b, turn = self.motion.shake[self.tick]
            ch, sh = self.heading_cos_sin
            self._move(self.centre[0] + a * ch - b * sh, self.centre[1] + a * sh + b * ch,
                       self.base_z + self.runner.protocol.lift_height,
                       pb.getQuaternionFromEuler([0, 0, self.heading + turn]))

    def after_step(self) -> None:
        self.tick += 1
        self.steps += 1
        if self.phase == "close":
            self._after_closing_step()
        elif self.tick % self.check_steps == 0 or self.tick >= self.phase_steps:
            if self._blew_up():
                return self._finish("unstable")
            if self._near_jaws(self.runner.protocol.lost_distance) == 0:
                self.quiet += 1
                if self.quiet >= self.lost_checks:
                    self._fail("slipped" if self.phase in ("lift", "hold") else "dropped")
            else:
                self.quiet = 0
            if self.result is None and self.tick >= self.phase_steps:
                self._end_phase()

    def _after_closing_step(self) -> None:
        c, g = self.runner.client, self.trial.gripper
        states = pb.getJointStates(self.grip, g.finger_joints, physicsClientId=c)
        (q0, v0, *_), (q1, v1, *_) = states
        slow_speed = self.runner.protocol.stall_fraction * g.closing_speed
        slow = abs(v0) < slow_speed and abs(v1) < slow_speed
        shut = abs(q0 - self.limits[0]) < 1e-4 and abs(q1 - self.limits[1]) < 1e-4
        self.quiet = self.quiet + 1 if slow else 0
        if self._blew_up():
            return self._finish("unstable")
        if not (shut or (self.quiet >= self.stall_steps and self.tick > 2) or self.tick >= self.close_steps):
            return
        faces = [g.face_at_zero[j] + g.face_per_unit[j] * s[0] for j, s in enumerate(states)]
        self.grip_width = faces[1] - faces[0]
        self.closing_turn = _wrap(self._object_height_and_yaw()[1] - self.start_yaw)
        if self.camera is not None:
            self.camera.snapshot("2-closed", self)
        self.grip_pose = self._relative_pose()
        held_distance = self.runner.protocol.held_distance
        if self.grip_width < held_distance or self._near_jaws(held_distance) < 2:
            self._fail("no_contact")
        if self.result is None:
            self._begin("lift")

    def _end_phase(self) -> None:
        p = self.runner.protocol
        held = self._near_jaws(p.held_distance) == 2 and not self._on_table()
        if self.phase == "lift":
            self._begin("hold")
        elif self.phase == "hold":
            if self.camera is not None:
                self.camera.snapshot("3-lifted", self)
            if held:
                self._begin("shake")
            else:
                self._fail("slipped")
                if self.result is None:
                    self._begin("shake")
        else:
            if self.camera is not None:
                self.camera.snapshot("4-shaken", self)
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
            if self.camera is not None:
                self.camera.snapshot(f"lost-{outcome}", self)
        if self.runner.early_stop:
            self._finish(outcome)

    def _finish(self, outcome: str) -> None:
        stable = outcome != "unstable"
        self.result = TrialResult(outcome, self.steps, self.grip_width, self.closing_turn,
                                  self._rise() if stable else math.nan, self._pivot() if stable else math.nan)

    # -- queries ------------------------------------------------------------------------

    def _move(self, x: float, y: float, z: float, orientation) -> None:
        pb.changeConstraint(self.constraint, [x, y, z], orientation, maxForce=BASE_FORCE,
                            physicsClientId=self.runner.client)

    def _near_jaws(self, distance: float) -> int:
        """How many of the two jaws are within ``distance`` of the object. Closest points
        decide, not Bullet's contact manifold, which can drop points while an object
        pivots. But the manifold's points are points of both surfaces, so a point pair
        closer than ``distance`` (less NEAR_SLACK for rounding) proves that jaw near: when
        it proves both, as in every lost check of a held object, the closest-points
        query (about 50 us) is skipped and the answer is the same."""
        c, jaws = self.runner.client, self.trial.gripper.jaw_links
        proven = set()
        limit = distance - NEAR_SLACK
        if limit > 0.0:
            for point in pb.getContactPoints(self.obj, self.grip, physicsClientId=c):
                if point[4] in jaws and point[4] not in proven:
                    (ax, ay, az), (bx, by, bz) = point[5], point[6]
                    if (ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2 <= limit * limit:
                        proven.add(point[4])
        if len(proven) == len(jaws):
            return len(jaws)
        # linkIndexA=-1: the prism, not its foot.
        links = {point[4] for point in pb.getClosestPoints(self.obj, self.grip, distance, linkIndexA=-1,
                                                            physicsClientId=c)}
        return sum(link in links for link in jaws)

    def _on_table(self) -> bool:
        return bool(pb.getContactPoints(self.obj, self.runner.table, physicsClientId=self.runner.client))

    def _relative_pose(self):
        """The object's orientation in the gripper's frame (quaternion)."""
        c = self.runner.client
        _, grip = pb.getBasePositionAndOrientation(self.grip, physicsClientId=c)
        _, obj = pb.getBasePositionAndOrientation(self.obj, physicsClientId=c)
        return pb.multiplyTransforms([0, 0, 0], pb.invertTransform([0, 0, 0], grip)[1], [0, 0, 0], obj)[1]

    def _pivot(self) -> float:
        """How far (rad) the object has turned in the gripper since the jaws stalled."""
        if self.grip_pose is None:
            return math.nan
        now = self._relative_pose()
        dot = abs(sum(a * b for a, b in zip(now, self.grip_pose)))
        return 2.0 * math.acos(min(1.0, dot))

    def _object_height_and_yaw(self) -> tuple[float, float]:
        pos, orn = pb.getBasePositionAndOrientation(self.obj, physicsClientId=self.runner.client)
        return pos[2], _yaw(orn)

    def _rise(self) -> float:
        return self._object_height_and_yaw()[0] - self.start_z

    def _blew_up(self) -> bool:
        """NaN anywhere, or the object faster than max_speed or spinning faster than max_spin."""
        p, c = self.runner.protocol, self.runner.client
        pos, _ = pb.getBasePositionAndOrientation(self.obj, physicsClientId=c)
        lin, ang = pb.getBaseVelocity(self.obj, physicsClientId=c)
        if not all(map(math.isfinite, (*pos, *lin, *ang))):
            return True
        return math.hypot(*lin) > p.max_speed or math.hypot(*ang) > p.max_spin

    def remove(self) -> None:
        c = self.runner.client
        pb.removeConstraint(self.constraint, physicsClientId=c)
        pb.removeBody(self.grip, physicsClientId=c)
        pb.removeBody(self.obj, physicsClientId=c)


#: With skip_free_travel, the closing jaws start this far short of the first contact (m),
#: time enough to reach the closing speed (in under a step) before touching.
SKIP_MARGIN = 0.002

#: A contact-manifold point pair proves a jaw within a distance only this much inside it
#: (m; :meth:`_Slot._near_jaws`). The manifold's pairs and the closest-points query round
#: edges and corners differently (by up to the collision margin): with 0.1 mm, 1 of the
#: 13,500 trials of make eval had a jaw 0.72 mm away by its manifold and 1.02 mm by the
#: query at the 1 mm held check. So the shortcut serves only the 5 mm lost checks.
NEAR_SLACK = 0.001

#: The jaws' lower edges start this far above the table (m).
_TABLE_GAP = 0.001


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


class _Camera:
    """PNG snapshots of one trial (pybullet's TinyRenderer, headless)."""

    WIDTH, HEIGHT = 640, 480

    def __init__(self, folder: Path, client: int):
        self.folder = folder
        self.client = client
        folder.mkdir(parents=True, exist_ok=True)

    def add_table(self) -> None:
        shape = pb.createVisualShape(pb.GEOM_BOX, halfExtents=[0.4, 0.4, 0.002], rgbaColor=[0.8, 0.82, 0.78, 1],
                                     physicsClientId=self.client)
        pb.createMultiBody(0, -1, shape, [0, 0, -0.002], physicsClientId=self.client)

    def snapshot(self, name: str, slot: _Slot) -> None:
        import matplotlib.image
        target = [slot.centre[0], slot.centre[1], 0.03]
        view = pb.computeViewMatrixFromYawPitchRoll(target, 0.32, math.degrees(slot.heading) + 35, -35, 0, 2,
                                                    physicsClientId=self.client)
        proj = pb.computeProjectionMatrixFOV(50, self.WIDTH / self.HEIGHT, 0.01, 3.0, physicsClientId=self.client)
        _, _, rgba, _, _ = pb.getCameraImage(self.WIDTH, self.HEIGHT, view, proj, renderer=pb.ER_TINY_RENDERER,
                                             physicsClientId=self.client)
        image = np.asarray(rgba, dtype=np.uint8).reshape(self.HEIGHT, self.WIDTH, 4)[:, :, :3]
        matplotlib.image.imsave(self.folder / f"{name}.png", image)

    def snapshot_footprint(self, trial: Trial) -> None:
        """A plan view of why the approach was blocked: the object and the pads."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5, 5))
        for geom, colour in [(trial.polygon, "tab:orange"), *[(pad, "tab:grey") for pad in pad_footprints(trial)]]:
            for ring in [geom.exterior, *geom.interiors]:
                xy = np.asarray(ring.coords)
                ax.fill(xy[:, 0], xy[:, 1], color=colour, alpha=0.6 if colour == "tab:grey" else 1.0)
        ax.set_aspect("equal")
        ax.set_title("approach_collision: a jaw pad comes down on the object")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        fig.savefig(self.folder / "1-approach_collision.png", dpi=100)
        plt.close(fig)
