"""The P_F estimator: deterministic answers on the calibration rectangle, behaviour under
approach noise, common random numbers, failure reasons and the Wilson interval."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import binom

from harness.belief import build_belief
from harness.grasp import Grasp, find_contacts
from harness.quality import (FAILURE_REASONS, PLANAR_REASONS, POOL_BLOCK, DrawPool, within_opening, default_streams,
                             draw_evaluation, estimate_p_f, evaluate_draws, evaluate_pairs, ranking_scores,
                             wilson_interval)
from harness.scene import load_scene
from harness.seeding import stream
from harness.settings import resolve

FRICTION, OPENING, JAW = 0.5, 0.10, 0.01


def settings(sigma_g: float, friction_spread: float = 0.0):
    """The calibration rectangle's settings (opening OPENING, jaw width JAW) with this noise."""
    return resolve(load_scene("rectangle"), {"sigma_g": sigma_g, "friction": FRICTION,
                                             "friction_spread": friction_spread})


@pytest.fixture(scope="module")
def rectangle():
    scene = load_scene("rectangle")
    belief = build_belief(scene, stream(0, "rectangle", 0, "sensor"))
    return belief, draw_evaluation(belief, 1000, *default_streams(0, "rectangle"))


def through_centre(angle_deg: float) -> Grasp:
    """A grasp through the rectangle's centre whose jaws start outside it."""
    return Grasp.from_centre((0.0, 0.0), math.radians(angle_deg), 0.09)


def test_p_f_without_approach_noise_is_the_deterministic_answer(rectangle):
    """10 degrees: the axis meets the short sides 10 degrees off their normal, inside the
    friction cone (atan 0.5 = 26.6 degrees); 40 degrees: it meets the long sides 50
    degrees off their normal, outside it."""
    _, draws = rectangle
    at10, at40 = estimate_p_f([through_centre(10), through_centre(40)], draws, settings(0.0))
    assert at10.p_f == 1.0 and at10.failures == dict.fromkeys(FAILURE_REASONS, 0)
    assert at40.p_f == 0.0 and at40.failures["friction_cone"] == 1000
    assert at10.ferrari_canny_mean > 0 and at40.ferrari_canny_mean == 0
    assert (at10.ci_low, at10.ci_high) == pytest.approx(wilson_interval(1000, 1000), abs=1e-15)


def test_p_f_falls_as_approach_noise_grows_near_a_corner(rectangle):
    """Jaws closing along x at y = 12 mm, 3 mm below the corner: with more noise, more
    draws slide the plates onto the corner's rounded normals."""
    _, draws = rectangle
    grasp = Grasp((-0.045, 0.012), (0.045, 0.012))
    p = [estimate_p_f(grasp, draws, settings(s))[0].p_f for s in (0.0, 0.002, 0.004, 0.008)]
    # The same draws at every sigma (common random numbers), so the decrease is not noise.
    assert all(a >= b for a, b in zip(p, p[1:])), p
    assert p[0] == 1.0 and p[-1] < 0.8


def test_grasps_judged_together_share_every_draw(rectangle):
    _, draws = rectangle
    grasps = [through_centre(10), Grasp((-0.045, 0.012), (0.045, 0.012))]
    together = evaluate_draws(grasps, draws, settings(0.004))
    for g, grasp in enumerate(grasps):
        alone = evaluate_draws(grasp, draws, settings(0.004))
        np.testing.assert_array_equal(together.closure[g], alone.closure[0])
        np.testing.assert_array_equal(together.reason[g], alone.reason[0])


def test_pairs_of_grasps_and_draws_are_judged_as_on_the_full_grid(rectangle):
    """evaluate_pairs on scattered (grasp, draw) pairs gives exactly the grid's entries."""
    _, draws = rectangle
    grasps = np.stack([through_centre(a).array for a in (0, 10, 35, 80)])
    grid = evaluate_draws(grasps, draws, settings(0.004))
    rng = np.random.default_rng(5)
    which, draw = rng.integers(0, 4, 300), rng.integers(0, len(draws), 300)
    pairs = evaluate_pairs(grasps[which], draw, draws, settings(0.004))
    for name in ("closure", "lifted", "reason", "pivots", "ferrari_canny", "lift_chance"):
        np.testing.assert_array_equal(getattr(pairs, name), getattr(grid, name)[which, draw], err_msg=name)
    assert (~grid.closure).any() and grid.closure.any()


@pytest.mark.parametrize("lift", [True, False])
def test_ranking_with_a_floor_drops_only_grasps_that_cannot_win(rectangle, lift):
    """The bounded ranking (a floor) against judging every grasp on every draw: each grasp
    it keeps has the very score and tie-break, each it drops scores below the bar (the
    floor, or the best score of the set), so the pick is the same; and it does drop some
    (grasps through the centre far off the rectangle's axes, an off-centre one)."""
    _, draws = rectangle
    grasps = np.stack([through_centre(a).array for a in (0, 5, 20, 35, 50, 65, 80, 90)]
                      + [Grasp((-0.045, y), (0.045, y)).array for y in (0.004, 0.012, 0.018)])
    s = settings(0.004)
    score, tie = ranking_scores(grasps, draws, s, lift)
    assert np.isfinite(score).all() and 0 <= score.min() < score.max() <= 1
    best = int(np.lexsort((-tie, -score))[0])
    for floor in (-np.inf, 0.8, float(score[best])):
        bounded, bounded_tie = ranking_scores(grasps, draws, s, lift, floor=floor)
        kept = np.isfinite(bounded)
        np.testing.assert_array_equal(bounded[kept], score[kept])
        np.testing.assert_array_equal(bounded_tie[kept], tie[kept])
        assert (score[~kept] < max(floor, score.max())).all()
        assert np.isneginf(bounded_tie[~kept]).all()
        assert int(np.lexsort((-bounded_tie, -bounded))[0]) == best
        # Without a floor the grasp ahead after the first block sets the bar.
        assert (~kept).sum() >= 3, (floor, score)


def test_ranking_splits_its_calls_without_changing_a_number(rectangle, monkeypatch):
    """ranking_scores judges at most RANK_PAIRS (grasp, draw) pairs a call, however many
    grasps and draws it is given: with a bound of 250 pairs the calls do split (the first
    block's 800 pairs, the leader's 900 draws), and every score and tie-break is the same
    bit for bit as with a call for each block."""
    import harness.quality as quality

    _, draws = rectangle
    grasps = np.stack([through_centre(a).array for a in (0, 2, 4, 6, 8, 10, 30, 60)])
    s = settings(0.004)
    whole = ranking_scores(grasps, draws, s, True, floor=-np.inf)
    sizes = []
    judge = quality.evaluate_pairs

    def counted(starts, index, *args, **kwargs):
        sizes.append(len(index))
        return judge(starts, index, *args, **kwargs)

    monkeypatch.setattr(quality, "evaluate_pairs", counted)
    monkeypatch.setattr(quality, "RANK_PAIRS", 250)
    split = ranking_scores(grasps, draws, s, True, floor=-np.inf)
    assert max(sizes) == 250 and len(sizes) >= 8, sizes
    assert np.isfinite(whole[0]).sum() >= 3  # grasps were judged beyond the first block
    np.testing.assert_array_equal(split[0], whole[0])
    np.testing.assert_array_equal(split[1], whole[1])


def test_the_bodies_of_samples_in_pieces_are_judged_alike_in_groups_of_any_size(monkeypatch):
    """The lift's outcomes on samples in several pieces (judged on their bodies, a group of
    body fields at a time: BODY_BYTES) are the same bit for bit with groups of 2 fields as
    with the default's one group, on the stapler's draws, many of them in pieces."""
    import harness.quality as quality

    scene = load_scene("stapler")
    belief = build_belief(scene, stream(0, "stapler", 0, "sensor"))
    draws = draw_evaluation(belief, 300, *default_streams(0, "stapler"))
    fragmented = int(draws.shapes.regions.fragmented.sum())
    grasps = np.array([[[-0.03, -0.04], [-0.03, 0.03]], [[0.0, -0.04], [0.0, 0.03]]])
    s = resolve(scene)
    assert 8 <= fragmented < quality.BODY_BYTES / (quality.BODY_FIELD_BYTES * draws.shapes.grid.size ** 2)
    one = evaluate_draws(grasps, draws, s)
    monkeypatch.setattr(quality, "BODY_BYTES", 2.5 * quality.BODY_FIELD_BYTES * draws.shapes.grid.size ** 2)
    groups = evaluate_draws(grasps, draws, s)
    for name in ("closure", "lifted", "reason", "pivots", "ferrari_canny", "lift_chance", "squeezed", "pushed"):
        np.testing.assert_array_equal(getattr(groups, name), getattr(one, name), err_msg=name)
    assert one.lifted[:, draws.shapes.regions.fragmented].any()  # the bodies were judged


def test_a_draw_pool_holds_the_same_draws_as_draw_evaluation(rectangle):
    """On the rectangle, 250 draws come block by block (the weight-space sampler) and 120
    at once (pathwise, whose stream depends on the split): either way the pool's draws are
    draw_evaluation's, and only the blocks asked for are drawn. Pathwise draws are the
    same bit for bit. Weight-space draws solve for a block's deviations in single
    precision in one product, whose rounding can depend on how many draws it holds under
    some BLAS kernels (OpenBLAS's Haswell kernels on this project's machine: up to 5e-9 m
    from draw 96 on): they agree to 1e-4 of the posterior's largest std, the bound the
    sampler's single precision keeps (test_gpis.py), and their regions to 1e-6 of the grid."""
    belief, _ = rectangle
    value_std = float(np.sqrt(belief.var.max()))
    gradient_std = float(np.sqrt(belief.gradient_var.max()))
    for n, sampler in ((250, "weight-space"), (120, "pathwise")):
        assert belief.sampler(n) == sampler
        whole = draw_evaluation(belief, n, *default_streams(3, "rectangle"))
        pool = DrawPool(belief, n, *default_streams(3, "rectangle"))
        first = pool.draws(30)
        assert len(first) == (POOL_BLOCK if sampler == "weight-space" else n) and pool.drawn == len(first)
        full = pool.draws(n)
        assert len(full) == n and len(pool.draws(1)) == n
        exact = sampler == "pathwise"
        for name, std in (("values", value_std), ("gx", gradient_std), ("gy", gradient_std),
                          ("twist", gradient_std / belief.grid.cell)):
            np.testing.assert_allclose(getattr(full.shapes, name), getattr(whole.shapes, name), rtol=0,
                                       atol=0 if exact else 1e-4 * std, err_msg=name)
        for name, scale in (("area", belief.grid.extent**2), ("center_of_mass", belief.grid.extent),
                            ("hull", belief.grid.extent)):
            np.testing.assert_allclose(getattr(full.shapes.regions, name), getattr(whole.shapes.regions, name),
                                       rtol=0, atol=0 if exact else 1e-6 * scale, err_msg=name)
        for name in ("approach", "friction", "pressure"):
            np.testing.assert_array_equal(getattr(full, name), getattr(whole, name), err_msg=name)
        assert full.torque_scale == whole.torque_scale


def test_every_draw_is_a_success_or_exactly_one_failure(rectangle):
    _, draws = rectangle
    grasps = [through_centre(25), Grasp((0.0, 0.0), (0.045, 0.0)), Grasp((-0.045, 0.05), (0.045, 0.05)),
              Grasp((-0.045, 0.012), (0.045, 0.012))]
    outcomes = evaluate_draws(grasps, draws, settings(0.004))
    estimates = outcomes.estimates
    for est, closure, reason, squeezed, pushed in zip(estimates, outcomes.closure, outcomes.reason,
                                                      outcomes.squeezed, outcomes.pushed):
        # Where the push did not move the closing line (harness.push), P_F loses the
        # planar failures and the draws the plates' squeeze brought into closure; P_L
        # loses every failure.
        planar = np.isin(reason, [FAILURE_REASONS.index(r) for r in PLANAR_REASONS])
        same = ~pushed
        assert same.sum() >= 50
        assert closure[same].sum() + planar[same].sum() + squeezed[same].sum() == same.sum()
        assert est.p_l * est.samples + sum(est.failures.values()) == pytest.approx(est.samples)
    assert estimates[1].failures["too_wide"] == 1000  # g1 starts inside the rectangle
    assert estimates[2].failures["missed"] == 1000  # passes 35 mm above it


def test_friction_spread_draws_the_coefficient_around_its_mean(rectangle):
    """Each draw holds exactly when its friction coefficient, max(0, 0.5 + 0.2 z), exceeds
    the draw's critical coefficient: the tangent of the larger angle between the contact
    line and an inward normal (computed here with arccos, independently of the cone
    test). At 70 degrees the plates meet the long faces 20 degrees tilted, so each
    touches with its leading edge: the contacts sit on diagonally opposite plate edges
    and the contact line is about 36 degrees off the normals, so only the draws with
    friction above tan 36 deg = 0.73 hold (about 12 %)."""
    _, draws = rectangle
    grasp = through_centre(70)
    closure = evaluate_draws(grasp, draws, settings(0.0, friction_spread=0.2)).closure[0]
    n = len(draws)
    contacts = find_contacts(draws.shapes, np.tile(grasp.array[0], (n, 1)), np.tile(grasp.array[1], (n, 1)), JAW)
    line = contacts.c2 - contacts.c1
    line /= np.linalg.norm(line, axis=1, keepdims=True)
    angle = np.maximum(np.arccos(-np.einsum("ij,ij->i", contacts.n1, line)),
                       np.arccos(np.einsum("ij,ij->i", contacts.n2, line)))
    gamma = np.maximum(0.0, FRICTION + 0.2 * draws.friction)
    clear = np.abs(gamma - np.tan(angle)) > 1e-9
    np.testing.assert_array_equal(closure[clear], (gamma > np.tan(angle))[clear])
    assert clear.sum() == n and 0.01 < closure.mean() < 0.3


def test_pairs_wider_than_the_opening_are_narrowed_about_their_midpoint():
    g1 = np.array([[-0.06, 0.0], [-0.03, 0.0]])
    g2 = np.array([[0.06, 0.01], [0.03, 0.0]])
    a, b = within_opening(g1, g2, 0.1)
    np.testing.assert_allclose(np.linalg.norm(b - a, axis=1), [0.1, 0.06], atol=1e-15)
    np.testing.assert_allclose((a + b) / 2, (g1 + g2) / 2, atol=1e-15)


# -- the Wilson interval ------------------------------------------------------------------


def test_wilson_interval_matches_its_formula():
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.27753279986, abs=1e-10)
    k = np.arange(0, 1001)
    lo, hi = wilson_interval(k, 1000)
    assert np.all((lo <= k / 1000) & (k / 1000 <= hi)) and hi[-1] == 1.0 and lo[0] == 0.0
    # p = 0.3, z^2 = 3.8415: centre 0.307398, half-width 0.088452 (by hand, to 6 digits).
    lo, hi = wilson_interval(30, 100)
    assert (lo, hi) == pytest.approx((0.218946, 0.395850), abs=1e-5)  # hand rounding


@pytest.mark.parametrize("p", [0.05, 0.3, 0.5, 0.8])
def test_wilson_interval_covers_at_its_nominal_rate(p):
    """Exact coverage over the binomial distribution (n = 100) is within 2.5 points of 95 %
    (the Wilson interval's known oscillation), and so is a simulated check of 4000
    intervals (Monte-Carlo sd 0.35 points)."""
    n = 100
    k = np.arange(n + 1)
    lo, hi = wilson_interval(k, n)
    exact = binom.pmf(k, n, p)[(lo <= p) & (p <= hi)].sum()
    assert abs(exact - 0.95) < 0.025
    sims = np.random.default_rng(int(p * 100)).binomial(n, p, 4000)
    lo, hi = wilson_interval(sims, n)
    assert abs(np.mean((lo <= p) & (p <= hi)) - 0.95) < 0.025


def test_p_f_intervals_cover_the_pooled_value_at_their_nominal_rate():
    """Simulation of the statistic: 10 000 paired draws for a near-corner grasp give its
    P_F to +-0.005; 100 disjoint estimates of 100 draws each must cover it about 95 % of
    the time (binomial sd 2.2 points, so at least 88 %)."""
    scene = load_scene("rectangle")
    belief = build_belief(scene, stream(1, "rectangle", 0, "sensor"))
    grasp = Grasp((-0.045, 0.0125), (0.045, 0.0125))
    outcomes = []
    for block in range(5):
        draws = draw_evaluation(belief, 2000, *default_streams(1, "rectangle", block))
        outcomes.append(evaluate_draws(grasp, draws, settings(0.004)).closure[0])
    outcomes = np.concatenate(outcomes)
    pooled = outcomes.mean()
    assert 0.2 < pooled < 0.9
    k = outcomes.reshape(100, 100).sum(axis=1)
    lo, hi = wilson_interval(k, 100)
    assert np.mean((lo <= pooled) & (pooled <= hi)) >= 0.88
