"""The gripper's URDF against its adapter: jaw faces, pad size and depth where the
adapter says they are."""

from __future__ import annotations

import pybullet as pb
import pytest

from harness.physics.gripper import PLATE_THICKNESS, GripperSpec


@pytest.fixture
def client():
    c = pb.connect(pb.DIRECT)
    yield c
    pb.disconnect(physicsClientId=c)




def test_the_adapter_places_the_jaw_faces_where_the_urdf_puts_them(client):
    spec = GripperSpec(opening=0.1, jaw_width=0.012, plate_height=0.01, force=20.0, closing_speed=0.05,
                       object_thickness=0.03)
    adapter = spec.adapter()
    grip = pb.loadURDF(adapter.urdf, [0, 0, 0.5], physicsClientId=client)
    for q in (0.0, 0.013, 0.05):
        for jaw, joint in enumerate(adapter.finger_joints):
            pb.resetJointState(grip, joint, q, physicsClientId=client)
        lo1, hi1 = pb.getAABB(grip, adapter.jaw_links[0], physicsClientId=client)
        lo2, hi2 = pb.getAABB(grip, adapter.jaw_links[1], physicsClientId=client)
        assert hi1[0] == pytest.approx(adapter.face_at_zero[0] + adapter.face_per_unit[0] * q, abs=1e-6)
        assert lo2[0] == pytest.approx(adapter.face_at_zero[1] + adapter.face_per_unit[1] * q, abs=1e-6)
        assert hi1[1] - lo1[1] == pytest.approx(0.012, abs=1e-6)
        assert hi1[0] - lo1[0] == pytest.approx(PLATE_THICKNESS, abs=1e-6)
        assert 0.5 - lo1[2] == pytest.approx(adapter.depth, abs=1e-6)
