"""The parametric parallel-jaw gripper: its URDF, and the adapter that any parallel-jaw
URDF (two prismatic finger joints closing along one axis) plugs into.

Frame of the gripper (the palm link): origin midway between the jaws at the height of
the jaw plates' top edge, x the closing axis (from jaw 1 towards jaw 2), z up. Each
jaw is a plate ``PLATE_THICKNESS`` thick along x, ``jaw_width`` wide along y, reaching
from the palm down to ``TABLE_CLEARANCE`` above the table. A finger joint's position is
how far its jaw has travelled inwards from fully open: 0 leaves the plate's inner face
at x = -opening/2 (jaw 1) or +opening/2 (jaw 2), ``opening / 2`` brings it to x = 0.
"""

from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

from harness.settings import GraspSettings

#: Thickness of each jaw plate along the closing axis (m).
PLATE_THICKNESS = 0.005
#: Gap between the jaw plates' lower edge and the table (m).
TABLE_CLEARANCE = 0.001
#: The palm: a box this thick (m) above the plates, spanning the open jaws.
PALM_THICKNESS = 0.02
#: Masses (kg); the floating base is held by a constraint, so they only set the inertia
#: the constraint and the finger motors work against.
PALM_MASS = 0.3
PLATE_MASS = 0.05


@dataclass(frozen=True)
class GripperSpec:
    """The parameters of the built-in gripper for one object thickness (metres, N, m/s)."""

    opening: float
    jaw_width: float
    plate_height: float
    force: float
    closing_speed: float
    object_thickness: float

    @classmethod
    def from_settings(cls, settings: GraspSettings) -> "GripperSpec":
        s = settings
        return cls(s.opening, s.jaw_width, s.plate_height, s.force, s.closing_speed, s.thickness)

    @property
    def top(self) -> float:
        """Height of the palm frame (the plates' top edge) when the plates touch down."""
        return self.object_thickness + self.plate_height

    @property
    def plate_length(self) -> float:
        """Vertical extent of a jaw plate."""
        return self.top - TABLE_CLEARANCE

    def urdf(self) -> str:
        """The gripper as URDF text."""
        half, t, w, length = self.opening / 2, PLATE_THICKNESS, self.jaw_width, self.plate_length
        palm = (self.opening + 2 * t, max(w, 0.02), PALM_THICKNESS)
        plate = (t, w, length)
        jaws = []
        for name, sign in (("jaw_1", -1), ("jaw_2", 1)):
            centre = (sign * (half + t / 2), 0.0, -length / 2)
            jaws.append(f"""
  <link name="{name}">
{_inertial(PLATE_MASS, plate, centre)}
{_box("visual", plate, centre, '<material name="steel"><color rgba="0.55 0.57 0.6 1"/></material>')}
{_box("collision", plate, centre)}
  </link>
  <joint name="{name}_joint" type="prismatic">
    <parent link="palm"/><child link="{name}"/>
    <origin xyz="0 0 0"/><axis xyz="{-sign} 0 0"/>
    <limit lower="0" upper="{half:.9g}" effort="{self.force:.9g}" velocity="{self.closing_speed:.9g}"/>
  </joint>""")
        palm_centre = (0.0, 0.0, PALM_THICKNESS / 2)
        return f"""<?xml version="1.0"?>
<!-- gpis-harness parallel-jaw gripper: opening {self.opening:.6g} m, jaw width {w:.6g} m,
     plate length {length:.6g} m. Written by harness/physics/gripper.py. -->
<robot name="parallel_jaw">
  <link name="palm">
{_inertial(PALM_MASS, palm, (0.0, 0.0, 0.0))}
{_box("visual", palm, palm_centre, '<material name="dark"><color rgba="0.25 0.25 0.28 1"/></material>')}
{_box("collision", palm, palm_centre)}
  </link>{"".join(jaws)}
</robot>
"""

    def urdf_path(self) -> Path:
        """The URDF written once per parameter set to the temporary directory (pybullet
        loads URDF from files only); the name is a hash of the text, so concurrent
        processes agree on it and never see a half-written file."""
        text = self.urdf()
        digest = hashlib.sha256(text.encode()).hexdigest()[:16]
        path = Path(tempfile.gettempdir()) / f"gpis-harness-gripper-{digest}.urdf"
        if not path.exists():
            part = path.with_suffix(f".{digest}.part")
            part.write_text(text)
            part.replace(path)
        return path

    def adapter(self) -> "GripperAdapter":
        half = self.opening / 2
        return GripperAdapter(urdf=str(self.urdf_path()), finger_joints=(0, 1), jaw_links=(0, 1),
                              closing_axis=(1.0, 0.0), face_at_zero=(-half, half), face_per_unit=(1.0, -1.0),
                              depth=self.plate_length, pad_width=self.jaw_width, pad_thickness=PLATE_THICKNESS,
                              force=self.force, closing_speed=self.closing_speed)


@dataclass(frozen=True)
class GripperAdapter:
    """What a trial needs to know about a parallel-jaw URDF; any gripper with two
    prismatic finger joints plugs in by filling this record.

    All vectors are in the URDF's base frame, whose z axis must point up:

    - ``finger_joints``: the joint indices of jaw 1 and jaw 2;
    - ``jaw_links``: the link indices whose contact with the object counts as holding it;
    - ``closing_axis``: (x, y) unit vector from jaw 1 towards jaw 2;
    - ``face_at_zero`` and ``face_per_unit``: where each jaw's inner face lies along the
      closing axis (metres from the base origin) as ``face_at_zero + face_per_unit * q``
      for joint position q; jaw 1 closes as its face coordinate grows, jaw 2 as it shrinks;
    - ``depth``: how far below the base origin the jaws' lower edges reach;
    - ``pad_width``, ``pad_thickness``: the jaw pads' extent across and along the closing
      axis (for the approach-collision check);
    - ``force``, ``closing_speed``: each finger motor's force limit (N) and speed limit (m/s).

    The closing target of each joint is its limit in the closing direction, read from
    the URDF.
    """

    urdf: str
    finger_joints: tuple[int, int]
    jaw_links: tuple[int, int]
    closing_axis: tuple[float, float]
    face_at_zero: tuple[float, float]
    face_per_unit: tuple[float, float]
    depth: float
    pad_width: float
    pad_thickness: float
    force: float
    closing_speed: float

    def joint_position(self, jaw: int, face: float) -> float:
        """The joint position that puts the jaw's inner face at ``face`` along the axis."""
        return (face - self.face_at_zero[jaw]) / self.face_per_unit[jaw]


def _box(kind: str, size, centre, extra: str = "") -> str:
    return (f'    <{kind}><origin xyz="{centre[0]:.9g} {centre[1]:.9g} {centre[2]:.9g}"/>'
            f'<geometry><box size="{size[0]:.9g} {size[1]:.9g} {size[2]:.9g}"/></geometry>{extra}</{kind}>')


def _inertial(mass: float, size, centre) -> str:
    a, b, c = size
    ixx, iyy, izz = (mass * (b * b + c * c) / 12, mass * (a * a + c * c) / 12, mass * (a * a + b * b) / 12)
    return (f'    <inertial><origin xyz="{centre[0]:.9g} {centre[1]:.9g} {centre[2]:.9g}"/><mass value="{mass:.9g}"/>'
            f'<inertia ixx="{ixx:.9g}" iyy="{iyy:.9g}" izz="{izz:.9g}" ixy="0" ixz="0" iyz="0"/></inertial>')
