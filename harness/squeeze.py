"""The plates' squeeze: a draw whose contacts are not in force closure turns on the table
under the plates' couple until they are (or it cannot), and failing that slides across
the closing line where the walls lean from the plates, until they are or until the
walls' pushes across that line cancel, a position the plates hold in the plane; a turn
or a slide that carries another wall of the object into a plate's side stops there,
held in the plane too. The lift model's planar step (docs/lift.md, "The squeeze" and
"The slide")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.grasp import OK, PATCH_DEPTH, TOO_WIDE, Contacts, SDFBatch, find_contacts, plate_closure, turn_about

#: The turn is followed in steps of this angle (rad). With P_L of 1000 draws on the plans
#: of the make eval before the squeeze (and the pushes at the first contacts), steps of 2,
#: 3 and 4 degrees ranked the plans' physical success at Spearman 0.682, 0.679 and 0.669;
#: 1 degree (in a prototype) as 2.
SQUEEZE_STEP = math.radians(2.0)
#: The largest turn followed (rad), beyond undoing the push's (harness.push). Half of
#: the draws squeezed into closure on make eval's plans close within 4 degrees, 88 %
#: within 10 and 99 % within 18. A cost cap when it was chosen, it stands for physics
#: the squeeze leaves out: at 90 degrees, mean-shape-lift on make eval moved to grasps
#: that need large squeezes and lost them (success 0.989 -> 0.937; the stapler 0 of 40),
#: while both engines squeeze a light pushed bar 37 degrees flush (docs/lift.md, "The
#: push"). Its cost, measured (docs/lift.md, "The squeeze's limit on the calibration
#: rectangle"): the calibration bar gripped through its centre 40-50 degrees off its length
#: is squeezed flush by both engines and kept, where the limit gives P_L 0.00-0.81; at 90
#: degrees make eval's lift planners move to long squeezes on posterior bodies, which
#: Bullet stops short (gp-gpis-opt-lift 0.997 -> 0.966, P_L's Spearman 0.623 -> 0.565).
SQUEEZE_LIMIT = math.radians(20.0)
#: During the squeeze each plate looks for the surface from this far (m) outside its last
#: contact: a 2 degree turn moves the wall under a 10 mm plate by well under 1 mm.
SQUEEZE_MARGIN = 0.003
#: The slide is followed in steps of this length (m), about a grid cell (2-3 mm on the
#: library and the sweep); the contacts themselves are found to well under that.
SLIDE_STEP = 0.002
#: The longest slide followed (m), a cost cap as SQUEEZE_LIMIT is: each step past the
#: last costs a search for the contacts of the draws still sliding, and most slides that
#: go on end with the object out of the jaws. 95 % of the slides into closure of the
#: regime sweep's trials end within 18 mm (docs/lift.md, "The slide").
SLIDE_LIMIT = 0.02


@dataclass(frozen=True)
class Squeeze:
    """Per draw (B,): whether the squeeze settled the object between the plates (brought
    them into force closure, slid the object to where the walls' pushes across the
    closing line cancel, or turned or slid it until another of its walls met a plate's
    side: held in the plane), the turn (rad) or the slide (m) that did (0 where it did
    not) and the contacts where it stopped (the first contacts for draws in closure at
    once, or not settled): c1, c2, w1, w2, edge1, edge2."""

    squeezed: np.ndarray
    turn: np.ndarray
    shift: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    w1: np.ndarray
    w2: np.ndarray
    edge1: np.ndarray
    edge2: np.ndarray


#: The contacts' fields a Squeeze keeps where it stopped.
_KEPT = ("c1", "c2", "w1", "w2", "edge1", "edge2")


def squeeze(fields: SDFBatch, g1, g2, field_index, contacts: Contacts, closure, friction, jaw_width: float,
            torque_scale: float, step: float = SQUEEZE_STEP, limit=SQUEEZE_LIMIT,
            slide_limit: float = SLIDE_LIMIT) -> Squeeze:
    """Follow the squeeze of B grasps (executed jaw starts g1, g2 (B, 2) on fields
    ``field_index`` (B,), with their ``contacts`` and force ``closure`` (B,)).

    A plate is flat, so it pushes along the closing direction u: on contacts offset
    across u the two pushes form a couple, N (c1 - c2) x u, which turns the object on the
    table (Goldberg 1993, the squeeze of a parallel-jaw gripper; Brost 1988). The couple
    is pure, so the object turns about its centre of mass. In the object's frame the jaws
    turn the other way about it; the contacts are found again each ``step`` until the
    plates are in force closure (squeezed), the couple changes sign without closure (the
    width's local minimum reached out of closure: the squeeze holds it there) or vanishes,
    a contact is lost (a plate slid off the object), the step carries another part of the
    object into a plate's side (blocked: held in the plane where the step before left it,
    :func:`_settle`), or the turn reaches ``limit`` (rad; float or (B,)). A draw
    the turn does not bring into closure then slides from its first contacts
    (:func:`_slide`), up to
    ``slide_limit`` (m; 0 turns only), unless neither the couple nor the walls' push
    across u acts there: then the plates hold it in the plane where it is. friction:
    float or (B,) coefficients.
    """
    g1 = np.asarray(g1, dtype=float)
    g2 = np.asarray(g2, dtype=float)
    b = len(g1)
    field_index = np.broadcast_to(np.asarray(field_index, dtype=np.int64), (b,))
    friction = np.broadcast_to(np.asarray(friction, dtype=float), (b,))
    com = fields.regions.center_of_mass[field_index]
    out = Squeeze(np.zeros(b, dtype=bool), np.zeros(b), np.zeros(b),
                  *(getattr(contacts, name).copy() for name in _KEPT))
    turning = _couple(*_pushes(contacts), g1, g2)
    candidates = (contacts.status == OK) & ~np.asarray(closure, dtype=bool) & np.isfinite(com[:, 0])
    active = candidates & (turning != 0)
    before = {name: getattr(contacts, name).copy() for name in _KEPT}
    angle = 0.0
    limit = np.broadcast_to(np.asarray(limit, dtype=float), (b,))
    while (active := active & (angle + step <= limit + 1e-12)).any():
        angle += step
        idx = np.flatnonzero(active)
        # The object turns by +angle in the couple's sense; the jaws, in its frame, by -angle
        # about its centre of mass.
        h1, h2 = (turn_about(g[idx], com[idx], -turning[idx] * angle) for g in (g1, g2))
        u = (h2 - h1) / np.linalg.norm(h2 - h1, axis=1, keepdims=True)
        found, h1, h2, closed, lost, blocked = _settle(fields, h1, u, idx, field_index, friction, com, jaw_width,
                                                       torque_scale, out, before)
        reversed_ = ~lost & (_couple(*_pushes(found), h1, h2) != turning[idx])
        out.turn[idx[closed]] = angle
        out.turn[idx[blocked]] = angle - step
        active[idx[closed | lost | blocked | reversed_]] = False
    # Neither a couple nor a push across u at the first contacts: the plates' pushes
    # balance there, and the object stays where it is, held in the plane.
    balanced = candidates & (turning == 0) & (_across(contacts, g1, g2, PATCH_DEPTH / jaw_width) == 0)
    out.squeezed[balanced] = True
    _slide(fields, g1, g2, field_index, contacts, candidates & ~out.squeezed, friction, com, jaw_width, torque_scale,
           out, slide_limit)
    return out


def _slide(fields: SDFBatch, g1, g2, field_index, contacts: Contacts, active, friction, com, jaw_width: float,
           torque_scale: float, out: Squeeze, limit: float) -> None:
    """The plates' slide, into ``out``, of draws the turn left out of force closure: on
    walls leaning from the plates the pushes have a component across the closing
    direction u (:func:`_across`), and with no closure to hold it the object slides that
    way on the table (Mason 1986; the squeeze of a wedge); the plates' friction enters
    through the closure test at each step. In the object's frame the jaws move the other
    way; the contacts are found again each
    SLIDE_STEP until the plates are in force closure (slid into it), the push across u
    changes sign or vanishes, a contact is lost (the object slid out of the jaws), another
    wall meets a plate's side (held where the step before left it, :func:`_settle`) or the
    slide reaches ``limit``. Where the push changes sign or vanishes, the walls hold the
    object in the plane out of force closure: the plates' pushes along u balance there,
    any shift across u brings back a push towards it, and the lift asks the plates for
    friction along the walls (the weight) and about u (its torque), not for planar
    closure. Such a draw is settled too (``out.squeezed``), and the lift is judged at
    those contacts (docs/lift.md, "The slide")."""
    flush = PATCH_DEPTH / jaw_width
    sense = _across(contacts, g1, g2, flush)
    active = active & (sense != 0)
    u = (g2 - g1) / np.linalg.norm(g2 - g1, axis=1, keepdims=True)
    across = np.column_stack([-u[:, 1], u[:, 0]])
    before = {name: getattr(contacts, name).copy() for name in _KEPT}
    shift = 0.0
    while active.any() and shift + SLIDE_STEP <= limit + 1e-12:
        shift += SLIDE_STEP
        idx = np.flatnonzero(active)
        move = -(sense[idx] * shift)[:, None] * across[idx]
        found, h1, h2, closed, lost, blocked = _settle(fields, g1[idx] + move, u[idx], idx, field_index, friction,
                                                       com, jaw_width, torque_scale, out, before)
        stopped = ~lost & ~blocked & ~closed & (_across(found, h1, h2, flush) != sense[idx])
        _keep(out, idx[stopped], found, stopped)
        out.shift[idx[closed | stopped]] = shift
        out.shift[idx[blocked]] = shift - SLIDE_STEP
        active[idx[closed | lost | blocked | stopped]] = False


def _settle(fields: SDFBatch, h1, u, idx, field_index, friction, com, jaw_width: float, torque_scale: float,
            out: Squeeze, before: dict):
    """One step of the squeeze for draws ``idx``, the first jaw moved (in the object's
    frame) to h1, closing along the unit vector u: the jaws are closed on the object, so
    each plate's search starts SQUEEZE_MARGIN outside its last contact (``before``'s c1
    and c2, the _KEPT fields of each draw's last contacts found, updated here), not at the
    jaw's start. The draws now in force closure are squeezed, with these contacts,
    into ``out``.

    A search that starts inside the object means that the step carried another part of it
    across the plate's side into its strip, deeper than the margin: a wall as steep as
    that cannot push a plate back along u, so it runs into the plate's side, which stops
    the turn or the slide. Such a draw is **blocked**: held in the plane where the step
    before left it, with those contacts (``before``'s), as the slide holds a draw where
    the walls' pushes cancel. Returns the contacts found, the plates' search starts, and which draws
    closed, which lost a contact (a plate slid off the object) and which were blocked."""
    t1 = np.einsum("ij,ij->i", before["c1"][idx] - h1, u) - SQUEEZE_MARGIN
    t2 = np.einsum("ij,ij->i", before["c2"][idx] - h1, u) + SQUEEZE_MARGIN
    h1, h2 = h1 + t1[:, None] * u, h1 + t2[:, None] * u
    found = find_contacts(fields, h1, h2, jaw_width, field_index=field_index[idx])
    closed, _ = plate_closure(found, friction[idx], com[idx], torque_scale, with_quality=False)
    blocked = found.status == TOO_WIDE
    out.squeezed[idx[blocked]] = True
    for name in _KEPT:
        getattr(out, name)[idx[blocked]] = before[name][idx[blocked]]
    ok = found.status == OK
    for name in _KEPT:
        before[name][idx[ok]] = getattr(found, name)[ok]
    _keep(out, idx[closed], found, closed)
    return found, h1, h2, closed, ~ok & ~blocked, blocked


def _keep(out: Squeeze, done, found: Contacts, which) -> None:
    """Record draws ``done`` as settled, with the contacts ``found[which]``."""
    out.squeezed[done] = True
    for name in _KEPT:
        getattr(out, name)[done] = getattr(found, name)[which]


def _across(contacts: Contacts, g1, g2, flush: float) -> np.ndarray:
    """The sense (B,) in which the walls push the object across the closing direction
    u = g2 - g1: +1 along u's left normal t, -1 against it, 0 where they do not. Each
    plate pushes along u against a wall whose inward normal leans from u (from +u for the
    first plate, -u for the second) by a towards t; without friction the pair pushes the
    object across u by tan(a_1) + tan(a_2) per unit push. A sum below ``flush`` (the
    slope at which a wall recedes PATCH_DEPTH across the plate, what the contacts call
    flush) is no push."""
    d = np.asarray(g2, dtype=float) - np.asarray(g1, dtype=float)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    t = np.column_stack([-u[:, 1], u[:, 0]])
    m1, m2 = -contacts.n1, -contacts.n2
    with np.errstate(invalid="ignore", divide="ignore"):
        push = (np.einsum("ij,ij->i", m1, t) / np.einsum("ij,ij->i", m1, u)
                - np.einsum("ij,ij->i", m2, t) / np.einsum("ij,ij->i", m2, u))
        return np.where(np.abs(push) >= flush, np.sign(push), 0.0)


def _pushes(contacts: Contacts) -> tuple[np.ndarray, np.ndarray]:
    """Where each plate's push acts (B, 2 each): the centre of its contact patch (the
    resultant of an even pressure over it), the first contact for a point or curved
    contact (one plate line touching)."""
    out = []
    for c, patch, width in ((contacts.c1, contacts.patch1, contacts.w1), (contacts.c2, contacts.patch2, contacts.w2)):
        touching = np.isfinite(patch[:, :, 0])
        count = touching.sum(axis=1)
        centre = np.where(touching[:, :, None], patch, 0.0).sum(axis=1) / np.maximum(count, 1)[:, None]
        out.append(np.where(((width > 0) & (count > 1))[:, None], centre, c))
    return out[0], out[1]


def _couple(c1, c2, g1, g2) -> np.ndarray:
    """The sense (B,) in which the plates' pushes along u = g2 - g1, at c1 and c2, turn the
    object: the sign of (c1 - c2) x u (+1 counter-clockwise, 0 for pushes on one line
    along u)."""
    d = np.asarray(g2) - np.asarray(g1)
    e = np.asarray(c1) - np.asarray(c2)
    with np.errstate(invalid="ignore"):
        return np.nan_to_num(np.sign(e[:, 0] * d[:, 1] - e[:, 1] * d[:, 0]))
