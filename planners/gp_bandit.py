"""GP-bandit: GP-P's candidates as the arms of a Beta-Bernoulli bandit (Laskey et al.,
CASE 2015): one pull judges one candidate on one paired draw of the pool, and the policy
spends the draws where they decide the choice. Thompson sampling's posteriors start from
the analytic model's P~_F of each candidate, worth a few draws (the model prior), and also
count the outcomes of overlapping candidates, up to a cap (shared evidence); both after
Dex-Net 1.0 (planners.allocation.Arms)."""

from __future__ import annotations

import numpy as np

from harness.grasp import Grasp
from harness.lift import MassBelief
from harness.quality import DrawPool, evaluate_pairs
from planners import candidates as cand
from planners.allocation import (DEFAULT_PRIOR_DRAWS, POLICIES, PRIOR_POLICIES, SHARED_DRAWS, Arms, allocate,
                                 model_prior, overlap_kernel)
from planners.base import Plan, Planner, Problem, Stopwatch, check_quality
from planners.gp_gpis_opt import COM_SAMPLES, model_quality

#: The discounts whose Gittins table is affordable (its calibration grows as
#: 1 / (1 - discount)^2).
DISCOUNTS = (0.5, 0.95)


class GPBandit(Planner):
    name = "gp-bandit"
    description = ("GP-P's candidates as bandit arms: draws spent by Thompson sampling (from the analytic model's "
                   "prior, sharing evidence between overlapping candidates), Gittins, Bayes-UCB or uniformly")
    BOUNDS = {"candidates": (1, 10_000), "samples": (1, 10_000), "budget_draws": (1, 100_000_000),
              "batch": (1, 100_000), "discount": DISCOUNTS, "angular_noise_deg": (0.0, 90.0),
              "shared_draws": (0.0, 100_000.0), "prior_draws": (0.0, 100_000.0)}

    def __init__(self, candidates: int = 100, samples: int = 1000, policy: str = "thompson",
                 budget_draws: int = 500, batch: int = 2000, discount: float = 0.9,
                 quality: str = "force_closure", angular_noise_deg: float = 10.0,
                 shared_draws: float | None = None, prior_draws: float | None = None):
        if min(candidates, samples, budget_draws, batch) < 1:
            raise ValueError("candidates, samples, budget_draws and batch must be at least 1")
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {policy!r}")
        if not DISCOUNTS[0] <= discount <= DISCOUNTS[1]:
            raise ValueError(f"discount must lie in [{DISCOUNTS[0]}, {DISCOUNTS[1]}], got {discount}")
        self.candidates = int(candidates)
        self.samples = int(samples)
        self.policy = policy
        self.budget_draws = int(budget_draws)
        self.batch = int(batch)
        self.discount = float(discount)
        self.quality = check_quality(quality)
        self.angular_noise_deg = float(angular_noise_deg)
        if shared_draws is None:  # Thompson sampling shares evidence by default; no other policy can
            shared_draws = SHARED_DRAWS if policy == "thompson" else 0.0
        if shared_draws < 0 or (shared_draws > 0 and policy != "thompson"):
            raise ValueError(f"shared_draws must be 0 or more, and 0 unless the policy is thompson "
                             f"(policy {policy!r}, shared_draws {shared_draws})")
        self.shared_draws = float(shared_draws)
        if prior_draws is None:  # Thompson sampling starts from the model by default; uniform is gp-p's
            prior_draws = DEFAULT_PRIOR_DRAWS[self.quality] if policy == "thompson" else 0.0
        if prior_draws < 0 or (prior_draws > 0 and policy not in PRIOR_POLICIES):
            raise ValueError(f"prior_draws must be 0 or more, and 0 unless the policy is "
                             f"{' or '.join(PRIOR_POLICIES)} (policy {policy!r}, prior_draws {prior_draws})")
        self.prior_draws = float(prior_draws)

    def shape_samples(self) -> int:
        return self.samples + (COM_SAMPLES if self.quality == "lift" else 0)

    def plan(self, problem: Problem, rng: np.random.Generator, record: list | None = None) -> Plan:
        """As Planner.plan; ``record`` (a list) receives (seconds, draws used, best grasp
        (2, 2)) before the first round (0 draws: the answer of the prior alone, the model's
        best candidate, or gp-p's first one under the uniform prior) and after every round,
        for convergence studies. Afterwards ``grasps_`` holds the candidates (G, 2, 2),
        ``arms_`` their posteriors and pulls (planners.allocation.Arms): where the draws
        went, and ``model_`` the model's P~_F (or P~_L) of each candidate (None without the
        model prior).

        The generator is used as gp-p uses it (candidates, then the pool's four streams),
        then once more for the policy's own stream (and, for the model prior of the lift
        quality, once more for its centre of mass samples): at the same seed both planners
        judge the same candidates on the same draws."""
        clock = Stopwatch(problem.time_budget_s)
        belief, settings = problem.belief, problem.settings
        if belief.mean_shape.is_empty:
            return Plan.without_grasp("no_surface", "the posterior mean has no inside", seconds=clock.phases)
        grasps = cand.generate(belief, self.candidates, rng, settings, np.radians(self.angular_noise_deg))
        clock.lap("candidates")
        if len(grasps) == 0:
            return Plan.without_grasp("no_candidate", "no candidate grasp fits the gripper", seconds=clock.phases)
        pool = DrawPool(belief, self.samples, *rng.spawn(4))
        policy_rng = rng.spawn(1)[0]
        lift = self.quality == "lift"

        def pull(arm, draw):
            outcomes = evaluate_pairs(grasps[arm], draw, pool.draws(int(draw.max()) + 1), settings, lift=lift)
            return (outcomes.lifted if lift else outcomes.closure), outcomes.ferrari_canny

        trace: list = []

        def after_round(arms: Arms, used: int):
            best = arms.best()
            seconds = clock.elapsed()
            trace.append((seconds, used, float(arms.mean[best])))
            if record is not None:
                record.append((seconds, used, grasps[best].copy()))

        model = prior = None
        if self.prior_draws > 0:
            mass = MassBelief.of_posterior(belief, settings, COM_SAMPLES, rng.spawn(1)[0]) if lift else None
            model = model_quality(problem, grasps, mass)
            prior = model_prior(model, self.prior_draws)
            clock.lap("model")
        neighbours = overlap_kernel(grasps, settings.sigma_g) if self.shared_draws > 0 else None
        arms = Arms.fresh(len(grasps), self.samples, neighbours, self.shared_draws, prior)
        if record is not None:
            record.append((clock.elapsed(), 0, grasps[arms.best()].copy()))
        arms = allocate(pull, arms, self.policy, self.budget_draws, self.batch, policy_rng, self.discount,
                        stop=clock.over_budget, after_round=after_round)
        self.grasps_, self.arms_, self.model_ = grasps, arms, model
        used = int(arms.pulls.sum())
        clock.lap("allocation")
        clock.phases["draws"] = pool.seconds  # drawn inside the allocation, as pulls reached them
        clock.phases["allocation"] -= pool.seconds
        finished = used >= self.budget_draws or arms.room.sum() == 0
        best = arms.best()
        g = grasps[best]
        return Plan(Grasp(tuple(g[0]), tuple(g[1])), "ok" if finished else "budget", float(arms.mean[best]),
                    iterations=len(trace), evaluations=used, seconds=clock.phases, trace=tuple(trace),
                    message=f"{self.policy}: {used} draws over {len(grasps)} candidates, the chosen one "
                            f"{int(arms.pulls[best])} ({int(arms.successes[best])} successes"
                            + ("" if model is None else f", model {model[best]:.2f}") + ")")
