"""GPIS: kernel blocks, posterior, hyperparameters and both samplers, each checked
against an independent computation with a stated tolerance."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from harness.gpis import GPIS, _Basis1D, _cov_rows, _joint_1d, select_active_set

L, C, M0 = 0.02, 1e-4, -0.01


def kernel(a, b, l=L, c=C):
    d = np.asarray(a, float) - np.asarray(b, float)
    return c * np.exp(-(d * d).sum(-1) / (2 * l * l))


def fd_cov(A, Ag, B, Bg, l=L, c=C):
    """Joint covariance of [f(A), df/dx(Ag), df/dy(Ag)] with [f(B), df/dx(Bg), df/dy(Bg)],
    built only from the scalar kernel by central differences (independent of the
    analytic derivative blocks)."""
    h = 1e-4 * l
    e = np.eye(2) * h

    def block(P, dp, Q, dq):
        # dp, dq: None for a value, i for d/dx_i
        a, b = P[:, None, :], Q[None, :, :]
        if dp is None and dq is None:
            return kernel(a, b, l, c)
        if dp is None:
            return (kernel(a, b + e[dq], l, c) - kernel(a, b - e[dq], l, c)) / (2 * h)
        if dq is None:
            return (kernel(a + e[dp], b, l, c) - kernel(a - e[dp], b, l, c)) / (2 * h)
        return (kernel(a + e[dp], b + e[dq], l, c) - kernel(a + e[dp], b - e[dq], l, c)
                - kernel(a - e[dp], b + e[dq], l, c) + kernel(a - e[dp], b - e[dq], l, c)) / (4 * h * h)

    rows = [(A, None), (Ag, 0), (Ag, 1)]
    cols = [(B, None), (Bg, 0), (Bg, 1)]
    return np.block([[block(P, dp, Q, dq) for Q, dq in cols] for P, dp in rows])


@pytest.fixture(scope="module")
def data():
    """A small scattered data set with values everywhere and gradients at half the points."""
    rng = np.random.default_rng(1)
    X = rng.uniform(-0.05, 0.05, (30, 2))
    values = np.linalg.norm(X, axis=1) - 0.03 + 0.001 * rng.standard_normal(30)
    grads = X / np.linalg.norm(X, axis=1, keepdims=True) + 0.05 * rng.standard_normal((30, 2))
    grads[::2] = np.nan
    noise = rng.uniform(0.5, 2.0, 30) * 1e-6
    gnoise = rng.uniform(0.5, 2.0, (30, 2)) * 1e-2
    return X, values, noise, grads, gnoise


def dense_posterior(data, P, with_gradients):
    """Reference posterior mean and covariance at P by finite-difference kernel blocks
    and a plain linear solve (no Cholesky, no analytic derivative)."""
    X, values, noise, grads, gnoise = data
    g = ~np.isnan(grads).any(1)
    K = fd_cov(X, X[g], X, X[g])
    K += np.diag(np.concatenate([noise, gnoise[g, 0], gnoise[g, 1]]))
    y = np.concatenate([values - M0, grads[g, 0], grads[g, 1]])
    Pg = P if with_gradients else P[:0]
    Ks = fd_cov(P, Pg, X, X[g])
    mean = Ks @ np.linalg.solve(K, y)
    mean[: len(P)] += M0
    cov = fd_cov(P, Pg, P, Pg) - Ks @ np.linalg.solve(K, Ks.T)
    return mean, cov


@pytest.fixture(scope="module")
def gp(data):
    X, values, noise, grads, gnoise = data
    return GPIS(lengthscale=L, scale=C, prior_mean=M0).fit(X, values, noise, grads, gnoise)


def test_kernel_derivative_blocks_match_finite_differences_of_the_kernel():
    rng = np.random.default_rng(0)
    A, B = rng.uniform(-0.04, 0.04, (7, 2)), rng.uniform(-0.04, 0.04, (9, 2))
    gmask = np.array([True, False, True, True, False, True, True, False, True])
    ref = fd_cov(A, A, B, B[gmask])
    value_rows = _cov_rows(A, B, gmask, L, C, "value")
    grad_rows = _cov_rows(A, B, gmask, L, C, "gradient")
    analytic = np.concatenate([value_rows, grad_rows[0], grad_rows[1]])
    # Central differences with h = 1e-4 l are accurate to ~1e-8 of each block's scale.
    scale = np.abs(ref).max()
    np.testing.assert_allclose(analytic, ref, rtol=0, atol=1e-6 * scale)


def test_lengthscale_derivative_of_the_blocks_matches_finite_differences():
    rng = np.random.default_rng(2)
    A, B = rng.uniform(-0.04, 0.04, (5, 2)), rng.uniform(-0.04, 0.04, (6, 2))
    gmask = np.ones(6, dtype=bool)
    for kind in ("value", "gradient"):
        analytic = _cov_rows(A, B, gmask, L, C, kind, dlog_lengthscale=True)
        step = 1e-6
        fd = (_cov_rows(A, B, gmask, L * np.exp(step), C, kind)
              - _cov_rows(A, B, gmask, L * np.exp(-step), C, kind)) / (2 * step)
        np.testing.assert_allclose(analytic, fd, rtol=0, atol=1e-6 * np.abs(fd).max())


def test_posterior_mean_and_variance_match_an_independent_dense_computation(data, gp):
    P = np.random.default_rng(3).uniform(-0.06, 0.06, (25, 2))
    mean, var = gp.predict(P)
    ref_mean, ref_cov = dense_posterior(data, P, with_gradients=False)
    # Finite-difference blocks limit the reference to ~1e-6 relative.
    np.testing.assert_allclose(mean, ref_mean, rtol=0, atol=1e-6 * np.abs(ref_mean).max())
    np.testing.assert_allclose(var, np.diag(ref_cov), rtol=0, atol=1e-6 * C)


def test_gradient_prediction_matches_the_dense_reference_and_its_variance(data, gp):
    P = np.random.default_rng(4).uniform(-0.06, 0.06, (15, 2))
    grad, gvar = gp.predict_gradient(P, return_var=True)
    ref_mean, ref_cov = dense_posterior(data, P, with_gradients=True)
    n = len(P)
    np.testing.assert_allclose(grad, np.column_stack([ref_mean[n:2 * n], ref_mean[2 * n:]]), rtol=0, atol=1e-5)
    ref_var = np.diag(ref_cov)
    np.testing.assert_allclose(gvar, np.column_stack([ref_var[n:2 * n], ref_var[2 * n:]]),
                               rtol=0, atol=1e-5 * C / L**2)


def test_predicted_gradient_is_the_derivative_of_the_predicted_mean(gp):
    P = np.random.default_rng(5).uniform(-0.06, 0.06, (20, 2))
    h = 1e-6
    fd = np.column_stack([(gp.predict(P + [h, 0])[0] - gp.predict(P - [h, 0])[0]) / (2 * h),
                          (gp.predict(P + [0, h])[0] - gp.predict(P - [0, h])[0]) / (2 * h)])
    # Unit-scale gradients; central differences at h = 1e-6 m are good to ~1e-7.
    np.testing.assert_allclose(gp.predict_gradient(P), fd, rtol=0, atol=1e-6)


def test_log_marginal_likelihood_gradient_matches_finite_differences(gp):
    lml, grad = gp.log_marginal_likelihood(0.017, 2e-4, -0.005, eval_gradient=True)
    theta = np.array([np.log(0.017), np.log(2e-4), -0.005])
    fd = []
    for i, h in enumerate((1e-6, 1e-6, 1e-8)):
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        f = lambda t: gp.log_marginal_likelihood(np.exp(t[0]), np.exp(t[1]), t[2])  # noqa: E731
        fd.append((f(up) - f(down)) / (2 * h))
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-3)


def test_maximum_likelihood_recovers_known_hyperparameters():
    """Three data sets drawn from the prior (l = 0.02 m, scale = 1e-4 m^2, mean -0.01 m),
    500 noisy values each. Over 12 such sets the estimates' relative spread was 2.3 %
    (l), 14 % (scale) and 1.8 mm (mean), with no visible bias; the averages of three
    must fall within about 3.5 standard errors."""
    estimates = []
    for seed in range(3):
        rng = np.random.default_rng(100 + seed)
        X = rng.uniform(-0.15, 0.15, (500, 2))
        K = _cov_rows(X, X, np.zeros(500, bool), L, C, "value") + 1e-10 * np.eye(500)
        noise = 1e-6
        y = M0 + np.linalg.cholesky(K) @ rng.standard_normal(500) + np.sqrt(noise) * rng.standard_normal(500)
        gp = GPIS(lengthscale=0.035, scale=4e-4, prior_mean=0.0, fit_hyperparameters=True)
        gp.fit(X, y, np.full(500, noise))
        estimates.append((gp.lengthscale_, gp.scale_, gp.prior_mean_))
    l, c, m = np.mean(estimates, axis=0)
    assert abs(l / L - 1) < 0.05
    assert abs(c / C - 1) < 0.30
    assert abs(m - M0) < 0.0036


def test_separable_basis_reproduces_the_1d_kernel_and_its_derivatives():
    nodes = np.linspace(-0.1, 0.1, 41)
    basis = _Basis1D(nodes, L)
    f, df = basis.at(nodes)
    t = nodes / L
    G = _joint_1d(t, t)
    n = len(nodes)
    feats = np.concatenate([f, df * L])
    # Eigenvalues are cut at 1e-8 of the largest, leaving an error of ~5e-9 of the
    # (unit) prior variance.
    np.testing.assert_allclose(feats @ feats.T, G, rtol=0, atol=1e-8)
    # Off the nodes (Nystrom extension) on a node spacing of l/4 the error stays tiny.
    x = np.random.default_rng(0).uniform(-0.09, 0.09, 30)
    fx, dfx = basis.at(x)
    ref = _joint_1d(x / L, x / L)
    got = np.concatenate([fx, dfx * L]) @ np.concatenate([fx, dfx * L]).T
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)
    assert n > basis.rank > 10


def test_active_set_keeps_the_band_and_a_regular_far_lattice():
    rng = np.random.default_rng(0)
    xs = (np.arange(40) + 0.5) * 0.005 - 0.1
    P = np.array([(x, y) for y in xs for x in xs])
    sdf = np.linalg.norm(P, axis=1) - 0.05
    values = np.clip(sdf, -0.015, 0.015) + 0.0005 * rng.standard_normal(len(P))
    noise = rng.uniform(1, 2, len(P)) * 1e-7
    idx = select_active_set(P, values, noise, band=0.0125, spacing=0.0135)
    near = np.flatnonzero(np.abs(values) <= 0.0125)
    assert set(near) <= set(idx)
    far = np.setdiff1d(idx, near)
    # The 0.195 m span is cut into 15 equal squares of 13 mm per axis; where a square
    # holds far readings exactly one is kept, the one nearest its centre.
    side = 0.195 / 15
    all_far = np.setdiff1d(np.arange(len(P)), near)
    bins = np.minimum(((P[all_far] - P[all_far].min(0)) / side).astype(int), 14)
    occupied = {tuple(b) for b in bins}
    kept = {tuple(b) for b in bins[np.isin(all_far, far)]}
    assert kept == occupied and len(far) == len(occupied)
    for k in far:
        b = bins[all_far == k][0]
        same = all_far[(bins == b).all(1)]
        centre = P[all_far].min(0) + (b + 0.5) * side
        dist = np.linalg.norm(P[same] - centre, axis=1)
        assert np.linalg.norm(P[k] - centre) <= dist.min() + 1e-12


# -- samplers ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def grid_problem():
    """A 10 x 10 grid with observations at a subset of its cells (values everywhere
    observed, gradients near the circle), and the independent dense posterior over
    values and gradients at every grid point."""
    m, extent = 10, 0.1
    xs = (np.arange(m) + 0.5) * extent / m - extent / 2
    P = np.array([(x, y) for y in xs for x in xs])
    rng = np.random.default_rng(7)
    keep = rng.random(len(P)) < 0.6
    X = P[keep]
    sdf = np.linalg.norm(X, axis=1) - 0.025
    values = sdf + 0.0005 * rng.standard_normal(len(X))
    grads = X / np.linalg.norm(X, axis=1, keepdims=True)
    grads[np.abs(sdf) > 0.012] = np.nan
    noise = np.full(len(X), 0.0005**2)
    gnoise = np.full((len(X), 2), 0.05)
    data = (X, values, noise, grads, gnoise)
    gp = GPIS(lengthscale=L, scale=C, prior_mean=M0).fit(*data)
    mean, cov = dense_posterior(data, P, with_gradients=True)
    return gp, xs, mean, cov


def _as_vector(values, grads):
    n = len(values)
    return np.concatenate([values.reshape(n, -1), grads[..., 0].reshape(n, -1), grads[..., 1].reshape(n, -1)], 1)


@pytest.mark.parametrize("method", ["exact", "pathwise", "weight-space", "fast"])
def test_moments_of_4000_grid_draws_match_the_exact_posterior(grid_problem, method):
    gp, xs, mean, cov = grid_problem
    n = 4000
    values, grads = gp.sample_grid(xs, xs, n, np.random.default_rng(11), method=method)
    assert values.shape == (n, 10, 10) and grads.shape == (n, 10, 10, 2)
    draws = _as_vector(values, grads)
    sd = np.sqrt(np.diag(cov))
    # Sample means: each within 4.5 standard errors (300 outputs; a false alarm has
    # probability ~2e-3 for a correct sampler).
    z = (draws.mean(0) - mean) / (sd / np.sqrt(n))
    assert np.abs(z).max() < 4.5
    # Sample variances: relative standard error sqrt(2/n) = 2.2 %; allow 4.5 of them.
    assert np.abs(draws.var(0) / sd**2 - 1).max() < 4.5 * np.sqrt(2 / n)
    # Correlations between values and gradients at a few points: standard error of a
    # sample correlation is (1 - rho^2) / sqrt(n).
    pick = np.r_[[0, 44, 45, 99], 100 + np.r_[44, 45], 200 + np.r_[44, 55]]
    rho = cov[np.ix_(pick, pick)] / np.outer(sd[pick], sd[pick])
    rho_hat = np.corrcoef(draws[:, pick].T)
    assert np.abs(rho_hat - rho).max() < 4.5 * (1 - rho**2).max() / np.sqrt(n) + 1e-3


@pytest.mark.parametrize("method", ["exact", "fast"])
def test_draws_at_scattered_points_match_the_posterior(gp, method):
    P = np.random.default_rng(12).uniform(-0.06, 0.06, (40, 2))
    n = 4000
    draws = gp.sample(P, n, np.random.default_rng(13), method=method)
    mean, var = gp.predict(P)
    z = (draws.mean(0) - mean) / np.sqrt(var / n)
    assert np.abs(z).max() < 4.5
    assert np.abs(draws.var(0) / var - 1).max() < 4.5 * np.sqrt(2 / n)


def test_single_precision_part_of_the_weight_space_sampler_is_accurate(grid_problem):
    gp, xs, mean, cov = grid_problem
    bx = gp._basis(0, xs)
    list(gp._weight_space_draws(bx, bx, 1, np.random.default_rng(0)))
    R32 = gp._weight_space(bx, bx).factor32
    F = gp._observation_features(bx, bx)
    noise = gp.noise_ + 1e-10 * gp._prior_diag()
    Fw = F * (np.sqrt(gp.scale_) / np.sqrt(noise))[:, None]
    R64 = np.linalg.cholesky(Fw.T @ Fw + np.eye(F.shape[1]))
    z = np.random.default_rng(1).standard_normal((F.shape[1], 200)).astype(np.float32)
    dev64 = sla.solve_triangular(R64, z.astype(float), lower=True, trans="T")
    dev32 = sla.solve_triangular(R32, z, lower=True, trans="T")
    post_sd = np.sqrt(np.diag(np.linalg.inv(R64 @ R64.T)))
    # Error of each coefficient relative to its posterior standard deviation.
    assert np.abs((dev32 - dev64) / post_sd[:, None]).max() < 1e-4


def test_sampling_is_reproducible_for_the_same_generator(grid_problem):
    gp, xs, _, _ = grid_problem
    a = gp.sample_grid(xs, xs, 5, np.random.default_rng(3))
    b = gp.sample_grid(xs, xs, 5, np.random.default_rng(3))
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_unknown_sampling_method_is_refused(grid_problem):
    gp, xs, _, _ = grid_problem
    with pytest.raises(ValueError, match="unknown sampling method"):
        gp.sample_grid(xs, xs, 2, np.random.default_rng(0), method="cholesky")


def test_kronecker_accumulated_precision_equals_the_dense_product(grid_problem):
    gp, xs, _, _ = grid_problem
    bx = gp._basis(0, xs)
    w = np.random.default_rng(2).uniform(0.5, 2.0, len(gp.targets_))
    F = gp._observation_features(bx, bx)
    dense = F.T @ (w[:, None] * F)
    t = np.random.default_rng(3).standard_normal(len(gp.targets_))
    kron, rhs = gp._normal_equations(bx, bx, w, t)
    np.testing.assert_allclose(kron, dense, rtol=0, atol=1e-12 * np.abs(dense).max())
    np.testing.assert_allclose(rhs, F.T @ t, rtol=0, atol=1e-12 * np.abs(F.T @ t).max())


def test_off_node_observations_use_the_dense_fallback_with_the_same_posterior(data, monkeypatch):
    """With few basis nodes allowed, the bases become uniform Nystrom node sets, the
    observations fall off the nodes, and the precision is built densely."""
    import harness.gpis as gpis_module

    monkeypatch.setattr(gpis_module, "_MAX_NODES", 20)
    gp = GPIS(lengthscale=L, scale=C, prior_mean=M0).fit(*data)
    P = np.random.default_rng(14).uniform(-0.05, 0.05, (30, 2))
    bx = gp._basis(0, P[:, 0])
    assert bx.node_index(gp.X_[:, 0]) is None
    n = 4000
    draws = gp.sample(P, n, np.random.default_rng(15))
    mean, var = gp.predict(P)
    assert np.abs((draws.mean(0) - mean) / np.sqrt(var / n)).max() < 4.5
    assert np.abs(draws.var(0) / var - 1).max() < 4.5 * np.sqrt(2 / n)


def test_log_marginal_likelihood_is_the_gaussian_log_density_of_the_data(data, gp):
    from scipy.stats import multivariate_normal

    X, values, noise, grads, gnoise = data
    g = ~np.isnan(grads).any(1)
    K = fd_cov(X, X[g], X, X[g]) + np.diag(np.concatenate([noise, gnoise[g, 0], gnoise[g, 1]]))
    y = np.concatenate([values, grads[g, 0], grads[g, 1]])
    mean = np.concatenate([np.full(len(X), M0), np.zeros(2 * g.sum())])
    ref = multivariate_normal(mean, K).logpdf(y)
    # Finite-difference covariance blocks and the 1e-10 jitter limit the agreement.
    assert gp.log_marginal_likelihood_ == pytest.approx(ref, abs=1e-3)
    assert gp.log_marginal_likelihood() == pytest.approx(gp.log_marginal_likelihood_, rel=1e-12)


@pytest.mark.parametrize("method", ["exact", "fast"])
def test_a_gpis_without_gradient_observations_samples_its_posterior(data, method):
    X, values, noise, _, _ = data
    gp = GPIS(lengthscale=L, scale=C, prior_mean=M0).fit(X, values, noise)
    P = np.random.default_rng(16).uniform(-0.06, 0.06, (30, 2))
    n = 4000
    draws = gp.sample(P, n, np.random.default_rng(17), method=method)
    mean, var = gp.predict(P)
    assert np.abs((draws.mean(0) - mean) / np.sqrt(var / n)).max() < 4.5
    assert np.abs(draws.var(0) / var - 1).max() < 4.5 * np.sqrt(2 / n)
    xs = np.linspace(-0.05, 0.05, 9)
    grid_values, grid_grads = gp.sample_grid(xs, xs, 50, np.random.default_rng(18), method=method)
    assert grid_values.shape == (50, 9, 9) and np.isfinite(grid_grads).all()


def test_a_gradient_with_one_unknown_component_is_not_observed(data):
    """A gradient row with NaN in one component counts as no gradient at that point (not
    as half of one): the posterior is the one without that row's gradient."""
    X, values, noise, grads, gnoise = data
    partial, none = grads.copy(), grads.copy()
    partial[1, 0] = np.nan
    none[1] = np.nan
    assert np.isfinite(grads[1]).all()
    P = np.random.default_rng(5).uniform(-0.05, 0.05, (20, 2))
    a = GPIS(lengthscale=L, scale=C, prior_mean=M0).fit(X, values, noise, partial, gnoise)
    b = GPIS(lengthscale=L, scale=C, prior_mean=M0).fit(X, values, noise, none, gnoise)
    full = GPIS(lengthscale=L, scale=C, prior_mean=M0).fit(X, values, noise, grads, gnoise)
    without = b.predict(P)
    for x, y in zip(a.predict(P), without):
        np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-15)
    assert np.abs(full.predict(P)[0] - without[0]).max() > 1e-6  # that gradient did inform the posterior
