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
