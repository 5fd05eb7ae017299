"""The plates' squeeze: a draw whose contacts are not in force closure turns on the table
under the plates' couple until they are (or it cannot), the lift model's planar step
(docs/lift.md, "The squeeze")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.grasp import OK, Contacts, SDFBatch, find_contacts, plate_closure

#: The turn is followed in steps of this angle (rad). With P_L of 1000 draws on the plans
#: of the make eval before the squeeze (and the pushes at the first contacts), steps of 2,
#: 3 and 4 degrees ranked the plans' physical success at Spearman 0.682, 0.679 and 0.669;
#: 1 degree (in a prototype) as 2.
SQUEEZE_STEP = math.radians(2.0)
#: The largest turn followed (rad). Half of the draws squeezed into closure on make
#: eval's plans close within 4 degrees, 88 % within 10 and 99 % within 18.
SQUEEZE_LIMIT = math.radians(20.0)
#: During the squeeze each plate looks for the surface from this far (m) outside its last
#: contact: a 2 degree turn moves the wall under a 10 mm plate by well under 1 mm.
SQUEEZE_MARGIN = 0.003


@dataclass(frozen=True)
class Squeeze:
    """Per draw (B,): whether the squeeze brought the plates into force closure, the turn
    (rad, 0 where it did not) and the contacts where it stopped (the first contacts
    for draws in closure at once, or not squeezed into it): c1, c2, w1, w2, edge1, edge2."""

    squeezed: np.ndarray
    turn: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    w1: np.ndarray
    w2: np.ndarray
    edge1: np.ndarray
    edge2: np.ndarray


#: The contacts' fields a Squeeze keeps where it stopped.
_KEPT = ("c1", "c2", "w1", "w2", "edge1", "edge2")


def squeeze(fields: SDFBatch, g1, g2, field_index, contacts: Contacts, closure, friction, jaw_width: float,
            torque_scale: float, step: float = SQUEEZE_STEP, limit: float = SQUEEZE_LIMIT) -> Squeeze:
    """Follow the squeeze of B grasps (executed jaw starts g1, g2 (B, 2) on fields
    ``field_index`` (B,), with their ``contacts`` and force ``closure`` (B,)).

    A plate is flat, so it pushes along the closing direction u: on contacts offset
    across u the two pushes form a couple, N (c1 - c2) x u, which turns the object on the
    table (Goldberg 1993, the squeeze of a parallel-jaw gripper; Brost 1988). The couple
    is pure, so the object turns about its centre of mass. In the object's frame the jaws
    turn the other way about it; the contacts are found again each ``step`` until the
    plates are in force closure (squeezed), the couple changes sign without closure (the
    width's local minimum reached out of closure: the squeeze holds it there) or vanishes,
    a contact is lost (a plate slid off the object, or meets it within SQUEEZE_MARGIN of
    where it starts looking), or the turn reaches ``limit``. friction: float or (B,)
    coefficients.
    """
    g1 = np.asarray(g1, dtype=float)
    g2 = np.asarray(g2, dtype=float)
    b = len(g1)
    field_index = np.broadcast_to(np.asarray(field_index, dtype=np.int64), (b,))
    friction = np.broadcast_to(np.asarray(friction, dtype=float), (b,))
    com = fields.regions.center_of_mass[field_index]
    out = Squeeze(np.zeros(b, dtype=bool), np.zeros(b), *(getattr(contacts, name).copy() for name in _KEPT))
    turning = _couple(*_pushes(contacts), g1, g2)
    active = (contacts.status == OK) & ~np.asarray(closure, dtype=bool) & (turning != 0) & np.isfinite(com[:, 0])
    last1, last2 = contacts.c1.copy(), contacts.c2.copy()
    angle = 0.0
    while active.any() and angle + step <= limit + 1e-12:
        angle += step
        idx = np.flatnonzero(active)
        # The object turns by +angle in the couple's sense; the jaws, in its frame, by -angle
        # about its centre of mass. They are closed on it: each plate's search starts
        # SQUEEZE_MARGIN outside its last contact, not at the jaw's start.
        h1, h2 = (_turn(g[idx], com[idx], -turning[idx] * angle) for g in (g1, g2))
        u = (h2 - h1) / np.linalg.norm(h2 - h1, axis=1, keepdims=True)
        t1 = np.einsum("ij,ij->i", last1[idx] - h1, u) - SQUEEZE_MARGIN
        t2 = np.einsum("ij,ij->i", last2[idx] - h1, u) + SQUEEZE_MARGIN
        h1, h2 = h1 + t1[:, None] * u, h1 + t2[:, None] * u
        found = find_contacts(fields, h1, h2, jaw_width, field_index=field_index[idx])
        closed, _ = plate_closure(found, friction[idx], com[idx], torque_scale, with_quality=False)
        lost = found.status != OK
        reversed_ = ~lost & (_couple(*_pushes(found), h1, h2) != turning[idx])
        last1[idx], last2[idx] = found.c1, found.c2
        done = idx[closed]
        out.squeezed[done] = True
        out.turn[done] = angle
        for name in _KEPT:
            getattr(out, name)[done] = getattr(found, name)[closed]
        active[idx[closed | lost | reversed_]] = False
    return out


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


def _turn(points, centre, angle) -> np.ndarray:
    """Points (B, 2) turned by ``angle`` (B,) rad about ``centre`` (B, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    v = points - centre
    return centre + np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]])
