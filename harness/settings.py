"""A grasp's settings: everything the analytic quality, the planners and the physics must
agree on (approach noise, friction and its spread, the gripper, the object's extrusion
and the lift), resolved once from a scene, the overrides of an experiment or the command
line, and the physics protocol."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

#: Standard gravity (m/s^2), as in the physics.
GRAVITY = 9.81
#: Peak acceleration of a minimum-jerk rise of height H in time T is this times H / T^2
#: (10 / sqrt(3), at a fifth of the way through the lift).
MINIMUM_JERK_PEAK = 10.0 / math.sqrt(3.0)

#: The settings a scene, an experiment or the command line may set, with their ranges:
#: (low, high, low end open). The scene parser and the config parser both check these.
BOUNDS = {
    "opening": (0.0, 10.0, True),
    "jaw_width": (0.0, 10.0, True),
    "sigma_g": (0.0, 1.0, False),
    "force": (0.0, 1e4, True),
    "closing_speed": (0.001, 10.0, False),  # from 1 mm/s: the closing's steps stay countable
    "plate_height": (0.0, 1.0, True),
    "thickness": (0.0, 1.0, True),
    "density": (1.0, 30000.0, False),
    "friction": (0.0, 10.0, False),
    "friction_spread": (0.0, 10.0, False),
    "load_factor": (1.0, 10.0, False),
}
#: Where a scene keeps each setting (table, key); the others are not part of a scene.
SCENE_FIELDS = {"opening": "gripper", "jaw_width": "gripper", "sigma_g": "gripper", "force": "gripper",
                "closing_speed": "gripper", "plate_height": "gripper", "thickness": "physics",
                "density": "physics", "friction": "physics"}


@dataclass(frozen=True)
class GraspSettings:
    """How a grasp is executed and what it holds (SI units).

    opening, jaw_width: the gripper's largest jaw separation and each plate's width across
    the line of action; sigma_g: approach noise (std of each jaw start's placement);
    friction, friction_spread: the jaw-object Coulomb coefficient and its std across
    draws; force: each jaw's force limit, the grip force once the jaws stall;
    closing_speed: each jaw's speed limit; plate_height: how far the plates reach above
    the object's top; thickness, density: the object's extrusion and density;
    lift_height: how high the protocol lifts; load_factor: the largest vertical load
    while lifting, in units of the weight (1 + the lift's peak acceleration / g).
    """

    opening: float
    jaw_width: float
    sigma_g: float
    friction: float
    friction_spread: float
    force: float
    closing_speed: float
    plate_height: float
    thickness: float
    density: float
    lift_height: float
    load_factor: float

    def frictions(self, deviates) -> np.ndarray:
        """Friction per draw from standard-normal deviates: max(0, friction + spread * deviate).
        The analytic quality and the physics trials both take theirs from here."""
        return np.maximum(0.0, self.friction + self.friction_spread * np.asarray(deviates, dtype=float))


def override_problem(name: str, value) -> str | None:
    """Why ``value`` cannot override setting ``name``, or None."""
    if name not in BOUNDS:
        return f"unknown setting (settings: {', '.join(BOUNDS)})"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return f"expected a finite number, got {value!r}"
    lo, hi, lo_open = BOUNDS[name]
    if (value <= lo if lo_open else value < lo) or value > hi:
        return f"{value:g} is out of range {'(' if lo_open else '['}{lo:g}, {hi:g}]"
    return None


def peak_load_factor(lift_height: float, lift_time: float) -> float:
    """1 + the peak acceleration of a minimum-jerk lift of ``lift_height`` in ``lift_time``, over g."""
    return 1.0 + MINIMUM_JERK_PEAK * lift_height / lift_time**2 / GRAVITY


def resolve(scene, overrides: Mapping[str, float] | None = None, protocol=None) -> GraspSettings:
    """The settings of ``scene`` with ``overrides`` (setting -> value, each checked against
    BOUNDS) and the lift of ``protocol`` (the default trial protocol when None). A load
    factor in the overrides replaces the protocol's (1 makes the lift model static)."""
    if protocol is None:
        from harness.protocol import Protocol

        protocol = Protocol()
    values = {name: float(getattr(getattr(scene, table), name)) for name, table in SCENE_FIELDS.items()}
    values["friction_spread"] = 0.0
    values["lift_height"] = float(protocol.lift_height)
    values["load_factor"] = peak_load_factor(protocol.lift_height, protocol.lift_time)
    for name, value in (overrides or {}).items():
        problem = override_problem(name, value)
        if problem:
            raise ValueError(f"setting {name}: {problem}")
        values[name] = float(value)
    return GraspSettings(**values)
