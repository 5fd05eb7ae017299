"""Benchmarks behind ``gpis-harness bench``: speeds measured as ratios within one run."""

from __future__ import annotations

import math
import multiprocessing
import resource
import time
from pathlib import Path

import numpy as np

#: Grid sizes of the sampling benchmark.
SAMPLING_SIZES = (25, 40, 55, 70, 100, 200)
#: Scene whose physical size, sensor and GPIS settings are kept while M varies.
SAMPLING_SCENE = "disk"
SAMPLES = 1000
REPEATS = 3


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _sampling_row(scene_name: str, size: int, exact_max_mb: float) -> dict:
    """One grid size, in a fresh process: fit and fast-sample (best of REPEATS, each on a
    fresh belief so the one-off basis set-up is included), then the exact sampler once."""
    from harness.belief import build_belief
    from harness.scene import load_scene
    from harness.seeding import stream

    scene = load_scene(scene_name, overrides=_sampling_overrides(size))
    fit_s, fast_s = math.inf, math.inf
    for r in range(REPEATS):
        t0 = time.perf_counter()
        belief = build_belief(scene, stream(0, "bench", size, "sensor"))
        t1 = time.perf_counter()
        belief.sample(SAMPLES, stream(0, "bench", size, "fast", r))
        t2 = time.perf_counter()
        fit_s, fast_s = min(fit_s, t1 - t0), min(fast_s, t2 - t1)
    fast_peak = _peak_mb()
    dim = 3 * size * size
    exact_mb = dim * dim * 8 / 2**20
    exact_s = None
    if exact_mb <= exact_max_mb:
        t0 = time.perf_counter()
        belief.sample(SAMPLES, stream(0, "bench", size, "exact"), method="exact")
        exact_s = time.perf_counter() - t0
    c = scene.grid.coords
    rank = belief.gp._basis(0, c).rank
    return {
        "M": size, "fit_s": fit_s, "fast_s": fast_s, "exact_s": exact_s, "peak_mb": _peak_mb(),
        "fast_peak_mb": fast_peak, "observations": len(belief.observations), "active": len(belief.active),
        "observed_scalars": len(belief.gp.targets_), "basis_rank": rank,
        "fast_method": belief.gp.fast_strategy(size, size, rank, rank, True, SAMPLES),
    }


def _in_fresh_process(func, *args):
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(1, maxtasksperchild=1) as pool:
        return pool.apply(func, args)


def _active_set_effect(scene_name: str) -> dict:
    """How much the active set changes the posterior near the true surface (cells within
    2 cells of it), against the fit on every reading with every gradient."""
    from dataclasses import replace

    from harness.belief import fit_belief, observe_scene
    from harness.scene import load_scene
    from harness.seeding import stream

    scene = load_scene(scene_name)
    obs = observe_scene(scene, stream(0, "bench", "active-set"))
    active = fit_belief(scene, obs)
    t0 = time.perf_counter()
    full = fit_belief(replace(scene, gpis=replace(scene.gpis, active_set=False)), obs)
    full_fit_s = time.perf_counter() - t0
    near = np.abs(scene.true_sdf) < 2 * scene.grid.cell
    dmean = np.abs(active.mean - full.mean)[near]
    ratio = np.sqrt(active.var[near] / full.var[near])
    err_full = np.abs(full.mean - scene.true_sdf)[near]
    return {
        "scene": scene_name, "M": scene.grid.size,
        "observed_scalars_full": len(full.gp.targets_), "observed_scalars_active": len(active.gp.targets_),
        "full_fit_s": full_fit_s,
        "mean_change_max_mm": float(dmean.max() * 1e3), "mean_change_p90_mm": float(np.percentile(dmean, 90) * 1e3),
        "std_ratio_median": float(np.median(ratio)), "std_ratio_max": float(ratio.max()),
        "full_error_vs_truth_p90_mm": float(np.percentile(err_full, 90) * 1e3),
    }


def _sampling_overrides(size: int, scene_name: str = SAMPLING_SCENE) -> dict:
    """Overrides that put a scene on an M x M grid while its physical quantities (SDF
    truncation, sensor noise and bands, GPIS hyperparameters) keep their values in metres
    at the scene's own grid; numerical settings given in cells (the active band) follow
    the grid. Sensor regions' parameters are not held (none of the benchmark scenes'
    regions has any given in cells)."""
    from harness.scene import load_scene

    native = load_scene(scene_name)
    sensor, gpis = native.sensor, native.gpis
    metres = lambda v: f"{v!r} m"  # noqa: E731
    return {"grid": {"size": size, "truncation": metres(native.truncation)},
            "sensor": {"noise": metres(sensor.noise), "surface_band": metres(sensor.surface_band),
                       "interior_depth": metres(sensor.interior_depth)},
            "gpis": {"lengthscale": metres(gpis.lengthscale), "scale": f"{gpis.scale!r} m^2",
                     "prior_mean": metres(gpis.prior_mean)}}


def sampling(sizes=SAMPLING_SIZES, exact_max_mb: float = 2500.0, scene: str = SAMPLING_SCENE) -> dict:
    """Fit and sampling times over grid sizes, the exact/fast ratio at M = 55 and the
    growth exponent of the fast sampler."""
    from harness.scene import load_scene

    for m in sizes:  # every size must make a valid scene, before any work
        load_scene(scene, overrides=_sampling_overrides(m))
    rows = [_in_fresh_process(_sampling_row, scene, m, exact_max_mb) for m in sizes]
    ms = np.array([r["M"] for r in rows], dtype=float)
    fast = np.array([r["fast_s"] for r in rows])
    exponent = float(np.polyfit(np.log(ms), np.log(fast), 1)[0]) if len(rows) > 1 else None
    at55 = next((r for r in rows if r["M"] == 55 and r["exact_s"] is not None), None)
    return {
        "scene": scene, "samples": SAMPLES, "rows": rows,
        "ratio_exact_over_fast_at_55": at55["exact_s"] / at55["fast_s"] if at55 else None,
        "fast_growth_exponent": exponent,
        "active_set_effect": _in_fresh_process(_active_set_effect, scene),
    }


#: Grid sizes of the P_F timing.
PLANNING_SIZES = (25, 50, 100, 200)
PF_REPEATS = 15


def _p_f_row(scene_name: str, size: int) -> dict:
    """One grid size, in a fresh process: draw the evaluation once, then time one P_F
    estimate with 1000 paired draws (best of PF_REPEATS after a warm-up)."""
    from harness.belief import build_belief
    from harness.grasp import Grasp
    from harness.quality import default_streams, draw_evaluation, estimate_p_f
    from harness.scene import load_scene
    from harness.seeding import stream
    from harness.settings import resolve

    scene = load_scene(scene_name, overrides=_sampling_overrides(size))
    belief = build_belief(scene, stream(0, "bench", size, "sensor"))
    t0 = time.perf_counter()
    draws = draw_evaluation(belief, SAMPLES, *default_streams(0, "bench", size))
    draws.shapes.twist, draws.shapes.regions  # noqa: B018  (set-up counted here)
    draws_s = time.perf_counter() - t0
    grasp = Grasp.from_centre((0.0, 0.0), 0.3, 0.09)
    settings = resolve(scene)
    estimate = estimate_p_f(grasp, draws, settings)[0]
    best = {False: math.inf, True: math.inf}
    for _ in range(PF_REPEATS):
        for lift in (False, True):  # interleaved, so both meet the same load on the machine
            t0 = time.perf_counter()
            estimate_p_f(grasp, draws, settings, lift=lift)
            best[lift] = min(best[lift], time.perf_counter() - t0)
    return {"M": size, "p_f_s": best[False], "p_l_s": best[True], "p_l_over_p_f": best[True] / best[False],
            "draws_s": draws_s, "p_f": estimate.p_f, "p_l": estimate.p_l, "peak_mb": _peak_mb()}


def _planner_row(scene_name: str, size: int) -> dict:
    """Seconds per SCP initialisation of gp-gpis-opt and per candidate of gp-p (1000
    draws), belief already built (its grid fields too), each the best of 3 plans."""
    from harness.belief import build_belief
    from harness.scene import load_scene
    from harness.seeding import stream
    from planners.base import Problem
    from planners.registry import make_planner

    scene = load_scene(scene_name, overrides=_sampling_overrides(size, scene_name))
    belief = build_belief(scene, stream(0, "bench", size, "sensor")).prepare()
    problem = Problem.for_belief(belief)
    out = {"M": size}
    for name, per in (("gp-gpis-opt", "initialisations"), ("gp-p", "candidates")):
        planner = make_planner(name)
        best = math.inf
        for r in range(3):
            t0 = time.perf_counter()
            planner.plan(problem, stream(0, "bench", size, name, r))
            best = min(best, time.perf_counter() - t0)
        out[name] = best / getattr(planner, per)
    return out


def planning(sizes=PLANNING_SIZES, scene: str = SAMPLING_SCENE, seeds: int | None = None, scenes=None,
             candidates: int | None = None, first_seed: int = 0, shared_draws=(), prior_draws=()) -> dict:
    """Seconds per P_F and per P_L estimate (1000 paired draws), per SCP initialisation and
    per GP-P candidate over grid sizes, with their growth; the convergence study; gp-gpis-opt
    against gp-p, both planning for the lift, over the library; and the bandit study
    (:func:`bandit`; ``seeds``, ``scenes``, ``candidates``, ``first_seed``,
    ``shared_draws`` and ``prior_draws`` as there; ``seeds = 0`` skips it)."""
    from harness.scene import library_names, load_scene

    study_names = _bandit_scenes(scenes)
    for m in sizes:
        load_scene(scene, overrides=_sampling_overrides(m))
        load_scene(PLANNER_SCENE, overrides=_sampling_overrides(m, PLANNER_SCENE))
    rows = [_in_fresh_process(_p_f_row, scene, m) for m in sizes]
    planners = [_in_fresh_process(_planner_row, PLANNER_SCENE, m) for m in sizes]
    lift_rows = [_in_fresh_process(_quality_scene, name, LIFT_PLANNERS, "p_l", LIFT_SEEDS)
                 for name in library_names()]
    convergence = [_in_fresh_process(_convergence, seed) for seed in range(CONVERGENCE_SEEDS)]
    ms = np.array([r["M"] for r in rows], dtype=float)

    def growth(values):
        return float(np.polyfit(np.log(ms), np.log(values), 1)[0]) if len(rows) > 1 else None

    at50 = next((r["p_f_s"] for r in rows if r["M"] == 50), None)
    ratio50 = next((r["p_l_over_p_f"] for r in rows if r["M"] == 50), None)
    scp = {str(r["M"]): r["gp-gpis-opt"] for r in planners}
    gpp = {str(r["M"]): r["gp-p"] for r in planners}
    return {"scene": scene, "draws": SAMPLES, "grasp": "through the centre at 0.3 rad, width 0.09 m",
            "rows": rows, "p_f_s_at_50": at50, "p_l_over_p_f_at_50": ratio50,
            "p_f_growth_exponent": growth([r["p_f_s"] for r in rows]),
            "planner_scene": PLANNER_SCENE, "scp_s_per_init": scp, "gpp_s_per_candidate": gpp,
            "scp_over_gpp": {m: scp[m] / gpp[m] for m in scp},
            "scp_growth_exponent": growth(list(scp.values())), **_convergence_summary(convergence),
            "lift_planners": _lift_summary(lift_rows),
            "bandit": bandit(seeds, study_names, candidates, first_seed, shared_draws, prior_draws)}


def _bandit_scenes(scenes) -> list[str]:
    """The bandit study's scenes, each checked (InputError for an unknown one) before any work."""
    from harness.bench import bandit_study

    names = list(scenes) if scenes is not None else bandit_study.study_scenes()
    for name in names:
        bandit_study.scene_of(name)
    return names


def bandit(seeds: int | None = None, scenes=None, candidates: int | None = None, first_seed: int = 0,
           shared_draws=(), prior_draws=()) -> dict:
    """The bandit convergence study (harness/bench/bandit_study.py): per scene (one process
    each) and seed, every gp-bandit policy's best grasp before any draw and after every
    round judged on 1000 evaluation draws against gp-p's choice; the draws (from 0) and
    seconds to within 1 % and 3 %, and the default planners' plan times. ``seeds``
    (default 3; 0 skips the study), ``scenes`` (default: the library and the shared
    outlines) and ``candidates`` (the arms of every run; default 100, gp-p's) set its
    size; the seeds are first_seed, first_seed + 1, ... (another first seed gives
    held-out runs). ``shared_draws`` and ``prior_draws`` add Thompson sampling with each
    of these values of shared evidence and of the model prior's weight (sensitivity
    studies)."""
    from harness.bench import bandit_study

    seeds = bandit_study.SEEDS if seeds is None else seeds
    candidates = bandit_study.CANDIDATES if candidates is None else int(candidates)
    shared_draws = [float(v) for v in shared_draws]
    prior_draws = [float(v) for v in prior_draws]
    names = _bandit_scenes(scenes)
    head = {"seeds": seeds, "first_seed": first_seed, "scenes": names, "candidates": candidates,
            "shared_draws": shared_draws, "prior_draws": prior_draws}
    if seeds == 0 or not names:
        return {**head, "runs": [], "summary": None}
    runs = [run for name in names
            for run in _in_fresh_process(bandit_study.scene_runs, name, seeds, candidates, first_seed, shared_draws,
                                         prior_draws)]
    return {**head, "tolerances": list(bandit_study.TOLERANCES), "adaptive_budget": bandit_study.ADAPTIVE_BUDGET,
            "runs": runs, "summary": bandit_study.summarise(runs)}


def _lift_summary(rows: list[dict]) -> dict:
    """gp-gpis-opt with the lift against gp-p with the lift over the library: mean P_L
    and mean plan time of each, and their ratios."""
    gpp, opt = (label for label, _, _ in LIFT_PLANNERS)
    p_l = {label: float(np.mean([np.mean(r["p_l"][label]) for r in rows])) for label in (opt, gpp)}
    seconds = {label: float(np.mean([np.mean(r["plan_s"][label]) for r in rows])) for label in (opt, gpp)}
    return {"seeds": LIFT_SEEDS, "rows": rows, "mean_p_l": p_l, "mean_plan_s": seconds,
            "p_l_ratio": p_l[opt] / p_l[gpp], "time_ratio": seconds[opt] / seconds[gpp]}


#: Scene of the planner timings (tilted, partly hidden: the optimiser has work to do).
PLANNER_SCENE = "marker"
#: The supplement's Fig. 1 object, at its own grid.
CONVERGENCE_SCENE = "plane"
CONVERGENCE_SEEDS = 3
CONVERGENCE_INITS = (1, 2, 3, 5, 10)


def _convergence(seed: int) -> dict:
    """The supplement's Fig. 1 on the toy plane (sigma_g = 1.5 cells, friction 0.4): the
    analytic P_F (1000 evaluation draws) of the best grasp so far against candidates for
    gp-p (its 100 candidates, in chunks of 10) and against initialisations for
    gp-gpis-opt (separate runs with 1, 2, 3, 5, 10), with the seconds each took."""
    from harness.belief import build_belief
    from harness.quality import default_streams, draw_evaluation, estimate_p_f
    from harness.scene import load_scene
    from harness.seeding import stream
    from harness.settings import resolve
    from planners.base import Problem
    from planners.gp_gpis_opt import GPGPISOpt
    from planners.gp_p import GPP

    scene = load_scene(CONVERGENCE_SCENE)
    settings = resolve(scene, {"sigma_g": 1.5 * scene.grid.cell, "friction": 0.4})
    belief = build_belief(scene, stream(seed, "convergence", "sensor")).prepare()
    problem = Problem(belief, settings)
    evaluation = draw_evaluation(belief, SAMPLES, *default_streams(seed, "convergence-evaluation"))

    def p_f(grasps):
        return [e.p_f for e in estimate_p_f(grasps, evaluation, settings)]

    record: list = []
    GPP().plan(problem, stream(seed, "convergence", "gp-p"), record=record)
    best_value, best_grasp, gpp = -np.inf, None, []
    for seconds, grasps, values in record:
        k = int(np.argmax(values))
        if values[k] > best_value:
            best_value, best_grasp = values[k], grasps[k]
        gpp.append((seconds, sum(len(r[1]) for r in record[: len(gpp) + 1]), p_f(best_grasp[None])[0]))
    opt = []
    for inits in CONVERGENCE_INITS:
        t0 = time.perf_counter()
        plan = GPGPISOpt(initialisations=inits).plan(problem, stream(seed, "convergence", "gp-gpis-opt", inits))
        opt.append((time.perf_counter() - t0, inits, p_f(plan.grasp)[0]))
    return {"seed": seed, "gp-p": gpp, "gp-gpis-opt": opt}


def _convergence_summary(runs: list) -> dict:
    """Per seed, the seconds each planner needs to reach 95 % of gp-p's best-of-100 (its
    final P_F): gp-p from its chunks, gp-gpis-opt from the smallest number of
    initialisations that reaches it. The speed-up is the ratio of the mean times."""
    t_gpp, t_opt = [], []
    for run in runs:
        target = 0.95 * run["gp-p"][-1][2]
        t_gpp.append(next(t for t, _, p in run["gp-p"] if p >= target))
        t_opt.append(next((t for t, _, p in run["gp-gpis-opt"] if p >= target), np.nan))
    final = {"gp-p": float(np.mean([r["gp-p"][-1][2] for r in runs])),
             "gp-gpis-opt": float(np.mean([r["gp-gpis-opt"][-1][2] for r in runs]))}
    return {"scene": CONVERGENCE_SCENE, "convergence": runs, "seconds_to_95pct": {"gp-p": t_gpp, "gp-gpis-opt": t_opt},
            "speedup_to_95pct": float(np.mean(t_gpp) / np.mean(t_opt)) if np.all(np.isfinite(t_opt)) else None,
            "final_p_f": final}


QUALITY_SEEDS = 5
QUALITY_PLANNERS = ("mean-shape", "gp-p", "gp-gpis-opt")
#: The lift variants compared in ``bench planning`` (label, registry name, parameters).
LIFT_PLANNERS = (("gp-p-lift", "gp-p", {"quality": "lift"}), ("gp-gpis-opt-lift", "gp-gpis-opt", {"quality": "lift"}))
LIFT_SEEDS = 3
#: A scene has heavy uncertainty when at least this fraction of its mean surface has a
#: posterior std above half a cell (seed 0's belief).
HEAVY_FRACTION = 0.10


def _quality_scene(name: str, variants=tuple((p, p, {}) for p in QUALITY_PLANNERS), metric: str = "p_f",
                   seeds: int = QUALITY_SEEDS) -> dict:
    """Analytic P_F, or P_L (``metric``; 1000 evaluation draws, the scene's settings), and
    plan time of each planner variant's grasp (label, registry name, parameters) on one
    scene, for ``seeds`` independent sensor readings."""
    from harness.belief import build_belief
    from harness.quality import default_streams, draw_evaluation, estimate_p_f
    from harness.scene import load_scene
    from harness.seeding import stream
    from planners.base import Problem
    from planners.registry import make_planner

    scene = load_scene(name)
    out = {"scene": name, metric: {v[0]: [] for v in variants}, "plan_s": {v[0]: [] for v in variants}}
    for seed in range(seeds):
        belief = build_belief(scene, stream(seed, name, 0, "sensor")).prepare()
        if seed == 0:
            out["uncertain_fraction"] = float(np.mean(belief.surface_std() > 0.5 * scene.grid.cell))
        problem = Problem.for_belief(belief)
        draws = draw_evaluation(belief, SAMPLES, *default_streams(seed, name))
        for label, pname, params in variants:
            planner = make_planner(pname, params)
            t0 = time.perf_counter()
            plan = planner.plan(problem, stream(seed, name, 0, "planner", label))
            out["plan_s"][label].append(time.perf_counter() - t0)
            value = getattr(estimate_p_f(plan.grasp, draws, problem.settings)[0], metric) if plan.grasp else 0.0
            out[metric][label].append(value)
    out["heavy"] = out["uncertain_fraction"] >= HEAVY_FRACTION
    return out


def quality(scenes=None) -> dict:
    """Mean analytic P_F of each planner per library scene over QUALITY_SEEDS seeds, and
    the means over all scenes and over the scenes with heavy uncertainty."""
    from harness.scene import library_names

    rows = [_in_fresh_process(_quality_scene, name) for name in (scenes or library_names())]
    mean = {p: float(np.mean([np.mean(r["p_f"][p]) for r in rows])) for p in QUALITY_PLANNERS}
    heavy = [r for r in rows if r["heavy"]]
    heavy_mean = {p: float(np.mean([np.mean(r["p_f"][p]) for r in heavy])) if heavy else None
                  for p in QUALITY_PLANNERS}
    return {"seeds": QUALITY_SEEDS, "rows": rows, "mean_p_f": mean, "heavy_scenes": [r["scene"] for r in heavy],
            "heavy_mean_p_f": heavy_mean}


#: Candidate grasps per library scene in the physics benchmark (two trials each).
PHYSICS_GRASPS_PER_SCENE = 12


def physics(grasps_per_scene: int = PHYSICS_GRASPS_PER_SCENE, seed: int = 0) -> dict:
    """Trials per second of Bullet's batched runner and of a naive one (a new world per
    trial, no early stop) on the same trials, and the outcome agreement with a 4x finer
    step; the same for MuJoCo on the same trials in the same run (its trials per second
    over Bullet's batched runner, its agreement with its own 4x finer step and with
    Bullet, trial by trial)."""
    from harness.physics.simulate import outcome_counts
    from harness.bench.physics_study import agreement, confusion, library_trials, run_batched, run_naive
    from harness.protocol import Protocol

    trials = library_trials(grasps_per_scene, seed).trials
    protocol = Protocol()
    batched = run_batched(trials, protocol)
    naive = run_naive(trials, protocol)
    fine = run_batched(trials, protocol.finer(4))
    mj = Protocol.of("mujoco")
    mujoco, mujoco_fine = run_batched(trials, mj), run_batched(trials, mj.finer(4))
    return {
        "mujoco": {"time_step": mj.time_step, "solver_iterations": mj.solver_iterations,
                   "trials_per_s": mujoco.rate, "over_pybullet": mujoco.rate / batched.rate,
                   "fine_step_agreement": agreement(mujoco.results, mujoco_fine.results),
                   "fine_step_disagreements": confusion(mujoco.results, mujoco_fine.results),
                   "agreement_with_pybullet": agreement(mujoco.results, batched.results),
                   "against_pybullet": confusion(batched.results, mujoco.results),
                   "outcomes": outcome_counts(mujoco.results),
                   "outcomes_fine_step": outcome_counts(mujoco_fine.results),
                   "seconds": {"batched": mujoco.seconds, "fine_step": mujoco_fine.seconds}},
        "trials": len(trials), "time_step": protocol.time_step, "solver_iterations": protocol.solver_iterations,
        "batched_trials_per_s": batched.rate, "naive_trials_per_s": naive.rate, "speedup": batched.rate / naive.rate,
        "fine_step_agreement": agreement(batched.results, fine.results),
        "fine_step_disagreements": confusion(batched.results, fine.results),
        "naive_agreement": agreement(batched.results, naive.results),
        "outcomes": outcome_counts(batched.results), "outcomes_fine_step": outcome_counts(fine.results),
        "seconds": {"batched": batched.seconds, "naive": naive.seconds, "fine_step": fine.seconds},
    }


def lift(trials: int = 16, seed: int = 0) -> dict:
    """The lift model against the physics: the bar sweeps (where P_L and simulated success
    fall through 0.5) and the friction levers of Bullet's contact manifolds on the
    library trial set (harness.bench.lift_study); the bar sweeps again in MuJoCo."""
    from harness.bench.lift_study import manifold_levers, validate

    return {**validate(trials=trials, seed=seed), "manifold_levers": manifold_levers(seed=seed),
            "mujoco": validate(trials=trials, seed=seed, engine="mujoco")}


def run(which: str = "all", exact_max_mb: float = 2500.0, sizes=None, seeds: int | None = None, scenes=None,
        candidates: int | None = None, first_seed: int = 0, shared_draws=(), prior_draws=(),
        out: str = "results/engines", workers: int | None = None) -> dict:
    """Run the named benchmark(s); returns a JSON-ready dict. ``seeds``, ``scenes``,
    ``candidates``, ``first_seed``, ``shared_draws`` and ``prior_draws`` set the bandit
    study (``bandit``, and inside ``planning``; see :func:`bandit`); ``out`` and
    ``workers`` the engines study (``engines``, not part of ``all``: it runs make eval's
    experiment twice)."""
    results = {}
    if which == "engines":
        import sys

        from harness.bench import engines_study

        return engines_study.run(out=Path(out), workers=workers,
                                 log=lambda line: print(line, file=sys.stderr, flush=True))
    if which in ("sampling", "all"):
        results["sampling"] = sampling(tuple(sizes or SAMPLING_SIZES), exact_max_mb)
    if which in ("planning", "all"):
        results["planning"] = planning(tuple(sizes or PLANNING_SIZES), seeds=seeds, scenes=scenes,
                                        candidates=candidates, first_seed=first_seed, shared_draws=shared_draws,
                                        prior_draws=prior_draws)
    if which == "bandit":
        results["bandit"] = bandit(seeds, scenes, candidates, first_seed, shared_draws, prior_draws)
    if which in ("quality", "all"):
        results["quality"] = quality()
    if which in ("physics", "all"):
        results["physics"] = physics()
    if which in ("lift", "all"):
        results["lift"] = lift()
    return results[which] if which != "all" else results


def format_results(results: dict) -> str:
    """A human-readable table of benchmark results."""
    if "speedup" in results:
        results = {"physics": results}
    elif "manifold_levers" in results:
        results = {"lift": results}
    elif "tolerances" in results or "summary" in results:
        results = {"bandit": results}
    elif "rows" in results:
        kind = ("sampling" if "active_set_effect" in results else "quality" if "heavy_scenes" in results
                else "planning")
        results = {kind: results}
    if "cell_rms" in results:
        from harness.bench.engines_study import format_lines

        return "\n".join(format_lines(results))
    lines = []
    for name, res in results.items():
        if name == "lift":
            lines += _lift_lines(res)
        if name == "bandit":
            lines += _bandit_lines(res)
        if name == "physics":
            lines.append(f"physics: {res['trials']} trials from the library scenes, step {res['time_step']:.6g} s, "
                         f"{res['solver_iterations']} solver iterations")
            lines.append(f"batched {res['batched_trials_per_s']:.2f} trials/s, naive (a new world per trial) "
                         f"{res['naive_trials_per_s']:.2f} trials/s: speedup {res['speedup']:.2f}")
            lines.append(f"agreement with a 4x finer step: {res['fine_step_agreement']:.3f}; "
                         f"differences: {res['fine_step_disagreements'] or 'none'}")
            lines.append("outcomes: " + ", ".join(f"{k} {v}" for k, v in res["outcomes"].items() if v))
            mj = res["mujoco"]
            lines.append(f"MuJoCo, the same trials: step {mj['time_step']:.6g} s, {mj['solver_iterations']} "
                         f"iterations, {mj['trials_per_s']:.2f} trials/s, {mj['over_pybullet']:.2f}x Bullet's batched "
                         f"runner; agreement with a 4x finer step {mj['fine_step_agreement']:.3f}, with Bullet "
                         f"{mj['agreement_with_pybullet']:.3f}")
            lines.append("MuJoCo outcomes: " + ", ".join(f"{k} {v}" for k, v in mj["outcomes"].items() if v)
                         + "; Bullet -> MuJoCo: " + (", ".join(f"{k} {v}" for k, v in mj["against_pybullet"].items())
                                                      or "no difference"))
        if name == "quality":
            lines.append(f"quality: mean analytic P_F over {res['seeds']} seeds (scene sigma_g and friction)")
            lines.append(f"{'scene':<15}" + "".join(f"{p:>13}" for p in QUALITY_PLANNERS) + "  heavy")
            for r in res["rows"]:
                lines.append(f"{r['scene']:<15}" + "".join(f"{np.mean(r['p_f'][p]):>13.3f}" for p in QUALITY_PLANNERS)
                             + f"  {'yes' if r['heavy'] else ''}")
            lines.append(f"{'mean':<15}" + "".join(f"{res['mean_p_f'][p]:>13.3f}" for p in QUALITY_PLANNERS))
            if res["heavy_scenes"]:
                lines.append(f"{'heavy mean':<15}" + "".join(f"{res['heavy_mean_p_f'][p]:>13.3f}"
                                                             for p in QUALITY_PLANNERS))
        if name == "planning":
            lines.append(f"planning: one P_F estimate and one P_L estimate (P_F and the lift) with {res['draws']} "
                         f"paired draws, scene '{res['scene']}', grasp {res['grasp']}")
            lines.append(f"{'M':>5} {'P_F ms':>8} {'P_L ms':>8} {'ratio':>6} {'draws s':>8} {'P_F':>6} {'P_L':>6} "
                         f"{'peak MB':>8}")
            for r in res["rows"]:
                lines.append(f"{r['M']:>5} {r['p_f_s'] * 1e3:>8.2f} {r['p_l_s'] * 1e3:>8.2f} {r['p_l_over_p_f']:>6.2f} "
                             f"{r['draws_s']:>8.2f} {r['p_f']:>6.3f} {r['p_l']:>6.3f} {r['peak_mb']:>8.0f}")
            if res["p_f_s_at_50"] is not None:
                lines.append(f"P_F estimate at M = 50: {res['p_f_s_at_50'] * 1e3:.2f} ms (the original: 1.1 to 2.5 s); "
                             f"P_L / P_F {res['p_l_over_p_f_at_50']:.2f}")
            if res["p_f_growth_exponent"] is not None:
                lines.append(f"P_F growth exponent (log time vs log M): {res['p_f_growth_exponent']:.2f}")
            lines.append(f"{'M':>5} {'SCP ms/init':>12} {'GP-P ms/cand':>13} {'ratio':>6}")
            for m, v in res["scp_s_per_init"].items():
                lines.append(f"{m:>5} {v * 1e3:>12.2f} {res['gpp_s_per_candidate'][m] * 1e3:>13.2f} "
                             f"{res['scp_over_gpp'][m]:>6.2f}")
            if res["scp_growth_exponent"] is not None:
                lines.append(f"SCP growth exponent: {res['scp_growth_exponent']:.2f}")
            t = res["seconds_to_95pct"]
            lines.append(f"convergence on the {CONVERGENCE_SCENE} (sigma_g 1.5 cells, friction 0.4), mean of "
                         f"{len(res['convergence'])} seeds: seconds to 95 % of gp-p's best-of-100: gp-p "
                         f"{np.mean(t['gp-p']):.3f}, gp-gpis-opt {np.nanmean(t['gp-gpis-opt']):.3f}; speed-up "
                         f"{res['speedup_to_95pct'] if res['speedup_to_95pct'] is None else round(res['speedup_to_95pct'], 1)}")
            lines.append("final P_F: " + ", ".join(f"{k} {v:.3f}" for k, v in res["final_p_f"].items()))
            lift = res["lift_planners"]
            lines.append(f"lift planners over the library ({lift['seeds']} seeds, P_L on 1000 evaluation draws): "
                         + ", ".join(f"{k} P_L {v:.3f} in {lift['mean_plan_s'][k]:.3f} s"
                                     for k, v in lift["mean_p_l"].items())
                         + f"; gp-gpis-opt-lift / gp-p-lift: P_L {lift['p_l_ratio']:.3f}, "
                           f"time {lift['time_ratio']:.3f}")
            if res.get("bandit"):
                lines += _bandit_lines(res["bandit"])
        if name == "sampling":
            lines.append(f"sampling: {res['samples']} grid samples (values + gradients), scene '{res['scene']}'")
            lines.append(f"{'M':>5} {'fit s':>8} {'fast s':>8} {'exact s':>9} {'peak MB':>9} {'D':>6} {'r':>4}  method")
            for r in res["rows"]:
                exact = f"{r['exact_s']:.2f}" if r["exact_s"] is not None else "-"
                lines.append(f"{r['M']:>5} {r['fit_s']:>8.3f} {r['fast_s']:>8.3f} {exact:>9} {r['peak_mb']:>9.0f} "
                             f"{r['observed_scalars']:>6} {r['basis_rank']:>4}  {r['fast_method']}")
            ratio = res["ratio_exact_over_fast_at_55"]
            lines.append(f"exact / fast at M = 55: {ratio:.0f}" if ratio else "exact / fast at M = 55: not measured")
            exp = res["fast_growth_exponent"]
            lines.append(f"fast growth exponent (log time vs log M): {exp:.2f}" if exp is not None else "")
            a = res["active_set_effect"]
            lines.append(
                f"active set at M = {a['M']}: {a['observed_scalars_active']} of {a['observed_scalars_full']} observed "
                f"scalars; near the surface the mean moves {a['mean_change_p90_mm']:.3f} mm (90th pct, max "
                f"{a['mean_change_max_mm']:.3f}), std ratio {a['std_ratio_median']:.3f} (max {a['std_ratio_max']:.3f}); "
                f"the full fit's own error vs truth: {a['full_error_vs_truth_p90_mm']:.3f} mm (90th pct)")
    return "\n".join(lines)


def _bandit_lines(res: dict) -> list[str]:
    from harness.bench import bandit_study

    summary = res.get("summary")
    if not summary:
        return ["bandit study: skipped (no seeds or no scenes)"]

    def num(v, fmt):
        return "never" if v is None else format(v, fmt)

    first = res.get("first_seed", 0)
    seeds = f"seeds {first} to {first + res['seeds'] - 1}" if res["seeds"] > 1 else f"seed {first}"
    width = max([15] + [len(policy) + 2 for policy in summary["policies"]])
    scenes = f"{len(res['scenes'])} scene{'' if len(res['scenes']) == 1 else 's'}"

    def times(v):  # a ratio; None: infinite (uniform never within, or the policy from 0 draws) or undefined
        return "inf" if v is None else f"{v:.1f}x" if v >= 0.1 else f"{v:.2f}x"

    lines = [f"bandit study: {summary['runs']} runs ({scenes} x {seeds}, "
             f"{res.get('candidates', 100)} candidates each); the best "
             f"grasp before any draw (0 draws) and after every round judged on 1000 evaluation draws against "
             f"gp-p's choice. Draws (and seconds) until it stays within 1 % / 3 %: median and 90th percentile over "
             f"runs (never: not within the run's draws), the median of uniform's over the policy's per run, and "
             f"the share of runs within before any draw and after 1000 draws",
             f"{'policy':<{width}}{'median':>14}{'p90':>16}{'seconds':>15}{'uniform/pol':>15}{'at 0':>11}"
             f"{'at 1000':>11}{'pull/draw':>10}{'judging':>9}{'plan s':>8}"]
    for policy, row in summary["policies"].items():
        one, three = row["1pct"], row["3pct"]

        def pair(key, fmt, row1=one, row3=three):
            return f"{num(row1[key], fmt)} / {num(row3[key], fmt)}"

        def share_at(budget, row1=one, row3=three):
            return f"{row1['within_after'].get(budget, math.nan):.2f}/{row3['within_after'].get(budget, math.nan):.2f}"

        ratios = " / ".join(times(r["median_uniform_over_policy_draws"]) for r in (one, three))
        lines.append(f"{policy:<{width}}{pair('median_draws', '.0f'):>14}{pair('p90_draws', '.0f'):>16}"
                     f"{pair('median_seconds', '.3f'):>15}{ratios:>15}{share_at('0'):>11}{share_at('1000'):>11}"
                     f"{num(row['pull_over_gp_p_draw'], '.2f'):>9}"
                     f"{num(row.get('judging_over_gp_p'), '.2f'):>9}{num(row['median_plan_s'], '.3f'):>8}")

    def interval(ci):
        return "[-]" if not ci else f"[{times(ci[0])}, {times(ci[1])}]"

    def share(v):
        return "n/a" if v is None else f"{v:.2f}"

    if all("uniform_over_policy_of_medians" in row["3pct"] for row in summary["policies"].values()):
        lines.append("uniform's median draws over the policy's, 3 % / 1 %, with 95 % intervals (the scenes "
                     "resampled, a scene's seeds together):")
        for policy, row in summary["policies"].items():
            lines.append(f"  {policy:<{width}}" + " / ".join(
                f"{times(row[k]['uniform_over_policy_of_medians']['value'])} "
                f"{interval(row[k]['uniform_over_policy_of_medians']['ci95'])}" for k in ("3pct", "1pct")))
    model = summary.get("model")
    if model:
        lines.append(f"the model alone (the candidate of highest P~_F, before any draw), {model['runs']} runs: P_F "
                     f"{model['mean_over_target']:.3f} of the target on average; within 1 % / 3 % in "
                     f"{model['within']['1pct']:.2f} / {model['within']['3pct']:.2f} of the runs")
    within = summary.get("candidates_within") or {}
    lines.append(f"candidates within 3 % / 1 % of the best, by gp-p's estimates (median share over runs): "
                 f"{share(within.get('3pct'))} / {share(within.get('1pct'))}. Draws count from 0, the answer "
                 f"before any draw; a ratio is inf where uniform never gets within, or where the policy is within "
                 f"from 0 draws and uniform is not")
    for group, part in summary.get("by_scenes", {}).items():
        within = part.get("candidates_within") or {}
        lines.append(f"{group} ({part['runs']} runs), draws to 3 % / 1 %, median, against uniform's "
                     f"(uniform's median over the policy's [95 % interval]; the median per-run ratio); candidates "
                     f"within {share(within.get('3pct'))} / {share(within.get('1pct'))}:")
        for policy, row in part["policies"].items():
            cells = []
            for key in ("3pct", "1pct"):
                c = row[key]
                mine, theirs = c["median_draws"], c["uniform_median_draws"]
                ratio = math.nan if mine is None or theirs is None else bandit_study._ratio(theirs, mine)
                over = "-" if math.isnan(ratio) else times(ratio if math.isfinite(ratio) else None)
                ci = " " + interval(c["uniform_over_policy_of_medians"]["ci95"]) \
                    if "uniform_over_policy_of_medians" in c else ""
                cells.append(f"{num(mine, '.0f')} vs {num(theirs, '.0f')} ({over}{ci}; "
                             f"{times(c['median_uniform_over_policy_draws'])})")
            lines.append(f"  {policy:<{width}}" + " / ".join(cells))
    lines.append(f"uniform made gp-p's choice in {summary['uniform_is_gp_p']} of {summary['runs']} runs; "
                 f"pull/draw: seconds per pull over gp-p's per draw, shape samples included; judging: "
                 f"without them")
    lines.append("library scenes, default parameters: " + ", ".join(
        f"{k} P_F {v['mean_p_f']:.3f} in {num(v['median_plan_s'], '.3f')} s (median; mean {v['mean_plan_s']:.3f})"
        for k, v in summary["library_defaults"].items() if v["runs"]))
    return lines


def _lift_lines(res: dict) -> list[str]:
    lines = _bar_lines(res)
    m = res["manifold_levers"]
    q = m["quartiles"]
    lines.append(f"Bullet's manifold levers on {m['plates']} plates of the library trial set, as fractions of the "
                 f"largest admissible lever: quartiles {q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f} (uniform: 0.25 / 0.50 / "
                 f"0.75), {m['single_point']:.0%} held by one point, {m['beyond_largest']:.1%} beyond the largest")
    if "mujoco" in res:
        lines += ["", "the same bars in MuJoCo:", *_bar_lines(res["mujoco"])]
    return lines


def _bar_lines(res: dict) -> list[str]:
    def at(v):
        return "never" if v is None else f"{v * 1e3:.1f}"

    def err(v):
        return "-" if v is None else f"{v:+.0%}"

    lines = [f"lift: bars gripped across their width, offsets from the centre of mass every "
             f"{res['rows'][0]['points'][1]['offset'] * 1e3:.0f} mm, {res['trials_per_offset']} trials and "
             f"{res['analytic_draws']} analytic draws per offset, sigma_g {res['sigma_g'] * 1e3:g} mm; offsets (mm) "
             f"where P_L and success fall through 0.5, and where half the draws turn in the model and in the "
             f"simulation; 'held at': the median angle of the turned trials that ended held",
             f"{'bar':<44} {'P_L':>6} {'success':>8} {'error':>6} {'turns':>6} {'turned':>7} {'error':>6}"
             f"  {'held at':>7}  failures"]
    for r in res["rows"]:
        held = "-" if r["held_turn_median"] is None else f"{r['held_turn_median']:.2f} rad"
        fails = ", ".join(f"{k} {v}" for k, v in sorted(r["failures"].items())) or "none"
        lines.append(f"{r['bar']:<44} {at(r['p_l_at']):>6} {at(r['success_at']):>8} {err(r['error']):>6} "
                     f"{at(r['model_turning_at']):>6} {at(r['turning_at']):>7} {err(r['turning_error']):>6}"
                     f"  {held:>7}  {fails}")
    largest = res["largest_error"]
    lines.append(f"largest relative error: P_L vs success {err(largest)}, the model's turning vs the "
                 f"simulation's {err(res['largest_turning_error'])}"
                 + (f"; {res['missing']} rows without a crossing on one side" if res["missing"] else ""))
    return lines
