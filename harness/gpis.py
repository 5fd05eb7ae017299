"""Gaussian process implicit surface: squared-exponential GP on the SDF with value and
gradient observations, heteroscedastic noise, ML-II hyperparameters, prediction, and
posterior samplers (the dense exact reference; fast ones in a separable basis)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy import optimize
from threadpoolctl import ThreadpoolController

#: Names accepted by GPIS.sample and GPIS.sample_grid.
SAMPLING_METHODS = ("fast", "exact", "pathwise", "weight-space")
#: Relative eigenvalue cut-off of the separable prior basis: the 1-D kernel is reproduced
#: to ~5e-9 of the prior variance, the 2-D one to ~1e-8 (tested), under 1e-4 of the
#: posterior variance at a well-observed surface.
_BASIS_TOL = 1e-8
#: Diagonal jitter of the training covariance, relative to each prior variance; keeps the
#: factorisation stable for near-duplicate inputs with tiny noise.
_JITTER = 1e-10
#: Largest number of distinct coordinates per axis used as exact basis nodes.
_MAX_NODES = 1500
#: The grid fields use the weight-space posterior up to an r^2 x r^2 matrix of this many
#: bytes, pointwise prediction (in chunks of PREDICT_CHUNK points) beyond.
FIELDS_BASIS_MAX_BYTES = 64e6
#: Points per chunk of pointwise prediction: bounds its temporaries to about 100 bytes
#: x PREDICT_CHUNK x the observed scalars (harness.memory).
PREDICT_CHUNK = 2048


def select_active_set(points: np.ndarray, values: np.ndarray, noise_var: np.ndarray,
                      band: float, spacing: float) -> np.ndarray:
    """Indices of the observations the GP is fitted on.

    All readings with |value| <= band (the surface, where the zero level is decided) are
    kept; elsewhere the field is far from zero and smooth at the lengthscale, so the
    plane is cut into equal squares of side at most ``spacing`` spanning the readings,
    and in each square the reading nearest its centre is kept (the least noisy on a
    tie), which leaves a regular lattice. With a band a fixed number of cells wide the
    count grows like the perimeter in cells, not like the area.
    """
    values = np.asarray(values, dtype=float)
    points = np.asarray(points, dtype=float)
    near = np.abs(values) <= band
    far = np.flatnonzero(~near)
    if far.size:
        p = points[far]
        lo, hi = p.min(axis=0), p.max(axis=0)
        counts = np.maximum(np.ceil((hi - lo) / spacing - 1e-9), 1).astype(np.int64)
        side = np.where(hi > lo, (hi - lo) / counts, 1.0)
        bins = np.minimum(((p - lo) / side).astype(np.int64), counts - 1)
        key = bins[:, 0] * counts[1] + bins[:, 1]
        offset = np.linalg.norm(p - (lo + (bins + 0.5) * side), axis=1)
        order = np.lexsort((np.asarray(noise_var)[far], np.round(offset / spacing, 9), key))
        first = np.ones(order.size, dtype=bool)
        first[1:] = key[order][1:] != key[order][:-1]
        far = far[order[first]]
    return np.sort(np.concatenate([np.flatnonzero(near), far]))


class GPIS:
    """GP on the signed distance function with k(a,b) = scale * exp(-|a-b|^2 / (2 lengthscale^2)).

    Parameters (metres): ``lengthscale``, ``scale`` (prior variance, m^2), ``prior_mean``
    (constant prior mean; negative biases unseen space to "inside"). With
    ``fit_hyperparameters=True`` :meth:`fit` maximises the log marginal likelihood over
    (lengthscale, scale, prior_mean) from these starting values, within the bounds.
    Learned state ends in ``_``.
    """

    def __init__(self, lengthscale: float = 0.02, scale: float = 1e-4, prior_mean: float = -0.01,
                 fit_hyperparameters: bool = False,
                 lengthscale_bounds: tuple[float, float] = (1e-4, 1.0),
                 scale_bounds: tuple[float, float] = (1e-10, 1.0),
                 prior_mean_bounds: tuple[float, float] = (-1.0, 1.0)):
        self.lengthscale = lengthscale
        self.scale = scale
        self.prior_mean = prior_mean
        self.fit_hyperparameters = fit_hyperparameters
        self.lengthscale_bounds = lengthscale_bounds
        self.scale_bounds = scale_bounds
        self.prior_mean_bounds = prior_mean_bounds

    # -- fitting ---------------------------------------------------------------

    def fit(self, points, values, noise_var, gradients=None, gradient_noise_var=None) -> "GPIS":
        """Condition on SDF values (N,) at points (N, 2) with noise variances (N,), and
        optionally gradients (N, 2) (rows with NaN are not observed) with noise variance
        a float, (N,) or (N, 2). Noise enters only the diagonal."""
        X = np.asarray(points, dtype=float).reshape(-1, 2)
        n = len(X)
        v = np.asarray(values, dtype=float).reshape(n)
        nv = np.broadcast_to(np.asarray(noise_var, dtype=float), (n,))
        if gradients is None:
            g = np.zeros(n, dtype=bool)
            grads = np.zeros((0, 2))
            gnv = np.zeros((0, 2))
        else:
            gr = np.asarray(gradients, dtype=float).reshape(n, 2)
            g = ~np.any(np.isnan(gr), axis=1)
            if gradient_noise_var is None:
                raise ValueError("gradient_noise_var is required with gradients")
            gv = np.asarray(gradient_noise_var, dtype=float)
            gv = np.broadcast_to(gv[:, None] if gv.ndim == 1 else gv, (n, 2))
            grads, gnv = gr[g], gv[g]
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(v)) and np.all(nv >= 0) and np.all(gnv >= 0)):
            raise ValueError("points and values must be finite and noise variances non-negative")
        self.X_ = X
        self.gradient_mask_ = g
        self.Xg_ = X[g]
        self.targets_ = np.concatenate([v, grads[:, 0], grads[:, 1]])
        self.noise_ = np.concatenate([nv, gnv[:, 0], gnv[:, 1]])
        self.n_values_ = n

        theta0 = np.array([math.log(self.lengthscale), math.log(self.scale), self.prior_mean])
        if self.fit_hyperparameters:
            bounds = [tuple(np.log(self.lengthscale_bounds)), tuple(np.log(self.scale_bounds)),
                      tuple(self.prior_mean_bounds)]
            theta0 = np.clip(theta0, [b[0] for b in bounds], [b[1] for b in bounds])
            res = optimize.minimize(lambda th: tuple(-x for x in self._lml(th, grad=True)), theta0,
                                    jac=True, method="L-BFGS-B", bounds=bounds)
            theta0 = res.x
        self.lengthscale_ = float(math.exp(theta0[0]))
        self.scale_ = float(math.exp(theta0[1]))
        self.prior_mean_ = float(theta0[2])
        K = self._train_cov(self.lengthscale_, self.scale_)
        K[np.diag_indices_from(K)] += self.noise_ + _JITTER * self._prior_diag()
        self.L_ = sla.cholesky(K, lower=True, check_finite=False)
        resid = self._residual(self.prior_mean_)
        self.alpha_ = sla.cho_solve((self.L_, True), resid, check_finite=False)
        self.log_marginal_likelihood_ = float(-0.5 * resid @ self.alpha_ - np.log(np.diag(self.L_)).sum()
                                              - 0.5 * len(resid) * math.log(2 * math.pi))
        self._cache: dict = {}
        return self

    def _residual(self, prior_mean: float) -> np.ndarray:
        r = self.targets_.copy()
        r[: self.n_values_] -= prior_mean
        return r

    def _train_cov(self, lengthscale: float, scale: float, dlog_lengthscale: bool = False) -> np.ndarray:
        rows_v = _cov_rows(self.X_, self.X_, self.gradient_mask_, lengthscale, scale, "value", dlog_lengthscale)
        rows_g = _cov_rows(self.Xg_, self.X_, self.gradient_mask_, lengthscale, scale, "gradient", dlog_lengthscale)
        return np.concatenate([rows_v, rows_g[0], rows_g[1]], axis=0)

    def _lml(self, theta: np.ndarray, grad: bool = False):
        """Log marginal likelihood at theta = (log l, log C, m) and its gradient."""
        l, c, m = math.exp(theta[0]), math.exp(theta[1]), theta[2]
        Ks = self._train_cov(l, c)
        K = Ks.copy()
        K[np.diag_indices_from(K)] += self.noise_ + _JITTER * np.diag(Ks)
        try:
            L = sla.cholesky(K, lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            return (-np.inf, np.zeros(3)) if grad else (-np.inf,)
        r = self._residual(m)
        alpha = sla.cho_solve((L, True), r, check_finite=False)
        lml = -0.5 * r @ alpha - np.log(np.diag(L)).sum() - 0.5 * len(r) * math.log(2 * math.pi)
        if not grad:
            return (lml,)
        Kinv = sla.cho_solve((L, True), np.eye(len(r)), check_finite=False)
        W = np.outer(alpha, alpha) - Kinv
        dK_dl = self._train_cov(l, c, dlog_lengthscale=True)
        g = np.array([0.5 * np.sum(W * dK_dl), 0.5 * np.sum(W * Ks), alpha[: self.n_values_].sum()])
        return lml, g

    def log_marginal_likelihood(self, lengthscale=None, scale=None, prior_mean=None, eval_gradient=False):
        """Log marginal likelihood of the fitted data at the given (default: fitted)
        hyperparameters; with ``eval_gradient`` also its gradient with respect to
        (log lengthscale, log scale, prior_mean)."""
        theta = np.array([math.log(lengthscale or self.lengthscale_), math.log(scale or self.scale_),
                          self.prior_mean_ if prior_mean is None else prior_mean])
        out = self._lml(theta, grad=eval_gradient)
        return out if eval_gradient else out[0]

    # -- prediction --------------------------------------------------------------

    def predict(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and variance (P,), (P,) of the latent SDF value (no observation noise)."""
        P = np.asarray(points, dtype=float).reshape(-1, 2)
        mean = np.empty(len(P))
        var = np.empty(len(P))
        for s in _chunks(len(P), PREDICT_CHUNK):
            Ks = _cov_rows(P[s], self.X_, self.gradient_mask_, self.lengthscale_, self.scale_, "value")
            mean[s] = self.prior_mean_ + Ks @ self.alpha_
            A = sla.solve_triangular(self.L_, Ks.T, lower=True, check_finite=False)
            var[s] = self.scale_ - np.einsum("ij,ij->j", A, A)
        return mean, np.maximum(var, 0.0)

    def predict_gradient(self, points, return_var: bool = False):
        """Gradient (P, 2) of the posterior mean; with ``return_var`` also the posterior
        variance (P, 2) of each gradient component."""
        P = np.asarray(points, dtype=float).reshape(-1, 2)
        grad = np.empty((len(P), 2))
        var = np.empty((len(P), 2))
        for s in _chunks(len(P), PREDICT_CHUNK):
            Kg = _cov_rows(P[s], self.X_, self.gradient_mask_, self.lengthscale_, self.scale_, "gradient")
            for i in range(2):
                grad[s, i] = Kg[i] @ self.alpha_
                if return_var:
                    A = sla.solve_triangular(self.L_, Kg[i].T, lower=True, check_finite=False)
                    var[s, i] = self.scale_ / self.lengthscale_**2 - np.einsum("ij,ij->j", A, A)
        return (grad, np.maximum(var, 0.0)) if return_var else grad

    def grid_fields(self, xs, ys) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Posterior mean (ny, nx), variance (ny, nx), mean gradient (ny, nx, 2) and the
        variance of each gradient component (ny, nx, 2) on the tensor grid ys x xs.

        From the separable weight-space posterior (the one the fast samplers draw from,
        equal to :meth:`predict` up to the basis cut-off): the mean is Psi mu Phi^T, the
        variances scale * f^T S f with S the coefficients' covariance and f the basis (or
        its derivative) at the point, summed row by row in O(M r^4 + M^2 r^2) instead of
        the O(M^2 D^2) of pointwise prediction. When the
        basis is too large for an r^2 x r^2 matrix (over 64 MB), pointwise prediction.
        """
        xs = np.asarray(xs, dtype=float)
        ys = np.asarray(ys, dtype=float)
        with single_threaded_blas():
            bx, by = self._basis(0, xs), self._basis(1, ys)
            if (bx.rank * by.rank) ** 2 * 8 > FIELDS_BASIS_MAX_BYTES:
                xx, yy = np.meshgrid(xs, ys)
                P = np.column_stack([xx.ravel(), yy.ravel()])
                mean, var = self.predict(P)
                grad, grad_var = self.predict_gradient(P, return_var=True)
                shape = (len(ys), len(xs))
                return (mean.reshape(shape), var.reshape(shape), grad.reshape(shape + (2,)),
                        grad_var.reshape(shape + (2,)))
            ws = self._weight_space(bx, by)
            fx, dfx = bx.at(xs)
            fy, dfy = by.at(ys)
            left = fy @ ws.mean
            mean = self.prior_mean_ + left @ fx.T
            grad = np.stack([left @ dfx.T, dfy @ ws.mean @ fx.T], axis=-1)
            inverse = sla.solve_triangular(ws.factor, np.eye(len(ws.factor)), lower=True, check_finite=False)
            cov = (inverse.T @ inverse).reshape(by.rank, bx.rank, by.rank, bx.rank)  # of vec(coef) / sqrt(scale)
            # f^T S f with f = psi_j (x) phi_i for values, psi_j (x) phi'_i and psi'_j (x) phi_i
            # for the two gradient components.
            var = np.empty((3, len(ys), len(xs)))
            for rows in _chunks(len(ys), 8):
                for k, (left, right) in enumerate(((fy, fx), (fy, dfx), (dfy, fx))):
                    t = np.tensordot(left[rows], cov, axes=(1, 0))  # (rows, rx, ry, rx)
                    u = np.einsum("jc,jacd->jad", left[rows], t)  # (rows, rx, rx)
                    var[k, rows] = np.einsum("ia,jai->ji", right, u @ right.T)
            var = np.maximum(self.scale_ * var, 0.0)
        return mean, var[0], grad, np.moveaxis(var[1:], 0, -1)

    # -- sampling ----------------------------------------------------------------

    def sample(self, points, n: int, rng: np.random.Generator, method: str = "fast") -> np.ndarray:
        """(n, P) posterior draws of the SDF value at points (P, 2).

        ``fast`` (= ``weight-space`` here, see :meth:`sample_grid`); ``exact``: dense
        Cholesky of the (P, P) posterior covariance.
        """
        P = np.asarray(points, dtype=float).reshape(-1, 2)
        if method == "exact":
            mean, _ = self.predict(P)
            prior = np.full(len(P), self.scale_)
            return mean + _mvn_draws(lambda: self._posterior_cov(P, False), prior, n, rng)
        _check_method(method)
        if method == "pathwise":
            raise ValueError("method 'pathwise' needs a grid; use sample_grid or 'weight-space'")
        with single_threaded_blas():
            return self._sample_points(P, n, rng)

    def _sample_points(self, P: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
        """Weight-space draws at scattered points."""
        bx = self._basis(0, P[:, 0])
        by = self._basis(1, P[:, 1])
        out = np.empty((n, len(P)))
        fx, _ = bx.at(P[:, 0])
        fy, _ = by.at(P[:, 1])
        mean_coef = self._weight_space(bx, by).mean
        out[:] = self.prior_mean_ + np.einsum("pb,ba,pa->p", fy, mean_coef, fx)
        fx32, fy32 = fx.astype(np.float32), fy.astype(np.float32)
        for s, dev in self._weight_space_draws(bx, by, n, rng):
            # value(p) = fy(p) . coef . fx(p), over blocks of points to bound the temporaries
            for p in _chunks(len(P), max(64, 2**21 // (len(dev) * bx.rank))):
                out[s, p] += np.einsum("npa,pa->np", np.matmul(fy32[p], dev), fx32[p])
        return out

    def sample_grid(self, xs, ys, n: int, rng: np.random.Generator, method: str = "fast"):
        """Posterior draws on the tensor grid ys x xs of the SDF values (n, ny, nx) and
        their gradients (n, ny, nx, 2), jointly.

        ``exact`` is the original's reference: the dense joint posterior over values and
        gradients at every grid point (3 nx ny dimensions), one Cholesky, O((nx ny)^3).

        The fast samplers use that the SE kernel separates, k = scale kx(x, x') ky(y, y'):
        the prior over values and gradients is exactly f = m + sqrt(scale) Psi Z Phi^T
        with 1-D bases Phi, Psi (an eigenbasis of the 1-D kernel and its derivative at
        the grid's coordinates, cut at 1e-8 relative, r ~ 3 x extent / lengthscale
        functions) and Z an r_y x r_x standard normal matrix. Conditioning is exact in
        that basis, in one of two ways:

        ``pathwise`` (observations on the grid): Matheron's rule, a prior draw plus the
        data's correction K(., X) (K + Sigma)^-1 (y - prior(X) - eps); the prior is
        evaluated on the grid and gathered, the correction formed from weight images
        scattered on the grid. O(M^2 r + D^2) per draw, D observed scalars.

        ``weight-space``: the posterior of vec(Z) is Gaussian with precision
        I + scale F^T Sigma^-1 F (F: observations as functions of Z); factorised once,
        then O(r^4 / 2 + M^2 r) per draw, independent of D.

        ``fast`` picks the cheaper of the two by counting multiply-adds.
        """
        xs = np.asarray(xs, dtype=float)
        ys = np.asarray(ys, dtype=float)
        if method == "exact":
            xx, yy = np.meshgrid(xs, ys)
            P = np.column_stack([xx.ravel(), yy.ravel()])
            mean, _ = self.predict(P)
            mgrad = self.predict_gradient(P)
            k = len(P)
            prior = np.concatenate([np.full(k, self.scale_), np.full(2 * k, self.scale_ / self.lengthscale_**2)])
            draws = _mvn_draws(lambda: self._posterior_cov(P, True), prior, n, rng)
            values = (mean + draws[:, :k]).reshape(n, len(ys), len(xs))
            grads = np.stack([mgrad[:, 0] + draws[:, k:2 * k], mgrad[:, 1] + draws[:, 2 * k:]], axis=-1)
            return values, grads.reshape(n, len(ys), len(xs), 2)
        _check_method(method)
        with single_threaded_blas():
            return self._sample_grid_fast(xs, ys, n, rng, method)

    def _sample_grid_fast(self, xs: np.ndarray, ys: np.ndarray, n: int, rng: np.random.Generator, method: str):
        """The separable samplers of :meth:`sample_grid` ('fast', 'pathwise', 'weight-space')."""
        bx, by = self._basis(0, xs), self._basis(1, ys)
        fx, dfx = bx.at(xs)
        fy, dfy = by.at(ys)
        values = np.empty((n, len(ys), len(xs)))
        # Component planes: contiguous writes; returned as an (n, ny, nx, 2) view.
        planes = np.empty((n, 2, len(ys), len(xs)))
        on_grid = self._grid_index(xs, ys)
        if method == "fast":
            method = self.grid_strategy(xs, ys, n)
        if method == "pathwise":
            if on_grid is None:
                raise ValueError("method 'pathwise' needs every observation on the grid")
            mean_coef = np.zeros((by.rank, bx.rank))
            draws = self._pathwise_on_grid(fx, dfx, fy, dfy, on_grid, n, rng)
        else:
            mean_coef = self._weight_space(bx, by).mean
            draws = self._weight_space_draws(bx, by, n, rng)
        # Mean fields once in double precision; each draw adds its deviation fields,
        # computed in the precision the strategy delivers them in.
        left = fy @ mean_coef
        mean_fields = (self.prior_mean_ + left @ fx.T, left @ dfx.T, dfy @ mean_coef @ fx.T)
        cast: dict = {}
        for s, dev in draws:
            if dev.dtype.name not in cast:
                cast[dev.dtype.name] = [a.astype(dev.dtype) for a in (fx, dfx, fy, dfy)]
            gx, gdx, gy, gdy = cast[dev.dtype.name]
            left = np.matmul(gy, dev)  # (k, ny, rx)
            np.add(np.matmul(left, gx.T), mean_fields[0], out=values[s])
            np.add(np.matmul(left, gdx.T), mean_fields[1], out=planes[s, 0])
            np.add(np.matmul(np.matmul(gdy, dev), gx.T), mean_fields[2], out=planes[s, 1])
        return values, np.moveaxis(planes, 1, -1)

    def _grid_index(self, xs: np.ndarray, ys: np.ndarray):
        """Flat indices of the training points in the grid ys x xs, or None if some
        training point is not a grid point (or two share one)."""
        ix, iy = _lookup(xs, self.X_[:, 0]), _lookup(ys, self.X_[:, 1])
        if ix is None or iy is None:
            return None
        flat = iy * len(xs) + ix
        return flat if np.unique(flat).size == flat.size else None

    def _pathwise_on_grid(self, fx, dfx, fy, dfy, flat: np.ndarray, n: int, rng: np.random.Generator,
                          chunk: int | None = None):
        """Posterior draws (slice, coef) by pathwise conditioning, every observation a grid point:
        the prior draw is evaluated on the whole grid and gathered, and the correction
        is formed from weight images scattered on the grid, which costs O(M^2 r) per
        draw instead of O(D r^2)."""
        ny, nx = len(fy), len(fx)
        g = self.gradient_mask_
        gflat = flat[g]
        sc = math.sqrt(self.scale_)
        prior_resid = self._residual(self.prior_mean_)
        noise_sd = np.sqrt(self.noise_ + _JITTER * self._prior_diag())  # as factorised in L_
        nv, ng = self.n_values_, int(g.sum())
        # Chunks of about 2 MB per grid field keep the temporaries in cache.
        chunk = chunk or max(8, min(256, 2**18 // (ny * nx)))
        for start in range(0, n, chunk):
            k = min(chunk, n - start)
            Z = rng.standard_normal((k, fy.shape[1], fx.shape[1]))
            eps = rng.standard_normal((k, len(noise_sd))) * noise_sd
            A = np.matmul(fy, Z)
            prior = np.concatenate([
                (A @ fx.T).reshape(k, -1)[:, flat],
                (A @ dfx.T).reshape(k, -1)[:, gflat],
                (np.matmul(dfy, Z) @ fx.T).reshape(k, -1)[:, gflat],
            ], axis=1)
            w = sla.cho_solve((self.L_, True), (prior_resid - eps - sc * prior).T, check_finite=False).T
            images = np.zeros((3, k, ny * nx))
            images[0][:, flat] = w[:, :nv]
            images[1][:, gflat] = w[:, nv:nv + ng]
            images[2][:, gflat] = w[:, nv + ng:]
            images = images.reshape(3, k, ny, nx)
            # sum_j w_j basis_j = Psi^T W0 Phi + Psi^T Wx Phi' + Psi'^T Wy Phi
            Q = np.matmul(fy.T, images[0] @ fx + images[1] @ dfx) + np.matmul(dfy.T, images[2] @ fx)
            yield slice(start, start + k), sc * Z + self.scale_ * Q

    def _basis(self, axis: int, query: np.ndarray) -> "_Basis1D":
        """The 1-D basis along ``axis`` whose nodes cover the query and training coordinates."""
        coords = _basis_nodes(np.concatenate([np.asarray(query).ravel(), self.X_[:, axis]]), self.lengthscale_)
        key = (axis, coords.tobytes())
        if key not in self._cache:
            self._cache[key] = _Basis1D(coords, self.lengthscale_)
        return self._cache[key]

    def _observation_features(self, bx: "_Basis1D", by: "_Basis1D") -> np.ndarray:
        """(D, r_y * r_x): each observed scalar as a linear function of the separable
        coefficients, i.e. f(x_n) = F[n] . vec(coef) for values, likewise for gradients."""
        key = ("features", id(bx), id(by))
        if key not in self._cache:
            fx, dfx = bx.at(self.X_[:, 0])
            fy, dfy = by.at(self.X_[:, 1])
            g = self.gradient_mask_
            outer = lambda a, b: (a[:, :, None] * b[:, None, :]).reshape(len(a), -1)  # noqa: E731
            self._cache[key] = np.concatenate([outer(fy, fx), outer(fy[g], dfx[g]), outer(dfy[g], fx[g])])
        return self._cache[key]

    def grid_strategy(self, xs, ys, n: int) -> str:
        """The sampler that :meth:`sample_grid`'s ``fast`` uses for n draws on the grid ys x xs:
        "pathwise" or "weight-space". Weight-space draws come sample by sample from the
        stream, so n draws made in several calls (with that method named) equal one
        call's; pathwise draws interleave their prior and noise draws by chunk."""
        xs, ys = np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)
        bx, by = self._basis(0, xs), self._basis(1, ys)
        return self.fast_strategy(len(xs), len(ys), bx.rank, by.rank, self._grid_index(xs, ys) is not None, n)

    def fast_strategy(self, nx: int, ny: int, rx: int, ry: int, on_grid: bool, n: int) -> str:
        """The cheaper exact sampler for n draws on an nx x ny grid (see fast_strategy)."""
        return fast_strategy(len(self.targets_), nx, ny, rx, ry, on_grid, n)

    def _weight_space(self, bx: "_Basis1D", by: "_Basis1D") -> "_WeightSpace":
        """Posterior of the separable coefficients (cached per pair of bases)."""
        key = ("weight-space", id(bx), id(by))
        if key not in self._cache:
            noise = self.noise_ + _JITTER * self._prior_diag()
            sc = math.sqrt(self.scale_)
            precision, rhs = self._normal_equations(bx, by, self.scale_ / noise,
                                                    self._residual(self.prior_mean_) * sc / noise)
            precision[np.diag_indices_from(precision)] += 1.0
            R = sla.cholesky(precision, lower=True, check_finite=False)
            mean = sla.cho_solve((R, True), rhs, check_finite=False)
            self._cache[key] = _WeightSpace(sc * mean.reshape(by.rank, bx.rank), R, R.astype(np.float32))
        return self._cache[key]

    def _normal_equations(self, bx: "_Basis1D", by: "_Basis1D", weights: np.ndarray, targets: np.ndarray):
        """F^T diag(weights) F (lower triangle at least) and F^T targets, where row n of F
        expresses observed scalar n in the separable basis.

        When every observation sits on the bases' nodes, a value reading at node (j, i)
        contributes w (psi_j psi_j^T) kron (phi_i phi_i^T) (gradient readings the same
        with phi' or psi'); summing first over each row of a weight image costs
        O(M^2 r^2 + M r^4) instead of the dense O(D r^4)."""
        ix, iy = bx.node_index(self.X_[:, 0]), by.node_index(self.X_[:, 1])
        if ix is None or iy is None:
            F = self._observation_features(bx, by)
            Fw = F * np.sqrt(weights)[:, None]
            return sla.blas.dsyrk(1.0, Fw, trans=1, lower=1), F.T @ targets
        g = self.gradient_mask_
        nv, ng = self.n_values_, int(g.sum())
        phi, dphi = bx.node_features()
        psi, dpsi = by.node_features()
        parts = [(psi, phi, iy, ix, slice(0, nv)),
                 (psi, dphi, iy[g], ix[g], slice(nv, nv + ng)),
                 (dpsi, phi, iy[g], ix[g], slice(nv + ng, nv + 2 * ng))]
        ry, rx = psi.shape[1], phi.shape[1]
        yy_rows, xx_rows = [], []
        rhs = np.zeros((ry, rx))
        for ys, xs, rows, cols, part in parts:
            if part.stop == part.start:
                continue
            image = np.zeros((len(ys), len(xs)))
            np.add.at(image, (rows, cols), weights[part])
            used = np.flatnonzero(image.any(axis=1))
            xx_rows.append(image[used] @ (xs[:, :, None] * xs[:, None, :]).reshape(len(xs), -1))
            yy_rows.append((ys[used, :, None] * ys[used, None, :]).reshape(len(used), -1))
            image[:] = 0.0
            np.add.at(image, (rows, cols), targets[part])
            rhs += ys.T @ image @ xs
        precision = (np.concatenate(yy_rows).T @ np.concatenate(xx_rows)).reshape(ry, ry, rx, rx)
        return precision.transpose(0, 2, 1, 3).reshape(ry * rx, ry * rx), rhs.ravel()

    def _weight_space_draws(self, bx: "_Basis1D", by: "_Basis1D", n: int, rng: np.random.Generator,
                            chunk: int = 256):
        """Yield (slice, dev) with dev (k, r_y, r_x) float32: draws of the separable
        coefficients minus their posterior mean, f = mean fields + Psi dev Phi^T.

        The deviations R^-T z are computed in single precision (about twice as fast);
        their relative error, about 1e-7 times the condition number of R, stays below
        1e-4 of the posterior standard deviation (tested). The mean is double precision.
        """
        R32 = self._weight_space(bx, by).factor32
        sc = np.float32(math.sqrt(self.scale_))
        for start in range(0, n, chunk):
            k = min(chunk, n - start)
            # Sample-major z, so that the stream does not depend on the chunk size.
            z = rng.standard_normal((k, R32.shape[0]), dtype=np.float32)
            # Precision = R R^T, so R^-T z has covariance precision^-1.
            dev = sla.solve_triangular(R32, z.T, lower=True, trans="T", check_finite=False)
            yield slice(start, start + k), sc * dev.T.reshape(k, by.rank, bx.rank)

    def _prior_diag(self) -> np.ndarray:
        """Prior variances of the training vector: scale for values, scale/l^2 for gradients."""
        ng = len(self.targets_) - self.n_values_
        return self.scale_ * np.concatenate([np.ones(self.n_values_), np.full(ng, self.lengthscale_**-2)])

    def _posterior_cov(self, P: np.ndarray, with_gradients: bool) -> np.ndarray:
        """Dense posterior covariance at P: values only (P, P), or values then x- then
        y-gradients (3P, 3P)."""
        l, c = self.lengthscale_, self.scale_
        every = np.ones(len(P), dtype=bool) if with_gradients else np.zeros(len(P), dtype=bool)
        dim = len(P) * (3 if with_gradients else 1)
        cov = np.empty((dim, dim))
        cross = np.empty((dim, len(self.targets_)))
        row = 0
        for kind in ("value", "gradient") if with_gradients else ("value",):
            for comp in range(2 if kind == "gradient" else 1):
                for s in _chunks(len(P), PREDICT_CHUNK):
                    block = _cov_rows(P[s], P, every, l, c, kind)
                    tblock = _cov_rows(P[s], self.X_, self.gradient_mask_, l, c, kind)
                    if kind == "gradient":
                        block, tblock = block[comp], tblock[comp]
                    rows = slice(row + s.start, row + s.stop)
                    cov[rows] = block
                    cross[rows] = tblock
                row += len(P)
        A = sla.solve_triangular(self.L_, cross.T, lower=True, check_finite=False)
        del cross
        # cov -= A^T A, in place on the lower triangle (BLAS syrk), then mirrored.
        cov = sla.blas.dsyrk(-1.0, A, beta=1.0, c=cov, trans=1, lower=1, overwrite_c=1)
        return cov


@dataclass(frozen=True)
class _WeightSpace:
    """Posterior of vec(coef) / sqrt(scale) in a separable basis: the mean coefficients
    (r_y, r_x), already times sqrt(scale), and the lower Cholesky factor of the precision
    I + scale F^T Sigma^-1 F, in double and single precision."""

    mean: np.ndarray
    factor: np.ndarray
    factor32: np.ndarray


class _Basis1D:
    """Eigenbasis of the 1-D unit SE kernel with its derivative at a set of nodes.

    The joint covariance G of (g(t_i), g'(t_i)) over the nodes (t in units of the
    lengthscale) factorises as G = V L V^T; keeping eigenvalues above a relative
    cut-off gives features phi(x) = [k(x, t), dk(x, t)/dt] V L^-1/2 (Nystrom), exact at
    the nodes, whose products reproduce k and its derivative blocks.
    """

    def __init__(self, nodes: np.ndarray, lengthscale: float):
        self.nodes = np.asarray(nodes, dtype=float)
        self.lengthscale = lengthscale
        t = self.nodes / lengthscale
        G = _joint_1d(t, t)
        lam, vec = np.linalg.eigh(G)
        keep = lam > _BASIS_TOL * lam[-1]
        self.rank = int(keep.sum())
        self._lam = lam[keep]
        self._proj = vec[:, keep] / np.sqrt(lam[keep])
        self._node_features = vec[:, keep] * np.sqrt(lam[keep])

    def node_features(self) -> tuple[np.ndarray, np.ndarray]:
        """Features (U, r) and their derivatives in metres (U, r) at the nodes."""
        u = len(self.nodes)
        return self._node_features[:u], self._node_features[u:] / self.lengthscale

    def node_index(self, coords: np.ndarray) -> np.ndarray | None:
        """Index of each coordinate among the nodes, or None if one is not a node."""
        return _lookup(self.nodes, coords)

    def at(self, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Features (P, r) and their derivatives in metres (P, r) at coordinates (P,)."""
        coords = np.asarray(coords, dtype=float)
        u = len(self.nodes)
        idx, on_node = _nearest(self.nodes, coords)
        f = np.empty((coords.size, self.rank))
        df = np.empty((coords.size, self.rank))
        f[on_node] = self._node_features[idx[on_node]]
        df[on_node] = self._node_features[u + idx[on_node]]
        if not np.all(on_node):
            off = ~on_node
            rows = _joint_1d(coords[off] / self.lengthscale, self.nodes / self.lengthscale)
            feat = rows @ self._proj
            f[off], df[off] = feat[: off.sum()], feat[off.sum():]
        df /= self.lengthscale
        return f, df


def fast_strategy(d: int, nx: int, ny: int, rx: int, ry: int, on_grid: bool, n: int) -> str:
    """The cheaper exact sampler for n draws on an nx x ny grid, with d observed scalars
    and basis ranks rx, ry: 'pathwise' or 'weight-space', from counted multiply-adds with
    rates measured on this project's reference machine: weight-space pays a one-off
    M r^4 + r^6 / 3 (large GEMMs, about 3x the rate of the per-draw work) and r^4 / 4 per
    draw; pathwise pays D^2 + 6 M^2 r + 4 M r^2 per draw at about 0.8x that rate, plus
    ~30 us overhead."""
    r2 = rx * ry
    weight_space = n * r2 * r2 / 4 + (max(nx, ny) * r2 * r2 + r2**3 / 3) / 3
    pathwise = n * (1.2 * (d * d + 3 * nx * ny * (rx + ry) + 4 * max(nx, ny) * r2) + 3e5)
    return "pathwise" if on_grid and pathwise < weight_space else "weight-space"


def _basis_nodes(coords: np.ndarray, lengthscale: float) -> np.ndarray:
    """The nodes of a 1-D basis covering ``coords``: the distinct coordinates, or, when
    there are more than _MAX_NODES, a dense uniform set (off-node coordinates then use
    the Nystrom extension)."""
    nodes = np.unique(np.round(coords, 12))
    if len(nodes) > _MAX_NODES:
        lo, hi = nodes[0] - lengthscale, nodes[-1] + lengthscale
        nodes = np.linspace(lo, hi, int(np.ceil((hi - lo) / (0.2 * lengthscale))) + 1)
    return nodes


def grid_basis_rank(coords: np.ndarray, lengthscale: float) -> int:
    """The rank of the 1-D basis that the grid fields and the fast samplers use along a
    grid axis with coordinates ``coords`` when every observation lies on the grid (as the
    sensor's readings do): a memory estimate's r (harness.memory)."""
    return _Basis1D(_basis_nodes(np.asarray(coords, dtype=float), lengthscale), lengthscale).rank


def _nearest(sorted_coords: np.ndarray, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest entry of a sorted array for each coordinate, and whether it
    matches to 1e-12 m."""
    coords = np.asarray(coords, dtype=float)
    if len(sorted_coords) == 1:
        idx = np.zeros(coords.shape, dtype=np.int64)
    else:
        idx = np.clip(np.searchsorted(sorted_coords, coords), 1, len(sorted_coords) - 1)
        idx = np.where(coords - sorted_coords[idx - 1] <= sorted_coords[idx] - coords, idx - 1, idx)
    return idx, np.abs(sorted_coords[idx] - coords) <= 1e-12


def _lookup(sorted_coords: np.ndarray, coords: np.ndarray) -> np.ndarray | None:
    """Index of each coordinate in a sorted array (to 1e-12 m), or None if one is absent."""
    idx, match = _nearest(sorted_coords, coords)
    return idx if np.all(match) else None


def _joint_1d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Joint covariance of (g(a), g'(a)) with (g(b), g'(b)) for the unit 1-D SE kernel."""
    d = a[:, None] - b[None, :]
    k = np.exp(-0.5 * d * d)
    return np.block([[k, d * k], [-d * k, (1.0 - d * d) * k]])


def _cov_rows(a: np.ndarray, X: np.ndarray, gmask: np.ndarray, lengthscale: float, scale: float,
              kind: str, dlog_lengthscale: bool = False) -> np.ndarray:
    """Covariance between f(a) (kind "value": shape (A, D)) or grad f(a) (kind
    "gradient": shape (2, A, D)) and the training vector [f(X), df/dx(X[g]), df/dy(X[g])].

    With ``dlog_lengthscale`` the derivative of that block with respect to log lengthscale.
    """
    d = a[:, None, :] - X[None, :, :]
    l2 = lengthscale * lengthscale
    s = (d * d).sum(-1) / l2
    k = scale * np.exp(-0.5 * s)
    dx, dy = d[..., 0][:, gmask], d[..., 1][:, gmask]
    kg, sg = k[:, gmask], s[:, gmask]
    if kind == "value":
        # cov(f(a), df(b)/db_j) = (a_j - b_j) / l^2 k
        vv, vx, vy = k, dx / l2 * kg, dy / l2 * kg
        if dlog_lengthscale:
            vv, vx, vy = vv * s, vx * (sg - 2), vy * (sg - 2)
        return np.concatenate([vv, vx, vy], axis=1)
    out = []
    for i, di in enumerate((d[..., 0], d[..., 1])):
        dig = di[:, gmask]
        # cov(df(a)/da_i, f(b)) = -(a_i - b_i) / l^2 k
        gv = -di / l2 * k
        # cov(df(a)/da_i, df(b)/db_j) = (delta_ij / l^2 - (a_i-b_i)(a_j-b_j) / l^4) k
        gx = ((i == 0) / l2 - dig * dx / l2**2) * kg
        gy = ((i == 1) / l2 - dig * dy / l2**2) * kg
        if dlog_lengthscale:
            gv = gv * (s - 2)
            gx = ((i == 0) / l2 * (sg - 2) - dig * dx / l2**2 * (sg - 4)) * kg
            gy = ((i == 1) / l2 * (sg - 2) - dig * dy / l2**2 * (sg - 4)) * kg
        out.append(np.concatenate([gv, gx, gy], axis=1))
    return np.stack(out)


@functools.cache
def _blas_controller() -> ThreadpoolController:
    return ThreadpoolController()


def single_threaded_blas():
    """The fast samplers' products are small (r ~ 40): BLAS threads do not speed them up
    and on the project's 2-core machine slowed them by about 40 % (measured). Parallel
    work belongs to worker processes, one BLAS thread each."""
    return _blas_controller().limit(limits=1, user_api="blas")


def _check_method(method: str) -> None:
    if method not in SAMPLING_METHODS:
        raise ValueError(f"unknown sampling method {method!r} ({', '.join(SAMPLING_METHODS)})")


def _chunks(n: int, size: int):
    return [slice(i, min(i + size, n)) for i in range(0, n, size)]


def _mvn_draws(make_cov, prior_diag: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, dim) zero-mean draws with the covariance returned by ``make_cov()`` (its lower
    triangle is used and overwritten).

    The posterior covariance of a smooth GP is numerically singular, so a jitter of
    1e-9 times each prior variance is added (grown tenfold, with a fresh matrix, until
    the Cholesky succeeds), as any dense sampler must.
    """
    jitter = 1e-9
    while True:
        cov = make_cov()
        cov[np.diag_indices_from(cov)] += jitter * prior_diag
        L, info = sla.lapack.dpotrf(cov, lower=1, overwrite_a=1, clean=1)
        if info == 0:
            break
        del cov, L
        if jitter >= 1e-5:
            raise np.linalg.LinAlgError("posterior covariance is not positive definite")
        jitter *= 10
    z = rng.standard_normal((L.shape[0], n))
    return sla.blas.dtrmm(1.0, L, z, lower=1, overwrite_b=1).T
