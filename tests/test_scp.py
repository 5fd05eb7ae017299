"""The SCP solver on small nonconvex problems with known optima."""

from __future__ import annotations

import numpy as np
import pytest

from harness.scp import SCPSettings, minimize


def hs006(x):
    """Hock-Schittkowski 6: min (1 - x1)^2 s.t. 10 (x2 - x1^2) = 0; optimum (1, 1), f = 0."""
    return (1 - x[:, 0]) ** 2, 10 * (x[:, 1] - x[:, 0] ** 2), np.zeros((len(x), 0))


def hs071(x):
    """Hock-Schittkowski 71: min x1 x4 (x1 + x2 + x3) + x3 s.t. x1 x2 x3 x4 >= 25,
    |x|^2 = 40, 1 <= x <= 5; optimum (1, 4.7430, 3.8211, 1.3794), f = 17.0140173."""
    f = x[:, 0] * x[:, 3] * x[:, :3].sum(axis=1) + x[:, 2]
    h = (x**2).sum(axis=1) - 40
    g = 25 - x.prod(axis=1)
    return f, h[:, None], g[:, None]


def parabola(x):
    """min (x - 2)^2 + (y - 1)^2 s.t. x^2 <= y, x + y <= 2; optimum (1, 1), f = 1."""
    f = (x[:, 0] - 2) ** 2 + (x[:, 1] - 1) ** 2
    g = np.column_stack([x[:, 0] ** 2 - x[:, 1], x[:, 0] + x[:, 1] - 2])
    return f, np.zeros((len(x), 0)), g


def test_hs006_reaches_its_optimum_from_the_standard_start():
    res = minimize(hs006, [[-1.2, 1.0]], -10, 10, 1, 0)
    assert res.status == ["converged"]
    np.testing.assert_allclose(res.x[0], [1.0, 1.0], atol=1e-4)
    assert res.objective[0] < 1e-7 and res.violation[0] < 1e-6


def test_hs071_reaches_the_published_optimum():
    res = minimize(hs071, [[1.0, 5.0, 5.0, 1.0]], 1, 5, 1, 1, SCPSettings(trust_init=0.5))
    assert res.status == ["converged"]
    np.testing.assert_allclose(res.x[0], [1.0, 4.7429996, 3.8211499, 1.3794082], atol=2e-4)
    assert res.objective[0] == pytest.approx(17.0140173, abs=1e-4)


def test_a_nonconvex_feasible_set_is_handled_from_an_infeasible_start():
    res = minimize(parabola, [[-2.0, 0.0]], -5, 5, 0, 2)
    assert res.status == ["converged"]
    np.testing.assert_allclose(res.x[0], [1.0, 1.0], atol=1e-4)
    assert res.objective[0] == pytest.approx(1.0, abs=1e-4)


def test_an_infeasible_problem_is_reported_as_such():
    def impossible(x):
        return x[:, 0], np.zeros((len(x), 0)), (x[:, 0] ** 2 + 1)[:, None]

    res = minimize(impossible, [[0.5]], -3, 3, 0, 1, SCPSettings(penalty_rounds=3))
    assert res.status == ["infeasible"] and res.violation[0] >= 1.0 - 1e-9


def test_problems_solved_together_reach_the_optima_they_reach_alone():
    """One block-diagonal QP serves all problems; OSQP's stopping test is global, so the
    iterates differ in their last digits, but every problem reaches its optimum."""
    starts = np.array([[-1.2, 1.0], [0.5, 2.0], [2.0, -1.0]])
    together = minimize(hs006, starts, -10, 10, 1, 0)
    assert all(s == "converged" for s in together.status)
    for i, x0 in enumerate(starts):
        alone = minimize(hs006, x0[None], -10, 10, 1, 0)
        np.testing.assert_allclose(together.x[i], alone.x[0], atol=5e-4)
        np.testing.assert_allclose(together.x[i], [1.0, 1.0], atol=5e-4)
    again = minimize(hs006, starts, -10, 10, 1, 0)
    np.testing.assert_array_equal(again.x, together.x)  # deterministic


def test_bounds_hold_at_every_iterate():
    seen = []

    def tracked(x):
        seen.append(x.copy())
        return parabola(x)

    minimize(tracked, [[-2.0, 0.0]], [-1.5, -0.5], [1.5, 1.5], 0, 2)
    # Finite differences step 1e-6 outside an iterate; iterates themselves stay inside.
    points = np.concatenate(seen)
    assert points[:, 0].min() >= -1.5 - 2e-6 and points[:, 1].max() <= 1.5 + 2e-6


def test_the_damped_bfgs_update_keeps_the_model_positive_definite_and_meets_powells_secant():
    """Powell's damping (Nocedal and Wright, Numerical Optimization, Procedure 18.2) against
    its formula: with enough curvature along the step (s.y >= 0.2 s.B s) the update is plain
    BFGS and meets the secant equation B+ s = y; along a step of negative curvature, where
    plain BFGS would lose positive definiteness, it meets B+ s = r with r = theta y + (1 -
    theta) B s, theta = 0.8 s.B s / (s.B s - s.y), and stays positive definite."""
    from harness.scp import _damped_bfgs

    rng = np.random.default_rng(3)
    a = rng.standard_normal((4, 4))
    b = a @ a.T + 4 * np.eye(4)
    s = rng.standard_normal(4)
    bs = b @ s
    for y, damped in ((b @ s + 0.1 * rng.standard_normal(4), False), (-0.5 * bs, True)):
        new = _damped_bfgs(b[None], s[None], y[None], np.array([False]))[0]
        sy, sbs = s @ y, s @ bs
        theta = 0.8 * sbs / (sbs - sy) if damped else 1.0
        assert (sy < 0.2 * sbs) == damped
        np.testing.assert_allclose(new @ s, theta * y + (1 - theta) * bs, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(new, new.T, atol=1e-12)
        assert np.linalg.eigvalsh(new).min() > 0


def test_an_unconstrained_descent_never_accepts_a_step_that_raises_the_objective():
    """Rosenbrock's valley from the standard start (-1.2, 1): the minimum (1, 1), and with no
    constraints the merit is the objective, which the trust region's ratio test keeps from
    rising at any iteration (accepting every step the model promises would raise it by
    about 1600 on the way)."""
    def rosenbrock(x):
        empty = np.zeros((len(x), 0))
        return 100 * (x[:, 1] - x[:, 0] ** 2) ** 2 + (1 - x[:, 0]) ** 2, empty, empty

    result = minimize(rosenbrock, np.array([[-1.2, 1.0]]), -10.0, 10.0, 0, 0)
    assert result.status == ["converged"]
    np.testing.assert_allclose(result.x[0], [1.0, 1.0], atol=1e-4)
    objective = np.array([step[2][0] for step in result.trace])
    assert np.all(np.diff(objective) <= 0.0)
