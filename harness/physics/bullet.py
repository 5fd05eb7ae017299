"""The pybullet engine: the runner that steps a batch of trials together in one pybullet
world, each trial's state machine in it, and headless PNG frames.

Batching: the runner puts up to ``batch_size`` trials in one world, each in its own
slot (bodies ``SLOT_SPACING`` apart), steps them together and removes a trial's bodies
as soon as its outcome is decided. Which trials share a world and in which slot is
fixed by their order in the list, never by the number of workers. A batch's light
objects (``LIGHT_FRACTION``) run in a world of their own at a finer step, in the same
slots.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np
import pybullet as pb

from harness.physics.bodies import create_body
from harness.physics.trial import (TABLE_GAP, BatchRunner, Trial, TrialMachine, TrialResult,
                                   prechecked, skipped_travel, yaw)
from harness.protocol import Protocol

#: Distance between neighbouring slots of a batch (m): far beyond any object, gripper,
#: shake and fall, so trials in one world never touch.
SLOT_SPACING = 2.0
#: The floating base's constraint may apply up to this force (N).
BASE_FORCE = 2000.0
#: An object lighter than this fraction of the lighter jaw's mass is squeezed between
#: plates far heavier than itself: a badly conditioned contact problem for Bullet's
#: iterative solver, which at the design's step lets the plates press into it and, across
#: a thin wall, close past it (a bar 8 cm long, 6 mm wide and 2.4 cm thick, gripped across
#: its middle at 20 N by 50 g plates: 0 of 16 trials held at 3.5 g, 8 at 6.9 g, 15 at 13.8
#: g, all at 27.6 g; all held at a four times finer step, and by MuJoCo at its own). Such an
#: object's trial runs at a LIGHT_REFINE times finer step, which held every bar of that
#: study down to 1.7 g (docs/physics.md, "Light objects"). The lightest shapes of make eval
#: weigh 0.4 of a jaw and more, so it runs as before.
LIGHT_FRACTION = 0.3
LIGHT_REFINE = 4


class BulletRunner(BatchRunner):
    """Runs trials in batches in one pybullet client, kept for the runner's life (one
    per worker process); each batch is one world."""

    def __init__(self, protocol: Protocol | None = None, batch_size: int = 16, early_stop: bool = True):
        super().__init__(protocol or Protocol(), batch_size, early_stop)
        self._client: int | None = None
        self._jaw_masses: dict[str, float] = {}

    def close(self) -> None:
        if self._client is not None:
            pb.disconnect(physicsClientId=self._client)
            self._client = None

    @property
    def client(self) -> int:
        if self._client is None:
            self._client = pb.connect(pb.DIRECT)
        return self._client

    # -- one world ---------------------------------------------------------------------

    def _reset_world(self, protocol: Protocol | None = None) -> None:
        c, p = self.client, protocol or self.protocol
        pb.resetSimulation(physicsClientId=c)
        pb.setPhysicsEngineParameter(fixedTimeStep=p.time_step, numSolverIterations=p.solver_iterations,
                                     numSubSteps=0, deterministicOverlappingPairs=1,
                                     enableConeFriction=int(p.cone_friction), physicsClientId=c)
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        self.table = pb.createMultiBody(0, plane, physicsClientId=c)
        pb.changeDynamics(self.table, -1, lateralFriction=p.table_friction, physicsClientId=c)

    def jaw_mass(self, gripper) -> float:
        """The lighter jaw's mass (kg), read once per gripper from its URDF as Bullet loads it."""
        mass = self._jaw_masses.get(gripper.urdf)
        if mass is None:
            c = self.client
            body = pb.loadURDF(gripper.urdf, physicsClientId=c)
            mass = min(pb.getDynamicsInfo(body, link, physicsClientId=c)[0] for link in gripper.jaw_links)
            pb.removeBody(body, physicsClientId=c)
            self._jaw_masses[gripper.urdf] = mass
        return mass

    def is_light(self, trial: Trial) -> bool:
        """Whether the trial's object weighs less than LIGHT_FRACTION of a jaw."""
        if trial.polygon.is_empty:
            return False
        mass = trial.polygon.area * trial.thickness * trial.density
        return mass < LIGHT_FRACTION * self.jaw_mass(trial.gripper)

    def _run_batch(self, batch: Sequence[Trial], frames: Path | None, trace=None) -> list[TrialResult]:
        """The batch's trials in one world; its light objects (LIGHT_FRACTION) in a second
        world at a LIGHT_REFINE times finer step, each trial in the slot its place in the
        batch gives it."""
        light = [self.is_light(trial) for trial in batch]
        results: list[TrialResult | None] = [None] * len(batch)
        for finer in (False, True):
            slots = [k for k in range(len(batch)) if light[k] == finer]
            if slots:
                protocol = self.protocol.finer(LIGHT_REFINE) if finer else self.protocol
                self._run_world(batch, slots, protocol, frames if 0 in slots else None, results,
                                trace if 0 in slots else None)
        return results  # type: ignore[return-value]

    def _run_world(self, batch: Sequence[Trial], slots: list[int], protocol: Protocol, frames: Path | None,
                   results: list, trace=None) -> None:
        """Run ``batch[k]`` for k in ``slots`` in one world under ``protocol``, into
        ``results[k]``; ``trace`` records batch[0]."""
        camera = _Camera(frames, self.client) if frames is not None else None
        self._reset_world(protocol)
        if camera is not None:
            camera.add_table()
        active: list[_Slot] = []
        for k in slots:
            trial = batch[k]
            results[k] = prechecked(trial)
            if results[k] is not None:
                if camera is not None and k == 0 and results[k].outcome == "approach_collision":
                    camera.snapshot_footprint(trial)
            else:
                active.append(_Slot(self, k, trial, (k * SLOT_SPACING, 0.0), protocol,
                                    camera if k == 0 else None))
                if k == 0:
                    active[-1].tracer = trace
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


class _Slot(TrialMachine):
    """One trial's bodies in a batch world, and its state machine."""

    def __init__(self, runner: BulletRunner, index: int, trial: Trial, origin: tuple[float, float],
                 protocol: Protocol, camera: "_Camera | None"):
        super().__init__(index, trial, protocol, runner.early_stop)
        self.runner, self.origin, self.camera = runner, origin, camera
        c, t, g = self.runner.client, self.trial, self.trial.gripper
        p = protocol
        ox, oy = self.origin
        body = create_body(c, t.polygon, t.thickness, t.density, 1.0, origin=self.origin,
                           visual=self.camera is not None, foot=p.table_hull, clipping=p.convex_clipping)
        self.obj, self.foot = body.body_id, body.foot
        for link in range(-1, pb.getNumJoints(self.obj, physicsClientId=c)):
            pb.changeDynamics(self.obj, link, frictionAnchor=int(p.friction_anchor), physicsClientId=c)
        g1, g2 = np.asarray(t.g1), np.asarray(t.g2)
        centre = 0.5 * (g1 + g2)
        width = math.dist(t.g1, t.g2)  # not np.linalg.norm: a BLAS dot product (see trial._along)
        heading = math.atan2(t.axis[1], t.axis[0]) - math.atan2(g.closing_axis[1], g.closing_axis[0])
        centre = (centre[0] + ox, centre[1] + oy)
        base_z = g.depth + TABLE_GAP
        orientation = pb.getQuaternionFromEuler([0, 0, heading])
        self.grip = pb.loadURDF(g.urdf, [centre[0], centre[1], base_z], orientation, physicsClientId=c,
                                flags=pb.URDF_INITIALIZE_SAT_FEATURES if p.convex_clipping else 0)
        # A compliant pad: each contact point of the gripper a spring and a damper.
        pad = {"contactStiffness": p.pad_stiffness, "contactDamping": p.pad_damping} if p.pad_stiffness > 0 else {}
        for link in range(-1, pb.getNumJoints(self.grip, physicsClientId=c)):
            pb.changeDynamics(self.grip, link, lateralFriction=t.friction, frictionAnchor=int(p.friction_anchor),
                              physicsClientId=c, **pad)
            pb.setCollisionFilterPair(self.grip, self.runner.table, link, -1, 0, physicsClientId=c)
            if self.foot is not None:
                pb.setCollisionFilterPair(self.obj, self.grip, self.foot, link, 0, physicsClientId=c)
        if self.foot is not None:  # the foot alone meets the table, and nothing else
            pb.setCollisionFilterPair(self.obj, self.runner.table, -1, -1, 0, physicsClientId=c)
        width -= 2 * skipped_travel(t, p)
        limits = []
        for jaw, joint in enumerate(g.finger_joints):
            q0 = g.joint_position(jaw, (-0.5 if jaw == 0 else 0.5) * width)
            info = pb.getJointInfo(self.grip, joint, physicsClientId=c)
            closes_up = (g.face_per_unit[jaw] > 0) == (jaw == 0)
            limits.append(info[9] if closes_up else info[8])
            pb.resetJointState(self.grip, joint, q0, physicsClientId=c)
            pb.setJointMotorControl2(self.grip, joint, pb.POSITION_CONTROL, targetPosition=limits[-1],
                                     force=g.force, maxVelocity=g.closing_speed / abs(g.face_per_unit[jaw]),
                                     physicsClientId=c)
        self.limits = tuple(limits)
        inertial = pb.getDynamicsInfo(self.grip, -1, physicsClientId=c)[3:5]
        self.pivot, self.pivot_orn = pb.invertTransform(*inertial)
        self.constraint = pb.createConstraint(self.grip, -1, -1, -1, pb.JOINT_FIXED, [0, 0, 0],
                                              self.pivot, [centre[0], centre[1], base_z],
                                              self.pivot_orn, orientation, physicsClientId=c)
        pb.changeConstraint(self.constraint, maxForce=BASE_FORCE, physicsClientId=c)
        self.start(width, centre, heading, base_z)

    # -- the engine's queries -----------------------------------------------------------

    def move(self, x: float, y: float, z: float, heading: float) -> None:
        pb.changeConstraint(self.constraint, [x, y, z], pb.getQuaternionFromEuler([0, 0, heading]),
                            maxForce=BASE_FORCE, physicsClientId=self.runner.client)

    def jaw_states(self):
        states = pb.getJointStates(self.grip, self.trial.gripper.finger_joints, physicsClientId=self.runner.client)
        return tuple((s[0], s[1]) for s in states)

    def jaws_shut(self, states) -> bool:
        return all(abs(q - limit) < 1e-4 for (q, _), limit in zip(states, self.limits))

    def snapshot(self, name: str) -> None:
        if self.camera is not None:
            self.camera.snapshot(name, self)

    def near_jaws(self, distance: float) -> int:
        """Closest points decide, not Bullet's contact manifold, which can drop points
        while an object pivots. But the manifold's points are points of both surfaces, so
        a point pair closer than ``distance`` (less NEAR_SLACK for rounding) proves that
        jaw near: when it proves both, as in every lost check of a held object, the
        closest-points query (about 50 us) is skipped and the answer is the same."""
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

    def on_table(self) -> bool:
        return bool(pb.getContactPoints(self.obj, self.runner.table, physicsClientId=self.runner.client))

    def poses(self):
        c = self.runner.client
        out = []
        for body in (self.grip, self.obj):
            position, orientation = pb.getBasePositionAndOrientation(body, physicsClientId=c)
            out += [np.array(position), np.array(pb.getMatrixFromQuaternion(orientation)).reshape(3, 3)]
        return tuple(out)

    def jaw_contacts(self):
        """The contact manifold's points between the object and each jaw link (on the jaw)."""
        from harness.physics.trace import pressure_centre

        jaws = self.trial.gripper.jaw_links
        points, forces = [[] for _ in jaws], [[] for _ in jaws]
        for point in pb.getContactPoints(self.obj, self.grip, physicsClientId=self.runner.client):
            if point[4] in jaws:
                j = jaws.index(point[4])
                points[j].append(point[6])
                forces[j].append(point[9])
        return [(len(points[j]), float(sum(forces[j])), pressure_centre(points[j], forces[j]))
                for j in range(len(jaws))]

    def relative_pose(self):
        c = self.runner.client
        _, grip = pb.getBasePositionAndOrientation(self.grip, physicsClientId=c)
        _, obj = pb.getBasePositionAndOrientation(self.obj, physicsClientId=c)
        return pb.multiplyTransforms([0, 0, 0], pb.invertTransform([0, 0, 0], grip)[1], [0, 0, 0], obj)[1]

    def object_height_and_yaw(self) -> tuple[float, float]:
        pos, orn = pb.getBasePositionAndOrientation(self.obj, physicsClientId=self.runner.client)
        return pos[2], yaw(orn)

    def blew_up(self) -> bool:
        p, c = self.protocol, self.runner.client
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


#: A contact-manifold point pair proves a jaw within a distance only this much inside it
#: (m; :meth:`_Slot.near_jaws`). The manifold's pairs and the closest-points query round
#: edges and corners differently (by up to the collision margin): with 0.1 mm, 1 of the
#: 13,500 trials of make eval had a jaw 0.72 mm away by its manifold and 1.02 mm by the
#: query at the 1 mm held check. So the shortcut serves only the 5 mm lost checks.
NEAR_SLACK = 0.001

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
        from harness.physics.frames import draw_footprint

        draw_footprint(trial, self.folder)
