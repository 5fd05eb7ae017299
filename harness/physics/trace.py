"""A trial traced check by check: how the object moves in the jaws and what carries it.

``simulate --trace FILE`` records the first trial of the run, in either engine, at the
end of closing and at every contact check of the lift, hold and shake (every
``check_interval``, 1/60 s): the phase and its step, the turn in the gripper and the rise
the trial's result reports, how far the gripper itself has risen since the jaws stalled
(it follows the protocol's path a few milliseconds behind), how far the object has moved
in the jaws, and each jaw's contact points (how many, the normal force they carry and
where their pressure centre lies). Tracing only reads the engine's state: a traced trial's result is the same, bit
for bit, as untraced (tested).

The slide is that of the *grip point*, the object point midway between the two jaws'
pressure centres when the jaws stalled, in the gripper's frame: ``across`` along the
closing axis, ``along`` the plates in the horizontal, ``up`` the vertical. An object
held rigidly keeps it at 0; one that turns about the grasp axis through the grip point
too; one that turns about another point, or slides down the plates, moves it (docs/lift.md,
"What MuJoCo's contacts do on a turning sample"). Without a contact point on each jaw when
they stalled there is no grip point, and the slides are NaN. A jaw's pressure centre is given
relative to the grip point in the same frame (its ``along`` and ``up``); it jumps when
the engine's contact points move between the ends of a line contact.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

#: The columns of a trace, in order.
COLUMNS = ("phase", "step", "time", "pivot", "rise", "gripper_rise", "slide_across", "slide_along", "slide_up",
           "on_table", "jaws_near", "jaw1_points", "jaw1_force", "jaw1_along", "jaw1_up",
           "jaw2_points", "jaw2_force", "jaw2_along", "jaw2_up")


class Tracer:
    """Rows of one trial's trace (:data:`COLUMNS`), recorded by the engine-neutral
    :class:`~harness.physics.trial.TrialMachine` from its engine's :meth:`poses` and
    :meth:`jaw_contacts`."""

    def __init__(self) -> None:
        self.rows: list[dict] = []
        self._grip_point = None   # (in the object's frame, in the gripper's frame)
        self._gripper_z = None    # the gripper frame's height when the jaws stalled

    def record(self, machine) -> None:
        grip_position, grip_rotation, obj_position, obj_rotation = machine.poses()
        contacts = machine.jaw_contacts()
        g = machine.trial.gripper
        cx, cy = g.closing_axis
        norm = math.hypot(cx, cy)
        axes = np.array([[cx / norm, cy / norm, 0.0], [-cy / norm, cx / norm, 0.0], [0.0, 0.0, 1.0]])

        def in_gripper(point):  # world point -> (across, along, up) in the gripper's frame
            return axes @ (grip_rotation.T @ (np.asarray(point, dtype=float) - grip_position))

        if self._gripper_z is None:
            self._gripper_z = float(grip_position[2])
        if self._grip_point is None:
            centres = [c for _, _, c in contacts if c is not None]
            if len(centres) == 2:
                point = 0.5 * (np.asarray(centres[0]) + np.asarray(centres[1]))
                self._grip_point = (obj_rotation.T @ (point - obj_position), in_gripper(point))
            else:
                self._grip_point = False
        if self._grip_point:
            in_object, start = self._grip_point
            grip = in_gripper(obj_position + obj_rotation @ in_object)
            slide = grip - start
        else:
            grip, slide = None, np.full(3, math.nan)
        row = {"phase": machine.phase, "step": machine.steps, "time": machine.steps * machine.protocol.time_step,
               "pivot": machine._pivot(), "rise": machine._rise(),
               "gripper_rise": float(grip_position[2]) - self._gripper_z, "slide_across": float(slide[0]),
               "slide_along": float(slide[1]), "slide_up": float(slide[2]), "on_table": bool(machine.on_table()),
               "jaws_near": machine.near_jaws(machine.protocol.held_distance)}
        for k, (points, force, centre) in enumerate(contacts, start=1):
            if centre is not None and grip is not None:
                where = in_gripper(centre) - grip
                along, up = float(where[1]), float(where[2])
            else:
                along = up = math.nan
            row |= {f"jaw{k}_points": int(points), f"jaw{k}_force": float(force), f"jaw{k}_along": along,
                    f"jaw{k}_up": up}
        self.rows.append(row)

    def write(self, path: Path) -> None:
        """The rows as CSV (SI units: s, rad, m, N)."""
        with open(path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=COLUMNS)
            writer.writeheader()
            writer.writerows(self.rows)


def pressure_centre(points, forces):
    """The normal-force-weighted centre (3,) of contact points (n, 3), or None without
    points; their plain mean when every force is zero."""
    if len(points) == 0:
        return None
    points, forces = np.asarray(points, dtype=float), np.asarray(forces, dtype=float)
    total = forces.sum()
    if total > 0:
        return (forces[:, None] * points).sum(axis=0) / total
    return points.mean(axis=0)
