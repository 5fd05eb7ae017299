"""Monte-Carlo probability of force closure (P_F) and of force closure and lift (P_L,
harness.lift) with paired draws over shape samples, approach noise, friction and the
plates' pressure, their Wilson intervals, and failure counts by reason."""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from harness.belief import Belief
from harness.grasp import (DEGENERATE, HULL_DIRECTIONS, MISSED, OK, TOO_WIDE, Contacts, Grasp, Regions, SDFBatch,
                           body_fields, find_contacts, plate_closure, replace_rows)
from harness.lift import LIFT_REASONS, judge, side_normal
from harness.settings import GraspSettings
from harness.push import push_and_squeeze

#: Failure reasons, in the order a draw is classified (the first that applies): the
#: planar ones (P_F), then the lift's for draws in force closure (P_L).
PLANAR_REASONS = ("too_wide", "missed", "degenerate_normal", "friction_cone")
FAILURE_REASONS = PLANAR_REASONS + LIFT_REASONS
#: The verdicts of a lifted draw as the ledger stores them: held level, or turned by the
#: weight and still lifted (harness.pipeline.verdict_label).
LIFTED_VERDICTS = ("lifted", "lifted_turned")
#: Memory (bytes) for the fields of samples in several pieces whose bodies
#: (harness.grasp.body_fields) are built and judged at once while judging the lift (at
#: BODY_FIELD_BYTES M^2 a field, 137 fields at M = 50): bounds it whatever the share of
#: such samples. Each group's push and squeeze are a call of their own, whose steps cost a
#: contact search of about 1 ms however few their draws; groups of 32 fields (the bound
#: until 2026-11-29, about 5.6 MB at M = 50) made the can opener's gp-p-lift plan 1.4
#: times as long (its draws are in pieces one time in two), for no lower peak.
BODY_BYTES = 24e6
#: Bytes per body field over M^2, a bound: building 137 of the can opener's at M = 50
#: peaked at 44 M^2 bytes a field and kept 16 M^2 (tracemalloc, 2026-11-29).
BODY_FIELD_BYTES = 70.0
#: Two-sided 95 % normal quantile.
Z95 = 1.959963984540054


def wilson_interval(successes, n, z: float = Z95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval for a binomial proportion (vectorised); (nan, nan) for n = 0."""
    k = np.asarray(successes, dtype=float)
    n = np.asarray(n, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        denom = 1.0 + z * z / n
        centre = (p + z * z / (2 * n)) / denom
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # At k = 0 and k = n the bounds are exactly 0 and 1; rounding must not leave the
    # estimate outside its own interval.
    lo = np.where(k == 0, 0.0, np.clip(centre - half, 0.0, 1.0))
    hi = np.where(k == n, 1.0, np.clip(centre + half, 0.0, 1.0))
    return (lo[()], hi[()]) if lo.ndim == 0 else (lo, hi)


@dataclass(frozen=True)
class EvaluationDraws:
    """The common random numbers of one belief: n shape samples (as a field batch) and,
    paired with them, standard-normal approach offsets (n, 2, 2) for g1 and g2,
    standard-normal friction deviates (n,) and uniform pressure deviates (n, 2) in [0, 1)
    (where each plate's friction lever lies in its admissible range; harness.lift). Every
    grasp compared on this belief is judged on the same draws; sigma_g and the friction
    spread scale the deviates at use."""

    shapes: SDFBatch
    approach: np.ndarray
    friction: np.ndarray
    pressure: np.ndarray
    torque_scale: float

    def __len__(self) -> int:
        return len(self.approach)

    def first(self, n: int) -> "EvaluationDraws":
        """The first n paired draws (all of them when there are fewer)."""
        if n >= len(self):
            return self
        return EvaluationDraws(self.shapes.first(n), self.approach[:n], self.friction[:n], self.pressure[:n],
                               self.torque_scale)


def draw_evaluation(belief: Belief, n: int, shapes_rng: np.random.Generator, approach_rng: np.random.Generator,
                    friction_rng: np.random.Generator, pressure_rng: np.random.Generator) -> EvaluationDraws:
    """Draw n paired evaluation draws for a belief (shape samples once per belief)."""
    shapes = belief.sample(n, shapes_rng)
    return EvaluationDraws(
        shapes=SDFBatch(belief.grid, shapes.values, shapes.gradients),
        approach=approach_rng.standard_normal((n, 2, 2)),
        friction=friction_rng.standard_normal(n),
        pressure=pressure_rng.random((n, 2)),
        torque_scale=belief.characteristic_length,
    )


#: Paired draws a DrawPool adds at a time.
POOL_BLOCK = 100


class DrawPool:
    """The n paired draws of :func:`draw_evaluation` (the same random numbers from the same
    four generators), drawn in blocks of ``block`` as they are first needed, so that a
    planner judging most grasps on a few draws pays for the shape samples (and their
    regions) it uses, not for all n. The shape samples match draw_evaluation's to float32
    rounding, not always bit for bit: under the pinned BLAS kernels
    (harness.provenance) a product's rounding can depend on how many samples it holds.
    gp-p draws its pool through a DrawPool too, so that gp-p and gp-bandit judge the
    very same numbers.

    The approach, friction and pressure deviates are drawn at once (they are cheap). The
    shape samples come block by block when the belief's sampler for n draws is
    weight-space, whose stream does not depend on how the draws are split; under the
    pathwise sampler, whose stream does, all n at once. ``seconds`` is the time spent
    drawing shapes and computing their derived fields."""

    def __init__(self, belief: Belief, n: int, shapes_rng: np.random.Generator, approach_rng: np.random.Generator,
                 friction_rng: np.random.Generator, pressure_rng: np.random.Generator, block: int = POOL_BLOCK):
        self.belief = belief
        self.n = int(n)
        self.approach = approach_rng.standard_normal((n, 2, 2))
        self.friction = friction_rng.standard_normal(n)
        self.pressure = pressure_rng.random((n, 2))
        self.method = belief.sampler(n)
        self.block = int(block) if self.method == "weight-space" else self.n
        self.drawn = 0
        self.seconds = 0.0
        self._shapes_rng = shapes_rng
        m = belief.grid.size
        self._fields = np.empty((4, n, m, m), dtype=np.float32)  # values, gx, gy, twist
        self._area = np.zeros(n)
        self._com = np.full((n, 2), np.nan)
        self._hull = np.full((n, HULL_DIRECTIONS, 2), -np.inf)
        self._fragmented = np.zeros(n, dtype=bool)
        self._spread = np.full(n, np.nan)
        self._draws: EvaluationDraws | None = None

    def __len__(self) -> int:
        return self.n

    def draws(self, count: int) -> EvaluationDraws:
        """The draws made so far, at least the first ``count`` (at most n), drawing the
        blocks that are missing."""
        start = time.perf_counter()
        grid = self.belief.grid
        while self.drawn < min(count, self.n):
            k = min(self.block, self.n - self.drawn)
            shapes = self.belief.sample(k, self._shapes_rng, method=self.method)
            part = SDFBatch(grid, shapes.values, shapes.gradients)
            s = slice(self.drawn, self.drawn + k)
            self._fields[:, s] = part.values, part.gx, part.gy, part.twist
            regions = part.regions
            self._area[s], self._com[s], self._hull[s] = regions.area, regions.center_of_mass, regions.hull
            self._fragmented[s], self._spread[s] = regions.fragmented, regions.spread
            self.drawn += k
            d = self.drawn
            shapes = SDFBatch.of_parts(grid, *self._fields[:, :d], Regions(self._area[:d], self._com[:d],
                                                                            self._hull[:d], self._fragmented[:d],
                                                                            self._spread[:d]))
            self._draws = EvaluationDraws(shapes, self.approach[:d], self.friction[:d], self.pressure[:d],
                                          self.belief.characteristic_length)
        self.seconds += time.perf_counter() - start
        return self._draws


@dataclass(frozen=True)
class QualityEstimate:
    """P_F and P_L of one grasp: the estimates and their Wilson 95 % intervals, the number
    of draws, failures by reason (all of them the draws P_L loses; P_F loses the planar
    reasons' draws and the squeezed ones, except where a sample's small pieces hold a
    draw for P_F that misses the body for P_L), the draws whose weight turned the object about
    the grasp axis (lifted or not), the mean Ferrari-Canny quality (0 for a failed draw),
    and the draws out of force closure that the plates' squeeze brought into it or holds
    in the plane (so P_L may exceed P_F; harness.squeeze)."""

    p_f: float
    ci_low: float
    ci_high: float
    samples: int
    failures: dict
    ferrari_canny_mean: float
    p_l: float
    p_l_ci_low: float
    p_l_ci_high: float
    pivots: int
    squeezed: int = 0

    def as_dict(self) -> dict:
        return {"p_f": self.p_f, "ci_low": self.ci_low, "ci_high": self.ci_high, "p_l": self.p_l,
                "p_l_ci_low": self.p_l_ci_low, "p_l_ci_high": self.p_l_ci_high, "samples": self.samples,
                "failures": dict(self.failures), "pivots": self.pivots, "squeezed": self.squeezed,
                "ferrari_canny_mean": self.ferrari_canny_mean}


@dataclass(frozen=True)
class DrawOutcomes:
    """Per-draw results (G, n) for G grasps: force closure (the paper's, at the first
    contacts), lifted (force closure at once or after the plates' squeeze, or held in
    the plane by it, and the lift; None when the lift was not judged), failure reason
    index into FAILURE_REASONS (-1 for lifted, or for force closure without the lift),
    whether the weight turned the object, the Ferrari-Canny quality, the lift's chance
    averaged over the levers (0 out of force closure; None when the lift was not
    judged), whether the squeeze settled the draw (into force closure, or held in the
    plane: harness.squeeze; never when the lift was not judged), and whether the push
    before the second plate arrived moved the closing line across the object
    (harness.push: the lift then judges another grasp than P_F's; None when the lift
    was not judged). ``lift_inputs``, when asked for (:func:`evaluate_draws`), holds the
    lift model's inputs and intermediates per draw (:data:`LIFT_INPUTS`; NaN where the
    plates were not in force closure, so the lift was not judged) and how the plates
    settled each draw (:data:`SETTLE_INPUTS`, every draw)."""

    closure: np.ndarray
    lifted: np.ndarray | None
    reason: np.ndarray
    pivots: np.ndarray
    ferrari_canny: np.ndarray
    lift_chance: np.ndarray | None = None
    squeezed: np.ndarray | None = None
    lift_inputs: dict | None = None
    pushed: np.ndarray | None = None

    @cached_property
    def estimates(self) -> list[QualityEstimate]:
        n = self.closure.shape[1]
        k = self.closure.sum(axis=1)
        kl = self.lifted.sum(axis=1) if self.lifted is not None else np.full(len(k), np.nan)
        lo, hi = wilson_interval(k, n)
        llo, lhi = wilson_interval(kl, n)
        counts = np.stack([(self.reason == r).sum(axis=1) for r in range(len(FAILURE_REASONS))], axis=1)
        fc = self.ferrari_canny.mean(axis=1)
        pivots = self.pivots.sum(axis=1)
        squeezed = self.squeezed.sum(axis=1) if self.squeezed is not None else np.zeros(len(k), dtype=int)
        return [QualityEstimate(float(k[g] / n), float(lo[g]), float(hi[g]), n,
                                {name: int(counts[g, r]) for r, name in enumerate(FAILURE_REASONS)}, float(fc[g]),
                                float(kl[g] / n), float(llo[g]), float(lhi[g]), int(pivots[g]), int(squeezed[g]))
                for g in range(len(k))]


#: The lift model's quantities per draw that ``evaluate_draws(..., lift_inputs=True)``
#: returns (harness.lift): the weight (N), the centre of mass's distance from the line
#: through the contacts (m), the torque demand T under the weight alone (m, in units of
#: the plates' friction lever), the lever sum the draw's pressure deviates give (m) and
#: its largest value (the two half-diagonals, m), each plate's patch width along the outline
#: (``width_1``, ``width_2``, m: 0 for a line contact, up to the plate's width on a flat
#: face; harness.grasp.PATCH_DEPTH), the reach beyond the contact line on the
#: centre of mass's side (m), the hang's gap to the lifted table (clearance - reach, m:
#: positive hangs clear straight down), the friction coefficient, each plate's share of
#: its friction carried as force at the lift's peak, u = lambda W / (2 mu N), whether a
#: plate presses its wall with its edge (1 or 0; harness.grasp.edge_contacts), the torque
#: demand under the lift's peak load (for analysis), cos of the largest turn at which the
#: object clears the table (harness.lift.clear_cosine) and cos of the turn at which an
#: edge-pressed plate lets go of one end (harness.lift.release_cosine; 0 without an
#: edge): lifted where the lever sum >= demand x max(clear_cos, release_cos).
LIFT_INPUTS = ("weight", "distance", "demand", "lever_sum", "largest_lever_sum", "width_1", "width_2", "reach",
               "hang_gap", "friction", "load_share", "edge", "peak_demand", "clear_cos", "release_cos")
#: How the plates settled each draw on the table before the lift (harness.push,
#: harness.squeeze), which ``evaluate_draws(..., lift_inputs=True)`` returns beside
#: LIFT_INPUTS and for every draw: the push's turn of the object before the second plate
#: arrived (rad, counter-clockwise positive), the squeeze's turn (rad, 0 where it did not
#: turn the draw into closure) and the slide across the closing line (m, 0 where there was
#: none), and the settling as a code (:data:`SETTLED`).
SETTLE_INPUTS = ("push_turn", "squeeze_turn", "slide", "settled")
#: The codes of SETTLE_INPUTS' ``settled``: not settled (out of force closure, or the
#: contacts failed), in force closure at the contacts after the push, turned by the
#: squeeze (into closure, or until another wall met a plate's side: held there), slid by
#: it (into closure, to where the walls' pushes cancel, or until another wall met a
#: plate's side: held in the plane), and held in the plane where it was (neither a couple
#: nor a push across the closing line, or another wall met a plate's side at the first
#: step).
SETTLED = ("none", "closure", "turn", "slide", "held")


def evaluate_draws(grasps, draws: EvaluationDraws, settings: GraspSettings, lift: bool = True,
                   lift_inputs: bool = False) -> DrawOutcomes:
    """Judge G grasps ((G, 2, 2) jaw starts, or Grasp objects) on every paired draw.

    Draw i perturbs g1 and g2 by sigma_g times its approach deviates, uses shape sample
    i, and friction max(0, friction + friction_spread * deviate). A perturbed pair wider
    than the gripper's opening is narrowed symmetrically to the opening (the gripper
    cannot open further). A draw fails, in this order, when a jaw starts inside the
    shape (too_wide), when no object lies between the jaws (missed), when a contact
    normal is undefined (degenerate_normal), when the plates' contact patches are not in
    force closure (friction_cone; harness.grasp.plate_closure) and, with the lift, the
    plates' squeeze does not bring them into it nor hold the object in the plane either
    (harness.squeeze; the lift's contacts are those after the push of the plate that
    arrives first, harness.push), and then, in force closure or so held, when the weight
    slides the object out (weight_slip) or turns it back onto the table (weight_torque)
    (harness.lift, with the shape sample's area and centre of mass and draw i's pressure
    deviates, at the contacts where the squeeze stopped).
    With the lift, the reasons are judged on the shape sample's body, the largest region
    the physics extrudes: on a sample in several pieces the jaws pass where the other
    pieces would be (harness.grasp.body_fields), so a draw P_F holds on a small piece is
    'missed' for P_L, as the physics finds no contact there. ``closure`` stays the
    paper's force closure at the first contacts on the whole sample (P_F).
    ``lift=False`` skips the lift (P_F alone; P_L is then NaN; the reasons are P_F's).
    ``lift_inputs`` keeps the lift model's quantities per draw (:data:`LIFT_INPUTS`), to
    look at why a verdict went as it did.
    """
    starts = as_starts(grasps)
    g, n = len(starts), len(draws)
    g1, g2 = executed_starts(starts, draws.approach, settings)
    return _judge(g1, g2, np.tile(np.arange(n), g), draws, settings, lift, (g, n), lift and lift_inputs)


def evaluate_pairs(grasps, draw_index, draws: EvaluationDraws, settings: GraspSettings,
                   lift: bool = True) -> DrawOutcomes:
    """Judge P (grasp, draw) pairs: grasp p ((P, 2, 2) jaw starts) on paired draw
    ``draw_index[p]`` only, exactly as :func:`evaluate_draws` judges that grasp on that
    draw. The outcomes' arrays are (P,) (their ``estimates`` are not defined). A bandit
    pulls its arms this way: each arm on its own next draw, all arms in one call."""
    starts = as_starts(grasps)
    index = np.asarray(draw_index, dtype=np.int64).reshape(-1)
    if len(index) != len(starts):
        raise ValueError(f"{len(starts)} grasps but {len(index)} draw indices")
    approach = draws.approach[index]
    g1, g2 = within_opening(starts[:, 0] + settings.sigma_g * approach[:, 0],
                            starts[:, 1] + settings.sigma_g * approach[:, 1], settings.opening)
    return _judge(g1, g2, index, draws, settings, lift, (len(index),))


def _judge(g1, g2, field, draws: EvaluationDraws, settings: GraspSettings, lift: bool, shape,
           keep: bool = False) -> DrawOutcomes:
    """Outcomes of executed jaw starts g1, g2 (B, 2) on draws ``field`` (B,), reshaped to
    ``shape`` (see :func:`evaluate_draws` for the order of the failure reasons)."""
    b = len(field)
    gamma = settings.frictions(draws.friction[field])
    contacts = find_contacts(draws.shapes, g1, g2, settings.jaw_width, field_index=field)
    closure, quality = plate_closure(contacts, gamma, draws.shapes.center_of_mass[field], draws.torque_scale)
    held = closure
    lifted = np.zeros(b, dtype=bool)
    pivots = np.zeros(b, dtype=bool)
    squeezed = np.zeros(b, dtype=bool)
    pushed = np.zeros(b, dtype=bool)
    chance = np.zeros(b)
    judged, in_closure = contacts, closure
    if lift:
        # The lift is judged on the body the physics extrudes (the largest region): on a
        # draw with other pieces, the jaws pass where those pieces would be.
        judged, in_closure, settled, push = _on_bodies(g1, g2, field, draws, contacts, closure, gamma, settings)
        squeezed, pushed = settled.squeezed, push.moved
        held = in_closure | squeezed
    ok = judged.status == OK
    reason = np.full(b, -1, dtype=np.int8)
    reason[~ok & (judged.status == TOO_WIDE)] = FAILURE_REASONS.index("too_wide")
    reason[~ok & (judged.status == MISSED)] = FAILURE_REASONS.index("missed")
    reason[~ok & (judged.status == DEGENERATE)] = FAILURE_REASONS.index("degenerate_normal")
    reason[ok & ~in_closure] = FAILURE_REASONS.index("friction_cone")
    if lift:
        reason[squeezed] = -1
    if lift and held.any():
        regions = draws.shapes.regions
        f = field[held]
        c1, c2, com = settled.c1[held], settled.c2[held], regions.center_of_mass[f]
        reach = regions.extent(f, c1, side_normal(com, c1, c2))
        verdict = judge(c1, c2, settled.w1[held], settled.w2[held], regions.area[f], com, reach, gamma[held],
                        draws.pressure[f], settings, np.maximum(settled.edge1[held], settled.edge2[held]))
        lifted[held], pivots[held], chance[held] = verdict.lifted, verdict.pivots, verdict.chance
        reason[np.flatnonzero(held)[~verdict.lifted]] = len(PLANAR_REASONS) + verdict.reason[~verdict.lifted]
    inputs = None
    if keep:
        inputs = {name: np.full(b, np.nan) for name in LIFT_INPUTS}
        if held.any():
            found = _lift_inputs(verdict, settled.w1[held], settled.w2[held], reach, gamma[held], settings)
            for name in LIFT_INPUTS:
                inputs[name][held] = found[name]
        if lift:
            inputs |= _settle_inputs(judged, in_closure, settled, push)
        inputs = {name: v.reshape(shape) for name, v in inputs.items()}
    return DrawOutcomes(closure.reshape(shape), lifted.reshape(shape) if lift else None, reason.reshape(shape),
                        pivots.reshape(shape), quality.reshape(shape), chance.reshape(shape) if lift else None,
                        squeezed.reshape(shape), inputs, pushed.reshape(shape) if lift else None)


def _settle_inputs(contacts: Contacts, closure, settled, pushed) -> dict:
    """SETTLE_INPUTS of every draw, from the contacts after the push, their force closure,
    the squeeze and the push."""
    code = np.zeros(len(closure))
    moved = settled.squeezed & ~closure
    code[moved] = SETTLED.index("held")
    code[moved & (settled.shift > 0)] = SETTLED.index("slide")
    code[moved & (settled.turn > 0)] = SETTLED.index("turn")
    code[closure & (contacts.status == OK)] = SETTLED.index("closure")
    return {"push_turn": np.asarray(pushed.turn, dtype=float).copy(), "squeeze_turn": settled.turn.copy(),
            "slide": settled.shift.copy(), "settled": code}


def _lift_inputs(verdict, w1, w2, reach, friction, settings: GraspSettings) -> dict:
    """The lift model's quantities (:data:`LIFT_INPUTS`) of draws in force closure: the
    verdict's own (harness.lift.LiftVerdict), the plates' patch widths w1 and w2, the
    reach, its gap to the lifted table, the friction and the load share."""
    from harness.lift import clearance

    reach, friction = np.asarray(reach, dtype=float), np.asarray(friction, dtype=float)
    with np.errstate(divide="ignore"):  # frictionless jaws: an infinite share
        share = settings.load_factor * verdict.weight / (2.0 * friction * settings.force)
    return {"weight": verdict.weight, "distance": verdict.distance, "demand": verdict.demand,
            "lever_sum": verdict.lever, "largest_lever_sum": verdict.largest_lever,
            "width_1": np.asarray(w1, dtype=float), "width_2": np.asarray(w2, dtype=float), "reach": reach,
            "hang_gap": clearance(settings) - reach, "friction": friction,
            "load_share": share,
            "edge": verdict.edge.astype(float), "peak_demand": verdict.peak_demand, "clear_cos": verdict.clear_cos,
            "release_cos": verdict.release_cos}


def _on_bodies(g1, g2, field, draws: EvaluationDraws, contacts: Contacts, closure, gamma, settings: GraspSettings):
    """The contacts, force closure and squeeze of the lift: the first contacts and their
    closure (P_F's), except on draws whose shape has pieces besides its body, where the
    jaws are marched again on the body alone (harness.grasp.body_fields); then the push
    before the second plate arrives and the squeeze, on the same fields
    (harness.push.push_and_squeeze)."""
    jaw, scale = settings.jaw_width, draws.torque_scale
    on_split = draws.shapes.regions.fragmented[field]
    if not on_split.any():
        return push_and_squeeze(draws.shapes, g1, g2, field, contacts, closure, gamma, jaw, scale)
    closure = closure.copy()
    pieces = []
    fragmented = np.unique(field[on_split])
    chunk = max(1, int(BODY_BYTES / (BODY_FIELD_BYTES * draws.shapes.grid.size ** 2)))
    for start in range(0, len(fragmented), chunk):  # a bounded number of body fields at once
        ids = fragmented[start:start + chunk]
        rows = np.flatnonzero(np.isin(field, ids))
        local = np.searchsorted(ids, field[rows])
        bodies = body_fields(draws.shapes, ids)
        on_body = find_contacts(bodies, g1[rows], g2[rows], jaw, field_index=local)
        body_closure, _ = plate_closure(on_body, gamma[rows], bodies.center_of_mass[local], scale, with_quality=False)
        pieces.append((rows, push_and_squeeze(bodies, g1[rows], g2[rows], local, on_body, body_closure, gamma[rows],
                                               jaw, scale)))
    contacts, closure, settled, pushed = push_and_squeeze(draws.shapes, g1, g2, field, contacts, closure, gamma, jaw,
                                                           scale, rest=~on_split)
    for rows, (on_body, body_closure, part, push_part) in pieces:
        contacts = replace_rows(contacts, rows, on_body)
        closure[rows] = body_closure
        settled = replace_rows(settled, rows, part)
        pushed = replace_rows(pushed, rows, push_part)
    return contacts, closure, settled, pushed


def estimate_p_f(grasps, draws: EvaluationDraws, settings: GraspSettings, lift: bool = True) -> list[QualityEstimate]:
    """P_F and P_L estimates of G grasps on the same paired draws (see :func:`evaluate_draws`)."""
    return evaluate_draws(grasps, draws, settings, lift).estimates


#: With a floor, ranking_scores judges the grasps on the draws up to each of these counts
#: in turn (then on the rest), dropping between blocks the grasps that can no longer win.
#: A call's fixed cost (the push's and the squeeze's steps, each a contact search of about
#: 1 ms however few its draws) makes many small blocks dear: on five of make eval's cells
#: gp-p-lift took 0.47 of its time with these ends, 0.56 with 100 and 400, 0.66 with a
#: block every 100 draws (2026-11-29; the plans the same with every choice:
#: docs/planners.md, "Helpers").
RANK_ENDS = (100, 250, 500)
#: With a floor, ranking_scores judges at most this many (grasp, draw) pairs in one call
#: (each call's arrays grow with its pairs), however many candidates a caller scores at
#: once: a chunk of 10 candidates (planners.sampling.CHUNK) on 1000 draws, as many as one
#: call judges without a floor.
RANK_PAIRS = 10_000
#: A grasp is dropped only when even a chance of 1 on every draw left would keep its score
#: this far below the bar: the sums' rounding (about 1e-13 over 1000 draws) cannot make it
#: win, so the pick and its score are those of judging every grasp on every draw.
RANK_SLACK = 1e-9
#: After the first block, the grasp ahead is judged on every draw, its score the bar, when
#: there is no floor yet or more than this many grasps are left to drop: one grasp's
#: every draw pays for itself when many grasps can fall below it. Timed on four of make
#: eval's cells (bench planning's search chunks, 2026-11-29; the plans the same either
#: way): with 90 grasps and a floor, 0.78-0.95 of the time; with 10 and a floor, 0.92-1.29.
RANK_LEAD = 10


def ranking_scores(grasps, draws: EvaluationDraws, settings: GraspSettings, lift: bool, floor: float | None = None):
    """How the Monte-Carlo planners rank G grasps on shared draws: (score, tie-break),
    each (G,). With the lift, the score is P_L with the plates' levers averaged instead
    of drawn (``DrawOutcomes.lift_chance``: the same expectation, less variance than the
    share of lifted draws); without, P_F. Ties (common near 0 and 1) go to the higher
    mean Ferrari-Canny quality. gp-p ranks its candidates by it, gp-gpis-opt its
    finalists.

    ``floor`` (the best score seen so far, or -inf) asks only for the winner: the grasps
    are judged block by block of draws (RANK_ENDS), and after each block a grasp whose
    score could not reach the bar even with a chance of 1 on every draw left is dropped
    (its score and tie-break are -inf). The bar is the floor or the score some grasp of
    the set is sure of already (its chances so far over every draw: a chance is never
    below 0), whichever is higher, less RANK_SLACK; without a floor, or with more than
    RANK_LEAD grasps, the grasp ahead after the first block is judged on every draw at
    once, so that its score is the bar. At most RANK_PAIRS pairs are judged a call. Every
    grasp not dropped gets the very score and tie-break it gets without a floor (each pair
    is judged as on the whole grid, evaluate_pairs; each row reduced alike), so the winner,
    its score and every tie are the same: an exact branch and bound, which spares the
    draws of grasps that lose early (most of a random candidate set's, and their draws out
    of force closure are the costly ones: the push and the squeeze)."""
    if floor is None or len(draws) <= RANK_ENDS[0]:
        if lift:
            outcomes = evaluate_draws(grasps, draws, settings)
            return outcomes.lift_chance.mean(axis=1), outcomes.ferrari_canny.mean(axis=1)
        estimates = estimate_p_f(grasps, draws, settings, lift=False)
        return np.array([e.p_f for e in estimates]), np.array([e.ferrari_canny_mean for e in estimates])
    starts = as_starts(grasps)
    g, n = len(starts), len(draws)
    chance, fc = np.zeros((g, n)), np.zeros((g, n))
    alive = np.ones(g, dtype=bool)
    judged = np.zeros(g, dtype=np.int64)  # each grasp's draws judged so far (a prefix)
    floor = float(floor)

    def judge_rows(rows, lo, hi):
        # At most RANK_PAIRS pairs a call: each pair's outcome does not depend on the
        # others in its call, so the split bounds the memory and changes no number.
        grasp_all, draw_all = np.repeat(rows, hi - lo), np.tile(np.arange(lo, hi), len(rows))
        for first in range(0, len(grasp_all), RANK_PAIRS):
            grasp_of, draw_of = grasp_all[first:first + RANK_PAIRS], draw_all[first:first + RANK_PAIRS]
            out = evaluate_pairs(starts[grasp_of], draw_of, draws, settings, lift)
            chance[grasp_of, draw_of] = out.lift_chance if lift else out.closure
            fc[grasp_of, draw_of] = out.ferrari_canny
        judged[rows] = hi

    ends = [e for e in RANK_ENDS if e < n] + [n]
    for k, (lo, hi) in enumerate(zip([0] + ends[:-1], ends)):
        rows = np.flatnonzero(alive & (judged < hi))
        if len(rows):
            judge_rows(rows, lo, hi)
        if hi == n:
            break
        live = np.flatnonzero(alive)
        if len(live) == 0:  # every grasp below the floor
            break
        known = chance[live].sum(axis=1)
        if k == 0 and (floor == -np.inf or len(live) > RANK_LEAD):
            # No floor yet (gp-p's first chunk), or many grasps to drop: the grasp ahead
            # after the first block is judged on every draw now, and its score is the bar.
            lead = live[int(np.argmax(known))]
            judge_rows(np.array([lead]), hi, n)
            known[live == lead] = chance[lead].sum()
        bar = max(floor, float(known.max()) / n) - RANK_SLACK
        alive[live[(known + (n - judged[live])) / n < bar]] = False
    score, tie = np.full(g, -np.inf), np.full(g, -np.inf)
    kept = chance[alive]
    # The rows as the whole grid reduces them: P_L's mean, P_F's count over n.
    score[alive] = kept.mean(axis=1) if lift else kept.astype(bool).sum(axis=1) / n
    tie[alive] = fc[alive].mean(axis=1)
    return score, tie


def as_starts(grasps) -> np.ndarray:
    if isinstance(grasps, Grasp):
        grasps = [grasps]
    if isinstance(grasps, (list, tuple)) and grasps and isinstance(grasps[0], Grasp):
        return np.stack([gr.array for gr in grasps])
    return np.asarray(grasps, dtype=float).reshape(-1, 2, 2)


def executed_starts(starts: np.ndarray, approach: np.ndarray, settings: GraspSettings):
    """The jaw starts executed under approach noise: each of G planned grasps (G, 2, 2)
    with each of n draws of standard-normal deviates (n, 2, 2), g1 and g2 each moved by
    sigma_g times its deviate, then narrowed to the opening. Returns g1, g2, each
    (G * n, 2), grasp-major. The analytic P_F and the physics trials both use this."""
    starts = np.asarray(starts, dtype=float).reshape(-1, 2, 2)
    g1 = (starts[:, None, 0, :] + settings.sigma_g * approach[None, :, 0, :]).reshape(-1, 2)
    g2 = (starts[:, None, 1, :] + settings.sigma_g * approach[None, :, 1, :]).reshape(-1, 2)
    return within_opening(g1, g2, settings.opening)


def within_opening(g1: np.ndarray, g2: np.ndarray, opening: float):
    """Narrow each pair wider than the opening symmetrically about its midpoint."""
    d = g2 - g1
    width = np.linalg.norm(d, axis=1)
    shrink = np.where(width > opening, (width - opening) / (2 * np.maximum(width, 1e-300)), 0.0)[:, None]
    return g1 + shrink * d, g2 - shrink * d


def default_streams(seed: int, scene_name: str, realisation: int = 0):
    """The named random streams of one belief's evaluation (see harness.seeding)."""
    from harness.seeding import stream

    return tuple(stream(seed, scene_name, realisation, purpose)
                 for purpose in ("shapes", "approach", "friction", "pressure"))
