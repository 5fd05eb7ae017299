"""The push before the grasp: the jaws close symmetrically about the gripper's centre, so
the plate nearer the object meets it first and pushes it across the table until the
other arrives, half the difference of the two plates' gaps if the object does not turn.
An object pushed off its centre of friction turns on the table as it goes, and the
grasp the plates then close is another one (docs/lift.md, "The push").

The push is quasi-static: the plates close slowly enough that the table's friction
balances the plate's push at every instant. The table's friction on a prism resting on
its face under an even pressure is bounded by a limit surface, which the model takes as
the ellipsoid of Lynch, Maekawa and Tanie (1992, "Manipulation and active sensing by
pushing using tactile feedback", IROS):

    (f_x / f_max)^2 + (f_y / f_max)^2 + (m / m_max)^2 = 1,   c = m_max / f_max,

with c the mean distance of the prism's cross-section from its centre of mass (the lever
of an even pressure's friction about it; harness.grasp.Regions.spread). The object's
motion is normal to the limit surface: its centre of mass moves along the friction
force f the plate overcomes, and it turns at (r x f) / c^2 per unit of that, r being the
contact's position from the centre of mass. Where the contact sticks, the contact point
moves with the plate: f = (I - p p^T / (c^2 + |p|^2)) v_p with p = (-r_y, r_x), v_p the
plate's velocity (closed form, tested). Where that force leaves the plate's friction
cone about the contact normal, the contact slides and the force lies on the cone's edge,
scaled so that the contact keeps up with the plate along the normal (Lynch and Mason
1996, "Stable pushing", IJRR 15(6)). Neither the weight nor the table's friction
coefficient enters: both scale the table's friction and the plate's push alike.

The contact normal is the plate's (the closing direction) where the plate's face meets
a corner or a curved wall, and the wall's where the plate's edge meets an inclined wall
(harness.grasp.edge_contacts). A plate flush on a flat wall pushes along a segment: it
translates the object with it when the line of the push through the centre of mass
crosses the segment, and otherwise the object pivots about the segment's end nearest
that line, the other end leaving the plate.

The push is followed in steps of at most PUSH_STEP along the closing direction and
PUSH_TURN of the object's turn. At each step the plates' contacts are found again in the
object's frame (as the squeeze does, harness.squeeze): the push ends when the other
plate touches, or when the object leaves the plates (a contact lost).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.grasp import (OK, PATCH_DEPTH, TOO_WIDE, Contacts, SDFBatch, find_contacts, plate_closure, replace_rows,
                           turn_about)
from harness.squeeze import SQUEEZE_LIMIT, Squeeze, squeeze

#: The push is followed in steps of at most this length (m) of the plate's travel, about
#: a grid cell, as the slide is (harness.squeeze.SLIDE_STEP).
PUSH_STEP = 0.002
#: ... and of at most this turn (rad) of the object, as the squeeze is
#: (harness.squeeze.SQUEEZE_STEP).
PUSH_TURN = math.radians(2.0)
#: Each plate searches for the surface from this far (m) behind its face: a step moves
#: the wall under the plate by well under it.
PUSH_MARGIN = 0.003
#: A plate within this distance (m) of the surface touches it: the contacts' flush
#: tolerance (harness.grasp.PATCH_DEPTH).
TOUCH = PATCH_DEPTH
#: A push that does not turn the object and moves the closing line by less than this (m)
#: across it at either contact leaves the contacts where they were (they are found to
#: well under a micrometre; a tenth of a millimetre is far below anything the plates
#: resolve). A push that turns the object at all has its contacts found again.
NEGLIGIBLE = 1e-4
#: Steps followed at most: a cost cap; a push ends sooner when the jaws meet.
MAX_STEPS = 200


@dataclass(frozen=True)
class Push:
    """Per draw (B,): the jaw starts g1, g2 (B, 2) in the object's frame after the push (the
    executed starts where the object did not move), how far the pushing plate pushed
    (m, 0 where the plates arrive together), the object's turn about the vertical (rad,
    counter-clockwise positive), whether the push moved the closing line across the
    object (its contacts must be found again) and how far each plate had closed from its
    start when the push ended (m; 0 where the object did not move)."""

    g1: np.ndarray
    g2: np.ndarray
    distance: np.ndarray
    turn: np.ndarray
    moved: np.ndarray
    travel: np.ndarray

    def plates(self, which) -> tuple[np.ndarray, np.ndarray]:
        """Where the plates of draws ``which`` stand in the object's frame when the push
        ends, each PUSH_MARGIN behind its face (B', 2), as the push's own searches start."""
        g1, g2 = self.g1[which], self.g2[which]
        u = (g2 - g1) / np.maximum(np.linalg.norm(g2 - g1, axis=1), 1e-300)[:, None]
        behind = (self.travel[which] - PUSH_MARGIN)[:, None] * u
        return g1 + behind, g2 - behind


def twist(r, normal, direction, friction, spread):
    """The object's motion per unit of the plate's travel: its centre of mass's velocity
    (B, 2) and its turn rate (B,, rad per metre), for a plate moving along ``direction``
    (B, 2, unit) pushing at ``r`` (B, 2, from the centre of mass) with the contact normal
    ``normal`` (B, 2, unit, into the object), plate friction ``friction`` (B,) and the
    limit surface's lever c = ``spread`` (B,) (see the module's docstring)."""
    r, normal, direction = (np.asarray(a, dtype=float) for a in (r, normal, direction))
    c2 = np.asarray(spread, dtype=float) ** 2
    p = np.column_stack([-r[:, 1], r[:, 0]])
    pp = np.einsum("ij,ij->i", p, p)
    force = direction - p * (np.einsum("ij,ij->i", p, direction) / (c2 + pp))[:, None]
    along = np.einsum("ij,ij->i", force, normal)
    norm = np.linalg.norm(force, axis=1)
    mu = np.asarray(friction, dtype=float)
    slides = along < norm / np.sqrt(1.0 + mu**2)
    if slides.any():
        tangent = np.column_stack([-normal[:, 1], normal[:, 0]])
        side = np.sign(np.einsum("ij,ij->i", force, tangent))
        edge = normal + (side * mu)[:, None] * tangent
        # The contact point's velocity along the normal, M edge . n with M = I + p p^T / c^2,
        # matches the plate's.
        keeps = np.einsum("ij,ij->i", edge, normal) + np.einsum("ij,ij->i", p, edge) * np.einsum(
            "ij,ij->i", p, normal) / c2
        scale = np.einsum("ij,ij->i", direction, normal) / keeps
        force = np.where(slides[:, None], edge * scale[:, None], force)
    turn = (r[:, 0] * force[:, 1] - r[:, 1] * force[:, 0]) / c2
    return force, turn


def push(fields: SDFBatch, g1, g2, field_index, contacts: Contacts, friction, jaw_width: float,
         active=None, step: float = PUSH_STEP, turn_step: float = PUSH_TURN) -> Push:
    """Follow the push of B grasps (executed jaw starts g1, g2 (B, 2) on fields
    ``field_index`` (B,), with their first ``contacts``); ``active`` (B,) limits it to
    some draws (default: every draw with both contacts). friction: float or (B,) plate
    coefficients. ``step`` and ``turn_step`` bound each step's travel (m) and turn (rad)."""
    g1 = np.asarray(g1, dtype=float)
    g2 = np.asarray(g2, dtype=float)
    b = len(g1)
    field_index = np.broadcast_to(np.asarray(field_index, dtype=np.int64), (b,))
    friction = np.broadcast_to(np.asarray(friction, dtype=float), (b,))
    regions = fields.regions
    com, spread = regions.center_of_mass[field_index], regions.spread[field_index]
    length = np.linalg.norm(g2 - g1, axis=1)
    u = (g2 - g1) / np.maximum(length, 1e-300)[:, None]
    centre = 0.5 * (g1 + g2)
    half = 0.5 * length
    gap1 = np.einsum("ij,ij->i", contacts.c1 - g1, u)
    gap2 = np.einsum("ij,ij->i", g2 - contacts.c2, u)
    ok = (contacts.status == OK) & np.isfinite(com[:, 0]) & (spread > 0)
    if active is not None:
        ok &= np.asarray(active, dtype=bool)
    travel = np.where(ok, np.minimum(gap1, gap2), 0.0)
    moving = ok & (np.abs(gap1 - gap2) > TOUCH)
    distance, turn = np.zeros(b), np.zeros(b)
    rows = np.flatnonzero(moving)
    current = _rows(contacts, moving)
    gaps = np.column_stack([gap1, gap2])[rows] - travel[rows, None]
    for _ in range(MAX_STEPS):
        if not len(rows):
            break
        first = gaps[:, 0] <= gaps[:, 1]  # the plate that pushes
        behind = np.where(first, gaps[:, 0], gaps[:, 1])
        other = np.where(first, gaps[:, 1], gaps[:, 0]) - np.abs(behind)
        travel[rows] += np.maximum(behind, 0.0)
        done = other <= TOUCH
        pick = np.where(first[:, None], current.c1, current.c2)
        normal_out = np.where(first[:, None], current.n1, current.n2)
        edge = np.where(first, current.edge1, current.edge2) > 0
        direction = np.where(first[:, None], u[rows], -u[rows])
        point, still = _flush_point(current, first, direction, com[rows])
        point = np.where(np.isnan(point[:, :1]), pick, point)
        normal = np.where(edge[:, None], -normal_out, direction)  # a flush plate is never an edge
        velocity, rate = twist(point - com[rows], normal, direction, friction[rows], spread[rows])
        velocity = np.where(still[:, None], direction, velocity)
        rate = np.where(still, 0.0, rate)
        forward = np.clip(np.einsum("ij,ij->i", velocity, direction), 0.0, None)
        delta = np.minimum(step, other / (1.0 + forward))
        with np.errstate(divide="ignore"):
            delta = np.minimum(delta, turn_step / np.abs(rate))
        # Within TOUCH the other plate arrives: the last bit of the push is taken whole.
        delta = np.where(done, np.maximum(other, 0.0) / (1.0 + forward), delta)
        delta = np.clip(np.minimum(delta, half[rows] - travel[rows]), 0.0, None)
        # The object moves by delta * velocity and turns by delta * rate about its centre of
        # mass; in its frame the gripper moves the other way.
        angle = delta * rate
        shift = delta[:, None] * velocity
        centre[rows] = turn_about(centre[rows] - shift, com[rows], -angle)
        u[rows] = turn_about(u[rows], np.zeros_like(u[rows]), -angle)
        travel[rows] += delta
        distance[rows] += delta
        turn[rows] += angle
        keep = ~done & (delta > 0) & (travel[rows] < half[rows])
        rows = rows[keep]
        if not len(rows):
            break
        reach = half[rows] - travel[rows]
        j1 = centre[rows] - reach[:, None] * u[rows]
        j2 = centre[rows] + reach[:, None] * u[rows]
        current = find_contacts(fields, j1 - PUSH_MARGIN * u[rows], j2 + PUSH_MARGIN * u[rows], jaw_width,
                                field_index=field_index[rows])
        found = current.status == OK
        gaps = np.column_stack([np.einsum("ij,ij->i", current.c1 - j1, u[rows]),
                                np.einsum("ij,ij->i", j2 - current.c2, u[rows])])
        rows, gaps = rows[found], gaps[found]
        current = _rows(current, found)
    new1 = centre - half[:, None] * u
    new2 = centre + half[:, None] * u
    line = _line_shift(g1, g2, new1, new2, contacts)
    moved = ok & ((np.abs(turn) > 0) | (line > NEGLIGIBLE))
    new1 = np.where(moved[:, None], new1, g1)
    new2 = np.where(moved[:, None], new2, g2)
    return Push(new1, new2, distance, turn, moved, np.where(moved, travel, 0.0))


def push_and_squeeze(fields: SDFBatch, g1, g2, field, contacts: Contacts, closure, gamma, jaw: float, scale: float,
                      rest=None) -> tuple[Contacts, np.ndarray, Squeeze, Push]:
    """The push before the second plate arrives (harness.push) and the squeeze
    (harness.squeeze) of draws ``rest`` (default all): where the push moved the closing
    line across the object, the contacts and their closure are found again from the jaw
    starts in the object's frame after it; the squeeze may turn the object back through
    the push's turn before its own limit (SQUEEZE_LIMIT) counts. Returns the contacts,
    their closure, the squeeze and the push."""
    field = np.broadcast_to(np.asarray(field, dtype=np.int64), (len(g1),))
    gamma = np.broadcast_to(np.asarray(gamma, dtype=float), (len(g1),))
    pushed = push(fields, g1, g2, field, contacts, gamma, jaw, active=rest)
    closure = np.array(closure, dtype=bool)
    if pushed.moved.any():
        rows = np.flatnonzero(pushed.moved)
        again = find_contacts(fields, pushed.g1[rows], pushed.g2[rows], jaw, field_index=field[rows])
        # In the object's frame the pushing plate's start recedes behind it as the object
        # goes, and a start beside another wall (a plate that started in a notch and
        # closed out of it) can end inside that wall, where the plate no longer is. The
        # plates then search from where they stand, as during the push.
        inside = again.status == TOO_WIDE
        if inside.any():
            near = rows[inside]
            again = replace_rows(again, np.flatnonzero(inside),
                                 find_contacts(fields, *pushed.plates(near), jaw, field_index=field[near]))
        closure[rows], _ = plate_closure(again, gamma[rows], fields.center_of_mass[field[rows]], scale,
                                         with_quality=False)
        contacts = replace_rows(contacts, rows, again)
    skip = closure if rest is None else closure | ~rest
    # The squeeze turns the object back through the push's turn before its own limit counts.
    limit = SQUEEZE_LIMIT + np.abs(pushed.turn)
    return (contacts, closure, squeeze(fields, pushed.g1, pushed.g2, field, contacts, skip, gamma, jaw, scale,
                                       limit=limit), pushed)


def _flush_point(contacts: Contacts, first, direction, com):
    """Where a plate flush on a flat wall pushes when the object pivots (B, 2: the flush
    segment's end nearest the push's line through the centre of mass; NaN for a point
    or an edge contact, and where it goes straight) and whether that line crosses the
    flush segment (B,: the object then goes straight)."""
    patch = np.where(first[:, None, None], contacts.patch1, contacts.patch2)
    width = np.where(first, contacts.w1, contacts.w2)
    edge = np.where(first, contacts.edge1, contacts.edge2) > 0
    touching = np.isfinite(patch[:, :, 0])
    flush = (width > 0) & (touching.sum(axis=1) > 1) & ~edge
    across = np.column_stack([-direction[:, 1], direction[:, 0]])
    side = np.einsum("bkj,bj->bk", patch - com[:, None, :], across)
    low = np.where(touching, side, np.inf).min(axis=1)
    high = np.where(touching, side, -np.inf).max(axis=1)
    still = flush & (low <= 0.0) & (high >= 0.0)
    nearest = np.argmin(np.where(touching, np.abs(side), np.inf), axis=1)
    point = np.take_along_axis(patch, nearest[:, None, None], axis=1)[:, 0]
    return np.where((flush & ~still)[:, None], point, np.nan), still


def _line_shift(g1, g2, h1, h2, contacts: Contacts) -> np.ndarray:
    """How far (B,) the closing line moved across itself at either first contact (0
    where there is none)."""
    out = np.zeros(len(g1))
    for c in (contacts.c1, contacts.c2):
        before = _distance(c, g1, g2)
        after = _distance(c, h1, h2)
        out = np.maximum(out, np.nan_to_num(np.abs(after - before)))
    return out


def _distance(point, a, b) -> np.ndarray:
    d = b - a
    rel = point - a
    return (rel[:, 0] * d[:, 1] - rel[:, 1] * d[:, 0]) / np.maximum(np.linalg.norm(d, axis=1), 1e-300)


def _rows(contacts: Contacts, which) -> Contacts:
    return Contacts(*(getattr(contacts, name)[which] for name in Contacts.__dataclass_fields__))
