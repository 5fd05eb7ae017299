"""Parallel-jaw grasps: contacts along the line of action on SDF fields (sub-cell,
batched), planar force closure, Ferrari-Canny quality and per-shape centres of mass."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cache, cached_property

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from harness.geometry import Grid

#: Contact status codes, and their names in failure counts.
OK, MISSED, TOO_WIDE, DEGENERATE = 0, 1, 2, 3
STATUS_NAMES = ("ok", "missed", "too_wide", "degenerate_normal")
#: Parallel lines swept across each jaw plate (its two edges included); fixed, so the
#: cost grows linearly with M. 5 lines on a 10 mm plate are 2.5 mm apart.
PLATE_LINES = 5
#: Step of the march along the line of action, in cells (shapes are at least two cells
#: thick, and the refinement searches one step either side of the bracket).
MARCH_STEP_CELLS = 1.0
#: Newton iterations on the bicubic interpolant after the march brackets a crossing;
#: from the bracket's ~0.1 mm they converge quadratically to well below 1e-6 of a cell.
NEWTON_STEPS = 2
#: Lines whose bracketed crossing is within this many cells of the earliest are refined
#: too: the bilinear bracket's error (h^2 curvature / 8) may have ranked them wrongly.
TIE_CELLS = 0.1
#: A contact's normal is degenerate when the SDF gradient there is shorter than this
#: (an SDF's gradient has length 1).
MIN_GRADIENT = 1e-3
#: A plate touches the object where the surface lies within this distance (m) of the
#: plate's face at the first contact: the contact patch's extent along the outline (see
#: :class:`Contacts`). Below the plate lines' spacing (2.5 mm on a 10 mm plate) it only
#: separates a flat face from a curved one.
PATCH_DEPTH = 0.0005
#: Wrenches within this fraction of their length of a plane through the origin count as
#: on it when a plate's several walls are judged together (plate_closure): the origin must
#: lie strictly inside their hull.
SPAN_TOLERANCE = 1e-9
#: A grasp may be this much wider than the gripper's opening (m) and still be executed
#: (narrowed to the opening): a width computed from two points carries rounding of
#: about 1e-17 m, far below anything the gripper resolves. One tolerance for `plan`,
#: `eval`, `simulate`, `quality` and the conformance kit (Grasp.problem).
WIDTH_TOLERANCE = 1e-9
#: Directions in which a region's extreme cells are kept (Regions.hull).
HULL_DIRECTIONS = 64
#: Neighbours through a cell side, within one field of an (F, M, M) stack.
_SIDES = np.zeros((3, 3, 3), dtype=bool)
_SIDES[1] = [[0, 1, 0], [1, 1, 1], [0, 1, 0]]
#: Work arrays of the march hold at most this many field evaluations at once.
_MAX_EVALUATIONS = 2_000_000


@dataclass(frozen=True)
class Grasp:
    """A parallel-jaw grasp: the jaw start points g1, g2 (metres). The jaws start there
    and close towards each other along the segment between them."""

    g1: tuple[float, float]
    g2: tuple[float, float]

    def __post_init__(self):
        object.__setattr__(self, "g1", (float(self.g1[0]), float(self.g1[1])))
        object.__setattr__(self, "g2", (float(self.g2[0]), float(self.g2[1])))

    @classmethod
    def from_centre(cls, centre, angle: float, width: float) -> "Grasp":
        """The grasp of the given width whose axis makes ``angle`` (radians) with x."""
        c = np.asarray(centre, dtype=float)
        half = 0.5 * width * np.array([math.cos(angle), math.sin(angle)])
        return cls(tuple(c - half), tuple(c + half))

    @property
    def array(self) -> np.ndarray:
        """[[x1, y1], [x2, y2]]."""
        return np.array([self.g1, self.g2])

    @property
    def width(self) -> float:
        return math.dist(self.g1, self.g2)

    @property
    def axis(self) -> np.ndarray:
        """Unit vector from g1 to g2."""
        d = np.subtract(self.g2, self.g1)
        return d / np.linalg.norm(d)

    @property
    def centre(self) -> np.ndarray:
        return 0.5 * (np.asarray(self.g1) + np.asarray(self.g2))

    def problem(self, grid: Grid, opening: float) -> str | None:
        """Why this grasp cannot be executed on the grid with this opening, or None."""
        if not np.all(np.isfinite(self.array)):
            return "coordinates must be finite"
        for name, g in (("g1", self.g1), ("g2", self.g2)):
            if not grid.contains(np.asarray(g)):
                half = 0.5 * grid.extent
                return f"jaw start {name} = ({g[0]:.4g}, {g[1]:.4g}) m is outside the grid [-{half:g}, {half:g}]^2 m"
        if self.width == 0.0:
            return "g1 and g2 coincide"
        if self.width > opening + WIDTH_TOLERANCE:
            return f"width {self.width:.6g} m exceeds the gripper opening {opening:.6g} m"
        return None


class SDFBatch:
    """F signed distance fields on one grid with their gradients: the belief's mean, one
    shape sample, a batch of samples, or an exact SDF.

    Between grid points the fields are read through a bicubic Hermite interpolant of the
    values, the gradients and a cross derivative (central differences of the gradients),
    so contacts are sub-cell and normals smooth.
    """

    def __init__(self, grid: Grid, values: np.ndarray, gradients: np.ndarray):
        values = np.asarray(values, dtype=float)
        gradients = np.asarray(gradients, dtype=float)
        if values.ndim == 2:
            values, gradients = values[None], gradients[None]
        m = grid.size
        if values.shape[1:] != (m, m) or gradients.shape != values.shape + (2,):
            raise ValueError(f"fields must be (F, {m}, {m}) with gradients (F, {m}, {m}, 2)")
        self.grid = grid
        # Single precision: positions come out to ~1e-6 of a cell, far below what any
        # contact needs, at half the memory and memory traffic of double precision.
        self.values = np.ascontiguousarray(values, dtype=np.float32)
        self.gx = np.ascontiguousarray(gradients[..., 0], dtype=np.float32)
        self.gy = np.ascontiguousarray(gradients[..., 1], dtype=np.float32)

    def __len__(self) -> int:
        return len(self.values)

    def first(self, n: int) -> "SDFBatch":
        """The first n fields (views, no copies)."""
        out = object.__new__(SDFBatch)
        out.grid, out.values, out.gx, out.gy = self.grid, self.values[:n], self.gx[:n], self.gy[:n]
        return out

    @classmethod
    def of_parts(cls, grid: Grid, values: np.ndarray, gx: np.ndarray, gy: np.ndarray, twist: np.ndarray,
                 regions: "Regions") -> "SDFBatch":
        """A batch over float32 arrays (F, M, M) used as they are (no copies), with its
        derived fields (the twist, the regions) computed elsewhere, e.g. part by part."""
        out = object.__new__(cls)
        out.grid, out.values, out.gx, out.gy = grid, values, gx, gy
        out.__dict__.update(twist=twist, regions=regions)  # the cached properties' slots
        return out

    @cached_property
    def twist(self) -> np.ndarray:
        """Cross derivative d2f/dxdy (F, M, M): the average of d(df/dx)/dy and
        d(df/dy)/dx by central differences (one-sided at the border)."""
        h = self.grid.cell
        return (0.5 * (np.gradient(self.gx, h, axis=1) + np.gradient(self.gy, h, axis=2))).astype(np.float32)

    @cached_property
    def regions(self) -> "Regions":
        """Each field's largest connected region inside the zero level: its area, centroid
        and convex hull (see :class:`Regions`)."""
        return _largest_regions(self.values.astype(float), self.grid)

    @property
    def center_of_mass(self) -> np.ndarray:
        """Centroid (F, 2) of each field's largest connected region inside the zero level
        (NaN for a field with no inside at all)."""
        return self.regions.center_of_mass


@dataclass(frozen=True)
class Regions:
    """The largest connected region inside the zero level of each of F fields, the body a
    physics trial extrudes (its *body*). The inside is where the fields' bilinear
    interpolant is negative, as the physics' outline (marching squares,
    harness.geometry.inside_region, then its largest part): nodes below zero connect
    through the sides of their cells, and across a cell's diagonal where the cell's
    centre (the mean of its corners) is below zero too, as marching squares decides a
    saddle. A region's cells count with the fraction of their area inside,
    clip(1/2 - f / h, 0, 1) (exact for a boundary parallel to a cell side); a cell
    partly inside (0 <= f < h/2) belongs to the region of an inside neighbour. area (F,)
    in m^2 (0 without an inside); center_of_mass (F, 2) (NaN without an inside); hull
    (F, V, 2): vertices of the convex hull of the centres of the region's cells (its
    extreme cells in V = HULL_DIRECTIONS directions), so that the region's extent in any
    direction is a maximum over V points (to within half a cell); fragmented (F,): the
    field has inside nodes outside its body (pieces the physics does not extrude);
    spread (F,): the mean distance (m) of the region's area from its centre of mass (NaN
    without an inside): the lever of the table's friction on the region under an even
    pressure (harness.push)."""

    area: np.ndarray
    center_of_mass: np.ndarray
    hull: np.ndarray
    fragmented: np.ndarray
    spread: np.ndarray

    def extent(self, field_index: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """How far (B,) region ``field_index[b]`` reaches from ``origin[b]`` along the unit
        vector ``direction[b]`` (-inf without an inside)."""
        points = self.hull[field_index]  # (B, V, 2)
        reach = np.einsum("bvk,bk->bv", points - origin[:, None, :], direction)
        return reach.max(axis=1)


@dataclass(frozen=True)
class Contacts:
    """Where each jaw first meets the zero level: points c1, c2 (B, 2), outward unit
    normals n1, n2 (B, 2) (NaN where there is no contact) and a status (B,) per grasp:
    OK, MISSED (no object between the jaws), TOO_WIDE (a jaw starts inside the
    object) or DEGENERATE (a vanishing gradient at a contact). Each plate's contact patch
    is made of the plate lines that meet the surface within PATCH_DEPTH of its first
    contact: patch1, patch2 (B, K, 2) hold where each of the K lines meets it (NaN for a
    line that does not touch, and where there is no contact), and w1, w2 (B,) the
    patch's extent along the outline (0 for a point or curved contact, up to the plate's
    width for a flat face; NaN where there is no contact). edge1, edge2 (B,) are the slopes
    at which the wall recedes from a plate that presses it with its edge, 0 where the
    plate does not (:func:`edge_contacts`, :func:`edge_slopes`). normals1, normals2 (B, K,
    2) are the contact normals at the touching lines of a plate that presses a wall with
    a corner besides its first contact (a plate across a concave corner or arc: the wall's
    normal at that corner, the plate's own at its other touching lines), NaN on every
    other plate and line (:func:`plate_closure`, :func:`_wall_normals`)."""

    c1: np.ndarray
    c2: np.ndarray
    n1: np.ndarray
    n2: np.ndarray
    status: np.ndarray
    w1: np.ndarray
    w2: np.ndarray
    patch1: np.ndarray
    patch2: np.ndarray
    edge1: np.ndarray
    edge2: np.ndarray
    normals1: np.ndarray
    normals2: np.ndarray


def edge_contacts(depth: np.ndarray, first: np.ndarray) -> np.ndarray:
    """Whether each plate presses the wall with its edge (B,): the wall meets the plate at
    an outer plate line and recedes from it across the plate, at a slope that would take
    it more than PATCH_DEPTH from the plate over the plate's width. A wall inclined to the
    plate, or a curved wall whose tangent point lies beyond the plate, touches the plate
    only along its edge; when the object turns about the grasp axis, the wall's distance
    from that edge then varies along it, and the pressure goes to one end of the edge
    (docs/lift.md, "Edge contacts"). A flat face (within PATCH_DEPTH of parallel to the
    plate) and a curved wall whose tangent point lies on the plate are not edge contacts;
    nor are two walls parallel to each other (:func:`find_contacts` checks that): the
    closing plates turn them flush.

    depth (B, K): each plate line's distance (m) from the plate to the wall beyond the
    first contact (0 on the first line, inf where a line misses); first (B,): the first
    contact's line. The slope at the edge is that of the quadratic through the outer line
    and its two inward neighbours (of the line beside it alone when the next misses), so
    that a curved wall whose closest approach lies on the plate has none."""
    return edge_slopes(depth, first, 1.0) > 0


def edge_slopes(depth: np.ndarray, first: np.ndarray, spacing: float) -> np.ndarray:
    """The slope (B,: metres per metre across the plate) at which the wall recedes from a
    plate that presses it with its edge (:func:`edge_contacts`), 0 where the plate does
    not; ``spacing`` (m) is the distance between plate lines."""
    b, k = depth.shape
    if k < 3:
        return np.zeros(b)
    rows = np.arange(b)
    outer = (first == 0) | (first == k - 1)
    step = np.where(first == 0, 1, -1)
    base = depth[rows, first]
    with np.errstate(invalid="ignore"):
        near = depth[rows, np.clip(first + step, 0, k - 1)] - base
        far = depth[rows, np.clip(first + 2 * step, 0, k - 1)] - base
        # Per plate line: the one-sided slope at the edge of the quadratic through (0, 0), (1, near), (2, far).
        slope = np.where(np.isfinite(far), 2.0 * near - 0.5 * far, near)
        edge = outer & np.isfinite(near) & (slope * (k - 1) > PATCH_DEPTH)
        return np.where(edge, slope / spacing, 0.0)


def find_contacts(fields: SDFBatch, g1, g2, jaw_width: float, field_index=None,
                  plate_lines: int = PLATE_LINES) -> Contacts:
    """Contacts of B grasps (jaw starts g1, g2, each (B, 2)) on the fields.

    Grasp b is evaluated on field ``field_index[b]`` (default: field b when there are B
    fields, else field 0). Each jaw is a plate of width ``jaw_width`` across the line of
    action; ``plate_lines`` parallel lines across it are marched from g1 to g2 in steps
    of at most MARCH_STEP_CELLS with bilinear interpolation, each grasp in as many equal
    steps as its own length needs (so a grasp's contacts do not depend on the other
    grasps in the batch). Jaw 1's contact is the first outside-to-inside crossing from g1
    over all lines, jaw 2's the first from g2 (the same lines, marched once). Crossings
    are refined by Newton steps on the bicubic interpolant, and the normal is that
    interpolant's normalised gradient.
    """
    g1 = np.atleast_2d(np.asarray(g1, dtype=float))
    g2 = np.atleast_2d(np.asarray(g2, dtype=float))
    b = len(g1)
    if field_index is None:
        field_index = np.arange(b) if len(fields) == b else np.zeros(b, dtype=np.int64)
    field_index = np.broadcast_to(np.asarray(field_index, dtype=np.int64), (b,))
    out = Contacts(*(np.full((b, 2), np.nan) for _ in range(4)), np.empty(b, dtype=np.int8),
                   np.full(b, np.nan), np.full(b, np.nan), *(np.full((b, plate_lines, 2), np.nan) for _ in range(2)),
                   np.zeros(b), np.zeros(b), *(np.full((b, plate_lines, 2), np.nan) for _ in range(2)))
    steps = march_steps(np.linalg.norm(g2 - g1, axis=1), fields.grid.cell)
    chunk = max(1, _MAX_EVALUATIONS // (plate_lines * int(steps.max(initial=2))))
    for start in range(0, b, chunk):
        s = slice(start, min(b, start + chunk))
        part = _contacts_chunk(fields, g1[s], g2[s], jaw_width, field_index[s], plate_lines, steps[s])
        for name in Contacts.__dataclass_fields__:
            getattr(out, name)[s] = getattr(part, name)
    return out


def march_steps(length: np.ndarray, cell: float) -> np.ndarray:
    """Samples (B,) of the march along lines of the given lengths (m): equal steps of at
    most MARCH_STEP_CELLS cells, both ends included, at least three samples."""
    return np.maximum(2, np.ceil(np.asarray(length, dtype=float) / (MARCH_STEP_CELLS * cell))).astype(np.intp) + 1


def _contacts_chunk(fields: SDFBatch, g1, g2, jaw_width, fidx, plate_lines, steps) -> Contacts:
    """find_contacts on one chunk; ``steps`` (B,) is each grasp's number of march samples."""
    b = len(g1)
    rows = np.arange(b)
    d = g2 - g1
    length = np.linalg.norm(d, axis=1)
    safe = np.where(length > 0, length, 1.0)
    perp = np.column_stack([-d[:, 1], d[:, 0]]) / safe[:, None]
    offsets = np.linspace(-0.5 * jaw_width, 0.5 * jaw_width, plate_lines)
    # Grasp b's samples at t = k / (steps_b - 1); the shorter rows repeat their end
    # (t = 1), which changes neither the first nor the last inside sample.
    last = int(steps.max())
    dt = 1.0 / (steps - 1)
    ts = np.minimum(np.arange(last)[None, :] / (steps - 1)[:, None], 1.0)  # (B, T)
    starts = g1[:, None, :] + offsets[None, :, None] * perp[:, None, :]  # (B, K, 2)
    f = read_lines(fields, fidx, starts, d, ts)  # (B, K, T)
    inside = f <= 0.0
    hit = inside.any(axis=2)

    # Jaw 1: first inside sample from g1; jaw 2: first inside sample from g2.
    i1 = np.argmax(inside, axis=2)
    i2 = last - 1 - np.argmax(inside[:, :, ::-1], axis=2)
    ok1 = hit & (i1 > 0)
    ok2 = hit & (i2 < last - 1)
    status = np.full(b, OK, dtype=np.int8)
    status[~(ok1.any(axis=1) & ok2.any(axis=1))] = MISSED
    status[inside[:, :, 0].any(axis=1) | inside[:, :, -1].any(axis=1)] = TOO_WIDE
    good = status == OK
    tie = TIE_CELLS * fields.grid.cell / safe[:, None]
    t1 = np.where(ok1, _secant(f, ts, np.maximum(i1 - 1, 0), i1), np.inf)
    t2 = np.where(ok2, _secant(f, ts, np.minimum(i2 + 1, last - 1), i2), -np.inf)
    # Refine the bracketed-earliest line of each jaw. A nearly tied line that is already
    # inside at that depth truly hits first (the bracket's error ranked it wrongly); only
    # those are refined in turn.
    best1 = np.argmin(t1, axis=1)
    best2 = np.argmax(t2, axis=1)
    row = np.concatenate([rows, rows])
    line = np.concatenate([best1, best2])
    t_best = np.concatenate([t1[rows, best1], t2[rows, best2]])
    t_best = np.where(np.concatenate([good, good]), t_best, 0.5)
    t_ref, point, normal, valid = _refine(fields, fidx[row], starts[row, line], d[row], t_best, dt[row])
    depth = np.stack([t_ref[:b], t_ref[b:]])  # (2, B)
    tied = np.stack([t1 <= t1[rows, best1][:, None] + tie, t2 >= t2[rows, best2][:, None] - tie])
    tied &= good[None, :, None]
    tied[0, rows, best1] = tied[1, rows, best2] = False
    jaw, trow, tline = np.nonzero(tied)
    if len(jaw):
        at = starts[trow, tline] + depth[jaw, trow][:, None] * d[trow]
        value, _ = interpolate(fields, fidx[trow], at)
        earlier = value < -1e-9 * fields.grid.cell
        jaw, trow, tline = jaw[earlier], trow[earlier], tline[earlier]
    if len(jaw):
        guess = np.where(jaw == 0, t1[trow, tline], t2[trow, tline])
        t_e, p_e, n_e, v_e = _refine(fields, fidx[trow], starts[trow, tline], d[trow], guess, dt[trow])
        # Keep, per jaw and grasp, the earliest of the refined lines (from that jaw's side).
        key = jaw * b + trow
        order = np.lexsort((np.where(jaw == 0, t_e, -t_e), key))
        pick = order[np.r_[True, key[order][1:] != key[order][:-1]]]
        slot = key[pick]
        sooner = np.where(jaw[pick] == 0, t_e[pick] < t_ref[slot], t_e[pick] > t_ref[slot])
        slot, pick = slot[sooner], pick[sooner]
        point[slot], normal[slot], valid[slot] = p_e[pick], n_e[pick], v_e[pick]
    status[good & ~(valid[:b] & valid[b:])] = DEGENERATE
    bad = np.concatenate([status != OK] * 2)
    point[bad] = np.nan
    normal[bad] = np.nan
    # Patches, from the bracketed crossings (one bilinear estimate for every line alike).
    depth = PATCH_DEPTH / safe[:, None]
    spacing = jaw_width / max(plate_lines - 1, 1)
    line_index = np.arange(plate_lines)
    widths, patches, edges, slopes, normals = [], [], [], [], []
    flush = math.sin(math.atan(PATCH_DEPTH / jaw_width)) if jaw_width > 0 else 1.0
    for t, touch, best, sense, first_normal in ((t1, t1 <= t1[rows, best1][:, None] + depth, best1, 1.0, normal[:b]),
                                                (t2, t2 >= t2[rows, best2][:, None] - depth, best2, -1.0, normal[b:])):
        touch &= (status == OK)[:, None]
        first = np.where(touch, line_index, plate_lines).min(axis=1)
        last = np.where(touch, line_index, -1).max(axis=1)
        widths.append(np.where(status == OK, (last - first) * spacing, np.nan))
        where = starts + np.where(touch, t, np.nan)[:, :, None] * d[:, None, :]
        patches.append(where)
        with np.errstate(invalid="ignore"):
            beyond = sense * (t - t[rows, best][:, None]) * length[:, None]  # the wall's distance beyond the first line
        beyond = np.where(np.isfinite(t), beyond, np.inf)
        edges.append(np.where(status == OK, edge_slopes(beyond, best, spacing), 0.0))
        slopes.append(_line_slope(beyond))
        normals.append(_wall_normals(fields, fidx, where, touch, best, first_normal, -sense * d / safe[:, None], perp,
                                     flush))
    # Walls parallel to each other within PATCH_DEPTH over the plate's width, however
    # inclined to the plates, are turned flush with both by the closing plates (the
    # squeeze): their contacts are faces, not edges. Seen from the two plates, parallel
    # walls recede towards opposite sides (their slopes across the lines cancel); the two
    # walls of a wedge recede towards the same side.
    with np.errstate(invalid="ignore"):
        wedge = np.abs(slopes[0] + slopes[1]) * (plate_lines - 1) > PATCH_DEPTH
    n1, n2 = normal[:b], normal[b:]
    return Contacts(point[:b], point[b:], n1, n2, status, *widths, *patches, np.where(wedge, edges[0], 0.0),
                    np.where(wedge, edges[1], 0.0), *normals)


def _wall_normals(fields: SDFBatch, fidx, where: np.ndarray, touch: np.ndarray, first: np.ndarray,
                  first_normal: np.ndarray, facing: np.ndarray, across: np.ndarray, flush: float) -> np.ndarray:
    """The contact normals (B, K, 2) at the touching lines ``where`` (B, K, 2) of the plates
    that press a wall with a corner besides their first contact, NaN on every other plate.
    A rigid plate pushes with its face wherever the wall it touches is flush with it, and
    with its corner where a wall approaches it beyond its edge: an outer line ``touch``-ing
    (B, K) such a wall (its normal, from the bicubic interpolant's gradient, leaning
    towards the plate's middle by more than ``flush``, the sine of the flush slope) takes
    the wall's normal, every other touching line the plate's own (``facing`` (B, 2): the
    outward normal of a wall flush with the plate). A plate across a concave corner or a
    concave arc presses both its corners (docs/lift.md, "A plate on two walls"). first
    (B,): the first contact's line, which keeps the first contact's normal
    ``first_normal`` (B, 2; Contacts.n1, n2); ``across`` (B, 2) runs from the first line
    to the last."""
    b, k = touch.shape
    out = np.full(where.shape, np.nan)
    if k < 2:
        return out
    lines = np.array([0, k - 1])
    rows, which = np.nonzero(touch[:, lines] & (first[:, None] != lines[None, :]))
    if not len(rows):
        return out
    line = lines[which]
    _, gradient = interpolate(fields, fidx[rows], where[rows, line])
    size = np.linalg.norm(gradient, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        wall = gradient / size
    outward = np.where(line == 0, -1.0, 1.0)  # from the plate's middle towards this edge
    corner = (size[:, 0] > MIN_GRADIENT) & (outward * np.einsum("ij,ij->i", wall, across[rows]) < -flush)
    rows, line, wall = rows[corner], line[corner], wall[corner]
    plates = np.unique(rows)
    out[plates] = np.where(touch[plates, :, None], facing[plates, None, :], np.nan)
    out[rows, line] = wall
    out[plates, first[plates]] = first_normal[plates]
    return out


def _line_slope(depth: np.ndarray) -> np.ndarray:
    """The least-squares slope (B,) of each row's depths (B, K) against the line index,
    over its finite entries (NaN with fewer than two)."""
    k = np.arange(depth.shape[1], dtype=float)
    finite = np.isfinite(depth)
    count = finite.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_k = np.where(finite, k, 0.0).sum(axis=1) / count
        mean_d = np.where(finite, depth, 0.0).sum(axis=1) / count
        dk = np.where(finite, k - mean_k[:, None], 0.0)
        dd = np.where(finite, depth - mean_d[:, None], 0.0)
        return np.where(count >= 2, (dk * dd).sum(axis=1) / (dk**2).sum(axis=1), np.nan)


def _secant(f, ts, i_out, i_in):
    """Parameter where the straight line between the samples at i_out (outside, f > 0)
    and i_in (inside, f <= 0) of each line (B, K) crosses zero; ts (B, T) are each
    grasp's sample parameters."""
    fa = np.take_along_axis(f, i_out[..., None], axis=2)[..., 0]
    fb = np.take_along_axis(f, i_in[..., None], axis=2)[..., 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(fa != fb, fa / (fa - fb), 0.0)
    t_out, t_in = np.take_along_axis(ts, i_out, axis=1), np.take_along_axis(ts, i_in, axis=1)
    return t_out + (t_in - t_out) * np.clip(frac, 0.0, 1.0)


def _refine(fields, fidx, start, d, t, dt):
    """Newton steps on the bicubic interpolant along start + t d, kept within one march
    step of the bracketed crossing; returns the parameters, contact points, unit normals
    (the gradient at the last iterate, 1e-7 m or less from the contact), and whether
    the gradient there is long enough to define a normal (compiled: harness.kernels)."""
    return _kernels().refine(*_flat_fields(fields), _ints(fidx), _floats(start), _floats(d), _floats(t),
                             _floats(dt), NEWTON_STEPS, MIN_GRADIENT)


def _kernels():
    """harness.kernels, imported on first use: numba takes about a second to import, which
    commands that never look for a contact need not pay."""
    from harness import kernels

    return kernels


@cache
def load_kernels() -> None:
    """Load the compiled reads now, once per process (from numba's cache: 0.7-1.2 s with
    numba's import; compiling them on a machine's first run takes a few seconds). A
    process that forks planners calls it first, so that no planner's time budget pays
    for it."""
    unit = SDFBatch(Grid(8, 1.0), np.zeros((8, 8)), np.zeros((8, 8, 2)))
    contacts = find_contacts(unit, [[-0.4, 0.0]], [[0.4, 0.0]], 0.1)
    interpolate(unit, np.zeros(1, dtype=np.int64), np.zeros((1, 2)))
    plate_closure(contacts, 0.5, np.zeros(2), 1.0, with_quality=False)


def _flat_fields(fields: SDFBatch):
    """The fields' arrays flattened, and the grid's numbers, as the kernels take them."""
    grid = fields.grid
    return (*(_flat(a) for a in (fields.values, fields.gx, fields.gy, fields.twist)),
            grid.size, float(grid.coords[0]), grid.cell)


def _flat(field: np.ndarray) -> np.ndarray:
    """A field flattened, as a read-only view whatever the field is (the belief's fields
    are read-only, derived ones are not): one specialisation of each kernel (_array)."""
    flat = field.reshape(-1)
    if flat.flags.writeable:
        flat = flat.view()
        flat.flags.writeable = False
    return flat


def _ints(a) -> np.ndarray:
    return _array(a, np.int64)


def _floats(a) -> np.ndarray:
    return _array(a, np.float64)


def _array(a, dtype) -> np.ndarray:
    """Contiguous and writeable (a copy only where needed): numba compiles, and loads from
    its cache, one specialisation per kind of array, read-only views being another kind."""
    return np.require(a, dtype=dtype, requirements=("C", "W"))


def read_lines(fields: SDFBatch, fidx, starts, d, ts) -> np.ndarray:
    """Bilinear field values (B, K, T) along the lines starts[b, k] + ts * d[b] of field
    fidx[b], with ts (T,) shared or (B, T) per grasp (a quick march; see
    :func:`interpolate` for the smooth interpolant); outside the grid's nodes the object
    is taken to be absent (a large positive value). In single precision, the positions
    too (compiled: harness.kernels)."""
    grid = fields.grid
    fidx = _ints(np.broadcast_to(fidx, (len(starts),)))
    ts = np.asarray(ts)
    t32 = _array(np.broadcast_to(ts.astype(np.float32), (len(fidx), ts.shape[-1])), np.float32)
    return _kernels().read_lines(_flat(fields.values), grid.size, float(grid.coords[0]), grid.cell, fidx,
                                 _floats(starts), _floats(d), t32)


def interpolate(fields: SDFBatch, fidx, points):
    """Value (B,) and gradient (B, 2) of field fidx[b] at points (B, 2), through the
    bicubic Hermite interpolant of the fields' values, gradients and cross derivatives
    (compiled: harness.kernels)."""
    points = _floats(points).reshape(-1, 2)
    return _kernels().interpolate(*_flat_fields(fields), _ints(np.broadcast_to(fidx, (len(points),))), points)


def force_closure(c1, c2, n1, n2, friction) -> np.ndarray:
    """Exact planar force closure of two point contacts with Coulomb friction.

    c1, c2: (B, 2) contact points; n1, n2: (B, 2) outward unit normals; friction: float
    or (B,). Two frictional point contacts in the plane are in force closure exactly
    when the segment between them lies strictly inside both friction cones (Nguyen
    1988): the angle between c2 - c1 and the inward normal -n1, and between c1 - c2
    and -n2, are both below atan(friction).
    """
    c1, c2, n1, n2 = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (c1, c2, n1, n2))
    d = c2 - c1
    length = np.linalg.norm(d, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = d / length[:, None]
        m1 = n1 / np.linalg.norm(n1, axis=1, keepdims=True)
        m2 = n2 / np.linalg.norm(n2, axis=1, keepdims=True)
    cos_limit = 1.0 / np.sqrt(1.0 + np.asarray(friction, dtype=float) ** 2)
    in_cone1 = -np.einsum("ij,ij->i", m1, u) > cos_limit
    in_cone2 = np.einsum("ij,ij->i", m2, u) > cos_limit
    return (length > 0) & in_cone1 & in_cone2


def plate_closure(contacts: Contacts, friction, com, torque_scale: float, with_quality: bool = True):
    """Force closure of the plates' contact patches, and its Ferrari-Canny quality.

    A plate pressed on a flat patch can push anywhere on it (the pressure over a rigid
    contact is not fixed by statics), so the grasp is in force closure when some pair of
    points, one on each patch, is. The pair judged is the one whose line lies deepest
    inside both friction cones (the first contacts' normals; the largest of the smaller
    cosine to each inward normal): the grasp is in force closure exactly when that pair
    is (:func:`force_closure`), and the quality is that pair's Ferrari-Canny quality. The
    patches' points are the first contacts and the other touching lines' crossings; for
    point and curved contacts (one line per patch) this is the first contacts' force
    closure and quality. friction: float or (B,); com: (2,) or (B, 2). Returns closure
    (B,) and quality (B,), 0 out of closure (and everywhere with ``with_quality=False``, which
    skips computing it)."""
    b = len(contacts.status)
    friction = np.broadcast_to(np.asarray(friction, dtype=float), (b,))
    com = np.broadcast_to(np.asarray(com, dtype=float), (b, 2))
    patch1 = np.concatenate([contacts.c1[:, None], contacts.patch1], axis=1)  # (B, K + 1, 2)
    patch2 = np.concatenate([contacts.c2[:, None], contacts.patch2], axis=1)
    # The pair whose line lies deepest in both cones (compiled: harness.kernels).
    i, j = _kernels().deepest_pairs(patch1, patch2, _floats(contacts.n1), _floats(contacts.n2))
    rows = np.arange(b)
    p1, p2 = patch1[rows, i], patch2[rows, j]
    closure = np.zeros(b, dtype=bool)
    ok = contacts.status == OK
    closure[ok] = force_closure(p1[ok], p2[ok], contacts.n1[ok], contacts.n2[ok], friction[ok])
    # A plate that presses walls with its corners pushes on each with that wall's normal:
    # judged on every touching point and its cone at once where no pair is in closure.
    walls = ok & ~closure & (np.isfinite(contacts.normals1[:, :, 0]).any(axis=1)
                             | np.isfinite(contacts.normals2[:, :, 0]).any(axis=1))
    many = np.flatnonzero(walls)
    wrenches = None
    if len(many):
        wrenches, count = _patch_wrenches(contacts, many, friction[many], com[many], torque_scale)
        closure[many] = _kernels().spans_wrenches(wrenches, count, SPAN_TOLERANCE)
    quality = np.zeros(b)
    if not with_quality:
        return closure, quality
    pair = closure & ~walls
    quality[pair] = ferrari_canny(p1[pair], p2[pair], contacts.n1[pair], contacts.n2[pair], friction[pair], com[pair],
                                  torque_scale)
    for r in np.flatnonzero(closure & walls):
        k = np.searchsorted(many, r)
        quality[r] = hull_radius(wrenches[k, :count[k]])
    return closure, quality


def _patch_wrenches(contacts: Contacts, rows, friction, com, torque_scale: float):
    """The friction-cone edge wrenches (R, M, 3) of every touching point of both plates of
    grasps ``rows`` (on a plate that presses walls with its corners each point with its own
    normal, Contacts.normals1/normals2; elsewhere with the plate's first contact's),
    packed first, and how many each grasp has (R,)."""
    points, normals = [], []
    for c, n, patch, own in ((contacts.c1, contacts.n1, contacts.patch1, contacts.normals1),
                             (contacts.c2, contacts.n2, contacts.patch2, contacts.normals2)):
        p = np.concatenate([c[rows, None], patch[rows]], axis=1)  # (R, K + 1, 2)
        first = np.broadcast_to(n[rows, None], p.shape)
        each = np.concatenate([n[rows, None], own[rows]], axis=1)
        separate = np.isfinite(own[rows, :, 0]).any(axis=1)
        points.append(p)
        normals.append(np.where(separate[:, None, None], each, first))
    p, n = np.concatenate(points, axis=1), np.concatenate(normals, axis=1)  # (R, P, 2)
    present = np.isfinite(p[:, :, 0]) & np.isfinite(n[:, :, 0])
    r_, k_ = np.nonzero(present)
    edge = contact_wrenches(p[r_, k_], p[r_, k_], n[r_, k_], n[r_, k_], friction[r_], com[r_], torque_scale)[:, :2]
    count = 2 * present.sum(axis=1)
    slot = 2 * (np.cumsum(present, axis=1) - 1)[r_, k_]
    wrenches = np.zeros((len(rows), 2 * p.shape[1], 3))
    wrenches[r_, slot], wrenches[r_, slot + 1] = edge[:, 0], edge[:, 1]
    return wrenches, count


def hull_radius(wrenches: np.ndarray) -> float:
    """The Ferrari-Canny quality of a set of wrenches (M, 3): the radius of the largest
    origin-centred ball inside their convex hull (0 when the origin is not strictly inside)."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(wrenches)
    except QhullError:
        return 0.0
    return float(max(0.0, (-hull.equations[:, 3]).min()))


def contact_wrenches(c1, c2, n1, n2, friction, com, torque_scale: float) -> np.ndarray:
    """The four friction-cone edge wrenches (B, 4, 3) = (fx, fy, torque / torque_scale):
    at contact i the forces -n_i +/- friction * t_i (unit normal component, t_i the
    tangent), torques about the centre of mass ``com`` ((2,) or (B, 2))."""
    gamma = np.asarray(friction, dtype=float).reshape(-1, 1, 1)
    wrenches = []
    for c, n in ((c1, n1), (c2, n2)):
        t = np.stack([-n[:, 1], n[:, 0]], axis=1)
        forces = -n[:, None, :] + np.array([1.0, -1.0])[None, :, None] * gamma * t[:, None, :]  # (B, 2, 2)
        arm = np.asarray(c, dtype=float) - np.asarray(com, dtype=float)
        torque = arm[:, None, 0] * forces[:, :, 1] - arm[:, None, 1] * forces[:, :, 0]
        wrenches.append(np.concatenate([forces, torque[:, :, None] / torque_scale], axis=2))
    return np.concatenate(wrenches, axis=1)


def ferrari_canny(c1, c2, n1, n2, friction, com, torque_scale: float) -> np.ndarray:
    """Ferrari-Canny quality (B,): the radius of the largest origin-centred ball inside the
    convex hull of the four edge wrenches (see :func:`contact_wrenches`), 0 when the
    origin is not strictly inside (no force closure).

    The hull of four wrenches is a tetrahedron; the radius is the smallest distance from
    the origin to its four face planes when the origin is on the inner side of all.
    ``torque_scale`` is the characteristic length that makes torque comparable with force
    (the harness uses the mean shape's largest distance from its centre of mass).
    """
    c1, c2, n1, n2 = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (c1, c2, n1, n2))
    w = contact_wrenches(c1, c2, n1, n2, friction, com, torque_scale)
    radius = np.full(len(w), np.inf)
    for omit in range(4):
        a, b, c = (w[:, k] for k in range(4) if k != omit)
        normal = _cross(b - a, c - a)
        # Orient each face's normal away from the omitted vertex (outwards).
        flip = np.einsum("ij,ij->i", normal, w[:, omit] - a) > 0
        normal[flip] *= -1
        size = np.linalg.norm(normal, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            distance = np.einsum("ij,ij->i", normal, a) / size
        radius = np.minimum(radius, np.where(size > 1e-12, distance, -np.inf))
    return np.where(np.isfinite(radius) & (radius > 0), radius, 0.0)


def replace_rows(record, rows, part):
    """A copy of a dataclass of per-row arrays (Contacts, a Squeeze, ...) with ``rows``
    taken from ``part``."""
    out = {}
    for f in dataclasses.fields(record):
        column = getattr(record, f.name).copy()
        column[rows] = getattr(part, f.name)
        out[f.name] = column
    return type(record)(**out)


def turn_about(points, centre, angle) -> np.ndarray:
    """Points (B, 2) turned by ``angle`` (B,) rad about ``centre`` (B, 2)."""
    c, s = np.cos(angle), np.sin(angle)
    v = points - centre
    return centre + np.column_stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]])


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise 3-D cross product (faster than np.cross on short rows)."""
    return np.column_stack([u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1],
                            u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                            u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]])


def _largest_regions(values: np.ndarray, grid: Grid) -> Regions:
    f, h = len(values), grid.cell
    frac = np.clip(0.5 - values / h, 0.0, 1.0)
    _, mine, fragmented = _bodies(values, h, frac)
    com = np.full((f, 2), np.nan)
    w = np.where(mine, frac, 0.0)
    total = w.sum(axis=(1, 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        com[:, 0] = w.sum(axis=1) @ grid.coords / total
        com[:, 1] = w.sum(axis=2) @ grid.coords / total
    com[total == 0] = np.nan
    if not mine.any():
        return Regions(np.zeros(f), com, np.full((f, 1, 2), -np.inf), fragmented, np.full(f, np.nan))
    x = grid.coords[None, None, :] - com[:, 0, None, None]
    y = grid.coords[None, :, None] - com[:, 1, None, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        spread = (w * np.sqrt(x * x + y * y)).sum(axis=(1, 2)) / total
    return Regions(total * h * h, com, _hulls(mine, grid), fragmented, spread)


def _bodies(values: np.ndarray, cell: float, frac: np.ndarray | None = None):
    """Each field's regions (:func:`body_labels`), the mask (F, M, M) of its body (the
    region of largest fractional area; the first in scan order on a tie) and whether it
    has other regions (F,)."""
    f = len(values)
    if frac is None:
        frac = np.clip(0.5 - values / cell, 0.0, 1.0)
    labels, count = body_labels(values, cell)
    if count == 0:
        return labels, np.zeros(values.shape, dtype=bool), np.zeros(f, dtype=bool)
    area = ndimage.sum_labels(frac, labels, index=np.arange(1, count + 1))
    # Labels run in scan order, so each field's regions hold a contiguous run of labels
    # (first..last); a field without any region has last < first.
    last = labels.reshape(f, -1).max(axis=1)
    first = np.concatenate([[0], np.maximum.accumulate(last)[:-1]]) + 1
    fields = np.flatnonzero(last >= first)
    starts = first[fields] - 1
    lengths = last[fields] - first[fields] + 1
    largest = np.repeat(np.maximum.reduceat(area, starts), lengths)
    candidates = np.where(area == largest, np.arange(1, count + 1), count + 1)
    best = np.zeros(f, dtype=np.int64)
    best[fields] = np.minimum.reduceat(candidates, starts)
    fragmented = np.zeros(f, dtype=bool)
    fragmented[fields] = lengths > 1
    return labels, labels == best[:, None, None], fragmented


def body_fields(fields: SDFBatch, ids: np.ndarray) -> SDFBatch:
    """Fields ``ids`` of ``fields`` with only their body (:class:`Regions`) left inside:
    the other pieces' nodes, and the nodes partly inside next to them only, are set at
    least one cell outside with a flat gradient, so that no jaw meets them (the physics
    extrudes the body alone) and the interpolant stays outside between them and their
    outside neighbours. The regions are the originals' (the same bodies)."""
    ids = np.asarray(ids, dtype=np.int64)
    h = fields.grid.cell
    values, gx, gy = fields.values[ids].copy(), fields.gx[ids].copy(), fields.gy[ids].copy()
    twist = fields.twist[ids].copy()
    labels, mine, _ = _bodies(values.astype(float), h)
    near_body = ndimage.binary_dilation(mine & (values < 0), structure=_SIDES)
    other = (labels > 0) & ~mine & ~near_body
    values[other] = np.maximum(values[other], h)
    gx[other], gy[other], twist[other] = 0.0, 0.0, 0.0
    r = fields.regions
    regions = Regions(r.area[ids], r.center_of_mass[ids], r.hull[ids], np.zeros(len(ids), dtype=bool), r.spread[ids])
    return SDFBatch.of_parts(fields.grid, values, gx, gy, twist, regions)


def body_labels(values: np.ndarray, cell: float) -> tuple[np.ndarray, int]:
    """Connected regions inside the zero level of each field of ``values`` (F, M, M), as
    marching squares draws them (see :class:`Regions`): labels (F, M, M) (0 outside;
    each field's labels a contiguous run, in scan order) and their number. A node partly
    inside (0 <= f < cell / 2) next to an inside node takes that node's label."""
    inside = values < 0
    labels, count = ndimage.label(inside, structure=_SIDES)
    if count == 0:
        return labels, 0
    # Saddles: a cell whose diagonal corners are inside and the others not is crossed
    # along that diagonal when its centre (the mean of its corners) is inside. Found on
    # the inside mask first; the corners' values are read at the saddles only.
    a, b, c, d = inside[:, :-1, :-1], inside[:, 1:, 1:], inside[:, :-1, 1:], inside[:, 1:, :-1]
    pairs = []
    for saddle, offsets in (((a & b) & ~(c | d), ((0, 0), (1, 1))), ((c & d) & ~(a | b), ((0, 1), (1, 0)))):
        f, i, j = np.nonzero(saddle)
        if not len(f):
            continue
        centre = (values[f, i, j] + values[f, i + 1, j + 1] + values[f, i, j + 1] + values[f, i + 1, j]) < 0
        f, i, j = f[centre], i[centre], j[centre]
        (p0, q0), (p1, q1) = offsets
        pairs.append((labels[f, i + p0, j + q0], labels[f, i + p1, j + q1]))
    if pairs:
        u = np.concatenate([p[0] for p in pairs]) - 1
        v = np.concatenate([p[1] for p in pairs]) - 1
        graph = coo_matrix((np.ones(len(u)), (u, v)), shape=(count, count))
        _, merged = connected_components(graph, directed=False)
        # Renumber the merged labels in order of their first label, so that each field's
        # labels stay a contiguous run in scan order.
        firsts = np.sort(np.unique(merged, return_index=True)[1])
        order = np.empty(len(firsts), dtype=labels.dtype)
        order[merged[firsts]] = np.arange(len(firsts))
        table = np.concatenate([[0], order[merged] + 1]).astype(labels.dtype)
        labels, count = table[labels], len(firsts)
    # Nodes partly inside next to an inside node: the region of that neighbour.
    border = ~inside & (values < 0.5 * cell)
    labels[border] = ndimage.grey_dilation(labels, footprint=_SIDES)[border]
    return labels, count


def _hulls(mine: np.ndarray, grid: Grid) -> np.ndarray:
    """For each mask, the centres of its cells that lie farthest out in HULL_DIRECTIONS
    directions (F, HULL_DIRECTIONS, 2), vertices of the cells' convex hull (-inf for an
    empty mask). A maximum over them is the mask's extent in any direction to within
    R (1 - cos(pi / HULL_DIRECTIONS)), 0.12 % of its radius R. Only border cells can be
    extreme, so only they are searched."""
    border = mine & ~ndimage.binary_erosion(mine, structure=np.ones((1, 3, 3), dtype=bool))
    field, iy, ix = np.nonzero(border)  # sorted by field
    out = np.full((len(mine), HULL_DIRECTIONS, 2), -np.inf)
    if not len(field):
        return out
    counts = np.bincount(field, minlength=len(mine))
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    slot = np.arange(len(field)) - first[field]
    xy = np.column_stack([grid.coords[ix], grid.coords[iy]])
    has = counts > 0
    # Padded with each field's first border cell, which cannot change a maximum.
    points = np.zeros((len(mine), int(counts.max()), 2))
    points[has] = xy[first[has]][:, None, :]
    points[field, slot] = xy
    angles = np.linspace(0.0, 2 * np.pi, HULL_DIRECTIONS, endpoint=False)
    directions = np.column_stack([np.cos(angles), np.sin(angles)]).astype(np.float32)
    # Single precision: only which point is farthest matters, and it is 15 times faster.
    best = np.argmax(directions @ points.astype(np.float32).transpose(0, 2, 1), axis=2)  # (F, D)
    out[has] = np.take_along_axis(points, best[:, :, None], axis=1)[has]
    return out
