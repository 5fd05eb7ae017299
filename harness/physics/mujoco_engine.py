"""The MuJoCo engine: the same trial as :mod:`harness.physics.bullet`, in MuJoCo.

Each trial is one MuJoCo model, compiled from MJCF text written here: the table (a
plane), the object (a free body whose collision geoms are the same convex pieces as in
Bullet, extruded, with the exact mass, centre of mass and principal inertia of the whole
prism, and the foot when the protocol has one), and the parallel jaw (a palm welded to a
mocap body that the protocol drives, two plates on prismatic joints, each pressed by
the force limit against a damper that sets the closing speed). The state machine and every outcome's rule are the
engine-neutral ones of :class:`harness.physics.trial.TrialMachine`.

The contact parameters are chosen from MuJoCo's documentation and from the physics of a
rubber-padded plate on a rigid wall, never by agreement with Bullet or with P_L; each
constant below says why, and docs/physics.md ("MuJoCo") has the fidelity study of the
time step and the solver's iterations.

A trial's model depends on nothing but the trial and the protocol, and MuJoCo is
deterministic on one machine, so a trial's result does not depend on the trials beside
it, on the batch size or on the number of workers.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import mujoco
import numpy as np
from shapely.geometry import Polygon

from harness.physics.bodies import FOOT_HEIGHT, convex_pieces, prism_vertices, recipe
from harness.physics.gripper import PALM_MASS, PALM_THICKNESS, PLATE_MASS
from harness.physics.trial import (TABLE_GAP, BatchRunner, Trial, TrialMachine, TrialResult, motion, prechecked,
                                   skipped_travel, yaw)
from harness.protocol import Protocol

#: A jaw's contacts with the object have four dimensions: the normal, two sliding
#: directions and torsion about the normal (condim 4). Rolling friction (condim 6) is
#: left out: a flat plate on a flat wall resists tipping through the spread of its
#: contact points (multiccd below), not through a rolling torque at each point.
JAW_CONDIM = 4
#: The object's contacts with the table: normal and sliding (condim 3); its resting
#: patch resists turning through the spread of the foot's contact points.
TABLE_CONDIM = 3
#: Radius (m) of the patch of rubber pad that carries one contact point's load. A pad
#: pressed on a wall conforms over a patch about as wide as the pad is thick (a pad of
#: 2 mm); under uniform pressure a disc of radius a resists a turn about its normal with
#: at most (2/3) mu a N (integrate mu N / (pi a^2) * r over the disc), so the torsional
#: coefficient is (2/3) mu PAD_RADIUS, a length, for each point.
PAD_RADIUS = 0.002
#: Ratio of the frictional to the normal constraints' impedance (elliptic cones). MuJoCo's
#: contacts are soft: at the default 1 a static friction force is held with a creep
#: velocity proportional to it, so a grasped object slides slowly out of any grip. Coulomb
#: static friction does not creep; MuJoCo's documentation recommends raising impratio to
#: make friction harder without changing the coefficient. From 10 on the outcomes stop
#: moving (100 changes 1 of 240 fidelity trials, 1 changes 31; docs/physics.md, "MuJoCo").
IMPRATIO = 10.0
#: Contact softness: solref's time constant (s) and damping ratio, the pad's stiffness.
#: With 4 ms a plate at 20 N sinks 0.2-0.6 mm into the object (tested), about 5e4 N/m:
#: k = E A / t of a 2 mm silicone-rubber pad (E about 1 MPa) over a square centimetre.
#: 4 ms is also two steps of 2 ms, the stiffest MuJoCo's documentation allows at that
#: step. Fixed in seconds, so that a finer step (the fidelity study) keeps the physics.
CONTACT_TIMECONST = 0.004
CONTACT_DAMPRATIO = 1.0
#: The weld that carries the palm along the protocol's path: as stiff as the contacts.
WELD_TIMECONST = 0.004
#: The table's size (m): a plane; only its visual extent depends on it.
TABLE_HALF = 1.0
#: Compiled models kept per process (70-100 kB each, and with each its spare MjData,
#: about 0.33 MB resident once a trial has used it: 43 MB for `bench physics`' 130
#: shapes): as many as the shapes' bodies (harness.physics.bodies.recipe). A
#: least-recently-used cache that is smaller than the shapes a process cycles through
#: misses on every trial: with 128, the 130 shapes of `bench physics`' trial set were
#: compiled again on every pass.
MODEL_CACHE = 256


def contact_timeconst(protocol: Protocol) -> float:
    """The contact time constant: CONTACT_TIMECONST, or two steps if the step is coarser."""
    return max(CONTACT_TIMECONST, 2.0 * protocol.time_step)


class MujocoRunner(BatchRunner):
    """Runs trials in MuJoCo, one model per trial: a batch is only a group of trials
    (the models are independent)."""

    def __init__(self, protocol: Protocol | None = None, batch_size: int = 16, early_stop: bool = True):
        super().__init__(protocol or Protocol.of("mujoco"), batch_size, early_stop)

    def _run_batch(self, batch: Sequence[Trial], frames: Path | None, trace=None) -> list[TrialResult]:
        from harness.physics.frames import Frames

        return [self.run_one(trial, Frames(frames) if frames is not None and k == 0 else None,
                             trace if k == 0 else None)
                for k, trial in enumerate(batch)]

    def run_one(self, trial: Trial, camera=None, tracer=None) -> TrialResult:
        early = prechecked(trial)
        if early is not None:
            if camera is not None and early.outcome == "approach_collision":
                camera.footprint(trial)
            return early
        slot = _Slot(self, trial, camera)
        slot.tracer = tracer
        m, d, step = slot.model, slot.data, mujoco.mj_step
        # Closing: every step is checked, and the gripper's target holds still.
        while slot.result is None and slot.phase == "close":
            step(m, d)
            slot.fresh = False
            slot.after_step()
        while slot.result is None:
            quiet = slot.undecided_steps()
            if quiet:
                slot.advance(quiet)
            slot.before_step()
            step(m, d)
            slot.fresh = False
            slot.after_step()
        slot.layout.give(d)
        return slot.result


class _Slot(TrialMachine):
    """One trial's model, data and state machine. The gripper's target follows paths
    computed once per trial (:meth:`_paths`) instead of :meth:`TrialMachine.move` at
    every step, so that steps that decide nothing run without the machine
    (:meth:`advance`)."""

    def __init__(self, runner: MujocoRunner, trial: Trial, camera=None):
        super().__init__(0, trial, runner.protocol, runner.early_stop)
        p, g, t = runner.protocol, trial.gripper, trial
        check_gripper(g)
        self.camera = camera
        g1, g2 = np.asarray(t.g1), np.asarray(t.g2)
        centre = 0.5 * (g1 + g2)
        heading = math.atan2(t.axis[1], t.axis[0]) - math.atan2(g.closing_axis[1], g.closing_axis[0])
        base_z = g.depth + TABLE_GAP
        self.layout = layout = _layout(compiled(object_xml(t.polygon, t.thickness, t.density, p.table_hull),
                                                gripper_xml(g, t.friction), options_xml(p), p.table_friction))
        self.model = m = layout.model
        self.data = d = layout.take()
        self.mocap_pos, self.mocap_quat = d.mocap_pos[0], d.mocap_quat[0]
        self.fresh = False
        self.obj, self.obj_qpos, self.obj_dof = layout.obj, layout.obj_qpos, layout.obj_dof
        # Views of the object's free joint: position and velocity (linear, angular).
        self.obj_position = d.qpos[self.obj_qpos:self.obj_qpos + 3]
        self.obj_turn = d.qpos[self.obj_qpos + 3:self.obj_qpos + 7]
        self.obj_velocity = d.qvel[self.obj_dof:self.obj_dof + 6]
        self.com_in_body = layout.com_in_body
        self.palm_qpos, self.finger_qpos, self.finger_dof = layout.palm_qpos, layout.finger_qpos, layout.finger_dof
        self.limits, self.jaw_geoms, self.table = layout.limits, layout.jaw_geoms, layout.table
        self.pieces, self.touching = layout.pieces, layout.touching
        # Per jaw, the piece last found near it, asked first (the count does not depend on the order).
        self.near_piece = [0, 0]
        width = math.dist(t.g1, t.g2) - 2 * skipped_travel(t, p)
        position, turn = (float(centre[0]), float(centre[1]), base_z), _turn(heading)
        d.qpos[self.palm_qpos:self.palm_qpos + 7] = (*position, *turn)
        d.mocap_pos[0], d.mocap_quat[0] = position, turn
        for jaw in range(2):
            d.qpos[self.finger_qpos[jaw]] = g.joint_position(jaw, (-0.5 if jaw == 0 else 0.5) * width)
        d.ctrl[:] = g.force
        mujoco.mj_forward(m, d)
        self.fresh = True
        self.start(width, position[:2], heading, base_z)
        self.paths = self._paths()

    # -- the engine's queries -----------------------------------------------------------

    def _kinematics(self) -> None:
        """Positions of every body and geom for the current state (mj_step leaves them
        as they were at the start of the step)."""
        if not self.fresh:
            mujoco.mj_kinematics(self.model, self.data)
            self.fresh = True

    def before_step(self) -> None:
        """The gripper's target at this step of the lift or the shake, from the paths
        computed once per trial (:meth:`_paths`)."""
        path = self.paths.get(self.phase)
        if path is not None:
            self.mocap_pos[:] = path[0][self.tick]
            self.mocap_quat[:] = path[1][self.tick]

    def advance(self, steps: int) -> None:
        """Run ``steps`` steps that decide nothing: along the path, or in one call to
        MuJoCo while the gripper holds still."""
        m, d = self.model, self.data
        path = self.paths.get(self.phase)
        if path is None:
            mujoco.mj_step(m, d, steps)
        else:
            positions, turns = path
            position, turn, step = self.mocap_pos, self.mocap_quat, mujoco.mj_step
            for k in range(self.tick, self.tick + steps):
                position[:] = positions[k]
                turn[:] = turns[k]
                step(m, d)
        self.fresh = False
        self.ticked(steps)

    def _paths(self) -> dict:
        """The gripper target's positions (n, 3) and turns (n, 4, quaternions; the lift's
        one turn broadcast) at each step of the lift and of the shake: the protocol's
        motion (trial.motion) about this trial's grasp centre and heading, as
        TrialMachine.before_step moves it."""
        (cx, cy), h, z = self.centre, self.heading, self.base_z
        rise, (a, b, turn) = _motion_arrays(self.protocol)
        lift = np.empty((len(rise), 3))
        lift[:, 0], lift[:, 1], lift[:, 2] = cx, cy, z + rise
        ch, sh = self.heading_cos_sin
        angle = 0.5 * (h + turn)
        shake, turns = np.empty((len(a), 3)), np.zeros((len(a), 4))
        shake[:, 0], shake[:, 1] = cx + a * ch - b * sh, cy + a * sh + b * ch
        shake[:, 2] = z + self.protocol.lift_height
        turns[:, 0], turns[:, 3] = np.cos(angle), np.sin(angle)
        return {"lift": (lift, np.broadcast_to(np.array(_turn(h)), (len(rise), 4))), "shake": (shake, turns)}

    def jaw_states(self):
        q, v = self.data.qpos, self.data.qvel
        (a0, a1), (u0, u1) = self.finger_qpos, self.finger_dof
        return (float(q[a0]), float(v[u0])), (float(q[a1]), float(v[u1]))

    def jaws_shut(self, states) -> bool:
        """A soft limit may be passed by a little: at or beyond it within 0.1 mm."""
        ((q0, _), (q1, _)), (limit0, limit1) = states, self.limits
        return q0 > limit0 - 1e-4 and q1 > limit1 - 1e-4

    def near_jaws(self, distance: float) -> int:
        """Each jaw is near when any of the object's pieces is within ``distance`` of it;
        the piece found last time is asked first (most checks then ask one piece a jaw)."""
        self._kinematics()
        m, d, pieces, distance_to = self.model, self.data, self.pieces, mujoco.mj_geomDistance
        near = 0
        for k, jaw in enumerate(self.jaw_geoms):
            first = self.near_piece[k]
            if distance_to(m, d, pieces[first], jaw, distance, None) < distance:
                near += 1
                continue
            for j, piece in enumerate(pieces):
                if j != first and distance_to(m, d, piece, jaw, distance, None) < distance:
                    self.near_piece[k] = j
                    near += 1
                    break
        return near

    def on_table(self) -> bool:
        """Touching the table: within the held distance of it, as a jaw counts as touching."""
        self._kinematics()
        m, d, limit = self.model, self.data, self.protocol.held_distance
        return any(mujoco.mj_geomDistance(m, d, geom, self.table, limit, None) < limit for geom in self.touching)

    def blew_up(self) -> bool:
        """With MuJoCo's automatic reset off (options_xml), a diverged state stays NaN. The
        speeds are :meth:`speeds`."""
        p = self.protocol
        speed, spin = self.speeds()
        # A speed that is NaN or infinite fails these comparisons too.
        if not (speed <= p.max_speed and spin <= p.max_spin):
            return True
        x, y, z = self.obj_position.tolist()
        return not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z))

    def speeds(self) -> tuple[float, float]:
        """The object's centre of mass's speed and its spin, as Bullet's base velocity
        gives them, from the state alone (no kinematics: the check runs at every closing
        step). A free joint's linear velocity is its frame origin's (the polygon's origin
        here) in the world; its angular velocity w is in the body's frame, so the centre
        of mass moves at v + R (w x c), c its place in the body's frame and R the body's
        turn (the joint's quaternion), and the spin's size is |w|."""
        vx, vy, vz, a, b, c = self.obj_velocity.tolist()
        qw, qx, qy, qz = self.obj_turn.tolist()
        cx, cy, cz = self.com_in_body
        ux, uy, uz = b * cz - c * cy, c * cx - a * cz, a * cy - b * cx  # w x c
        # R u for the unit quaternion (qw, q): u + 2 qw (q x u) + 2 q x (q x u).
        tx, ty, tz = 2.0 * (qy * uz - qz * uy), 2.0 * (qz * ux - qx * uz), 2.0 * (qx * uy - qy * ux)
        rx = ux + qw * tx + qy * tz - qz * ty
        ry = uy + qw * ty + qz * tx - qx * tz
        rz = uz + qw * tz + qx * ty - qy * tx
        return math.hypot(vx + rx, vy + ry, vz + rz), math.hypot(a, b, c)

    def object_height_and_yaw(self) -> tuple[float, float]:
        self._kinematics()
        w, x, y, z = self.data.xquat[self.obj]
        return float(self.data.xipos[self.obj][2]), yaw((x, y, z, w))

    def relative_pose(self):
        q = self.data.qpos
        grip = q[self.palm_qpos + 3:self.palm_qpos + 7]
        obj = q[self.obj_qpos + 3:self.obj_qpos + 7]
        inverse, out = np.empty(4), np.empty(4)
        mujoco.mju_negQuat(inverse, grip)
        mujoco.mju_mulQuat(out, inverse, obj)
        return tuple(float(v) for v in out)

    def snapshot(self, name: str) -> None:
        if self.camera is not None:
            self._kinematics()
            self.camera.snapshot(name, self)

    def poses(self):
        self._kinematics()
        d, palm = self.data, self.layout.palm
        return (d.xpos[palm].copy(), d.xmat[palm].reshape(3, 3).copy(), d.xpos[self.obj].copy(),
                d.xmat[self.obj].reshape(3, 3).copy())

    def jaw_contacts(self):
        """The contacts of the last step's collision (MuJoCo's contact list), by jaw body."""
        from harness.physics.trace import pressure_centre

        m, d = self.model, self.data
        bodies = [int(m.geom_bodyid[g]) for g in self.jaw_geoms]
        points, forces, force = ([], []), ([], []), np.zeros(6)
        for k in range(d.ncon):
            c = d.contact[k]
            pair = (int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2]))
            if self.obj not in pair:
                continue
            for jaw, body in enumerate(bodies):
                if body in pair:
                    mujoco.mj_contactForce(m, d, k, force)
                    points[jaw].append(c.pos.copy())
                    forces[jaw].append(float(force[0]))
        return [(len(points[j]), float(sum(forces[j])), pressure_centre(points[j], forces[j])) for j in range(2)]


@lru_cache(maxsize=8)
def _motion_arrays(p: Protocol) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The protocol's motion (trial.motion) as arrays: the lift's rise and the shake's
    offsets along and across the closing axis and its turn."""
    m = motion(p)
    return np.asarray(m.rise), tuple(np.asarray(m.shake).T)


class _Layout:
    """A compiled model's indices (bodies, joints, geoms) and one spare MjData, kept with
    the model for the process's life: a trial takes the spare, reset to the model's
    initial state as a new MjData is (mj_resetData; MjData's constructor calls it), and
    gives it back when it ends; a trial that finds no spare (another holds it) gets new
    data."""

    def __init__(self, m: mujoco.MjModel):
        self.model = m
        body, jnt = m.body, m.joint
        self.obj = body("object").id
        self.palm = body("palm").id
        # The centre of mass in the object's frame (the inertial's position).
        self.com_in_body = tuple(float(v) for v in m.body_ipos[self.obj])
        self.obj_qpos = int(m.jnt_qposadr[jnt("object").id])
        self.obj_dof = int(m.jnt_dofadr[jnt("object").id])
        self.palm_qpos = int(m.jnt_qposadr[jnt("palm").id])
        self.finger_qpos = [int(m.jnt_qposadr[jnt(f"jaw_{k + 1}").id]) for k in range(2)]
        self.finger_dof = [int(m.jnt_dofadr[jnt(f"jaw_{k + 1}").id]) for k in range(2)]
        self.limits = tuple(float(m.jnt_range[jnt(f"jaw_{k + 1}").id][1]) for k in range(2))
        self.jaw_geoms = [m.geom(f"plate_{k + 1}").id for k in range(2)]
        mine = [k for k in range(m.ngeom) if m.geom_bodyid[k] == self.obj]
        foot = [k for k in mine if m.geom(k).name == "foot"]
        self.pieces = [k for k in mine if k not in foot]
        # The geoms that may touch the table: the foot where the model has one (the
        # protocol's table_hull), else every piece.
        self.touching = foot or mine
        self.table = m.geom("table").id
        self.spare: mujoco.MjData | None = None

    def take(self) -> mujoco.MjData:
        d, self.spare = self.spare, None
        if d is None:
            return mujoco.MjData(self.model)
        mujoco.mj_resetData(self.model, d)
        return d

    def give(self, d: mujoco.MjData) -> None:
        self.spare = d


@lru_cache(maxsize=MODEL_CACHE)
def _layout(m: mujoco.MjModel) -> _Layout:
    return _Layout(m)


def check_gripper(g) -> None:
    """MuJoCo builds the built-in parallel jaw from the adapter's numbers; a gripper
    from another URDF cannot be translated."""
    if not Path(g.urdf).name.startswith("gpis-harness-gripper-") or tuple(g.closing_axis) != (1.0, 0.0) \
            or tuple(g.face_per_unit) != (1.0, -1.0):
        raise ValueError("the MuJoCo engine runs the built-in parallel-jaw gripper only "
                         f"(got {g.urdf}); use the pybullet engine for another URDF")


def _floats(values) -> str:
    return " ".join(f"{float(v):.12g}" for v in values)


@lru_cache(maxsize=256)
def object_xml(polygon: Polygon, thickness: float, density: float, foot: bool) -> tuple[str, str]:
    """The object's mesh assets and its body (MJCF), in the polygon's frame: each convex
    piece of :func:`~harness.physics.bodies.convex_pieces` extruded to the full
    thickness (MuJoCo's convex geoms have no margin to shrink for), and with ``foot``
    a slab over the convex hull at the bottom that alone meets the table (as in Bullet,
    docs/physics.md "The foot"). The inertial is the exact prism's, in its principal frame."""
    shape = recipe(polygon, thickness, density, convex_pieces)  # Bullet's pieces and mass properties
    props, moments, (qx, qy, qz, qw) = shape.props, shape.moments, shape.principal_axes
    assets, geoms = [], []
    for k, piece in enumerate(shape.pieces):
        assets.append(f'<mesh name="piece{k}" vertex="{_floats(np.ravel(prism_vertices(piece, 0.0, thickness)))}"/>')
        geoms.append(f'<geom name="piece{k}" type="mesh" mesh="piece{k}" contype="1" '
                     f'conaffinity="{0 if foot else 2}" group="1"/>')
    if foot:
        slab = prism_vertices(polygon.convex_hull, 0.0, min(FOOT_HEIGHT, 0.5 * thickness))
        assets.append(f'<mesh name="foot" vertex="{_floats(np.ravel(slab))}"/>')
        geoms.append('<geom name="foot" type="mesh" mesh="foot" contype="0" conaffinity="2" group="3"/>')
    body = (f'<body name="object"><freejoint name="object"/>'
            f'<inertial pos="{_floats(props.com)}" quat="{_floats((qw, qx, qy, qz))}" mass="{props.mass:.12g}" '
            f'diaginertia="{_floats(moments)}"/>{"".join(geoms)}</body>')
    return "".join(assets), body


def _turn(heading: float) -> tuple[float, float, float, float]:
    """The quaternion (w, x, y, z) of a turn by ``heading`` about the vertical."""
    return (math.cos(0.5 * heading), 0.0, 0.0, math.sin(0.5 * heading))


@lru_cache(maxsize=64)
def gripper_xml(g, friction: float) -> str:
    """The palm (welded to the mocap body ``target``), the two plates on prismatic
    joints and their motors, from the built-in gripper's adapter (harness.physics.gripper),
    at the origin (each trial places it through the state: one model serves every trial
    of a shape)."""
    half, t, w, length = g.face_at_zero[1], g.pad_thickness, g.pad_width, g.depth
    torsion = 2.0 / 3.0 * friction * PAD_RADIUS
    palm = (half + t, max(w, 0.02) / 2, PALM_THICKNESS / 2)
    plate = (t / 2, w / 2, length / 2)
    # Each jaw closes under a constant force, the gripper's force limit, against a viscous
    # damper of force / closing speed in its joint: free, it closes at the closing speed
    # (reached in a tenth of a millisecond); held by the object, it presses with exactly
    # the force limit, as Bullet's finger motor does once it stalls (tested). The damper
    # is integrated implicitly (implicitfast). A carriage driving the plate through a
    # joint's dry friction squeezed with less: MuJoCo's dry friction is as soft as its
    # contacts (docs/physics.md, "MuJoCo").
    damping = g.force / g.closing_speed
    jaws = []
    for k, sign in ((1, -1), (2, 1)):
        jaws.append(
            f'<body name="jaw_{k}" gravcomp="1"><joint name="jaw_{k}" type="slide" axis="{-sign} 0 0" '
            f'range="0 {half:.12g}" limited="true" damping="{damping:.12g}"/>'
            f'<inertial pos="{sign * (half + t / 2):.12g} 0 {-length / 2:.12g}" mass="{PLATE_MASS}" '
            f'diaginertia="{_floats(_box_inertia(PLATE_MASS, plate))}"/>'
            f'<geom name="plate_{k}" type="box" size="{_floats(plate)}" '
            f'pos="{sign * (half + t / 2):.12g} 0 {-length / 2:.12g}" contype="0" conaffinity="1" '
            f'condim="{JAW_CONDIM}" priority="1" friction="{friction:.12g} {torsion:.12g} 0" '
            f'rgba="0.55 0.57 0.6 1"/></body>')
    actuators = "".join(f'<motor joint="jaw_{k}" gear="1"/>' for k in (1, 2))
    return (f'<body name="target" mocap="true"/>'
            f'<body name="palm" gravcomp="1"><freejoint name="palm"/>'
            f'<inertial pos="0 0 0" mass="{PALM_MASS}" diaginertia="{_floats(_box_inertia(PALM_MASS, palm))}"/>'
            f'<geom name="palm" type="box" size="{_floats(palm)}" pos="0 0 {PALM_THICKNESS / 2:.12g}" '
            f'contype="0" conaffinity="1" priority="1" condim="{JAW_CONDIM}" '
            f'friction="{friction:.12g} {torsion:.12g} 0" rgba="0.25 0.25 0.28 1"/>'
            f'{"".join(jaws)}</body>'
            f'</worldbody><actuator>{actuators}</actuator>'
            f'<equality><weld body1="palm" body2="target" relpose="0 0 0 1 0 0 0" '
            f'solref="{WELD_TIMECONST} 1"/></equality>')


def options_xml(p: Protocol) -> str:
    """The simulation options: the protocol's step and iterations; Newton's solver;
    the elliptic cone (pyramidal without ``cone_friction``); implicit integration of the
    plates' dampers; several contacts between convex geoms (multiccd), so that a plate
    flat on a wall is held over a patch, not at one point."""
    cone = "elliptic" if p.cone_friction else "pyramidal"
    tc = contact_timeconst(p)
    return (f'<option timestep="{p.time_step:.12g}" iterations="{p.solver_iterations}" solver="Newton" '
            f'cone="{cone}" impratio="{IMPRATIO:.12g}" integrator="implicitfast" gravity="0 0 -9.81">'
            f'<flag multiccd="enable" autoreset="disable"/></option>'
            f'<default><geom solref="{tc:.12g} {CONTACT_DAMPRATIO:.12g}"/></default>')


@lru_cache(maxsize=MODEL_CACHE)
def compiled(obj: tuple[str, str], gripper: str, options: str, table_friction: float) -> mujoco.MjModel:
    """The trial's model from its parts' MJCF, compiled once per process for each shape,
    gripper and protocol (a compile takes 4-10 ms; an experiment executes each posterior
    sample once per planner and the true shape in every truth trial). Never changed
    after compiling: every trial gets data (MjData) in the model's initial state
    (:class:`_Layout`)."""
    assets, body = obj
    xml = (f'<mujoco model="gpis-harness trial"><compiler angle="radian" inertiafromgeom="false"/>'
           f'{options}<asset>{assets}</asset><worldbody>'
           f'<geom name="table" type="plane" size="{TABLE_HALF} {TABLE_HALF} 0.1" contype="2" conaffinity="0" '
           f'condim="{TABLE_CONDIM}" priority="1" friction="{table_friction:.12g} 0 0" rgba="0.8 0.82 0.78 1"/>'
           f'{body}{gripper}</mujoco>')
    return mujoco.MjModel.from_xml_string(xml)


def _box_inertia(mass: float, half_size) -> tuple[float, float, float]:
    a, b, c = (2 * s for s in half_size)
    return mass * (b * b + c * c) / 12, mass * (a * a + c * c) / 12, mass * (a * a + b * b) / 12
