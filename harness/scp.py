"""Sequential convex programming in the TrajOpt style (Schulman et al. 2013), batched over
independent problems: l1 penalties on linearised constraints, a trust region, penalty
increases, and a QP subproblem solved by OSQP (set up once, then only updated)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import osqp
import scipy.sparse as sp


@dataclass(frozen=True)
class SCPSettings:
    """Trust region (in the units of x), penalties and stopping rules."""

    trust_init: float = 1.0
    trust_min: float = 1e-4
    trust_max: float = 10.0
    trust_grow: float = 1.5  # on an accepted step
    trust_shrink: float = 0.5  # on a rejected step
    accept_ratio: float = 0.25  # accept when true / predicted merit improvement exceeds this
    penalty_init: float = 10.0
    penalty_growth: float = 2.0
    penalty_rounds: int = 6
    max_iterations: int = 200
    improve_tol: float = 1e-7  # relative: stop when the model promises less than this
    constraint_tol: float = 1e-6
    proximal: float = 1e-6  # weight of |step|^2 / 2, so flat directions do not drift
    fd_step: float = 1e-6  # finite differences of the problem functions...
    fd_central: bool = True  # ...central (2n + 1 rows per problem) or forward (n + 1)
    qp_tolerance: float = 1e-6  # OSQP's absolute and relative tolerance (then polished)
    hessian_init: float = 0.0  # the Lagrangian Hessian model before any curvature is seen (x I)


@dataclass
class SCPResult:
    """Per problem: the solution x (P, n), its objective, its constraint violation
    (sum |h| + sum max(0, g)), iterations and status ("converged", "infeasible",
    "iteration_limit", "time_limit"); plus the total function evaluations (rows) and a
    trace of (seconds, evaluations, objective (P,), violation (P,), done (P,)) per
    iteration."""

    x: np.ndarray
    objective: np.ndarray
    violation: np.ndarray
    iterations: np.ndarray
    status: list
    evaluations: int
    trace: list = field(default_factory=list)


def minimize(fun, x0, lower, upper, n_eq: int, n_ineq: int, settings: SCPSettings = SCPSettings(),
             time_budget: float | None = None) -> SCPResult:
    """Minimise f(x) subject to h(x) = 0, g(x) <= 0 and lower <= x <= upper, for P
    independent problems at once.

    ``fun(X)`` takes rows X (k, n) and returns f (k,), h (k, n_eq), g (k, n_ineq); it is
    called on many rows at once (Jacobians are central differences of one call).

    The loops of TrajOpt run as one state machine per problem: convexify at x, solve the
    QP (the objective's gradient with a damped-BFGS model of the Lagrangian's Hessian,
    multipliers from the QP's duals, plus a small proximal term; l1 penalties rho |h + J_h d| and
    rho max(0, g + J_g d) through slack variables, |d|_inf within the trust region and
    the bounds); accept the step when the true merit improvement is at least
    accept_ratio times the model's prediction, then grow the region, else shrink it.
    When the model promises no more improvement (or the region has collapsed), a
    feasible problem is done; an infeasible one gets rho multiplied, up to
    penalty_rounds times, and is then declared infeasible.
    """
    start = time.perf_counter()
    x = np.array(x0, dtype=float, ndmin=2)
    p, n = x.shape
    lower = np.broadcast_to(np.asarray(lower, dtype=float), (p, n))
    upper = np.broadcast_to(np.asarray(upper, dtype=float), (p, n))
    x = np.clip(x, lower, upper)
    s = settings
    qp = _BatchQP(p, n, n_eq, n_ineq, s.proximal, s.qp_tolerance)
    trust = np.full(p, s.trust_init)
    rho = np.full(p, s.penalty_init)
    rounds = np.zeros(p, dtype=int)
    done = np.zeros(p, dtype=bool)
    status = ["iteration_limit"] * p
    iterations = np.zeros(p, dtype=int)
    # Every point is evaluated together with its finite-difference stencil (one call), so
    # an accepted step arrives with its Jacobians and a rejected one needs none.
    lin, evaluations = _linearise(fun, x, s, n_eq, n_ineq)
    trace = []
    hessian = np.repeat(s.hessian_init * np.eye(n)[None], p, axis=0)  # damped-BFGS model of the Lagrangian's Hessian
    first = np.ones(p, dtype=bool)
    for _ in range(s.max_iterations):
        active = ~done
        if not active.any():
            break
        if time_budget is not None and time.perf_counter() - start > time_budget:
            for i in np.flatnonzero(active):
                status[i] = "time_limit"
            break
        iterations[active] += 1
        f, h, g, grad, jh, jg = lin
        step_lo = np.where(active[:, None], np.maximum(-trust[:, None], lower - x), 0.0)
        step_hi = np.where(active[:, None], np.minimum(trust[:, None], upper - x), 0.0)
        d, lam, mu = qp.solve(hessian, grad, h, jh, g, jg, rho, step_lo, step_hi)
        trial_lin, used = _linearise(fun, x[active] + d[active], s, n_eq, n_ineq)
        evaluations += used
        trial = _scatter(lin, trial_lin, active)
        merit = f + rho * _violation(h, g)
        curvature = np.einsum("pi,pij,pj->p", d, hessian, d) + s.proximal * np.einsum("ij,ij->i", d, d)
        model = (f + np.einsum("ij,ij->i", grad, d) + 0.5 * curvature
                 + rho * _violation(h + np.einsum("pkn,pn->pk", jh, d), g + np.einsum("pkn,pn->pk", jg, d)))
        predicted = merit - model
        actual = merit - (trial[0] + rho * _violation(trial[1], trial[2]))
        accept = active & (predicted > 0) & (actual >= s.accept_ratio * predicted)
        # Second-order correction for rejected steps (against the Maratos effect): move
        # back onto the constraints violated at the trial point, least-norm, and retest.
        retry = active & ~accept & (predicted > 0)
        if retry.any():
            rows = np.concatenate([jh, jg * (trial[2] > 0)[:, :, None]], axis=1)
            residual = np.concatenate([trial[1], np.maximum(trial[2], 0.0)], axis=1)
            correction = -np.einsum("pnk,pk->pn", np.linalg.pinv(rows), residual)
            # The correction may leave the trust region somewhat (to twice its radius).
            corrected = np.clip(d + correction, np.maximum(-2 * trust[:, None], lower - x),
                                np.minimum(2 * trust[:, None], upper - x))
            second_lin, used = _linearise(fun, x[retry] + corrected[retry], s, n_eq, n_ineq)
            evaluations += used
            second = _scatter(lin, second_lin, retry)
            good = retry & (merit - (second[0] + rho * _violation(second[1], second[2]))
                            >= s.accept_ratio * predicted)
            d = np.where(good[:, None], corrected, d)
            trial = tuple(np.where(good.reshape((-1,) + (1,) * (a.ndim - 1)), b, a) for a, b in zip(trial, second))
            accept = accept | good
        if accept.any():  # curvature along the accepted steps, with the new multipliers
            lag = lambda lin_: lin_[3] + np.einsum("pkn,pk->pn", lin_[4], lam) + np.einsum("pkn,pk->pn", lin_[5], mu)  # noqa: E731
            y = lag(trial) - lag(lin)
            hessian[accept] = _damped_bfgs(hessian[accept], d[accept], y[accept], first[accept])
            first[accept] = False
            x[accept] = x[accept] + d[accept]
            lin = tuple(np.where(accept.reshape((-1,) + (1,) * (a.ndim - 1)), b, a) for a, b in zip(lin, trial))
        trust = np.where(accept, np.minimum(trust * s.trust_grow, s.trust_max),
                         np.where(active, trust * s.trust_shrink, trust))
        f, h, g = lin[:3]
        stalled = active & ((predicted <= s.improve_tol * (1 + np.abs(merit))) | (trust < s.trust_min))
        feasible = _violation(h, g) <= s.constraint_tol
        for i in np.flatnonzero(stalled & feasible):
            done[i], status[i] = True, "converged"
        bump = stalled & ~feasible & (rounds < s.penalty_rounds)
        rho[bump] *= s.penalty_growth
        rounds[bump] += 1
        trust[bump] = np.maximum(trust[bump], s.trust_init)
        for i in np.flatnonzero(stalled & ~feasible & ~bump):
            done[i], status[i] = True, "infeasible"
        trace.append((time.perf_counter() - start, evaluations, f.copy(), _violation(h, g), done.copy()))
    f, h, g = lin[:3]
    return SCPResult(x, f, _violation(h, g), iterations, status, evaluations, trace)


def _linearise(fun, x, s: SCPSettings, n_eq, n_ineq):
    """f, h, g and their finite-difference derivatives (grad, J_h, J_g) at the rows of x,
    from one call on the rows and their stencils; and the number of rows evaluated."""
    p, n = x.shape
    offsets = (np.concatenate([np.eye(n), -np.eye(n)]) if s.fd_central else np.eye(n)) * s.fd_step
    stencil = np.concatenate([np.zeros((1, n)), offsets])  # the point itself first
    points = (x[:, None, :] + stencil[None]).reshape(-1, n)
    f, h, g = _call(fun, points, n_eq, n_ineq)
    k = len(stencil)
    f, h, g = f.reshape(p, k), h.reshape(p, k, n_eq), g.reshape(p, k, n_ineq)
    if s.fd_central:
        hi, lo, span = slice(1, n + 1), slice(n + 1, 2 * n + 1), 2 * s.fd_step
        grad = (f[:, hi] - f[:, lo]) / span
        jh = np.swapaxes((h[:, hi] - h[:, lo]) / span, 1, 2)
        jg = np.swapaxes((g[:, hi] - g[:, lo]) / span, 1, 2)
    else:
        grad = (f[:, 1:] - f[:, :1]) / s.fd_step
        jh = np.swapaxes((h[:, 1:] - h[:, :1]) / s.fd_step, 1, 2)
        jg = np.swapaxes((g[:, 1:] - g[:, :1]) / s.fd_step, 1, 2)
    return (f[:, 0], h[:, 0], g[:, 0], grad, jh, jg), len(points)


def _scatter(base, part, rows):
    """``base`` (a tuple of arrays over all problems) with the given rows replaced by ``part``."""
    out = tuple(a.copy() for a in base)
    for a, b in zip(out, part):
        a[rows] = b
    return out


def _damped_bfgs(b, s, y, first):
    """Powell's damped BFGS update of Hessian models b (k, n, n) for steps s and
    gradient changes y (k, n); stays positive definite. A model's first update starts
    from the scaled identity (y.y / s.y) I."""
    sy = np.einsum("ij,ij->i", s, y)
    scale = np.where(sy > 1e-12, np.einsum("ij,ij->i", y, y) / np.maximum(sy, 1e-12), 1.0)
    b = np.where(first[:, None, None], scale[:, None, None] * np.eye(s.shape[1]), b)
    bs = np.einsum("kij,kj->ki", b, s)
    sbs = np.einsum("ij,ij->i", s, bs)
    theta = np.where(sy >= 0.2 * sbs, 1.0, 0.8 * sbs / np.maximum(sbs - sy, 1e-300))
    r = theta[:, None] * y + (1 - theta)[:, None] * bs
    sr = np.einsum("ij,ij->i", s, r)
    ok = (sbs > 1e-300) & (sr > 1e-300)
    update = (-np.einsum("ki,kj->kij", bs, bs) / np.where(ok, sbs, 1.0)[:, None, None]
              + np.einsum("ki,kj->kij", r, r) / np.where(ok, sr, 1.0)[:, None, None])
    return np.where(ok[:, None, None], b + update, b)


def _violation(h, g):
    return np.abs(h).sum(axis=1) + np.maximum(g, 0.0).sum(axis=1)


def _call(fun, x, n_eq, n_ineq):
    f, h, g = fun(x)
    k = len(x)
    return (np.asarray(f, dtype=float).reshape(k), np.asarray(h, dtype=float).reshape(k, n_eq),
            np.asarray(g, dtype=float).reshape(k, n_ineq))


class _BatchQP:
    """The block-diagonal QP of all problems, with a fixed sparsity pattern.

    Variables per problem: the step d (n), slacks t (n_eq) with |h + J_h d| <= t, and
    slacks s (n_ineq) with max(0, g + J_g d) <= s. Minimise
    d^T (B + proximal I) d / 2 + grad . d + rho (sum t + sum s).
    """

    def __init__(self, p: int, n: int, n_eq: int, n_ineq: int, proximal: float, tolerance: float):
        self.p, self.n, self.ne, self.ni = p, n, n_eq, n_ineq
        m = n + n_eq + n_ineq
        rows_per = 2 * n_eq + 2 * n_ineq + n
        entries = []  # (row, col) of one block, in the order values are supplied
        r = 0
        for sign in (1, -1):  # sign * J_h d - t <= sign * (-h)
            for k in range(n_eq):
                entries += [(r + k, j) for j in range(n)] + [(r + k, n + k)]
            r += n_eq
        for k in range(n_ineq):  # J_g d - s <= -g
            entries += [(r + k, j) for j in range(n)] + [(r + k, n + n_eq + k)]
        r += n_ineq
        entries += [(r + k, n + n_eq + k) for k in range(n_ineq)]  # s >= 0
        r += n_ineq
        entries += [(r + k, k) for k in range(n)]  # step bounds
        block = np.array(entries, dtype=np.int64).reshape(-1, 2)
        rows = (block[None, :, 0] + rows_per * np.arange(p)[:, None]).ravel()
        cols = (block[None, :, 1] + m * np.arange(p)[:, None]).ravel()
        ids = np.arange(1, len(rows) + 1, dtype=float)
        a = sp.csc_matrix((ids, (rows, cols)), shape=(p * rows_per, p * m))
        self._order = a.data.astype(np.int64) - 1  # CSC position -> our entry index
        self._a = a
        # P: a dense upper triangle over each problem's step, nothing on the slacks.
        iu = np.triu_indices(n)
        prow = (iu[0][None, :] + m * np.arange(p)[:, None]).ravel()
        pcol = (iu[1][None, :] + m * np.arange(p)[:, None]).ravel()
        pm = sp.csc_matrix((np.arange(1, len(prow) + 1, dtype=float), (prow, pcol)), shape=(p * m, p * m))
        self._p_order = pm.data.astype(np.int64) - 1
        self._p_matrix = pm
        self._triu = iu
        self.proximal = proximal
        self.tolerance = tolerance
        self._solver = None

    def solve(self, hessian, grad, h, jh, g, jg, rho, step_lo, step_hi):
        """The step (p, n) and the multipliers of the linearised constraints, lambda (p,
        n_eq) and mu (p, n_ineq), for the given convex quadratic model."""
        p, n, ne, ni = self.p, self.n, self.ne, self.ni
        values = []
        for sign in (1, -1):
            if ne:
                values.append(np.concatenate([sign * jh, -np.ones((p, ne, 1))], axis=2).reshape(p, -1))
        if ni:
            values.append(np.concatenate([jg, -np.ones((p, ni, 1))], axis=2).reshape(p, -1))
            values.append(np.ones((p, ni)))
        values.append(np.ones((p, n)))
        data = np.concatenate(values, axis=1).ravel()[self._order]
        inf = np.inf
        lo = np.concatenate([np.full((p, 2 * ne + ni), -inf), np.zeros((p, ni)), step_lo], axis=1).ravel()
        hi = np.concatenate([-h, h, -g, np.full((p, ni), inf), step_hi], axis=1).ravel()
        q = np.concatenate([grad, rho[:, None] * np.ones((p, ne + ni))], axis=1).ravel()
        blocks = hessian + self.proximal * np.eye(n)
        pdata = blocks[:, self._triu[0], self._triu[1]].ravel()[self._p_order]
        if self._solver is None:
            self._a.data = data
            self._p_matrix.data = pdata
            self._solver = osqp.OSQP()
            self._solver.setup(P=self._p_matrix, q=q, A=self._a, l=lo, u=hi, verbose=False,
                               eps_abs=self.tolerance, eps_rel=self.tolerance, polishing=True, max_iter=4000)
        else:
            self._solver.update(q=q, l=lo, u=hi, Ax=data, Px=pdata)
        result = self._solver.solve(raise_error=False)
        if result.x is None or not np.all(np.isfinite(result.x)):
            return np.zeros((p, n)), np.zeros((p, ne)), np.zeros((p, ni))
        step = np.clip(result.x.reshape(p, -1)[:, :n], step_lo, step_hi)
        y = result.y.reshape(p, -1)
        lam = y[:, :ne] - y[:, ne:2 * ne]
        mu = np.maximum(y[:, 2 * ne:2 * ne + ni], 0.0)
        return step, lam, mu
