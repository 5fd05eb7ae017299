"""Bandit allocation of Monte-Carlo draws among candidate grasps (the arms): Beta-Bernoulli
posteriors, the policies that choose each round's pulls, and the Gittins index table.

Pure numbers: a pull is whatever ``pull(arms, draws)`` says it is (planners/gp_bandit.py
judges one candidate on one paired shape draw), so the policies are tested on synthetic
Bernoulli arms with known means."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import sparse, spatial, special

from harness.quality import Z95, wilson_interval

#: The policies: Thompson sampling, the Gittins index, Bayes-UCB, uniform allocation
#: (round-robin: gp-p's allocation) and iterative pruning (the baseline of the study).
POLICIES = ("thompson", "gittins", "ucb", "uniform", "pruning")
#: Rounds start at FIRST_ROUND pulls and grow by ROUND_GROWTH times the draws spent so
#: far, up to the caller's batch: the first rounds, whose outcomes change the allocation
#: most, stay small; the later ones spread the fixed cost of a round's one vectorised
#: evaluation (about 1 ms) over many pulls.
FIRST_ROUND = 20
ROUND_GROWTH = 0.25
#: Shared evidence (Thompson sampling, after Dex-Net 1.0's correlated Beta posteriors):
#: each arm's posterior also counts its neighbours' outcomes, weighted by how much the two
#: grasps overlap as executed (overlap_kernel), scaled down so that together they are worth
#: at most SHARED_DRAWS of its own draws. Its own draws then outweigh them as they
#: accumulate, so the posterior mean still converges to the arm's own P_F.
SHARED_DRAWS = 10.0
#: The model prior (model_prior; Thompson sampling, after Dex-Net 1.0's prior from
#: similar objects): arm a's prior is Beta(1 + n m_a, 1 + n (1 - m_a)), m_a the analytic
#: model's P~_F of the candidate, worth n = PRIOR_DRAWS draws. 5 is the model's accuracy
#: measured as draws: over gp-p's candidates on held-out seeds (100 and 101, the study's
#: 24 scenes, 4800 candidates) the mean of m (1 - m) over the mean squared error of m
#: against the candidates' P_F on 1000 draws, minus 1, was 5.2 (the method of moments: a
#: Beta(n m, n (1 - m)) spread equals that error when n + 1 is that ratio).
PRIOR_DRAWS = 5.0
#: The default weight per quality. The lift's model P~_L ranks the candidates less well
#: (rank correlation 0.78 with their per-draw lift rate, library at seed 100) and is far
#: too pessimistic (by 0.28 on average): its mean squared error exceeds m (1 - m), so the
#: same measure gives it no weight, and gp-bandit planning for the lift starts from the
#: uniform prior unless told otherwise.
DEFAULT_PRIOR_DRAWS = {"force_closure": PRIOR_DRAWS, "lift": 0.0}
#: The policies that take an informative prior: Thompson sampling draws from any Beta
#: posterior, and uniform allocation's only use of it is the answer. The index policies'
#: tables and quantiles assume the uniform prior (and pruning's Wilson bounds ignore it).
PRIOR_POLICIES = ("thompson", "uniform")
#: Overlaps below this are dropped (the kernel is sparse).
OVERLAP_CUTOFF = 1e-3
#: Thompson rounds (thompson_counts): the threshold is this lower quantile of the leading
#: arms' posteriors, the THOMPSON_LEADERS arms of highest posterior mean. An arm that lies
#: above it with probability below THOMPSON_SPARSE (THOMPSON_SPARSE_CLOSED when its
#: conditional law has a closed form) gets values only where it does: an inverse CDF costs
#: about 16 posterior draws, a closed form about 2 (measured with numpy and scipy here).
THOMPSON_QUANTILE = 1e-3
THOMPSON_LEADERS = 4
THOMPSON_SPARSE = 0.05
THOMPSON_SPARSE_CLOSED = 0.3
#: The Gittins table holds every state of up to this many pulls (Beta(1,1) prior); beyond
#: it the exploration bonus decays as 1 / (pulls + 3), the rate of Brezzi & Lai's (2002)
#: approximation, from the table's last row.
GITTINS_PULLS = 100
#: Retirement rewards on which the calibration is solved (a cosine grid on [0, 1], denser
#: near 0 and 1 where the indices of much-pulled arms crowd); with linear interpolation
#: between them the indices are within 3e-5 of the restart-in-state formulation
#: (measured at discounts 0.9 and 0.95; tests/test_bandit.py).
GITTINS_GRID = 2048
#: The calibration's horizon is cut where discount^horizon falls below this.
GITTINS_TOLERANCE = 1e-7


@dataclass
class Arms:
    """The Beta-Bernoulli posterior of each of A arms: ``successes`` and ``pulls`` (A,),
    the sum of each arm's tie-break values over its pulls (``tie``; a grasp's
    Ferrari-Canny quality), how many draws each arm may take at most (``depth``: the
    pool's size) and which arms are still in play (``alive``: pruning drops arms; every
    other policy keeps them all).

    With ``neighbours`` (a sparse (A, A) matrix of overlaps in [0, 1], zero diagonal;
    :func:`overlap_kernel`) and ``shared_draws`` > 0, arm a's posterior also counts its
    neighbours' outcomes: S_a = sum_b W_ab successes_b and F_a = sum_b W_ab failures_b,
    both scaled by min(1, shared_draws / (S_a + F_a)), so that they are worth at most
    ``shared_draws`` of its own draws (``shared``: (2, A), the scaled S and F, recomputed
    by :meth:`record`; set the counts through it).

    ``prior`` (2, A) holds each arm's prior Beta(alpha_0, beta_0); None is the uniform
    Beta(1, 1) (:func:`model_prior` builds an informative one)."""

    successes: np.ndarray
    pulls: np.ndarray
    tie: np.ndarray
    depth: int
    alive: np.ndarray
    neighbours: sparse.csr_matrix | None = None
    shared_draws: float = 0.0
    shared: np.ndarray | None = None
    prior: np.ndarray | None = None

    def __post_init__(self):
        if self.prior is None:
            self.prior = np.ones((2, len(self.pulls)))
        if self.shared is None:
            self._share()

    @classmethod
    def fresh(cls, count: int, depth: int, neighbours=None, shared_draws: float = 0.0, prior=None) -> "Arms":
        return cls(np.zeros(count, dtype=np.int64), np.zeros(count, dtype=np.int64), np.zeros(count), int(depth),
                   np.ones(count, dtype=bool), neighbours, float(shared_draws),
                   prior=None if prior is None else np.asarray(prior, dtype=float))

    def __len__(self) -> int:
        return len(self.pulls)

    @property
    def shares(self) -> bool:
        """Whether the posteriors count the neighbours' outcomes."""
        return self.neighbours is not None and self.shared_draws > 0

    @property
    def informed(self) -> bool:
        """Whether any arm's prior differs from the uniform Beta(1, 1)."""
        return bool(np.any(self.prior != 1.0))

    @property
    def alpha(self) -> np.ndarray:
        return self.prior[0] + self.successes + self.shared[0]

    @property
    def beta(self) -> np.ndarray:
        return self.prior[1] + self.pulls - self.successes + self.shared[1]

    @property
    def mean(self) -> np.ndarray:
        """Posterior means (alpha_0 + successes + S) / (alpha_0 + beta_0 + pulls + S + F):
        (1 + successes) / (2 + pulls) under the uniform prior without shared evidence."""
        alpha = self.alpha
        return alpha / (alpha + self.beta)

    def _share(self) -> None:
        if not self.shares:
            self.shared = np.zeros((2, len(self.pulls)))
            return
        s = self.neighbours @ self.successes.astype(float)
        f = self.neighbours @ (self.pulls - self.successes).astype(float)
        total = s + f
        scale = np.ones_like(total)
        over = total > self.shared_draws
        scale[over] = self.shared_draws / total[over]
        self.shared = np.stack([scale * s, scale * f])

    @property
    def room(self) -> np.ndarray:
        """Draws each arm may still take (0 for a dropped arm)."""
        return np.where(self.alive, self.depth - self.pulls, 0)

    def record(self, arms: np.ndarray, success: np.ndarray, tie: np.ndarray) -> None:
        """Add the outcomes of one round's pulls (an arm may appear several times)."""
        np.add.at(self.successes, arms, np.asarray(success, dtype=np.int64))
        np.add.at(self.pulls, arms, 1)
        np.add.at(self.tie, arms, np.asarray(tie, dtype=float))
        self._share()

    def best(self) -> int:
        """The arm with the highest posterior mean; ties go to more pulls, then to the
        higher mean tie-break value, then to the lower index (gp-p's order)."""
        tie_mean = self.tie / np.maximum(self.pulls, 1)
        return int(np.lexsort((np.arange(len(self)), -tie_mean, -self.pulls, -self.mean))[0])


def allocate(pull, arms: Arms, policy: str, budget: int, batch: int, rng: np.random.Generator,
             discount: float = 0.9, stop=None, after_round=None) -> Arms:
    """Spend up to ``budget`` pulls on ``arms`` in rounds chosen by ``policy`` (FIRST_ROUND
    pulls, then ROUND_GROWTH times the pulls so far, at most ``batch``). Arm a's j-th pull
    is its draw j: ``pull(arm_index (k,), draw_index (k,))`` returns (success (k,) bool,
    tie (k,) float) for one round, all arms at once. Stops
    when the budget is spent, every arm in play has taken ``arms.depth`` draws, or
    ``stop()`` says so (checked between rounds); ``after_round(arms, used)`` is called
    after each round. Returns ``arms``, updated in place."""
    if policy not in POLICIES:
        raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    if arms.shares and policy != "thompson":
        raise ValueError(f"shared evidence is for Thompson sampling; policy {policy!r} judges each arm alone")
    if arms.informed and policy not in PRIOR_POLICIES:
        raise ValueError(f"an informative prior is for {' and '.join(PRIOR_POLICIES)}; policy {policy!r}'s indices "
                         f"assume the uniform prior")
    used = int(arms.pulls.sum())
    while used < budget and arms.room.sum() > 0 and not (stop is not None and stop()):
        k = min(batch, max(FIRST_ROUND, int(ROUND_GROWTH * used)), budget - used)
        counts = round_counts(policy, arms, k, used, rng, discount)
        if not counts.any():
            break
        chosen = np.repeat(np.arange(len(arms)), counts)
        draws = arms.pulls[chosen] + _ranks(counts)
        success, tie = pull(chosen, draws)
        arms.record(chosen, success, tie)
        used += len(chosen)
        if policy == "pruning":
            prune(arms)
        if after_round is not None:
            after_round(arms, used)
    return arms


def round_counts(policy: str, arms: Arms, k: int, used: int, rng: np.random.Generator,
                 discount: float = 0.9) -> np.ndarray:
    """Pulls (A,) each arm takes in a round of at most k pulls (never beyond its room).

    - thompson: k posterior draws of every arm's success probability; each pull goes to
      the arm whose draw is highest (an arm may win several; parallel Thompson sampling;
      drawn by :func:`thompson_counts`).
    - gittins, ucb: the k largest index values, an arm's m-th pull in the round valued
      at its index after m pulls whose outcomes equal its posterior mean (the believer's
      batch: within a round an arm's index falls only with its pulls).
    - uniform: round-robin in arm order from the ``used`` pulls before it, so arm a's
      j-th pull is pull j A + a overall: every arm takes draws in the same order.
    - pruning: every arm in play the same share of k (one pull each to the k least
      pulled when k is smaller than their number).
    """
    room = arms.room
    if policy == "thompson":
        live = np.flatnonzero(room > 0)
        counts = np.zeros(len(arms), dtype=np.int64)
        counts[live] = thompson_counts(arms.alpha[live], arms.beta[live], k, rng)
    elif policy in ("gittins", "ucb"):
        counts = _believer_counts(arms, k, room, _index_function(policy, used, discount))
    elif policy == "uniform":
        counts = np.bincount((used + np.arange(k)) % len(arms), minlength=len(arms))
    elif policy == "pruning":
        alive = np.flatnonzero(room > 0)
        share = max(1, k // max(len(alive), 1))
        counts = np.zeros(len(arms), dtype=np.int64)
        if share * len(alive) > k:  # fewer pulls than arms: the least-pulled first
            alive = alive[np.lexsort((alive, arms.pulls[alive]))[:k]]
        counts[alive] = share
    else:
        raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
    return np.minimum(counts, room)


def thompson_counts(alpha: np.ndarray, beta: np.ndarray, k: int, rng: np.random.Generator,
                    quantile: float = THOMPSON_QUANTILE) -> np.ndarray:
    """How many of k independent posterior draws each of A Beta(alpha, beta) arms wins
    (the largest value of the draw's A values): parallel Thompson sampling's round, exact
    in distribution, without drawing the values of arms that cannot win.

    A threshold tau is set at the ``quantile`` lower quantile of the THOMPSON_LEADERS arms
    of highest posterior mean, so that some arm lies above it in all but a ``quantile``
    share of the draws. Arm a lies above it with probability p_a = I_{1 - tau}(beta_a,
    alpha_a). The *dense* arms (p_a at least THOMPSON_SPARSE_CLOSED when alpha or beta
    is 1, whose conditional law is a power, else THOMPSON_SPARSE) get a value in every
    draw, as usual. For each *sparse* arm, the draws where it lies above tau are a
    Bernoulli process (geometric gaps), and only there it gets a value, from its
    posterior conditioned above tau (closed form or inverse CDF): below tau it cannot beat
    a dense arm that lies above. A draw where neither does draws the sparse arms
    conditioned below tau. The cost per draw is the dense arms plus the sparse arms'
    expected exceedances, instead of A."""
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    a = len(alpha)
    if a == 0 or k <= 0:
        return np.zeros(a, dtype=np.int64)
    if a == 1:
        return np.array([k], dtype=np.int64)
    mean = alpha / (alpha + beta)
    leaders = np.argsort(-mean, kind="stable")[:THOMPSON_LEADERS]
    tau = float(special.betaincinv(alpha[leaders], beta[leaders], quantile).max())
    tail = special.betainc(beta, alpha, 1.0 - tau)  # P(theta_a > tau)
    closed = (alpha == 1.0) | (beta == 1.0)
    sparse = np.setdiff1d(np.flatnonzero(tail < np.where(closed, THOMPSON_SPARSE_CLOSED, THOMPSON_SPARSE)),
                          leaders)
    dense = np.setdiff1d(np.arange(a), sparse)
    # Dense arms, tau's leaders always among them: a value in every draw.
    theta = rng.beta(alpha[dense], beta[dense], size=(k, len(dense)))
    pick = np.argmax(theta, axis=1)
    best = theta[np.arange(k), pick]
    winners = dense[pick]
    if len(sparse) == 0:
        return np.bincount(winners, minlength=a)
    # Sparse arms: values only where they lie above tau.
    draw, local = _bernoulli_process(tail[sparse], k, rng)
    arm = sparse[local]
    value = _above(alpha[arm], beta[arm], tail[arm], tau, rng)
    if len(draw):
        order = np.lexsort((-value, draw))
        first = order[np.r_[True, draw[order][1:] != draw[order][:-1]]]
        beats = value[first] > best[draw[first]]
        winners[draw[first][beats]] = arm[first][beats]
    # Draws where no arm lies above tau: the sparse arms' values conditioned below it.
    seen = np.zeros(k, dtype=bool)
    seen[draw] = True
    low = np.flatnonzero(~seen & (best <= tau))
    if len(low):
        below = special.betainc(alpha[sparse], beta[sparse], tau)
        values = special.betaincinv(alpha[sparse], beta[sparse], rng.random((len(low), len(sparse))) * below)
        j = np.argmax(values, axis=1)
        beats = values[np.arange(len(low)), j] > best[low]
        winners[low[beats]] = sparse[j[beats]]
    return np.bincount(winners, minlength=a)


def _bernoulli_process(p: np.ndarray, k: int, rng: np.random.Generator):
    """Independent Bernoulli(p[a]) trials in draws 0..k-1 of every arm a: the (draw, arm)
    pairs of the successes, from geometric gaps between them."""
    a = len(p)
    active = np.flatnonzero(p > 0)
    last = np.full(a, -1, dtype=np.int64)  # each arm's last success so far
    draws, arms = [], []
    while len(active):
        q = p[active]
        mean = (k - 1 - last[active]) * q
        m = np.ceil(mean + 4.0 * np.sqrt(mean) + 4.0).astype(np.int64)
        rep = np.repeat(active, m)
        gaps = np.minimum(rng.geometric(np.repeat(q, m)), k + 1)  # a longer gap ends the k draws alike
        ends = np.cumsum(m)
        total = np.cumsum(gaps)
        offset = np.repeat(np.concatenate([[0], total[ends[:-1] - 1]]), m)
        position = np.repeat(last[active], m) + total - offset
        keep = position < k
        draws.append(position[keep])
        arms.append(rep[keep])
        reached = position[ends - 1]  # where each arm's last gap ended
        last[active] = np.where(reached < k, reached, last[active])
        active = active[reached < k]  # these may succeed again within the k draws
    return np.concatenate(draws) if draws else np.zeros(0, np.int64), \
        np.concatenate(arms) if arms else np.zeros(0, np.int64)


def _above(alpha: np.ndarray, beta: np.ndarray, tail: np.ndarray, tau: float, rng: np.random.Generator):
    """One value from each Beta(alpha, beta) conditioned above tau, whose probability
    there is ``tail``: in closed form when beta = 1 (P(theta > x) = 1 - x^alpha) or
    alpha = 1 (P(theta > x) = (1 - x)^beta), else by the inverse CDF of 1 - theta, a
    Beta(beta, alpha) variate below 1 - tau."""
    u = rng.random(len(alpha)) * tail
    with np.errstate(divide="ignore", invalid="ignore"):
        power_b = (1.0 - u) ** (1.0 / alpha)  # 1 - theta^alpha = u   (beta = 1)
        power_a = 1.0 - u ** (1.0 / beta)  # (1 - theta)^beta = u  (alpha = 1)
    general = (alpha != 1.0) & (beta != 1.0)
    inverse = np.zeros(len(alpha))
    if general.any():
        inverse[general] = 1.0 - special.betaincinv(beta[general], alpha[general], u[general])
    return np.where(beta == 1.0, power_b, np.where(alpha == 1.0, power_a, inverse))


def model_prior(model: np.ndarray, draws: float = PRIOR_DRAWS) -> np.ndarray:
    """Arms' priors (2, A) from a model's success probabilities ``model`` (A,) in [0, 1]:
    Beta(1 + draws m, 1 + draws (1 - m)), the uniform prior plus ``draws`` pseudo-draws
    whose success rate is the model's (``draws`` = 0: the uniform prior)."""
    m = np.clip(np.asarray(model, dtype=float), 0.0, 1.0)
    return np.stack([1.0 + draws * m, 1.0 + draws * (1.0 - m)])


def overlap_kernel(grasps, sigma: float, cutoff: float = OVERLAP_CUTOFF) -> sparse.csr_matrix:
    """How much each two of G grasps (jaw starts (G, 2, 2)) overlap as executed: W (G, G),
    sparse, zero diagonal. Under approach noise each executed grasp is its four start
    coordinates x plus N(0, sigma^2 I_4) (the pair's narrowing to the opening aside); the
    Bhattacharyya coefficient of two such Gaussians is exp(-|x_i - x_j|^2 / (8 sigma^2)),
    with the jaws' order ignored (the larger of the two orders' values). Values below
    ``cutoff`` are dropped; without approach noise (sigma = 0) no two distinct grasps
    overlap."""
    x = np.asarray(grasps, dtype=float).reshape(-1, 4)
    g = len(x)
    if g < 2 or sigma <= 0:
        return sparse.csr_matrix((g, g))
    reach = sigma * math.sqrt(8.0 * math.log(1.0 / cutoff))
    tree = spatial.cKDTree(x)
    orders = []
    for other in (tree, spatial.cKDTree(x[:, [2, 3, 0, 1]])):  # the jaws as given, then swapped
        found = tree.sparse_distance_matrix(other, reach, output_type="ndarray")
        value = np.exp(-found["v"] ** 2 / (8.0 * sigma**2))
        keep = (found["i"] != found["j"]) & (value >= cutoff)
        orders.append(sparse.csr_matrix((value[keep], (found["i"][keep], found["j"][keep])), shape=(g, g)))
    return orders[0].maximum(orders[1]).tocsr()


def prune(arms: Arms, z: float = Z95) -> None:
    """Iterative pruning (Kehoe et al. 2012): drop every arm whose Wilson upper bound lies
    below the best Wilson lower bound among the arms in play (an arm never pulled keeps
    its place)."""
    alive = arms.alive & (arms.pulls > 0)
    if not alive.any():
        return
    low, high = wilson_interval(arms.successes, np.maximum(arms.pulls, 1), z)
    floor = low[alive].max()
    arms.alive &= ~(alive & (high < floor))


def _ranks(counts: np.ndarray) -> np.ndarray:
    """0, 1, ..., counts[a] - 1 for every arm a, concatenated (np.repeat's order)."""
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    return np.arange(int(counts.sum())) - starts


#: Believer steps: an arm's m-th pull in a round is valued at its index after these
#: virtual pulls (every m up to 16, then steps of about a fifth).
_STEPS = np.unique(np.concatenate([np.arange(17), np.round(16 * 1.2 ** np.arange(1, 60))]).astype(np.int64))


def _believer_counts(arms: Arms, k: int, room: np.ndarray, index) -> np.ndarray:
    """The round's pulls by the k largest believer index values (see round_counts). The
    virtual pulls come in steps (_STEPS), each valued at its first pull's index, so the
    work is O(A log k) index evaluations."""
    steps = _STEPS[_STEPS < k]
    start = np.minimum(steps[None, :], room[:, None])  # (A, S)
    size = np.diff(np.concatenate([start, np.minimum(np.full((len(arms), 1), k), room[:, None])], axis=1), axis=1)
    mean = arms.mean[:, None]
    value = index(arms.successes[:, None] + mean * start, arms.pulls[:, None] + start)
    value = np.where(size > 0, value, -np.inf)
    arm = np.broadcast_to(np.arange(len(arms))[:, None], start.shape)
    order = np.lexsort((arm.ravel(), start.ravel(), -value.ravel()))
    taken = np.cumsum(size.ravel()[order])
    share = np.clip(k - (taken - size.ravel()[order]), 0, size.ravel()[order])
    counts = np.zeros(len(arms), dtype=np.int64)
    np.add.at(counts, arm.ravel()[order], share)
    return counts


def _index_function(policy: str, used: int, discount: float):
    """index(successes, pulls) (broadcast, successes may be fractional) of a policy."""
    if policy == "gittins":
        return functools.partial(gittins_index, discount=discount)
    level = 1.0 - 1.0 / (used + 1.0)
    return functools.partial(bayes_ucb_index, level=level)


def bayes_ucb_index(successes, pulls, level: float):
    """Bayes-UCB (Kaufmann, Cappe & Garivier 2012): the ``level`` quantile of the Beta(1 +
    successes, 1 + pulls - successes) posterior; the round's ``level`` is 1 - 1/t after
    t - 1 pulls (their c = 0)."""
    s = np.asarray(successes, dtype=float)
    n = np.asarray(pulls, dtype=float)
    if level <= 0.0:
        return (1.0 + s) / (2.0 + n)
    return special.betaincinv(1.0 + s, 1.0 + n - s, level)


def gittins_index(successes, pulls, discount: float = 0.9):
    """The Gittins index of Beta(1 + successes, 1 + pulls - successes) arms (broadcast;
    fractional successes interpolate linearly between the table's states). Up to
    GITTINS_PULLS pulls it is read from :func:`gittins_table`; beyond, the index is the
    posterior mean plus the table's last-row bonus (index minus mean, interpolated in the
    mean) times (GITTINS_PULLS + 3) / (pulls + 3)."""
    table = gittins_table(discount)
    s = np.asarray(successes, dtype=float)
    n = np.asarray(pulls, dtype=np.int64)
    s, n = np.broadcast_arrays(s, n)
    last = GITTINS_PULLS
    inside = n <= last
    ni = np.minimum(n, last)
    lo = np.clip(np.floor(s), 0, ni).astype(np.int64)
    hi = np.minimum(lo + 1, ni)
    frac = np.clip(s - lo, 0.0, 1.0)
    within = table[ni, lo] + frac * (table[ni, hi] - table[ni, lo])
    mean = (1.0 + s) / (2.0 + n)
    grid_mean = (1.0 + np.arange(last + 1)) / (last + 2.0)
    bonus = np.interp(mean, grid_mean, table[last] - grid_mean) * (last + 3.0) / (n + 3.0)
    return np.where(inside, within, mean + bonus)


@functools.lru_cache(maxsize=8)
def gittins_table(discount: float = 0.9, pulls: int = GITTINS_PULLS, grid: int = GITTINS_GRID) -> np.ndarray:
    """Gittins indices G[n, s] (n = 0..pulls pulls, s = 0..n successes; NaN above the
    diagonal) of a Bernoulli arm with a Beta(1 + s, 1 + n - s) posterior and discount
    ``discount``, by calibration (Gittins 1979; Gittins, Glazebrook & Weber 2011, ch. 8):
    the index is the retirement reward lambda per step at which pulling once more and
    retiring for ever, lambda / (1 - discount), are worth the same.

    One backward induction over the states of up to pulls + H pulls (H: where
    discount^H < GITTINS_TOLERANCE; at that depth the arm is valued as known, max(lambda,
    mean) / (1 - discount)) values every state at once for each of ``grid`` + 1 retirement
    rewards on [0, 1] (see GITTINS_GRID). The advantage of pulling over retiring falls
    strictly with lambda (slope below -1), so each state's index lies between the last
    reward at which pulling wins and the next; it is placed by linear interpolation of
    the advantage. Computed once per process and discount (0.2 s at 0.9, 0.6 s at 0.95)
    and cached.
    """
    if not 0.0 < discount < 1.0:
        raise ValueError(f"discount must lie in (0, 1), got {discount}")
    horizon = math.ceil(math.log(GITTINS_TOLERANCE) / math.log(discount))
    depth = pulls + horizon
    lam = 0.5 - 0.5 * np.cos(np.pi * np.arange(grid + 1) / grid)  # denser near 0 and 1
    retire = (lam / (1.0 - discount))[:, None]
    mean = (1.0 + np.arange(depth + 1)) / (depth + 2.0)
    value = np.maximum(retire, mean[None, :] / (1.0 - discount))
    table = np.full((pulls + 1, pulls + 1), np.nan)
    for n in range(depth - 1, -1, -1):
        mean = (1.0 + np.arange(n + 1)) / (n + 2.0)
        pull_on = mean * (1.0 + discount * value[:, 1:]) + (1.0 - mean) * discount * value[:, :-1]
        if n <= pulls:
            advantage = pull_on - retire
            k = np.clip((advantage > 0).sum(axis=0) - 1, 0, grid - 1)
            col = np.arange(n + 1)
            a0, a1 = advantage[k, col], advantage[k + 1, col]
            table[n, : n + 1] = lam[k] + (lam[k + 1] - lam[k]) * a0 / (a0 - a1)
        value = np.maximum(retire, pull_on)
    table.setflags(write=False)
    return table
