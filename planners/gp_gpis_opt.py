"""GP-GPIS-OPT (Mahler et al., ICRA 2015): a grasp optimised by sequential convex
programming for a smooth surrogate of P_F on the mean shape under approach noise and
shape uncertainty, minus a penalty on shape uncertainty at the contacts, subject to
antipodal constraints. With ``quality = "lift"`` the surrogate is of P_L instead: each
sigma point's P_F term times the lift model's smooth probability, with the centre of
mass's posterior mean and spread (harness.lift.MassBelief), plus, out of the cone, the
lift's probability where the plates' squeeze settles the mean shape; the optima and the
screened starts are re-ranked by P_L, each as it is and slid along its closing line so
that both plates reach the mean shape together (:func:`centred`: the lift model's push,
which the surrogate does not model).

Decision variables: the two jaw start points (in cells), not the contact points as in the
paper. With jaw plates a grasp's contacts lie on the plate's edges as often as on its
axis, so a grasp rebuilt from its contacts is a different grasp (on the toy plane,
candidates rebuilt that way kept a rank correlation of only 0.65 with their own P_F).
With jaw starts, the contacts come from the same plate sweep as the evaluation and the
physics (harness.grasp.find_contacts on the mean): contacts on the mean surface and a
collision-free approach hold by construction, and there are no equality constraints.
"""

from __future__ import annotations

import math

import numpy as np

from scipy.special import ndtr

from harness.grasp import OK, Grasp, SDFBatch, find_contacts, interpolate, plate_closure
from harness.lift import MassBelief
from harness.quality import draw_evaluation, ranking_scores
from harness.scp import SCPSettings, minimize
from harness.squeeze import squeeze
from planners import candidates as cand
from planners.base import Plan, Planner, Problem, Stopwatch, check_quality

#: Sigma points over approach noise: each jaw start offset across the axis by the
#: 3-point Gauss-Hermite nodes 0, +-sqrt(3) sigma_g (weights 2/3, 1/6, 1/6), 9 in all.
#: (The original used +-sigma_g with weights 1, e^-1/2, e^-1, which understates the
#: noise's spread; these nodes integrate a Gaussian exactly up to degree 5.)
_NODES = np.array([-math.sqrt(3.0), 0.0, math.sqrt(3.0)])
_NODE_W = np.array([1 / 6, 2 / 3, 1 / 6])
_K = np.array([(a, b) for a in _NODES for b in _NODES])
_W = np.array([wa * wb for wa in _NODE_W for wb in _NODE_W])
#: The sigma point with no offset: the nominal grasp.
_NOMINAL = int(np.flatnonzero((_K == 0).all(axis=1))[0])
#: Posterior shape samples behind the centre of mass's mean and spread (quality "lift").
COM_SAMPLES = 64
#: ``finalists``' default: every optimum re-ranked with quality "lift", none with force closure.
AUTO = -1
#: The smoothing of the friction cone's edge (degrees): the default ``temperature_deg``.
TEMPERATURE_DEG = 5.0


def model_quality(problem: Problem, grasps: np.ndarray, mass: MassBelief | None = None,
                  temperature_deg: float = TEMPERATURE_DEG) -> np.ndarray:
    """The surrogate P~_F (or P~_L with a MassBelief) of jaw-start grasps (G, 2, 2) in
    metres: the analytic model gp-gpis-opt optimises, without drawing a shape. gp-bandit
    takes its prior from it."""
    objective = SurrogateObjective(problem, 0.0, math.radians(temperature_deg), mass)
    return np.clip(objective.surrogate(np.asarray(grasps, dtype=float).reshape(-1, 4) / objective.h), 0.0, 1.0)


class GPGPISOpt(Planner):
    name = "gp-gpis-opt"
    description = "sequential convex programming on a smooth P_F (or P_L) surrogate minus an uncertainty penalty (OSQP)"
    BOUNDS = {"initialisations": (1, 1000), "screen": (1, 10_000), "nu": (0.0, 100.0),
              "temperature_deg": (0.1, 45.0), "max_iterations": (1, 1000), "finalists": (-1, 1000),
              "rerank_samples": (1, 10_000), "angular_noise_deg": (0.0, 90.0)}

    def __init__(self, initialisations: int = 10, screen: int = 100, nu: float = 1.0,
                 temperature_deg: float = TEMPERATURE_DEG,
                 max_iterations: int = 20, finalists: int = AUTO, rerank_samples: int = 200,
                 angular_noise_deg: float = 10.0, quality: str = "force_closure"):
        if min(initialisations, screen, max_iterations, rerank_samples) < 1 or finalists < AUTO:
            raise ValueError("initialisations, screen, max_iterations and rerank_samples must be >= 1, "
                             "finalists >= -1")
        if nu < 0 or temperature_deg <= 0:
            raise ValueError("nu must be >= 0 and temperature_deg > 0")
        self.initialisations = int(initialisations)
        self.screen = int(screen)
        self.nu = float(nu)
        self.temperature_deg = float(temperature_deg)
        self.max_iterations = int(max_iterations)
        self.quality = check_quality(quality)
        # AUTO: the lift's finalists are every optimum (the surrogate does not model the
        # squeeze, nor the lift's levers as P_L draws them); force closure keeps the
        # paper's pick, the surrogate's best.
        auto = self.initialisations if self.quality == "lift" else 0
        self.finalists = auto if finalists == AUTO else int(finalists)
        self.rerank_samples = int(rerank_samples)
        self.angular_noise_deg = float(angular_noise_deg)

    def shape_samples(self) -> int:
        return (self.rerank_samples if self.finalists else 0) + (COM_SAMPLES if self.quality == "lift" else 0)

    def plan(self, problem: Problem, rng: np.random.Generator) -> Plan:
        clock = Stopwatch(problem.time_budget_s)
        belief = problem.belief
        if belief.mean_shape.is_empty:
            return Plan.without_grasp("no_surface", "the posterior mean has no inside", seconds=clock.phases)
        init_rng, rerank_rng, mass_rng = rng.spawn(3)
        grasps = cand.generate(belief, max(self.screen, self.initialisations), init_rng, problem.settings,
                               math.radians(self.angular_noise_deg))
        mass = (MassBelief.of_posterior(belief, problem.settings, COM_SAMPLES, mass_rng) if self.quality == "lift"
                else None)
        objective = SurrogateObjective(problem, self.nu, math.radians(self.temperature_deg), mass)
        c = (find_contacts(objective.mean, grasps[:, 0], grasps[:, 1], problem.settings.jaw_width)
             if len(grasps) else None)
        if c is None or not np.any(c.status == OK):
            return Plan.without_grasp("no_candidate", "no initial grasp meets the mean shape", seconds=clock.phases)
        ok = c.status == OK
        starts = grasps[ok]
        x0 = starts.reshape(-1, 4) / objective.h
        # Random starts, screened: the surrogate's best of the pool start the SCP.
        f0, _, g0 = objective(x0)
        best = np.lexsort((f0, np.maximum(g0, 0).sum(axis=1) > 0.5))[: self.initialisations]
        x0, starts = x0[best], starts[best]
        start_violation = np.maximum(g0[best], 0.0).sum(axis=1)
        clock.lap("initialisation")
        budget = None if problem.time_budget_s is None else max(0.0, problem.time_budget_s - clock.elapsed())
        settings = SCPSettings(trust_init=2.0, trust_min=0.01, trust_max=8.0, max_iterations=self.max_iterations,
                               penalty_init=1.0, improve_tol=1e-3, constraint_tol=1e-3, fd_step=1e-4,
                               fd_central=False, qp_tolerance=1e-4)
        lower, upper = objective.bounds()
        result = minimize(objective, x0, lower, upper, 0, objective.n_ineq, settings, time_budget=budget)
        clock.lap("scp")

        feasible = result.violation <= settings.constraint_tol
        order = np.lexsort((result.objective, ~feasible))  # feasible first, then by objective
        jaws = objective.jaw_starts(result.x)
        valid = objective.valid(jaws)
        order = [i for i in order if valid[i]]
        estimate, message = None, ""
        if order and self.finalists > 1:
            # Infeasible optima (out of the friction cone on the mean) are not executed
            # (status "infeasible"): they compete only when no optimum is feasible. The
            # feasible starts compete beside them: the SCP descends the surrogate, not the
            # re-ranking's estimate, and an optimum can be worse than its start there.
            finalists = ([i for i in order if feasible[i]] or order)[: self.finalists]
            entries, ok = jaws[finalists], feasible[finalists]
            start_ok = (start_violation <= settings.constraint_tol) & objective.valid(starts)
            entries = np.concatenate([entries, starts[start_ok]])
            ok = np.concatenate([ok, np.ones(int(start_ok.sum()), dtype=bool)])
            if self.quality == "lift":
                # Each competes as it is and slid along its closing line so that both
                # plates reach the mean shape together (P_L's push, harness.push).
                entries = np.concatenate([entries, centred(entries, objective, problem.settings.jaw_width)])
                ok = np.concatenate([ok, ok])
            draws = draw_evaluation(belief, self.rerank_samples, *rerank_rng.spawn(4))
            score, tie = ranking_scores(entries, draws, problem.settings, self.quality == "lift")
            pick = int(np.lexsort((-tie, -score))[0])  # as gp-p ranks: best score, then Ferrari-Canny
            estimate, message = float(score[pick]), f"finalists and starts re-ranked on {self.rerank_samples} draws"
            grasp, status = entries[pick], ("ok" if ok[pick] else "infeasible")
            clock.lap("rerank")
        elif order:
            chosen = order[0]
            estimate = float(objective.surrogate(result.x[chosen:chosen + 1])[0])
            grasp, status = jaws[chosen], ("ok" if feasible[chosen] else "infeasible")
        else:  # no optimised grasp is executable: fall back to the best start
            grasp, message = starts[0], "no optimised grasp was executable; returning a start"
            status = "ok" if feasible[0] else "infeasible"
        if any(s == "time_limit" for s in result.status):
            # Cut short by the budget: the best grasp so far is executed only if it is
            # feasible ("budget", as "ok"); an infeasible one stays "infeasible".
            if status == "ok":
                status = "budget"
            message = "; ".join(m for m in (message, "stopped at the time budget") if m)
        trace = _trace(result, settings.constraint_tol)
        return Plan(Grasp(tuple(grasp[0]), tuple(grasp[1])), status, estimate,
                    iterations=int(result.iterations.max()), evaluations=result.evaluations, seconds=clock.phases,
                    trace=trace, message=message)


def centred(jaws: np.ndarray, objective: "SurrogateObjective", jaw_width: float) -> np.ndarray:
    """Grasps (R, 2, 2) slid along their closing lines so that both plates reach the mean
    shape together (the same line, width and contacts on the mean): the jaws close
    symmetrically, so a plate that arrives first pushes the object until the other does,
    which the lift model counts (harness.push) and the surrogate does not (its pull
    towards one clearance per jaw is a weak regulariser, and the SCP can leave a jaw
    centimetres out). A slid grasp that would leave the grid is left as it was."""
    g1, g2 = jaws[:, 0], jaws[:, 1]
    c = find_contacts(objective.mean, g1, g2, jaw_width)
    u = (g2 - g1) / np.maximum(np.linalg.norm(g2 - g1, axis=1, keepdims=True), 1e-300)
    gap1 = np.einsum("ij,ij->i", c.c1 - g1, u)
    gap2 = np.einsum("ij,ij->i", g2 - c.c2, u)
    shift = np.where(c.status == OK, 0.5 * (gap1 - gap2), 0.0)
    slid = jaws + shift[:, None, None] * u[:, None, :]
    return np.where(objective.valid(slid)[:, None, None], slid, jaws)


def _trace(result, tol):
    """(seconds, evaluations, best surrogate objective so far among feasible iterates)."""
    best, out = np.inf, []
    for seconds, evaluations, objective, violation, _ in result.trace:
        feasible = violation <= tol
        if feasible.any():
            best = min(best, float(objective[feasible].min()))
        out.append((seconds, evaluations, best))
    return tuple(out)


class SurrogateObjective:
    """GP-GPIS-OPT's objective and constraints for the SCP solver, vectorised over rows of
    x = (g1, g2), the jaw starts in cells.

    Objective: nu * (var(c1) + var(c2)) / scale - P~_F(x), plus a small pull (1e-3 per
    cell^2) of each jaw start towards one clearance from its contact, which fixes the
    otherwise free sliding of a jaw along the axis. P~_F approximates P_F under approach
    noise and shape uncertainty: for each sigma point (jaw starts offset across the axis
    by the Gauss-Hermite nodes) the contacts are the plates' first crossings of the mean
    (find_contacts: bicubic, sub-cell), and the grasp holds with probability
    Phi(m1 / s1) Phi(m2 / s2), where m_i = atan(friction) - (angle between the contact line
    and contact i's inward normal) and s_i^2 = temperature^2 + (the posterior std of that
    normal's angle at the nominal contact, from the gradient variance)^2. A sigma point
    whose plates start inside, miss, or find no normal scores 0. With a MassBelief
    (quality "lift") each sigma point's term is multiplied by the lift's smooth
    probability at its contacts (MassBelief.margin: the centre of mass's posterior
    distance from the contact line and its spread, the weight, the patches, the hang),
    and the rest of the sigma point's probability (out of the cone) by the lift's at the
    contacts where the plates' squeeze settles the mean shape (0 where it does not:
    :meth:`_squeezed`); the objective maximises that P~_L instead.
    Inequalities: both nominal contacts in their friction cones (radians; with a
    MassBelief, met where the squeeze settles the nominal grasp); the width
    within the opening; each jaw start at least a clearance minus sigma_g from its
    contact (cells). Bounds keep the jaw starts in the grid.
    """

    def __init__(self, problem: Problem, nu: float, temperature: float, mass: MassBelief | None = None):
        belief = problem.belief
        self.mass = mass
        grid = belief.grid
        self.problem = problem
        self.settings = settings = problem.settings
        self.h = grid.cell
        self.nu = nu
        self.temperature = temperature
        self.cone = math.atan(settings.friction)
        self.gap = cand.clearance(belief, settings.sigma_g)
        self.mean = belief.mean_field
        scale = belief.gp.scale_
        # Variance of the value and mean variance of the two gradient components, both as
        # smooth fields on the grid (normalised by the prior's), read at the contacts.
        var = belief.var / scale
        grad_var = belief.gradient_var.mean(axis=-1)
        self.uncertainty = SDFBatch(grid, np.stack([var, grad_var]),
                                    np.stack([np.stack(np.gradient(a, grid.cell, axis=(1, 0)), -1)
                                              for a in (var, grad_var)]))
        self.n_ineq = 2 + 1 + 2

    def bounds(self):
        limit = (0.5 * self.problem.belief.grid.extent - self.h) / self.h
        return -limit, limit

    def jaw_starts(self, x):
        """Jaw starts (R, 2, 2) in metres."""
        return x.reshape(-1, 2, 2) * self.h

    def valid(self, jaws):
        half = 0.5 * self.problem.belief.grid.extent
        width = np.linalg.norm(jaws[:, 1] - jaws[:, 0], axis=1)
        return (width <= self.settings.opening) & (np.abs(jaws) < half).all(axis=(1, 2)) & np.isfinite(width)

    def _evaluate(self, x):
        """Contacts of every sigma point: c1, c2, n1, n2 (R, 9, 2), ok (R, 9), the patch
        widths w1, w2 (R, 9) and the larger edge slope of the two plates (R, 9; 0: no edge)."""
        jaws = self.jaw_starts(x)
        g1, g2 = jaws[:, 0], jaws[:, 1]
        d = g2 - g1
        perp = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        shift = self.settings.sigma_g * _K  # (9, 2): offsets of jaw 1 and jaw 2 across the axis
        s1 = (g1[:, None, :] + shift[None, :, 0, None] * perp[:, None, :]).reshape(-1, 2)
        s2 = (g2[:, None, :] + shift[None, :, 1, None] * perp[:, None, :]).reshape(-1, 2)
        c = find_contacts(self.mean, s1, s2, self.settings.jaw_width, field_index=np.zeros(len(s1), dtype=np.int64))
        r = len(x)
        settled = None if self.mass is None else self._squeezed(s1, s2, c).reshape(r, -1)
        return (c.c1.reshape(r, -1, 2), c.c2.reshape(r, -1, 2), c.n1.reshape(r, -1, 2), c.n2.reshape(r, -1, 2),
                (c.status == OK).reshape(r, -1), c.w1.reshape(r, -1), c.w2.reshape(r, -1),
                np.maximum(c.edge1, c.edge2).reshape(r, -1), settled)

    def _squeezed(self, s1, s2, c):
        """The lift's smooth probability (B,) at the contacts where the plates' squeeze
        (harness.squeeze) settles the mean shape, for sigma points out of force closure
        on it that it brings into closure (or holds in the plane); 0 for the rest."""
        belief, settings = self.problem.belief, self.settings
        closed, _ = plate_closure(c, settings.friction, belief.center_of_mass, belief.characteristic_length,
                                  with_quality=False)
        out = squeeze(self.mean, s1, s2, 0, c, closed, settings.friction, settings.jaw_width,
                      belief.characteristic_length)
        return self.mass.settled_margin(out, out.squeezed & ~closed, settings.friction, settings, self.h)

    def _terms(self, x) -> dict:
        """The objective's and constraints' parts at rows x (see the class docstring)."""
        r = len(x)
        c1, c2, n1, n2, ok, w1, w2, edge, squeezed = self._evaluate(x)
        line = c2 - c1
        line /= np.maximum(np.linalg.norm(line, axis=-1, keepdims=True), 1e-12)
        a1 = np.arccos(np.clip(-np.einsum("rsk,rsk->rs", n1, line), -1.0, 1.0))
        a2 = np.arccos(np.clip(np.einsum("rsk,rsk->rs", n2, line), -1.0, 1.0))
        hit = ok[:, _NOMINAL]
        contacts = np.concatenate([c1[:, _NOMINAL], c2[:, _NOMINAL]])
        contacts = np.where(np.concatenate([hit, hit])[:, None], contacts, 0.0)
        values, _ = interpolate(self.uncertainty, np.repeat([0, 1], 2 * r), np.concatenate([contacts, contacts]))
        var, grad_var = values[: 2 * r].reshape(2, r), values[2 * r:].reshape(2, r)
        _, grad = interpolate(self.mean, np.zeros(2 * r, dtype=np.int64), contacts)
        angle_sd = np.sqrt(np.maximum(grad_var, 0.0)) / np.maximum(np.linalg.norm(grad, axis=1).reshape(2, r), 1e-6)
        spread = np.sqrt(self.temperature**2 + angle_sd**2)  # (2, R)
        hold = ndtr((self.cone - a1) / spread[0][:, None]) * ndtr((self.cone - a2) / spread[1][:, None])
        jaws = self.jaw_starts(x)
        reach = np.stack([np.linalg.norm(jaws[:, 0] - c1[:, _NOMINAL], axis=1),
                          np.linalg.norm(jaws[:, 1] - c2[:, _NOMINAL], axis=1)], axis=1)
        reach = np.where(hit[:, None], reach, self.gap)
        cone = np.stack([a1[:, _NOMINAL], a2[:, _NOMINAL]], axis=1) - self.cone
        if self.mass is not None:
            # A nominal grasp the squeeze settles meets its cone constraints where it settles.
            cone = np.where((squeezed[:, _NOMINAL] > 0)[:, None], np.minimum(cone, 0.0), cone)
            lift = np.zeros(ok.shape)
            lift[ok] = self.mass.margin(c1[ok], c2[ok], w1[ok], w2[ok], self.settings.friction, self.settings,
                                        self.h, edge[ok])
            # Out of the cone, the plates squeeze the object until they are in it (or
            # cannot): P_L's planar step, followed on the mean shape.
            hold = hold * lift + (1.0 - hold) * squeezed
        return {
            "quality": np.where(ok, hold, 0.0) @ _W,
            "uncertainty": self.nu * np.where(hit, var.sum(axis=0), 0.0),
            "pull": 1e-3 * (((reach - self.gap) / self.h) ** 2).sum(axis=1),
            # A nominal grasp that finds no contacts violates its cone constraints by a radian.
            "cone": np.where(hit[:, None], cone, 1.0),
            "width": ((np.linalg.norm(jaws[:, 1] - jaws[:, 0], axis=1) - self.settings.opening) / self.h)[:, None],
            "clear": (self.gap - self.settings.sigma_g - reach) / self.h,
        }

    def __call__(self, x):
        """f (R,), h (R, 0), g (R, n_ineq) for the SCP solver."""
        t = self._terms(x)
        g = np.concatenate([t["cone"], t["width"], t["clear"]], axis=1)
        return t["uncertainty"] - t["quality"] + t["pull"], np.zeros((len(x), 0)), g

    def surrogate(self, x):
        """P~_F, or P~_L with a MassBelief (R,)."""
        return self._terms(x)["quality"]
