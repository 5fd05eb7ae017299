"""Extruded bodies against exact geometry: mass properties in closed form, convex
pieces that tile the polygon, pybullet's mass and centre of mass, resting height."""

from __future__ import annotations

import numpy as np
import pybullet as pb
import pytest
import shapely
import shapely.affinity
from shapely.geometry import box

from harness.belief import build_belief
from harness.canonical import canonical
from harness.geometry import Grid, inside_region, largest_region
from harness.physics.bodies import (convex_pieces, create_body, field_polygon, principal_frame, refined,
                                    prism_mass_properties)
from harness.physics.simulate import make_trials, truth_polygon
from harness.settings import resolve
from harness.physics.engines import make_runner
from harness.scene import load_scene
from harness.seeding import stream


@pytest.fixture
def client():
    c = pb.connect(pb.DIRECT)
    pb.setGravity(0, 0, -9.81, physicsClientId=c)
    yield c
    pb.disconnect(physicsClientId=c)


def _body_mass_and_com(client, body) -> tuple[float, np.ndarray]:
    """Total mass and centre of mass of a multibody, read back from pybullet."""
    total, moment = 0.0, np.zeros(3)
    for link in range(-1, pb.getNumJoints(body, physicsClientId=client)):
        m = pb.getDynamicsInfo(body, link, physicsClientId=client)[0]
        pos = (pb.getBasePositionAndOrientation(body, physicsClientId=client)[0] if link < 0
               else pb.getLinkState(body, link, physicsClientId=client)[0])
        total += m
        moment += m * np.asarray(pos)
    return total, moment / total



def test_prism_mass_properties_match_the_box_closed_form():
    a, b, t, rho = 0.06, 0.03, 0.02, 700.0
    props = prism_mass_properties(box(0.01, -0.02, 0.01 + a, -0.02 + b), t, rho)
    m = rho * a * b * t
    assert props.mass == pytest.approx(m, rel=1e-12)
    np.testing.assert_allclose(props.com, [0.01 + a / 2, -0.02 + b / 2, t / 2], atol=1e-15)
    np.testing.assert_allclose(np.diag(props.inertia), [m * (b * b + t * t) / 12, m * (a * a + t * t) / 12,
                                                        m * (a * a + b * b) / 12], rtol=1e-10)
    assert abs(props.inertia[0, 1]) < 1e-15 * m


def test_prism_mass_properties_of_a_turned_frame_with_a_hole_match_the_closed_form():
    """A 6 x 4 cm frame (a 4 x 2 cm hole in its middle, the outer box less the inner)
    turned 30 degrees about a point off its centre: the mass and the centre of mass are
    the frame's, and the in-plane inertia is R diag(I_xx, I_yy) R^T, with its product of
    inertia, while I_zz keeps the sum of the two."""
    t, rho, angle = 0.02, 700.0, np.radians(30.0)
    outer, inner = (0.06, 0.04), (0.04, 0.02)
    hole = box(-0.02, -0.01, 0.02, 0.01).exterior.coords
    frame = shapely.Polygon(box(-0.03, -0.02, 0.03, 0.02).exterior.coords, [hole])
    turned = shapely.affinity.translate(shapely.affinity.rotate(frame, angle, origin=(0.0, 0.0), use_radians=True),
                                        0.01, -0.005)
    props = prism_mass_properties(turned, t, rho)
    masses = [rho * a * b * t for a, b in (outer, inner)]
    m = masses[0] - masses[1]
    assert props.mass == pytest.approx(m, rel=1e-12)
    np.testing.assert_allclose(props.com, [0.01, -0.005, t / 2], atol=1e-15)
    # About the centre in the frame's own axes: the outer box's less the hole's.
    parts = ((1, masses[0], outer), (-1, masses[1], inner))
    ixx, iyy = (sum(sign * mk * dims[k] ** 2 / 12 for sign, mk, dims in parts) for k in (1, 0))
    r = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    in_plane = r @ np.diag([ixx, iyy]) @ r.T
    z2 = m * t * t / 12
    np.testing.assert_allclose(props.inertia[:2, :2], in_plane + z2 * np.eye(2), rtol=1e-10, atol=1e-16)
    assert abs(in_plane[0, 1]) > 0.1 * ixx  # the turn gives a product of inertia to check
    assert props.inertia[2, 2] == pytest.approx(ixx + iyy, rel=1e-10)


def _rotation(q) -> np.ndarray:
    return np.array(pb.getMatrixFromQuaternion(q)).reshape(3, 3)


@pytest.mark.parametrize("name", ["tape", "stapler", "plane", "marker", "disk", "rectangle"])
def test_the_closed_form_principal_frame_diagonalises_the_inertia(name):
    props = prism_mass_properties(truth_polygon(load_scene(name)), 0.03, 700.0)
    moments, quaternion = principal_frame(props.inertia)
    r = _rotation(quaternion)
    assert np.linalg.norm(quaternion) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(r @ np.diag(moments) @ r.T, props.inertia, rtol=0, atol=1e-12 * max(moments))
    np.testing.assert_allclose(sorted(moments), np.linalg.eigvalsh(props.inertia), rtol=1e-12)


@pytest.mark.parametrize("inertia", [np.diag([2.0, 1.0, 3.0]), np.diag([1.0, 2.0, 3.0]), np.diag([1.0, 1.0, 2.0]),
                                     np.array([[1.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 2.0]])])
def test_the_principal_frame_of_special_tensors(inertia):
    # Axis-aligned either way round, a round outline's equal moments, 45 degrees.
    moments, quaternion = principal_frame(inertia)
    r = _rotation(quaternion)
    np.testing.assert_allclose(r @ np.diag(moments) @ r.T, inertia, atol=1e-15)


def test_outlines_for_the_physics_are_canonical():
    scene = load_scene("marker")
    belief = build_belief(scene, stream(0, "marker", 0, "sensor"))
    polygons = [truth_polygon(scene)] + [field_polygon(f, scene.grid)
                                         for f in belief.sample(5, stream(0, "test-physics")).values]
    for polygon in polygons:
        xy = shapely.get_coordinates(polygon)
        assert len(xy) > 4 and polygon.is_valid
        np.testing.assert_array_equal(xy, canonical(xy))


@pytest.mark.parametrize("name", ["tape", "stapler", "can_opener", "plane"])
def test_convex_pieces_are_convex_and_tile_the_polygon(name):
    polygon = truth_polygon(load_scene(name))
    pieces = convex_pieces(polygon)
    assert len(pieces) >= 2  # these shapes are concave
    for piece in pieces:
        assert piece.area >= piece.convex_hull.area * (1 - 1e-9)
    union = shapely.union_all(pieces)
    assert abs(sum(p.area for p in pieces) - union.area) < 1e-9 * polygon.area  # no overlaps
    assert union.symmetric_difference(polygon).area < 1e-6 * polygon.area     # and no gaps


@pytest.mark.parametrize("name", ["tape", "stapler", "rectangle"])
def test_body_mass_and_centre_of_mass_match_the_polygon(client, name):
    scene = load_scene(name)
    polygon = truth_polygon(scene)
    t, rho = scene.physics.thickness, scene.physics.density
    body = create_body(client, polygon, t, rho, 0.5, origin=(0.3, -0.2))
    mass, com = _body_mass_and_com(client, body.body_id)
    assert mass == pytest.approx(rho * polygon.area * t, rel=0.01)
    size = np.sqrt(polygon.area)
    expected = np.array([polygon.centroid.x + 0.3, polygon.centroid.y - 0.2, t / 2])
    assert np.linalg.norm(com - expected) < 0.01 * size
    # and the simplified polygon keeps the true shape's area within 1 %
    assert polygon.area == pytest.approx(scene.shape.area, rel=0.01)


def test_a_posterior_sample_body_has_the_samples_inside_area(client):
    scene = load_scene("tape")
    belief = build_belief(scene, stream(0, "tape", 0, "sensor"))
    field = belief.sample(1, stream(0, "test-physics")).values[0]
    polygon = field_polygon(field, scene.grid)
    region = largest_region(inside_region(*refined(field, scene.grid, 2)))
    assert polygon.area == pytest.approx(region.area, rel=0.01)
    # on the belief's own cells (linear along each cell side) within 2 %
    assert polygon.area == pytest.approx(largest_region(inside_region(field, scene.grid)).area, rel=0.02)
    # a second formulation of the inside area: count the cells whose centre is inside
    cells = (field < 0).sum() * scene.grid.cell ** 2
    assert polygon.area == pytest.approx(cells, rel=0.05)
    body = create_body(client, polygon, scene.physics.thickness, scene.physics.density, 0.5)
    mass, _ = _body_mass_and_com(client, body.body_id)
    assert mass == pytest.approx(scene.physics.density * scene.physics.thickness * polygon.area, rel=0.01)


def test_the_refined_field_is_the_cubic_spline_through_the_nodes():
    """A bicubic polynomial lies in the spline's space, so the refined field is that
    polynomial at every fine node (beyond the outermost coarse nodes too) to rounding."""
    grid = Grid(20, 0.2)
    cubic = lambda x, y: 0.3 * x ** 3 - 2 * x * y ** 2 + 0.5 * y ** 3 + x * y - 0.2 * y + 0.01  # noqa: E731
    fine_field, fine = refined(cubic(*np.meshgrid(grid.coords, grid.coords)), grid, 3)
    assert (fine.size, fine.extent) == (60, 0.2)
    np.testing.assert_allclose(fine_field, cubic(*np.meshgrid(fine.coords, fine.coords)), rtol=0, atol=1e-14)


def _box_sdf(x, y, a, b):
    qx, qy = np.abs(x) - a, np.abs(y) - b
    return np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0)


def test_refined_cells_cut_a_box_s_corners_less():
    """The exact signed distance of a 5 x 4 cm box on 5 mm cells: marching squares on
    the cells themselves cuts the corners (the outline's greatest distance from the box,
    at a corner, 1.77 mm); on cells twice as fine (the protocol's refinement) 1.20 mm,
    four times 0.77 mm. The area stays within 1 % of the box's either way."""
    grid = Grid(40, 0.2)
    field = _box_sdf(*np.meshgrid(grid.coords, grid.coords), 0.025, 0.02)
    exact = box(-0.025, -0.02, 0.025, 0.02)
    cut = {k: field_polygon(field, grid, k).hausdorff_distance(exact) for k in (1, 2, 4)}
    assert cut[1] == pytest.approx(1.77e-3, abs=0.05e-3)
    assert cut[2] < 0.75 * cut[1] and cut[4] < 0.5 * cut[1]
    for k in (1, 2, 4):
        assert field_polygon(field, grid, k).area == pytest.approx(exact.area, rel=0.01)


def test_an_empty_sample_gives_an_empty_polygon_and_the_outcome_empty_shape():
    scene = load_scene("rectangle")
    empty = field_polygon(np.full((scene.grid.size, scene.grid.size), 0.01), scene.grid)
    assert empty.is_empty
    trial = make_trials(resolve(scene), [[-0.045, 0], [0.045, 0]], [empty], np.zeros((1, 2, 2)))
    assert make_runner().run(trial)[0].outcome == "empty_shape"


def test_the_body_rests_on_the_table_at_its_true_height(client):
    plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
    pb.createMultiBody(0, plane, physicsClientId=client)
    body = create_body(client, box(-0.03, -0.015, 0.03, 0.015), 0.03, 400.0, 0.5)
    for _ in range(120):
        pb.stepSimulation(physicsClientId=client)
    z = pb.getBasePositionAndOrientation(body.body_id, physicsClientId=client)[0][2]
    assert z == pytest.approx(0.015, abs=2e-4)  # Bullet's collision margin is compensated


def test_a_concave_body_rests_at_its_true_height_with_true_faces(client):
    """The compound's pieces (three for this U) are shrunk by the margin Bullet adds back:
    the prism rests with its centre of mass at half its thickness, and a probe finds the
    outer face and the notch's floor where the polygon has them."""
    plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
    pb.createMultiBody(0, plane, physicsClientId=client)
    u_shape = box(-0.06, -0.03, 0.06, 0.03).difference(box(-0.02, -0.01, 0.02, 0.04))
    body = create_body(client, u_shape, 0.03, 800.0, 0.5)
    assert len(body.pieces) >= 3
    for _ in range(240):
        pb.stepSimulation(physicsClientId=client)
    z = pb.getBasePositionAndOrientation(body.body_id, physicsClientId=client)[0][2]
    assert z == pytest.approx(0.015, abs=2e-4)
    sphere = pb.createCollisionShape(pb.GEOM_SPHERE, radius=0.001, physicsClientId=client)
    for where, gap in (((0.07, 0.0), 0.009), ((0.0, 0.01), 0.019)):  # beside the face x = 0.06; in the notch
        probe = pb.createMultiBody(0, sphere, basePosition=[*where, 0.015], physicsClientId=client)
        near = min(p[8] for p in pb.getClosestPoints(body.body_id, probe, 0.05, physicsClientId=client))
        assert near == pytest.approx(gap, abs=2e-4), where


def test_cutting_a_convex_shape_into_pieces_changes_nothing_physical(monkeypatch):
    """Convex bars (an ellipse, a box, a rounded box) held at several offsets and angles
    behave the same whether each body is one convex piece or four: the pieces form one
    rigid body. With one fixed link per piece (the first design) 56 of these 63 trials
    agreed (0.89, five fewer successes); the compound agrees on 61 (0.97, the level of
    chaos near the slip threshold)."""
    from harness.physics import bodies
    from harness.physics.gripper import GripperSpec
    from harness.physics.trial import Trial

    gripper = GripperSpec(opening=0.1, jaw_width=0.01, plate_height=0.01, force=20.0, closing_speed=0.05,
                          object_thickness=0.03).adapter()
    bars = [shapely.affinity.scale(shapely.geometry.Point(0, 0).buffer(1.0, 64), 0.075, 0.02).simplify(0.0005),
            box(-0.075, -0.015, 0.075, 0.015), box(-0.07, -0.02, 0.07, 0.02).buffer(0.008).simplify(0.0005)]
    trials = []
    for bar in bars:
        for d in np.linspace(0.0, 0.06, 7):
            for angle in (-0.3, 0.0, 0.3):
                u = np.array([np.sin(angle), np.cos(angle)])
                c = np.array([d, 0.0])
                trials.append(Trial(bar, tuple(c - 0.045 * u), tuple(c + 0.045 * u), tuple(u), 0.03, 800.0, 0.5,
                                    gripper))
    with make_runner() as runner:
        whole = [r.outcome for r in runner.run(trials)]

    def quarters(polygon):
        xs = np.linspace(-0.09, 0.09, 5)
        return [shapely.geometry.polygon.orient(polygon.intersection(box(a, -1, b, 1)), 1.0)
                for a, b in zip(xs[:-1], xs[1:])]

    monkeypatch.setattr(bodies, "convex_pieces", quarters)
    with make_runner() as runner:
        cut = [r.outcome for r in runner.run(trials)]
    agreement = np.mean([a == b for a, b in zip(whole, cut)])
    assert agreement >= 0.93, (whole, cut)
    assert abs(whole.count("success") - cut.count("success")) <= 2


def test_a_rebuilt_shape_gives_the_same_body_and_a_swapped_decomposition_is_honoured(client, monkeypatch):
    """Bodies are built from a per-process recipe cached by the exact polygon: the second
    body of a shape has the first's pieces and mass; a different decomposition function
    (as the cut-bar test swaps in) gets its own recipe, never the cached one."""
    from harness.physics import bodies

    bar = box(-0.06, -0.015, 0.06, 0.015)
    first = create_body(client, bar, 0.03, 400.0, 0.5)
    again = create_body(client, shapely.Polygon(bar.exterior.coords), 0.03, 400.0, 0.5, origin=(1.0, 0.0))
    assert again.pieces == first.pieces and len(first.pieces) == 1
    assert _body_mass_and_com(client, again.body_id)[0] == _body_mass_and_com(client, first.body_id)[0]
    assert again.body_id != first.body_id

    def halves(polygon):
        return [polygon.intersection(box(-1, -1, 0, 1)), polygon.intersection(box(0, -1, 1, 1))]

    monkeypatch.setattr(bodies, "convex_pieces", halves)
    cut = create_body(client, bar, 0.03, 400.0, 0.5, origin=(2.0, 0.0))
    assert len(cut.pieces) == 2
    assert sum(p.area for p in cut.pieces) == pytest.approx(bar.area, rel=1e-12)
    mass, com = _body_mass_and_com(client, cut.body_id)
    assert mass == pytest.approx(400.0 * 0.03 * bar.area, rel=1e-9)
    assert com == pytest.approx([2.0, 0.0, 0.015], abs=1e-9)


def test_a_foot_carries_the_weight_on_the_hull_corners_at_the_true_height(client):
    """With a foot, the U of the test above rests on its convex hull's slab alone: at the
    same height, with the same mass and centre of mass (the foot is massless), on at most
    4 contact points, each at a corner of the hull (the outer corners of the U, less the
    1 mm margin), and those points carry the whole weight."""
    plane_shape = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client)
    plane = pb.createMultiBody(0, plane_shape, physicsClientId=client)
    u_shape = box(-0.06, -0.03, 0.06, 0.03).difference(box(-0.02, -0.01, 0.02, 0.04))
    body = create_body(client, u_shape, 0.03, 800.0, 0.5, foot=True)
    assert body.foot == 0 and pb.getNumJoints(body.body_id, physicsClientId=client) == 1
    pb.setCollisionFilterPair(body.body_id, plane, -1, -1, 0, physicsClientId=client)
    mass, com = _body_mass_and_com(client, body.body_id)
    assert mass == pytest.approx(800.0 * 0.03 * u_shape.area, rel=1e-9)
    assert com[:2] == pytest.approx([u_shape.centroid.x, u_shape.centroid.y], abs=1e-9)
    for _ in range(240):
        pb.stepSimulation(physicsClientId=client)
    z = pb.getBasePositionAndOrientation(body.body_id, physicsClientId=client)[0][2]
    assert z == pytest.approx(0.015, abs=2e-4)
    points = pb.getContactPoints(body.body_id, plane, physicsClientId=client)
    assert 3 <= len(points) <= 4 and {p[3] for p in points} == {0}
    corners = np.array([(x, y) for x in (-0.059, 0.059) for y in (-0.029, 0.029)])
    for p in points:
        assert np.min(np.hypot(*(corners - np.asarray(p[5][:2])).T)) < 5e-4, p[5]
    assert sum(p[9] for p in points) == pytest.approx(mass * 9.81, rel=0.02)


def test_the_jaws_pass_through_the_foot_and_grip_the_prism():
    """A jaw that starts in the U's notch (inside the hull, outside the polygon) closes on
    the arm as if the foot were not there: the grip width is the arm's 4 cm with the foot
    and without it, and both grips hold."""
    from harness.physics.gripper import GripperSpec
    from harness.physics.trial import Trial
    from harness.protocol import Protocol

    gripper = GripperSpec(opening=0.1, jaw_width=0.01, plate_height=0.01, force=20.0, closing_speed=0.05,
                          object_thickness=0.03).adapter()
    u_shape = box(-0.06, -0.03, 0.06, 0.03).difference(box(-0.02, -0.01, 0.02, 0.04))
    trial = Trial(u_shape, (0.0, 0.015), (0.085, 0.015), (1.0, 0.0), 0.03, 400.0, 0.5, gripper)
    widths, outcomes = [], []
    for foot in (False, True):
        with make_runner(Protocol(table_hull=foot)) as runner:
            result = runner.run([trial])[0]
        widths.append(result.grip_width)
        outcomes.append(result.outcome)
    assert widths == pytest.approx([0.04, 0.04], abs=1e-3)
    assert outcomes == ["success", "success"]
