"""Shapes as rigid bodies: the zero level of an SDF field as a polygon (largest region,
holes kept, simplified), its convex decomposition, the exact mass properties of the
extruded prism, and the pybullet multibody."""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
import threading
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import pybullet as pb
import shapely
from shapely.geometry import Polygon

from harness.canonical import canonical_polygon
from harness.geometry import Grid, inside_region, largest_region, polygons
from harness.protocol import Protocol

#: Simplification tolerance, in cells: a quarter cell moves the outline far less than
#: the posterior's uncertainty and keeps the pieces few.
SIMPLIFY_CELLS = 0.25


def field_polygon(field: np.ndarray, grid: Grid, refinement: int = Protocol.body_refinement) -> Polygon:
    """The largest connected region inside the zero level of ``field`` (sub-cell marching
    squares), holes kept, simplified within a quarter cell; empty if there is none.

    With ``refinement`` k > 1 the outline is drawn on a grid k times finer, the field
    interpolated between the nodes by the cubic spline through them (:func:`refined`):
    marching squares interpolates linearly along each cell side, so on the belief's own
    cells every corner of the outline is cut by up to a cell (docs/physics.md, "The
    sample's body")."""
    if refinement > 1:
        field, grid = refined(field, grid, refinement)
    return simplified_outline(largest_region(inside_region(field, grid)), grid.cell)


def refined(field: np.ndarray, grid: Grid, factor: int) -> tuple[np.ndarray, Grid]:
    """``field`` on a grid ``factor`` times finer over the same square: the bicubic
    interpolating spline through the nodes (scipy's FITPACK, no BLAS: the same numbers on
    every host for the same field), continued beyond the outermost nodes by its end
    pieces."""
    from scipy.interpolate import RectBivariateSpline

    fine = Grid(grid.size * factor, grid.extent)
    half = 0.5 * grid.extent
    spline = RectBivariateSpline(grid.coords, grid.coords, np.asarray(field, dtype=float).T, kx=3, ky=3, s=0,
                                 bbox=[-half, half, -half, half])
    return spline(fine.coords, fine.coords).T, fine


def simplified_outline(region: Polygon, cell: float) -> Polygon:
    """A region's outline for the physics: its vertices canonical (harness.canonical),
    then simplified within SIMPLIFY_CELLS cells, its largest part. Rounding first makes
    the simplification decide on the same numbers on every host; it keeps a subset of
    the vertices, so the result stays canonical (unless rounding would have made the
    region invalid; see :func:`~harness.canonical.canonical_polygon`)."""
    if region.is_empty:
        return region
    region = canonical_polygon(region)
    simple = region.simplify(SIMPLIFY_CELLS * cell, preserve_topology=True)
    return largest_region(simple) if not simple.is_empty else region


def convex_pieces(polygon: Polygon) -> list[Polygon]:
    """A decomposition of ``polygon`` (holes allowed) into convex pieces: GEOS's
    constrained Delaunay triangulation, then Hertel-Mehlhorn: remove each diagonal
    (longest first) whose two endpoints stay convex in the merged piece. At most four
    times the optimal number of pieces."""
    triangles = polygons(shapely.constrained_delaunay_triangles(polygon))
    index: dict[tuple[float, float], int] = {}
    rings: list[list[int] | None] = []
    for tri in triangles:
        if tri.area <= 0.0:
            continue
        coords = shapely.geometry.polygon.orient(tri, 1.0).exterior.coords[:-1]
        rings.append([index.setdefault((x, y), len(index)) for x, y in coords])
    points = np.array(list(index), dtype=float).reshape(-1, 2)
    owner = {(ring[i], ring[(i + 1) % 3]): k for k, ring in enumerate(rings) for i in range(3)}
    diagonals = sorted({(a, b) for a, b in owner if a < b and (b, a) in owner},
                       key=lambda e: (-float(np.hypot(*(points[e[0]] - points[e[1]]))), e))
    for a, b in diagonals:
        p, q = owner.get((a, b)), owner.get((b, a))
        if p is None or q is None or p == q:
            continue
        merged = _merge(rings[p], rings[q], a, b, points)
        if merged is None:
            continue
        rings[p], rings[q] = merged, None
        del owner[(a, b)], owner[(b, a)]
        for i, v in enumerate(merged):
            owner[(v, merged[(i + 1) % len(merged)])] = p
    return [Polygon(points[ring]) for ring in rings if ring is not None]


def _merge(ring_p: list[int], ring_q: list[int], a: int, b: int, points: np.ndarray) -> list[int] | None:
    """The union of two counter-clockwise convex rings sharing the edge a->b (in p) and
    b->a (in q), or None if it is not convex at a or b."""
    i, j = ring_p.index(b), ring_q.index(a)
    from_b = ring_p[i:] + ring_p[:i]       # b, ..., a  (all of p, starting at b)
    from_a = ring_q[j:] + ring_q[:j]       # a, ..., b  (all of q, starting at a)
    merged = from_b + from_a[1:-1]         # b ... a ... (q's vertices between a and b)
    n = len(merged)
    for v in (0, len(from_b) - 1):         # the positions of b and a
        prev, here, nxt = points[merged[v - 1]], points[merged[v]], points[merged[(v + 1) % n]]
        d1, d2 = here - prev, nxt - here
        if d1[0] * d2[1] - d1[1] * d2[0] < -1e-18:
            return None
    return merged


@dataclass(frozen=True)
class MassProperties:
    """Of a uniform prism: mass (kg), centre of mass (3,) and inertia tensor (3, 3) about
    it, in the body's frame (the polygon's plane at z = 0 to z = thickness)."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


def prism_mass_properties(poly: Polygon, thickness: float, density: float) -> MassProperties:
    """Exact mass properties of a polygon (holes allowed) extruded by ``thickness``."""
    area, first, second = _area_moments(poly)
    mass = density * area * thickness
    cx, cy = first / area
    # Second moments about the centroid: int x^2, int y^2, int xy dA.
    sxx = second[0] - area * cx * cx
    syy = second[1] - area * cy * cy
    sxy = second[2] - area * cx * cy
    lam = density * thickness
    z2 = mass * thickness**2 / 12.0
    inertia = np.array([[lam * syy + z2, -lam * sxy, 0.0],
                        [-lam * sxy, lam * sxx + z2, 0.0],
                        [0.0, 0.0, lam * (sxx + syy)]])
    return MassProperties(mass, np.array([cx, cy, 0.5 * thickness]), inertia)


def _area_moments(poly: Polygon):
    """Area, first moments (int x, int y) and second moments (int x^2, int y^2, int xy)
    of a polygon with holes, by the shoelace formulas over its rings."""
    area = 0.0
    first = np.zeros(2)
    second = np.zeros(3)
    poly = shapely.geometry.polygon.orient(poly, sign=1.0)  # exterior ccw, holes cw
    for ring in [poly.exterior, *poly.interiors]:
        xy = np.asarray(ring.coords)
        x0, y0, x1, y1 = xy[:-1, 0], xy[:-1, 1], xy[1:, 0], xy[1:, 1]
        cross = x0 * y1 - x1 * y0
        area += cross.sum() / 2
        first += np.array([((x0 + x1) * cross).sum(), ((y0 + y1) * cross).sum()]) / 6
        second += np.array([((x0 * x0 + x0 * x1 + x1 * x1) * cross).sum() / 12,
                            ((y0 * y0 + y0 * y1 + y1 * y1) * cross).sum() / 12,
                            ((x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0) * cross).sum() / 24])
    return area, first, second


@dataclass(frozen=True)
class Body:
    """An object in a pybullet world: its id, the polygon and pieces it was built from,
    the mass properties of the whole prism (in the polygon's frame), and the link index
    of its foot (None without one; see :func:`create_body`)."""

    body_id: int
    polygon: Polygon
    pieces: tuple
    mass: MassProperties
    foot: int | None = None


#: Height of the foot slab above the object's base (m); it only meets the table, so any
#: height works that stays inside the prism.
FOOT_HEIGHT = 0.002


#: Bullet's default collision margin of a convex hull (m); see :func:`_core`.
COLLISION_MARGIN = 0.001
#: Colour of the object in rendered frames (RGBA).
OBJECT_RGBA = (0.85, 0.45, 0.15, 1.0)


def create_body(client: int, polygon: Polygon, thickness: float, density: float, friction: float,
                origin=(0.0, 0.0), visual: bool = False, foot: bool = False, clipping: bool = False) -> Body:
    """The polygon extruded to a prism of ``thickness`` lying on the table (z = 0), its
    frame shifted by ``origin`` (x, y), as one rigid body: a single pybullet base whose
    collision shape is the compound of the convex pieces, with the exact mass, centre of
    mass and principal inertia of the whole prism. Lateral friction ``friction``; a
    visual mesh only when ``visual`` (for rendering).

    One base, not one fixed link per piece: the fidelity study (docs/physics.md) found
    that a convex shape cut into fixed links behaved unlike the same shape in one piece
    (agreement 0.89), while the compound agreed with it (0.97, chaos level).

    ``foot``: the body also gets a massless link, fixed to the base, whose collision
    shape is a FOOT_HEIGHT slab over the polygon's convex hull at the prism's bottom
    (link index 0). The caller makes the foot the only part that meets the table and
    keeps it from meeting anything else (the trial runner, harness.physics.trial): the
    object then rests on at most 4 contact points (one manifold) instead of up to 4 per
    piece. For a prism tilted by less than 90 degrees the lowest point of the hull slab
    is the lowest point of the prism (a hull vertex is a vertex of the polygon's bottom
    ring), so where the object touches the table does not change; only how many points
    share its weight when it lies flat (docs/physics.md, "The foot")."""
    made = recipe(polygon, thickness, density, convex_pieces)
    flags = pb.URDF_INITIALIZE_SAT_FEATURES if clipping else 0
    mesh, foot_vertices = _bullet_meshes(polygon, thickness, density, convex_pieces)
    path = _mesh_file(mesh)
    try:
        shape = pb.createCollisionShape(pb.GEOM_MESH, fileName=str(path), flags=flags, physicsClientId=client)
    finally:
        path.unlink(missing_ok=True)  # read at once; thousands of posterior samples must not pile up
    look = -1
    if visual:
        vertices, indices = [], []
        for piece in made.pieces:
            ring = prism_vertices(piece, 0.0, thickness)
            indices += [len(vertices) + i for i in _prism_triangles(len(ring) // 2)]
            vertices += ring
        look = pb.createVisualShape(pb.GEOM_MESH, vertices=vertices, indices=indices, rgbaColor=OBJECT_RGBA,
                                    physicsClientId=client)
    links = {}
    if foot:
        slab = pb.createCollisionShape(pb.GEOM_MESH, vertices=foot_vertices, flags=flags, physicsClientId=client)
        links = dict(linkMasses=[0.0], linkCollisionShapeIndices=[slab], linkVisualShapeIndices=[-1],
                     linkPositions=[[0.0, 0.0, 0.0]], linkOrientations=[[0.0, 0.0, 0.0, 1.0]],
                     linkInertialFramePositions=[[0.0, 0.0, 0.0]], linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]],
                     linkParentIndices=[0], linkJointTypes=[pb.JOINT_FIXED], linkJointAxis=[[0.0, 0.0, 1.0]])
    body = pb.createMultiBody(baseMass=made.props.mass, baseCollisionShapeIndex=shape, baseVisualShapeIndex=look,
                              basePosition=[float(origin[0]), float(origin[1]), 0.0],
                              baseInertialFramePosition=made.props.com.tolist(),
                              baseInertialFrameOrientation=made.principal_axes, physicsClientId=client, **links)
    pb.changeDynamics(body, -1, localInertiaDiagonal=made.moments, lateralFriction=friction,
                      physicsClientId=client)
    if foot:
        pb.changeDynamics(body, 0, lateralFriction=friction, physicsClientId=client)
    return Body(body, polygon, made.pieces, made.props, 0 if foot else None)


@dataclass(frozen=True)
class Recipe:
    """What a body is built from that depends only on its shape, in every engine: the
    convex pieces, the mass properties, the principal moments and the principal axes (a
    quaternion)."""

    pieces: tuple
    props: MassProperties
    moments: list
    principal_axes: list


@lru_cache(maxsize=256)
def recipe(polygon: Polygon, thickness: float, density: float, decompose) -> Recipe:
    """Built once per process for each shape: an experiment executes every posterior
    sample once per planner and the true shape in every truth trial. Keyed by the exact
    polygon and by the decomposition function itself (so a test that swaps the
    decomposition never sees a body built by another)."""
    pieces = tuple(decompose(polygon))
    props = prism_mass_properties(polygon, thickness, density)
    moments, axes = principal_frame(props.inertia)
    return Recipe(pieces, props, moments, axes)


@lru_cache(maxsize=256)
def _bullet_meshes(polygon: Polygon, thickness: float, density: float, decompose) -> tuple[str, list]:
    """Bullet's collision geometry of a shape, once per process: the compound's OBJ text
    (the pieces shrunk by the collision margin) and the vertices of the foot slab."""
    pieces = recipe(polygon, thickness, density, decompose).pieces
    mesh = _compound_text([_core(piece, thickness) for piece in pieces], thickness)
    hull, margin = _core(polygon.convex_hull, thickness)
    z0 = min(margin, 0.25 * thickness)
    return mesh, prism_vertices(hull, z0, z0 + min(FOOT_HEIGHT, thickness - 2 * z0))


def _compound_text(cores: list, thickness: float) -> str:
    """An OBJ text with one object per convex piece (pybullet builds a compound of convex
    hulls only from a file). Each hull gets Bullet's default margin, COLLISION_MARGIN, so
    pieces are shrunk by it (:func:`_core`)."""
    lines, base = [], 1
    for k, (core, margin) in enumerate(cores):
        z0 = min(margin, 0.25 * thickness)  # prisms thinner than 4 mm come out up to 2 mm thick
        ring = prism_vertices(core, z0, thickness - z0)
        lines.append(f"o piece{k}")
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in ring]
        tris = _prism_triangles(len(ring) // 2)
        lines += [f"f {tris[i] + base} {tris[i + 1] + base} {tris[i + 2] + base}" for i in range(0, len(tris), 3)]
        base += len(ring)
    return "\n".join(lines) + "\n"


def _mesh_file(text: str) -> Path:
    """``text`` written to a temporary OBJ file. The name holds this process's id, this
    thread's (a Dask worker may run tasks in several threads, each building bodies) and a
    hash of the text: no other process or thread touches it, and a name always means the
    same shape."""
    digest = hashlib.sha256(text.encode()).hexdigest()[:20]
    path = Path(tempfile.gettempdir()) / f"gpis-harness-body-{os.getpid()}-{threading.get_ident()}-{digest}.obj"
    path.write_text(text)
    return path


def _core(piece: Polygon, thickness: float) -> tuple[Polygon, float]:
    """The piece shrunk by Bullet's collision margin, and the margin: Bullet rounds each
    convex hull of a compound outwards by its default margin (COLLISION_MARGIN, which
    cannot be set per child), so the hull of the shrunk piece collides like the piece
    itself, up to corners rounded by the margin (tested: rest height, face distances).
    A sliver too thin to shrink keeps its shape and is 1 mm too large."""
    margin = COLLISION_MARGIN
    core = piece.buffer(-margin, join_style="mitre")
    if isinstance(core, Polygon) and not core.is_empty and core.area > 0.05 * piece.area:
        return core, margin
    return piece, margin


def prism_vertices(piece: Polygon, z0: float, z1: float) -> list:
    """Bottom ring (counter-clockwise) then top ring of the prism over a convex piece."""
    ring = np.asarray(shapely.geometry.polygon.orient(piece, 1.0).exterior.coords)[:-1]
    return np.concatenate([np.column_stack([ring, np.full(len(ring), z0)]),
                           np.column_stack([ring, np.full(len(ring), z1)])]).tolist()


def _prism_triangles(n: int) -> list[int]:
    """Outward triangles of a convex prism whose 2n vertices are the counter-clockwise
    bottom ring followed by the top ring."""
    tris = []
    for k in range(1, n - 1):
        tris += [0, k + 1, k]              # bottom, facing down
        tris += [n, n + k, n + k + 1]      # top, facing up
    for k in range(n):
        a, b = k, (k + 1) % n
        tris += [a, b, n + b, a, n + b, n + a]
    return tris


def principal_frame(inertia: np.ndarray) -> tuple[list, list]:
    """The principal moments of a prism's inertia tensor and the rotation (a quaternion
    x, y, z, w) whose columns are their axes. The prism's z axis is principal, so the
    rotation is the turn about z, within 45 degrees, that diagonalises the tensor's x-y
    block, found in closed form with square roots and divisions only: LAPACK's
    eigenvectors would depend on the host's BLAS kernels in their last bits, in their
    signs, and (for a round outline, whose two in-plane moments agree) in direction."""
    a, b, c = float(inertia[0, 0]), float(inertia[0, 1]), float(inertia[1, 1])
    half_gap = 0.5 * (a - c)
    radius = math.sqrt(half_gap * half_gap + b * b)
    mean = 0.5 * (a + c)
    if radius == 0.0:
        return [a, c, float(inertia[2, 2])], [0.0, 0.0, 0.0, 1.0]
    # The first axis turned by t from x, |t| <= pi/4: cos 2t = |half_gap| / radius and
    # sin 2t = sign * b / radius, its moment mean + sign * radius; the quaternion of a
    # turn t about z is (0, 0, sin t/2, cos t/2). No cosine below 1/sqrt(2): no cancellation.
    sign = 1.0 if half_gap >= 0.0 else -1.0
    cos_t = math.sqrt(0.5 * (1.0 + abs(half_gap) / radius))
    sin_t = sign * b / radius / (2.0 * cos_t)
    cos_half = math.sqrt(0.5 * (1.0 + cos_t))
    return ([mean + sign * radius, mean - sign * radius, float(inertia[2, 2])],
            [0.0, 0.0, sin_t / (2.0 * cos_half), cos_half])
