"""The plates' squeeze on an ellipse turned between parallel plates (against the closed
form of its width and a brute-force search of the turned grasps), and its place in P_L
(never in P_F)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import shapely
import shapely.affinity

from harness.geometry import Grid, grid_sdf, grid_sdf_gradient
from harness.grasp import SDFBatch, find_contacts, plate_closure
from harness.quality import FAILURE_REASONS, EvaluationDraws, evaluate_draws
from harness.scene import load_scene
from harness.settings import resolve
from harness.squeeze import SQUEEZE_LIMIT, SQUEEZE_STEP, squeeze

A, B = 0.030, 0.015  # semi-axes along x and y
JAW = 0.01
GRID = Grid(200, 0.1)  # 0.5 mm cells


@pytest.fixture(scope="module")
def ellipse() -> SDFBatch:
    t = np.linspace(0.0, 2 * math.pi, 2000, endpoint=False)
    shape = shapely.Polygon(np.column_stack([A * np.cos(t), B * np.sin(t)]))
    return SDFBatch(GRID, grid_sdf(shape, GRID)[None], grid_sdf_gradient(shape, GRID)[None])


def jaws(theta, half=0.045):
    """Jaw starts (1, 2) each, closing along u = (sin theta, cos theta) through the centre:
    theta from the minor axis."""
    u = np.array([math.sin(theta), math.cos(theta)])
    return (-half * u)[None], (half * u)[None]


def run(fields, theta, friction):
    g1, g2 = jaws(theta)
    contacts = find_contacts(fields, g1, g2, JAW)
    closed, _ = plate_closure(contacts, friction, np.zeros(2), 0.05)
    return contacts, closed, squeeze(fields, g1, g2, 0, contacts, closed, friction, JAW, 0.05, slide_limit=0.0)


def width(theta):
    """The ellipse's width along (sin theta, cos theta): 2 sqrt(A^2 s^2 + B^2 c^2)."""
    return 2 * math.hypot(A * math.sin(theta), B * math.cos(theta))


def test_an_ellipse_turns_towards_its_minor_axis_until_the_plates_are_in_force_closure(ellipse):
    """Off its minor axis the plates' pushes make a couple that turns the ellipse towards
    it, where its width is least (the squeeze; the centre of mass is the centre, so the
    grasp stays through it). The turn is the first whole step at which the turned grasp
    is in force closure, found here by judging every turned grasp on its own; the
    settled contacts lie the ellipse's closed-form width apart at theta0 - turn, and
    turning the other way would never have closed."""
    mu, theta0 = 0.2, math.radians(20.0)
    steps = np.arange(1, int(round(SQUEEZE_LIMIT / SQUEEZE_STEP)) + 1) * SQUEEZE_STEP
    for sense in (-1.0, 1.0):  # towards the minor axis, then away from it
        turned = [run(ellipse, theta0 + sense * a, mu)[1][0] for a in steps]
        if sense < 0:
            expected = steps[turned.index(True)]
        else:
            assert not any(turned)
    contacts, closed, out = run(ellipse, theta0, mu)
    assert not closed[0] and out.squeezed[0]
    assert out.turn[0] == pytest.approx(expected, abs=1e-9)
    assert 0 < expected < theta0
    theta = theta0 - out.turn[0]
    u = np.array([math.sin(theta), math.cos(theta)])
    assert float((out.c2[0] - out.c1[0]) @ u) == pytest.approx(width(theta), abs=2e-4)
    assert width(theta) < width(theta0)


def test_a_grasp_in_force_closure_is_not_squeezed(ellipse):
    contacts, closed, out = run(ellipse, math.radians(4.0), 0.2)
    assert closed[0] and not out.squeezed[0] and out.turn[0] == 0.0
    np.testing.assert_array_equal(out.c1, contacts.c1)
    np.testing.assert_array_equal(out.c2, contacts.c2)


def test_without_friction_the_squeeze_stops_at_the_widths_minimum(ellipse, monkeypatch):
    """With mu = 0 no two contacts are in force closure (strictly inside a cone of zero
    width). From 9 degrees off the minor axis the ellipse turns towards it, where its
    width is least and the couple vanishes; the fifth 2-degree step would carry it past
    (to -1 degree), where the couple reverses. So the squeeze gives up after at most five
    searches for the contacts (the limit would allow ten) and leaves the first contacts."""
    import harness.squeeze

    searches = []

    def counted(*args, **kwargs):
        searches.append(1)
        return find_contacts(*args, **kwargs)

    monkeypatch.setattr(harness.squeeze, "find_contacts", counted)
    contacts, closed, out = run(ellipse, math.radians(9.0), 0.0)
    assert not closed[0] and not out.squeezed[0] and out.turn[0] == 0.0
    np.testing.assert_array_equal(out.c1, contacts.c1)
    assert SQUEEZE_STEP == pytest.approx(math.radians(2.0)) and SQUEEZE_LIMIT == pytest.approx(math.radians(20.0))
    assert 1 <= len(searches) <= 5


def test_the_squeeze_counts_in_p_l_and_not_in_p_f(ellipse):
    """A light ellipse squeezed into closure is lifted (P_L = 1) though out of force
    closure at the first contacts (P_F = 0); without the lift nothing is squeezed."""
    n = 8
    draws = EvaluationDraws(SDFBatch(GRID, np.repeat(ellipse.values, n, axis=0),
                                     np.repeat(np.stack([ellipse.gx, ellipse.gy], axis=-1), n, axis=0)),
                            np.zeros((n, 2, 2)), np.zeros(n), np.full((n, 2), 0.5), 0.05)
    settings = replace(resolve(load_scene("disk"), {"sigma_g": 0.0, "friction": 0.2}), density=1.0)
    grasp = np.stack(jaws(math.radians(20.0)), axis=1)[0]
    out = evaluate_draws(grasp, draws, settings)
    est = out.estimates[0]
    assert est.p_f == 0.0 and est.p_l == 1.0 and est.squeezed == n
    assert (out.reason == -1).all() and sum(est.failures.values()) == 0
    only_p_f = evaluate_draws(grasp, draws, settings, lift=False)
    assert not only_p_f.squeezed.any()
    assert (only_p_f.reason == FAILURE_REASONS.index("friction_cone")).all()


def test_a_plate_pushes_at_its_patchs_centre_and_a_curved_wall_at_the_contact(ellipse):
    """On the rectangle's long face every plate line touches, and the push acts at the
    patch's centre: on the jaw's axis, on the face. On the ellipse 30 degrees off its
    minor axis one plate line touches (the wall falls away more than PATCH_DEPTH across
    the 2.5 mm to the next), and the push acts at the first contact."""
    from harness.squeeze import _pushes

    scene = load_scene("rectangle")
    truth = SDFBatch(scene.grid, scene.true_sdf[None], scene.true_sdf_gradient[None])
    contacts = find_contacts(truth, np.array([[0.01, -0.045]]), np.array([[0.01, 0.045]]), JAW)
    assert contacts.w1[0] == pytest.approx(JAW) and contacts.w2[0] == pytest.approx(JAW)
    p1, p2 = _pushes(contacts)
    np.testing.assert_allclose(p1[0], [0.01, -0.015], atol=1e-5)
    np.testing.assert_allclose(p2[0], [0.01, 0.015], atol=1e-5)
    g1, g2 = jaws(math.radians(30.0))
    curved = find_contacts(ellipse, g1, g2, JAW)
    q1, q2 = _pushes(curved)
    assert curved.w1[0] == 0 and curved.w2[0] == 0
    np.testing.assert_array_equal(q1, curved.c1)
    np.testing.assert_array_equal(q2, curved.c2)


# -- the slide -------------------------------------------------------------------------

R_OUT, R_IN = 0.040, 0.025  # the ring's radii


@pytest.fixture(scope="module")
def ring() -> SDFBatch:
    t = np.linspace(0.0, 2 * math.pi, 2000, endpoint=False)
    circle = np.column_stack([np.cos(t), np.sin(t)])
    shape = shapely.Polygon(R_OUT * circle, [R_IN * circle[::-1]])
    return SDFBatch(GRID, grid_sdf(shape, GRID)[None], grid_sdf_gradient(shape, GRID)[None])


def rim(offset):
    """Jaw starts (1, 2) each closing along +y on the ring's rim below its centre, one
    outside it and one in its hole, ``offset`` (m) to the right of the radial line."""
    return np.array([[offset, -0.048]]), np.array([[offset, -0.012]])


def closes(fields, g1, g2, friction):
    contacts = find_contacts(fields, g1, g2, JAW)
    return contacts, plate_closure(contacts, friction, np.zeros(2), 0.05)[0]


def test_the_walls_push_across_the_closing_line_by_the_tangents_of_their_leans():
    """Closed form: plates pushing along u on walls whose inward normals lean by a1 and a2
    towards u's left normal push the object across u by tan(a1) + tan(a2) per unit push;
    below the flush slope (PATCH_DEPTH over the plate's width) no push counts."""
    from types import SimpleNamespace

    from harness.squeeze import _across

    g1, g2 = np.array([[0.0, -0.04]] * 5), np.array([[0.0, 0.04]] * 5)  # u = +y, left normal -x
    leans = np.radians([[10.0, 10.0], [10.0, -25.0], [1.0, 1.0], [-30.0, 29.0], [-30.0, 20.0]])

    def inward(a, along):  # a unit vector leaning from ``along`` (+-y) by a towards -x
        return np.column_stack([-np.sin(a), along * np.cos(a)])

    contacts = SimpleNamespace(n1=-inward(leans[:, 0], 1.0), n2=-inward(leans[:, 1], -1.0))
    flush = 0.0005 / JAW
    expected = np.tan(leans[:, 0]) + np.tan(leans[:, 1])
    np.testing.assert_array_equal(_across(contacts, g1, g2, flush),
                                  np.where(np.abs(expected) >= flush, np.sign(expected), 0.0))
    assert list(_across(contacts, g1, g2, flush)) == [1.0, -1.0, 0.0, 0.0, -1.0]  # -30 and +29: tan sum -0.023, flush


def test_a_ring_gripped_on_its_rim_off_its_radial_line_slides_into_force_closure(ring):
    """One jaw in the ring's hole, one outside, 8 mm off the radial line: the outer plate
    meets the outer wall by its edge, the inner plate the hole's wall by its far edge,
    both walls leaning away from the radial line, out of force closure at mu = 0.2; a turn
    about the centre changes nothing on a ring. The walls push the ring sideways, the jaws
    move back towards its radial line in its frame, and the slide ends at the first
    SLIDE_STEP at which the shifted grasp is in force closure, found here by judging
    every shifted grasp on its own (the other way, none is within 8 mm)."""
    from harness.squeeze import SLIDE_STEP

    mu, offset = 0.2, 0.008
    g1, g2 = rim(offset)
    contacts, closed = closes(ring, g1, g2, mu)
    assert not closed[0] and contacts.edge1[0] and contacts.edge2[0]
    shifts = np.arange(1, int(round(offset / SLIDE_STEP)) + 1) * SLIDE_STEP
    towards = [closes(ring, *rim(offset - s), mu)[1][0] for s in shifts]
    away = [closes(ring, *rim(offset + s), mu)[1][0] for s in shifts]
    assert any(towards) and not any(away)
    expected = shifts[towards.index(True)]
    out = squeeze(ring, g1, g2, 0, contacts, closed, mu, JAW, 0.05, slide_limit=0.1)
    assert out.squeezed[0] and out.turn[0] == 0.0
    assert out.shift[0] == pytest.approx(expected, abs=1e-9)
    settled, _ = closes(ring, *rim(offset - expected), mu)
    np.testing.assert_allclose(out.c1[0], settled.c1[0], atol=1e-9)
    np.testing.assert_allclose(out.c2[0], settled.c2[0], atol=1e-9)
    without = squeeze(ring, g1, g2, 0, contacts, closed, mu, JAW, 0.05, slide_limit=0.0)  # the turn alone
    assert not without.squeezed[0]


def test_on_slippery_jaws_the_ring_slides_to_where_the_walls_pushes_cancel_and_is_held_there(ring):
    """At mu = 0.1 no grasp of the ring's rim within 8 mm of its radial line but on it is in
    force closure (the plate in the hole meets its wall by one edge, beyond the cone's 5.7
    degrees). The walls push the ring sideways until their pushes across the closing line
    change sign; there the plates' pushes balance and any shift brings a push back (the
    ring is held in the plane), found here by judging the walls' push at every shifted
    grasp on its own. The slide stops there, or where a shifted grasp is in force
    closure, whichever comes first, and the lift is judged at those contacts. On
    the radial line itself the plate in the hole presses the wall with both corners, whose
    normals lean 11.5 degrees either way (harness.grasp.plate_closure): in force closure,
    with nothing to squeeze."""
    from harness.squeeze import SLIDE_STEP, _across

    mu, offset = 0.1, 0.008
    flush = 0.0005 / JAW
    g1, g2 = rim(offset)
    contacts, closed = closes(ring, g1, g2, mu)
    assert not closed[0]
    shifts = np.arange(1, int(round(offset / SLIDE_STEP)) + 2) * SLIDE_STEP
    assert [closes(ring, *rim(offset - s), mu)[1][0] for s in shifts] == [abs(offset - s) < 1e-9 for s in shifts]
    start = _across(contacts, g1, g2, flush)[0]
    pushes = [_across(closes(ring, *rim(offset - s), mu)[0], *rim(offset - s), flush)[0] for s in shifts]
    held = [closes(ring, *rim(offset - s), mu)[1][0] for s in shifts]
    expected = shifts[next(k for k, (p, h) in enumerate(zip(pushes, held)) if p != start or h)]
    assert abs(expected - offset) <= SLIDE_STEP
    out = squeeze(ring, g1, g2, 0, contacts, closed, mu, JAW, 0.05, slide_limit=0.1)
    assert out.squeezed[0] and out.shift[0] == pytest.approx(expected, abs=1e-9)
    settled, _ = closes(ring, *rim(offset - expected), mu)
    np.testing.assert_allclose(out.c1[0], settled.c1[0], atol=1e-9)
    np.testing.assert_allclose(out.c2[0], settled.c2[0], atol=1e-9)
    on_line, closed = closes(ring, *rim(0.0), mu)  # both of the plate's corners on the hole's wall
    corners = on_line.normals2[0, [0, -1]]
    lean = np.degrees(np.arctan2(np.abs(corners[:, 0]), np.abs(corners[:, 1])))
    np.testing.assert_allclose(lean, math.degrees(math.asin(0.005 / R_IN)), atol=1.0)
    stays = squeeze(ring, *rim(0.0), 0, on_line, closed, mu, JAW, 0.05, slide_limit=0.1)
    assert closed[0] and not stays.squeezed[0]


def test_the_plates_hold_a_draw_where_neither_a_couple_nor_a_push_acts():
    """A square gripped across its diagonal, its corners in the plates' middles: both
    plates meet corners, the first contacts' normals (the corners' bisectors) lie along
    the closing line, so at mu = 0 the grasp is out of force closure (frictionless
    contacts cannot resist a turn about the centre) and yet no couple turns the square
    and no wall pushes it across: the plates hold it where it is."""
    from harness.squeeze import _across, _couple, _pushes

    side = 0.03
    square = shapely.Polygon([(-side / 2, -side / 2), (side / 2, -side / 2), (side / 2, side / 2),
                              (-side / 2, side / 2)])
    turned = shapely.affinity.rotate(square, 45.0, origin=(0, 0))
    fields = SDFBatch(GRID, grid_sdf(turned, GRID)[None], grid_sdf_gradient(turned, GRID)[None])
    g1, g2 = np.array([[0.0, -0.045]]), np.array([[0.0, 0.045]])
    contacts, closed = closes(fields, g1, g2, 0.0)
    assert not closed[0]
    assert _couple(*_pushes(contacts), g1, g2)[0] == 0.0 and _across(contacts, g1, g2, 0.0005 / JAW)[0] == 0.0
    out = squeeze(fields, g1, g2, 0, contacts, closed, 0.0, JAW, 0.05)
    assert out.squeezed[0] and out.turn[0] == 0.0 and out.shift[0] == 0.0
    np.testing.assert_array_equal(out.c1, contacts.c1)


def test_a_disk_gripped_off_centre_by_the_plates_edges_slides_out_of_the_jaws(ring):
    """A disk gripped 16 mm off its centre by 10 mm plates meets them by their inner
    edges, its walls leaning 11 degrees from the plates, beyond mu = 0.1: they push the
    disk away from the plates (the squeeze of a watermelon seed), the jaws move outwards in
    its frame and lose it; no shifted grasp that way is in force closure."""
    t = np.linspace(0.0, 2 * math.pi, 2000, endpoint=False)
    shape = shapely.Polygon(0.03 * np.column_stack([np.cos(t), np.sin(t)]))
    disk = SDFBatch(GRID, grid_sdf(shape, GRID)[None], grid_sdf_gradient(shape, GRID)[None])
    mu, offset = 0.1, 0.016
    g1, g2 = np.array([[offset, -0.045]]), np.array([[offset, 0.045]])
    contacts, closed = closes(disk, g1, g2, mu)
    assert not closed[0] and contacts.edge1[0] and contacts.edge2[0]
    assert not any(closes(disk, g1 + [[s, 0.0]], g2 + [[s, 0.0]], mu)[1][0] for s in np.arange(0.0005, 0.03, 0.0005))
    out = squeeze(disk, g1, g2, 0, contacts, closed, mu, JAW, 0.05, slide_limit=0.1)
    assert not out.squeezed[0] and out.shift[0] == 0.0
    np.testing.assert_array_equal(out.c1, contacts.c1)


def test_the_slide_counts_in_p_l_where_the_turn_cannot_help(ring):
    """P_L of the ring's rim grasp of the slide test: 1 with the slide (up to the gripper's
    opening), against P_F's 0, on identical draws."""
    n = 4
    draws = EvaluationDraws(SDFBatch(GRID, np.repeat(ring.values, n, axis=0),
                                     np.repeat(np.stack([ring.gx, ring.gy], axis=-1), n, axis=0)),
                            np.zeros((n, 2, 2)), np.zeros(n), np.full((n, 2), 0.5), 0.05)
    settings = replace(resolve(load_scene("disk"), {"sigma_g": 0.0, "friction": 0.2}), density=1.0)
    out = evaluate_draws(np.concatenate(rim(0.008))[None], draws, settings)
    est = out.estimates[0]
    assert est.p_f == 0.0 and est.p_l == 1.0 and est.squeezed == n


def test_bench_lifts_slide_cases_judged_by_the_model():
    """bench lift's slide cases, their model side (the physics is the bench's): the ring
    gripped 8 mm off its radial line is out of force closure at the first contacts on
    nearly every draw (sigma_g 1 mm) and slides into it on every one; the disk gripped 16
    mm off its centre slides out of the jaws on every draw; on slippery jaws (mu 0.1) the
    ring is out of force closure on every draw and held where the walls' pushes cancel."""
    from harness.bench.lift_study import SLIDES, _exact_draws

    ring_case, disk_case, slippery_ring = SLIDES
    for case, offset, p_f, p_l in ((ring_case, 0.008, 0.0, 1.0), (disk_case, 0.016, 0.0, 0.0),
                                   (slippery_ring, 0.008, 0.0, 1.0)):
        scene = case.scene()
        settings, _, draws = _exact_draws(scene, 100, 0, case.label)
        out = evaluate_draws(case.grasp(offset), draws, settings)
        assert out.closure.mean() == pytest.approx(p_f, abs=0.02)
        assert out.lifted.mean() == pytest.approx(p_l, abs=0.02)


def _draws_on(fields: SDFBatch, n: int) -> EvaluationDraws:
    """n identical draws of one field, no approach noise, friction as the settings say."""
    return EvaluationDraws(SDFBatch(GRID, np.repeat(fields.values, n, axis=0),
                                    np.repeat(np.stack([fields.gx, fields.gy], axis=-1), n, axis=0)),
                           np.zeros((n, 2, 2)), np.zeros(n), np.full((n, 2), 0.5), 0.05)


def test_the_draws_say_how_the_plates_settled_them(ellipse, ring):
    """evaluate_draws(..., lift_inputs=True) reports per draw how the plates settled it
    (harness.quality.SETTLE_INPUTS, as `report --draws` writes them): the ellipse 4 degrees
    off its minor axis is in force closure at once; 20 degrees off, the squeeze turns it
    by the turn the squeeze itself finds (its own test above checks that turn against
    judging every turned grasp); the ring gripped 8 mm off its radial line slides by the
    slide the squeeze finds with the quality's slide limit; at mu = 0 the square gripped corner
    to corner (the test above) is held in the plane where it is: no couple, no push across.
    The push turns none of them."""
    from harness.quality import SETTLE_INPUTS, SETTLED
    from harness.squeeze import SLIDE_LIMIT

    settings = replace(resolve(load_scene("disk"), {"sigma_g": 0.0, "friction": 0.2}), density=1.0)
    grasps = np.stack([np.concatenate(jaws(math.radians(a)), axis=0) for a in (4.0, 20.0)])
    out = evaluate_draws(grasps, _draws_on(ellipse, 2), settings, lift_inputs=True).lift_inputs
    assert set(SETTLE_INPUTS) <= set(out)
    assert [SETTLED[int(c)] for c in out["settled"][:, 0]] == ["closure", "turn"]
    _, _, direct = run(ellipse, math.radians(20.0), 0.2)
    assert out["squeeze_turn"][1, 0] == pytest.approx(direct.turn[0], abs=1e-12) and direct.turn[0] > 0
    assert out["squeeze_turn"][0, 0] == 0.0 and (out["slide"] == 0.0).all()
    np.testing.assert_allclose(out["push_turn"], 0.0, atol=1e-12)

    g1, g2 = rim(0.008)
    contacts, closed = closes(ring, g1, g2, 0.2)
    direct = squeeze(ring, g1, g2, 0, contacts, closed, 0.2, JAW, 0.05, slide_limit=SLIDE_LIMIT)
    ringed = evaluate_draws(np.concatenate(rim(0.008))[None], _draws_on(ring, 2), settings,
                            lift_inputs=True).lift_inputs
    assert [SETTLED[int(c)] for c in ringed["settled"][0]] == ["slide", "slide"]
    np.testing.assert_allclose(ringed["slide"][0], direct.shift[0], atol=1e-12)
    assert direct.shift[0] > 0 and (ringed["squeeze_turn"] == 0.0).all()

    frictionless = replace(settings, friction=0.0)
    square = shapely.affinity.rotate(shapely.Polygon([(-0.015, -0.015), (0.015, -0.015), (0.015, 0.015),
                                                      (-0.015, 0.015)]), 45.0, origin=(0, 0))
    fields = SDFBatch(GRID, grid_sdf(square, GRID)[None], grid_sdf_gradient(square, GRID)[None])
    held = evaluate_draws(np.array([[[0.0, -0.045], [0.0, 0.045]]]), _draws_on(fields, 2), frictionless,
                          lift_inputs=True).lift_inputs
    assert [SETTLED[int(c)] for c in held["settled"][0]] == ["held", "held"]
    assert (held["squeeze_turn"] == 0.0).all() and (held["slide"] == 0.0).all()


def test_a_slide_that_runs_another_wall_into_a_plates_side_is_held_where_it_stopped():
    """A wedge narrowing to +x (walls leaning 30 degrees from the plates, beyond mu = 0.3)
    with a tooth hanging below its lower wall from x = 10 mm: gripped across at x = 0, the
    walls push the wedge towards -x, so the jaws slide towards +x in its frame, until the
    lower plate's strip (10 mm wide) would take in the tooth, whose wall is square to the
    plate: it cannot push the plate back along the closing line, it runs into the plate's
    side and stops the slide. The draw is held in the plane where the step before left it
    (before this rule, the search starting inside the tooth counted as a lost contact and
    the draw as out of closure). Checked against judging each shifted grasp on its own:
    the step it stops at is the first whose lower search, from SQUEEZE_MARGIN below the
    last contact, starts inside the tooth, and the held contacts are the shifted grasp's
    own. On the wedge without its tooth the slide goes on past that point."""
    from harness.grasp import OK, TOO_WIDE
    from harness.squeeze import SLIDE_STEP, SQUEEZE_MARGIN, _across, _couple, _pushes

    mu, lean = 0.3, math.tan(math.radians(30.0))

    def lower(x):
        return -0.012 + lean * x

    def upper(x):
        return 0.012 - lean * x

    wedge = [(-0.03, lower(-0.03)), (0.010, lower(0.010)), (0.022, lower(0.022)), (0.022, upper(0.022)),
             (-0.03, upper(-0.03))]
    toothed = [(-0.03, lower(-0.03)), (0.010, lower(0.010)), (0.010, -0.03), (0.022, -0.03), (0.022, upper(0.022)),
               (-0.03, upper(-0.03))]

    def fields(outline):
        shape = shapely.Polygon(outline)
        return SDFBatch(GRID, grid_sdf(shape, GRID)[None], grid_sdf_gradient(shape, GRID)[None]), shape

    def at(shift):
        return np.array([[shift, -0.045]]), np.array([[shift, 0.045]])

    tooth, shape = fields(toothed)
    com = np.array(shape.centroid.coords[0])
    g1, g2 = at(0.0)
    contacts = find_contacts(tooth, g1, g2, JAW)
    closed, _ = plate_closure(contacts, mu, com, 0.05)
    assert not closed[0] and _couple(*_pushes(contacts), g1, g2)[0] == 0.0
    assert _across(contacts, g1, g2, 0.0005 / JAW)[0] == 1.0  # the jaws move towards +x in the wedge's frame
    # Each shifted grasp on its own: the lower plate's search from SQUEEZE_MARGIN below the
    # contact of the shift before; the first that starts inside the tooth stops the slide.
    shifts = np.arange(1, 8) * SLIDE_STEP
    last = contacts
    for shift in shifts:
        h1, h2 = at(shift)
        start = last.c1[0, 1] - SQUEEZE_MARGIN
        probe = find_contacts(tooth, np.array([[shift, start]]), h2, JAW)
        if probe.status[0] == TOO_WIDE:
            held = shift - SLIDE_STEP
            break
        last = find_contacts(tooth, h1, h2, JAW)
        assert last.status[0] == OK and not plate_closure(last, mu, com, 0.05)[0][0]
    else:
        raise AssertionError("the tooth never met the plate")
    assert held > 0
    out = squeeze(tooth, g1, g2, 0, contacts, closed, mu, JAW, 0.05, slide_limit=0.02)
    assert out.squeezed[0] and out.turn[0] == 0.0
    assert out.shift[0] == pytest.approx(held, abs=1e-9)
    expected = find_contacts(tooth, *at(held), JAW)
    np.testing.assert_allclose(out.c1[0], expected.c1[0], atol=1e-9)
    np.testing.assert_allclose(out.c2[0], expected.c2[0], atol=1e-9)
    plain, plain_shape = fields(wedge)
    plain_contacts = find_contacts(plain, g1, g2, JAW)
    plain_closed, _ = plate_closure(plain_contacts, mu, np.array(plain_shape.centroid.coords[0]), 0.05)
    # Without the tooth, the same searches go on past the shift the tooth stopped: none
    # starts inside the wedge, and each shifted grasp is still out of closure...
    plain_com = np.array(plain_shape.centroid.coords[0])
    last = plain_contacts
    for shift in np.arange(1, round(held / SLIDE_STEP) + 4) * SLIDE_STEP:
        h1, h2 = at(shift)
        probe = find_contacts(plain, np.array([[shift, last.c1[0, 1] - SQUEEZE_MARGIN]]), h2, JAW)
        assert probe.status[0] == OK
        last = find_contacts(plain, h1, h2, JAW)
        assert last.status[0] == OK and not plate_closure(last, mu, plain_com, 0.05)[0][0]
    # ... so the slide runs on to its limit (20 mm) out of closure, and with a longer limit
    # until the plates slide off the wedge's narrow end (at 26 mm: a lost contact). Neither
    # is settled, and no shift is recorded.
    for limit in (0.02, 0.03):
        on = squeeze(plain, g1, g2, 0, plain_contacts, plain_closed, mu, JAW, 0.05, slide_limit=limit)
        assert not on.squeezed[0] and on.shift[0] == 0.0
    assert find_contacts(plain, *at(0.024), JAW).status[0] == OK
    assert find_contacts(plain, *at(0.026), JAW).status[0] != OK


def test_a_turn_that_runs_another_wall_into_a_plates_side_is_held_at_the_step_before():
    """A 6 x 2 cm bar gripped through its centre with the closing line 12 degrees off its
    faces' normal, at mu = 0.1: the plates touch the faces with their edges, and the
    squeeze turns the bar until they lie within the cone (closure at 8 degrees, 4 off
    flush). With a tooth standing 8 mm above the upper face at x = -7 to -4 mm, the upper
    plate's strip sweeps towards it as the bar turns: at the step where the plate's search,
    from SQUEEZE_MARGIN outside its last contact, starts inside the tooth, the tooth runs
    into the plate's side. The turn is then held in the plane at the step before, with
    that step's contacts (checked against the turned grasps judged one by one)."""
    from harness.grasp import OK, TOO_WIDE, turn_about
    from harness.squeeze import SQUEEZE_MARGIN, _couple, _pushes

    mu = 0.1

    def fields(outline):
        shape = shapely.Polygon(outline)
        return SDFBatch(GRID, grid_sdf(shape, GRID)[None], grid_sdf_gradient(shape, GRID)[None]), shape

    bar = [(-0.03, -0.01), (0.03, -0.01), (0.03, 0.01), (-0.03, 0.01)]
    toothed = [*bar[:3], (-0.004, 0.01), (-0.004, 0.018), (-0.007, 0.018), (-0.007, 0.01), bar[3]]
    g1, g2 = jaws(math.radians(12.0))
    plain, _ = fields(bar)
    contacts = find_contacts(plain, g1, g2, JAW)
    closed, _ = plate_closure(contacts, mu, np.zeros(2), 0.05)
    out = squeeze(plain, g1, g2, 0, contacts, closed, mu, JAW, 0.05, slide_limit=0.0)
    assert not closed[0] and out.squeezed[0] and out.turn[0] == pytest.approx(math.radians(8.0), abs=1e-9)

    tooth, shape = fields(toothed)
    com = np.array(shape.centroid.coords[0])
    contacts = find_contacts(tooth, g1, g2, JAW)
    closed, _ = plate_closure(contacts, mu, com, 0.05)
    sense = _couple(*_pushes(contacts), g1, g2)[0]
    last, held = contacts, None
    for k in range(1, int(round(SQUEEZE_LIMIT / SQUEEZE_STEP)) + 1):
        h1, h2 = (turn_about(g, com[None], -sense * k * SQUEEZE_STEP) for g in (g1, g2))
        u = (h2 - h1)[0] / np.linalg.norm(h2 - h1)
        t1, t2 = (last.c1[0] - h1[0]) @ u - SQUEEZE_MARGIN, (last.c2[0] - h1[0]) @ u + SQUEEZE_MARGIN
        probe = find_contacts(tooth, h1 + t1 * u, h1 + t2 * u, JAW)
        if probe.status[0] == TOO_WIDE:
            held = (k - 1) * SQUEEZE_STEP
            break
        assert probe.status[0] == OK and not plate_closure(probe, mu, com, 0.05)[0][0]
        last = probe
    assert held == pytest.approx(math.radians(6.0), abs=1e-9)
    out = squeeze(tooth, g1, g2, 0, contacts, closed, mu, JAW, 0.05, slide_limit=0.0)
    assert not closed[0] and out.squeezed[0]
    assert out.turn[0] == pytest.approx(held, abs=1e-9)
    np.testing.assert_allclose(out.c1[0], last.c1[0], atol=1e-9)
    np.testing.assert_allclose(out.c2[0], last.c2[0], atol=1e-9)
