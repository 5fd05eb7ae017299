"""The lift model: whether a grasp in planar force closure also carries the object's
weight once lifted, per shape draw, with that draw's mass and centre of mass
(docs/lift.md).

Once lifted, each plate must carry half the weight by friction along the wall, and
together they must resist the weight's torque about the grasp axis, W d (d: the centre
of mass's distance from the line through the contacts), by torsional friction over
their contact patches. Each plate's patch is a soft-finger
contact with an elliptic limit surface (Howe and Cutkosky 1996),

    (f_t / (mu N))^2 + (tau / (kappa mu N))^2 <= 1,

so with the weight's share f_t = W / 2 a plate resists at most
kappa mu N sqrt(1 - (f_t / (mu N))^2) of torque. kappa is the mean lever of the
friction over the patch. A rigid plate pressed on a rigid wall does not fix its pressure
distribution (the contact is statically indeterminate): every lever from 0 (all pressure
at the patch centre) to the patch's half-diagonal (all pressure at two opposite corners)
is admissible. The model takes kappa uniform on that range, one draw per plate and shape
draw (the draws' ``pressure`` deviates); docs/lift.md shows that Bullet's contact
manifolds spread over the same range.

A torque beyond the plates' resistance turns the object about the grasp axis until the
weight's lever has shortened to what they resist, W d cos(theta) = resistance, where
the plates' friction stops it (as Bullet's compliant pads stop bars: docs/lift.md,
"Bars"). It is still lifted if, turned that far, it clears the table: its extent
beyond the grasp axis on the side of its centre of mass, turned down by theta, stays
above the lifted table. Otherwise the turn puts it back on the table
(``weight_torque``). A weight beyond the plates' friction slides it out
(``weight_slip``). The lift's acceleration raises the load for a tenth of a second;
friction stops the brief turn it starts on a plate's patch (bars turned 0.04-0.15 rad
and held), so the turn and the slide are judged under the weight alone. A plate that
presses the wall with its edge (a wall inclined to the plate:
harness.grasp.edge_contacts) holds the object as a patch only while the turn is small:
as the object turns, the wall's distance from the plate's edge varies along the edge, by
s (h / 2) sin(theta) at its ends for a wall receding at slope s, and once that passes the
pad's compression delta one end lets go, the pressure goes to the other, and the object
swings on two points and is lost (``edge_turn``; docs/lift.md, "Edge contacts"). So an
edge-pressed object is lifted only if the turn stops before sin(theta_r) = delta / (s h / 2)
(:func:`release_cosine`), judged under the weight alone as every turn is: nothing stops a
turn past theta_r. delta = F / PAD_STIFFNESS, the pad's compression under the grip force.
(Before 2026-11-28 an edge contact lost every turned object, judged at the lift's peak:
the rigid pad's limit, delta = 0.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.settings import GRAVITY, GraspSettings

#: Failure reasons of the lift, in the order a draw in force closure is classified.
LIFT_REASONS = ("weight_slip", "weight_torque", "edge_turn")
SLIP, TORQUE, EDGE_TURN = 0, 1, 2
#: The jaw plates end this far above the table (harness.physics.gripper.TABLE_CLEARANCE).
PLATE_CLEARANCE = 0.001
#: A jaw pad's stiffness (N/m) over a plate's patch: about 2 mm of silicone rubber (E about
#: 1 MPa) over 0.8 cm^2, E A / t about 4e4 N/m, the pad both engines model (Bullet's
#: compliant pad and MuJoCo's soft contacts sink 0.2-0.6 mm at 20 N; docs/physics.md, "A
#: compliant pad in Bullet"). A plate pressed by F sinks F / PAD_STIFFNESS (0.5 mm at
#: 20 N); an edge concentrates the force and sinks further, so this is the smaller
#: compression and the earlier release.
PAD_STIFFNESS = 4.0e4


def patch_height(settings: GraspSettings) -> float:
    """Vertical extent (m) of a plate's contact patch on the prism's wall: the overlap of
    the wall (0 to the thickness) with the plate (from PLATE_CLEARANCE above the table
    to plate_height above the object's top)."""
    return max(0.0, min(settings.thickness, settings.thickness + settings.plate_height) - PLATE_CLEARANCE)


def axis_height(settings: GraspSettings) -> float:
    """Height (m) of the grasp axis above the table before the lift: the patch's centre."""
    return PLATE_CLEARANCE + 0.5 * patch_height(settings)


def clearance(settings: GraspSettings) -> float:
    """How far (m) a turned object hanging below the grasp axis may reach and still clear
    the lifted table: the lift height plus the axis's height above the table."""
    return settings.lift_height + axis_height(settings)


def clear_cosine(reach, settings: GraspSettings) -> np.ndarray:
    """cos(theta_c) (B,) of the largest turn theta_c about the grasp axis at which the
    lifted object still clears the table, 0 where it clears it hanging straight down.
    Turned by theta, the object's lowest point (its ``reach`` beyond the axis, on its
    bottom face, the axis a height z_a above that face) lies reach sin(theta) + z_a
    cos(theta) below the axis, which is z_a + the lift height above the table."""
    za, lift = axis_height(settings), settings.lift_height
    reach = np.asarray(reach, dtype=float)
    radius = np.hypot(reach, za)
    with np.errstate(invalid="ignore", divide="ignore"):
        theta = np.arcsin(np.clip((za + lift) / radius, -1.0, 1.0)) - np.arctan2(za, reach)
    return np.where(reach <= za + lift, 0.0, np.cos(theta))


def release_cosine(slope, settings: GraspSettings) -> np.ndarray:
    """cos(theta_r) (B,) of the turn about the grasp axis at which a plate pressing its wall
    with its edge lets go of one end of the edge. The wall recedes from the edge across
    the plate at ``slope`` (dimensionless; 0 where the plate does not press with its
    edge) and the grasp axis passes through the edge, so turned by theta the wall lies
    slope (h / 2) sin(theta) beyond the edge's ends (h the patch height): the pad,
    pressed in by delta = F / PAD_STIFFNESS, lets go where that reaches delta,
    sin(theta_r) = delta / (slope h / 2). 0 where the plate does not press with its edge
    or no turn releases it."""
    slope = np.asarray(slope, dtype=float)
    delta = settings.force / PAD_STIFFNESS
    with np.errstate(invalid="ignore", divide="ignore"):
        sine = delta / (slope * 0.5 * patch_height(settings))
        return np.where((slope > 0) & (sine < 1.0), np.sqrt(np.maximum(1.0 - sine**2, 0.0)), 0.0)


def weight_of(area, settings: GraspSettings) -> np.ndarray:
    """The weight (N) of a prism of this cross-section area (m^2), the settings' thickness
    and density."""
    return settings.density * settings.thickness * GRAVITY * np.asarray(area, dtype=float)


def largest_lever(width, height: float) -> np.ndarray:
    """The largest admissible mean lever of friction over a width x height patch: its
    half-diagonal (all pressure at two opposite corners)."""
    return np.hypot(0.5 * np.asarray(width, dtype=float), 0.5 * height)


def torque_demand(weight, distance, friction, settings: GraspSettings, load_factor: float = 1.0) -> np.ndarray:
    """The weight's torque about the grasp axis in units of the plates' friction lever
    capacity: T = W_l d / (mu N sqrt(1 - (W_l / (2 mu N))^2)), with W_l the weight times
    ``load_factor`` (1: the weight alone; the lift's peak: settings.load_factor). The
    plates hold when kappa_1 + kappa_2 >= T; NaN where the load slides the object out."""
    capacity = np.asarray(friction, dtype=float) * settings.force
    load = load_factor * np.asarray(weight, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = load / (2.0 * capacity)
        return np.where(share <= 1.0, load * np.asarray(distance) / (capacity * np.sqrt(1.0 - share**2)), np.nan)


def hold_probability(demand, lever_1, lever_2) -> np.ndarray:
    """P(kappa_1 + kappa_2 >= demand) for kappa_i uniform on [0, lever_i]: the chance that
    the plates resist the torque, a smooth (piecewise quadratic, C1) function of the
    demand, for surrogates. 0 where the demand is NaN (the weight slides out)."""
    a = np.minimum(lever_1, lever_2)
    b = np.maximum(lever_1, lever_2)
    t = np.asarray(demand, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        below = np.where(t <= a, t**2 / (2 * a * b), np.where(t <= b, (t - 0.5 * a) / b,
                                                               1.0 - (a + b - t) ** 2 / (2 * a * b)))
    below = np.where(t <= 0, 0.0, np.where(t >= a + b, 1.0, below))
    return np.where(np.isnan(t), 0.0, 1.0 - below)


@dataclass(frozen=True)
class LiftVerdict:
    """Per draw: lifted or not (B,), the lift reason index into LIFT_REASONS (-1 when
    lifted), whether the torque turned the object (lifted or not), and the chance of the
    lift averaged over the levers instead of drawn (smooth; its mean over draws estimates
    P_L with less variance than the verdicts' share); and the quantities the verdict was
    made of: the weight (N), the centre of mass's distance from the contact line (m), the
    torque demand T under the weight alone (m; NaN where the weight slides the object
    out) and under the lift's peak load (``peak_demand``: for analysis; no verdict uses it), the
    drawn lever sum kappa_1 + kappa_2 and its largest value (m), whether a plate presses
    with its edge, cos of the largest turn at which the object clears the table
    (:func:`clear_cosine`) and cos of the turn at which an edge-pressed plate lets go of
    one end (:func:`release_cosine`; 0 without an edge)."""

    lifted: np.ndarray
    reason: np.ndarray
    pivots: np.ndarray
    chance: np.ndarray
    weight: np.ndarray
    distance: np.ndarray
    demand: np.ndarray
    lever: np.ndarray
    largest_lever: np.ndarray
    edge: np.ndarray
    peak_demand: np.ndarray
    clear_cos: np.ndarray
    release_cos: np.ndarray


def needed_lever(demand, stop, release) -> np.ndarray:
    """The lever sum a draw needs to be lifted: the turn the weight starts must stop
    (T cos(theta) = kappa_1 + kappa_2) where the object clears the table, T cos(theta_c),
    and, on an edge, before the plate lets go of one end, T cos(theta_r): T max(stop,
    release) (``release`` 0 without an edge). NaN where the weight slides the object out."""
    return np.asarray(demand, dtype=float) * np.maximum(stop, release)


def judge(c1, c2, w1, w2, area, com, reach, friction, pressure, settings: GraspSettings, edge=None) -> LiftVerdict:
    """The lift of B draws in force closure.

    c1, c2 (B, 2): contacts; w1, w2 (B,): the plates' patch widths along the outline;
    area (B,) and com (B, 2): the draw's region area (m^2) and centre of mass;
    reach (B,): the region's extent beyond the line c1-c2 on its centre of mass's side;
    friction (B,): the draw's coefficient; pressure (B, 2): uniform deviates in [0, 1)
    placing each plate's lever in its admissible range; edge (B,): the slope at which the
    wall recedes from a plate pressing it with its edge, the larger of the two plates'
    (harness.grasp.Contacts.edge1/edge2; 0 or default: no edge contact).

    The weight's demand T (:func:`torque_demand`, the weight alone) against the drawn
    lever sum K: where T > K the object turns until T cos(theta) = K and is lifted if at
    that angle it clears the table, K >= T cos(theta_c) (:func:`clear_cosine`); on an edge
    it must also stop before the plate lets go of one end, K >= T cos(theta_r)
    (:func:`release_cosine`), else it swings out (``edge_turn``).
    """
    weight = weight_of(area, settings)
    slope = np.zeros(len(weight)) if edge is None else np.asarray(edge, dtype=float)
    edge = slope > 0
    distance = line_distance(com, c1, c2)
    demand = torque_demand(weight, distance, friction, settings)
    peak = torque_demand(weight, distance, friction, settings, settings.load_factor)
    height = patch_height(settings)
    largest = largest_lever(w1, height), largest_lever(w2, height)
    lever = pressure[:, 0] * largest[0] + pressure[:, 1] * largest[1]
    slip = np.isnan(demand)
    pivots = ~slip & (demand > lever)
    stop = clear_cosine(reach, settings)
    release = release_cosine(slope, settings)
    hangs_clear = lever >= demand * stop
    lifted = ~slip & (lever >= needed_lever(demand, stop, release))
    reason = np.full(len(weight), -1, dtype=np.int8)
    reason[slip] = SLIP
    reason[~slip & ~hangs_clear] = TORQUE
    reason[~slip & hangs_clear & ~lifted] = EDGE_TURN
    chance = hold_probability(needed_lever(demand, stop, release), *largest)
    return LiftVerdict(lifted, reason, pivots, np.where(slip, 0.0, chance),
                       weight, distance, demand, lever, largest[0] + largest[1], edge, peak, stop, release)


def line_distance(point, c1, c2) -> np.ndarray:
    """Distance (B,) of points from the lines through c1 and c2 (B, 2 each)."""
    d = np.asarray(c2, dtype=float) - c1
    rel = np.asarray(point, dtype=float) - c1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.abs(rel[:, 0] * d[:, 1] - rel[:, 1] * d[:, 0]) / np.linalg.norm(d, axis=1)


def side_normal(point, c1, c2) -> np.ndarray:
    """Unit normals (B, 2) of the lines c1-c2, pointing to the side of ``point``."""
    d = np.asarray(c2, dtype=float) - c1
    n = np.column_stack([-d[:, 1], d[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    side = np.sign(np.einsum("ij,ij->i", np.asarray(point, dtype=float) - c1, n))
    return n * np.where(side == 0, 1.0, side)[:, None]


def smooth_lift(distance, distance_sd, weight, friction, w1, w2, reach, reach_scale, settings: GraspSettings,
                edge=None):
    """A smooth lift probability for surrogates, :func:`judge`'s chance averaged over a
    Gaussian centre-of-mass distance (mean ``distance``, std ``distance_sd``) and a
    Gaussian reach (mean ``reach``, std ``reach_scale``), each by 3-point Gauss-Hermite:
    the chance that the uniform levers stop the turn where the object clears the table
    and, where a plate presses with its edge (``edge``, (B,) the wall's slope there, 0
    for none), before the plate lets go of one end."""
    height = patch_height(settings)
    l1, l2 = largest_lever(w1, height), largest_lever(w2, height)
    nodes, weights = (-math.sqrt(3.0), 0.0, math.sqrt(3.0)), (1 / 6, 2 / 3, 1 / 6)
    release = release_cosine(np.zeros(np.shape(distance)) if edge is None else edge, settings)
    stops = [(w, clear_cosine(np.asarray(reach, dtype=float) + z * reach_scale, settings))
             for z, w in zip(nodes, weights)]
    chance = 0.0
    for z, w in zip(nodes, weights):
        d = np.abs(distance + z * distance_sd)
        static = torque_demand(weight, d, friction, settings)
        chance = chance + w * sum(v * hold_probability(needed_lever(static, stop, release), l1, l2)
                                  for v, stop in stops)
    slides = np.isnan(torque_demand(weight, 0.0, friction, settings))
    return np.where(slides, 0.0, chance)


@dataclass(frozen=True)
class MassBelief:
    """What a planner knows of the object's mass: the weight (N), the centre of mass's
    mean (2,) and covariance (2, 2), and the convex hull (V, 2) of the shape it plans on
    (the mean shape's largest region)."""

    weight: float
    com: np.ndarray
    com_cov: np.ndarray
    hull: np.ndarray

    @classmethod
    def of_mean_shape(cls, belief, settings: GraspSettings) -> "MassBelief":
        """The mean shape's weight and centre of mass, taken as certain."""
        regions = belief.mean_field.regions
        return cls(float(weight_of(regions.area[0], settings)), regions.center_of_mass[0], np.zeros((2, 2)),
                   regions.hull[0])

    @classmethod
    def of_posterior(cls, belief, settings: GraspSettings, n: int, rng: np.random.Generator) -> "MassBelief":
        """The weight and the centre of mass's mean and covariance over n posterior shape
        samples (their largest regions, as the physics extrudes), with the mean shape's hull."""
        from harness.grasp import SDFBatch

        shapes = belief.sample(n, rng)
        regions = SDFBatch(belief.grid, shapes.values, shapes.gradients).regions
        found = regions.area > 0
        com = regions.center_of_mass[found]
        cov = np.cov(com, rowvar=False) if len(com) > 2 else np.zeros((2, 2))
        return cls(float(weight_of(regions.area[found].mean(), settings)), com.mean(axis=0), cov,
                   belief.mean_field.regions.hull[0])

    def margin(self, c1, c2, w1, w2, friction, settings: GraspSettings, reach_scale: float,
               edge=None) -> np.ndarray:
        """The smooth lift probability (B,) of grasps with contacts c1, c2 (B, 2), patch
        widths w1, w2 (B,) and edge slopes ``edge`` (B,: the larger plate's; default none):
        :func:`smooth_lift` with the centre of mass's distance from the contact line, its
        std across the line (from the covariance), and the hull's reach beyond the line on
        the centre of mass's side."""
        c1, c2 = np.asarray(c1, dtype=float), np.asarray(c2, dtype=float)
        com = np.broadcast_to(self.com, c1.shape)
        normal = side_normal(com, c1, c2)
        distance_sd = np.sqrt(np.maximum(np.einsum("bi,ij,bj->b", normal, self.com_cov, normal), 0.0))
        reach = (np.einsum("vk,bk->bv", self.hull, normal) - np.einsum("bk,bk->b", c1, normal)[:, None]).max(axis=1)
        return smooth_lift(line_distance(com, c1, c2), distance_sd, self.weight, friction, w1, w2, reach,
                           reach_scale, settings, edge)

    def settled_margin(self, settled, rows, friction, settings: GraspSettings, reach_scale: float) -> np.ndarray:
        """:meth:`margin` (B,) at the contacts where the plates' squeeze left each grasp
        (``settled``, a harness.squeeze.Squeeze of B grasps) on the grasps ``rows`` ((B,)
        bool), 0 on the others."""
        out = np.zeros(len(rows))
        out[rows] = self.margin(settled.c1[rows], settled.c2[rows], settled.w1[rows], settled.w2[rows], friction,
                                settings, reach_scale, np.maximum(settled.edge1, settled.edge2)[rows])
        return out
