"""The bandit convergence study (``bench bandit``, part of ``bench planning``): how many
draws, and how many seconds, each gp-bandit policy needs before its chosen grasp is within
1 % and 3 % of the best candidate's P_F, against uniform allocation and iterative pruning,
like Laskey et al. (CASE 2015), over the library scenes and the shared outlines.

One run is one scene and seed: one belief, the planners' stream shared by gp-p and every
policy (so all judge the same candidates on the same pool of draws), and 1000 evaluation
draws of the study's own, on which the best grasp before any draw (the answer of the
prior alone) and after every round is judged. The target is the P_F of gp-p's choice
(every candidate on all its draws), which uniform allocation reaches exactly when its
budget covers every candidate's draws.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from shapely.geometry import Polygon

from harness.bench.common import in_fresh_process
from harness.belief import build_belief
from harness.errors import InputError
from harness.quality import default_streams, draw_evaluation, estimate_p_f
from harness.scene import Scene, library_names, load_scene, parse_scene
from harness.seeding import stream
from planners.allocation import PRIOR_DRAWS
from planners.base import Problem
from planners.gp_bandit import GPBandit
from planners.gp_p import GPP
from planners.registry import make_planner

#: The shared outlines beside the repository (../shared/objects), when present.
SHARED_OBJECTS = Path(__file__).resolve().parents[3] / "shared" / "objects"
SEEDS = 3
#: Candidates (arms) per run: gp-p's default; ``bench bandit --candidates 1000`` is Laskey
#: et al.'s count.
CANDIDATES = 100
TOLERANCES = (0.01, 0.03)
#: The study's allocations, label: (gp-bandit's policy, its shared_draws, its
#: prior_draws; None: the default). "thompson" is gp-bandit's default, whose posteriors
#: start from the analytic model's prior and share evidence between overlapping
#: candidates; "thompson-no-model" shares evidence under the uniform prior;
#: "thompson-alone" judges every arm on its own draws under the uniform prior, as Laskey
#: et al.'s Thompson sampling did. "uniform-model" is uniform allocation answering with
#: the model's prior in its posteriors: what the model adds to the answer without
#: changing where the draws go.
ALLOCATIONS = {"thompson": ("thompson", None, None), "thompson-no-model": ("thompson", None, 0.0),
               "thompson-alone": ("thompson", 0.0, 0.0), "gittins": ("gittins", None, None),
               "ucb": ("ucb", None, None), "uniform": ("uniform", None, None),
               "uniform-model": ("uniform", None, PRIOR_DRAWS), "pruning": ("pruning", None, None)}
#: Labels of the extra Thompson sampling allocations of the sensitivity studies
#: (``--shared-draws``, ``--prior-draws``): ``thompson-shared-<value>`` and
#: ``thompson-prior-<value>``.
SHARED_PREFIX = "thompson-shared-"
PRIOR_PREFIX = "thompson-prior-"
#: Resamples of the scenes behind the 95 % intervals of the ratios of medians (a cluster
#: bootstrap: a scene's seeds stay together, as they share its outline and sensor).
BOOTSTRAP = 2000
#: Draws after which the study reports the share of runs within each tolerance (0: the
#: answer before any draw).
ANYTIME_BUDGETS = (0, 20, 250, 500, 1000, 2000, 5000)
EVALUATION_DRAWS = 1000
#: Budget (draws) of the adaptive policies; uniform and pruning may spend every
#: candidate's draws (uniform then makes gp-p's choice).
ADAPTIVE_BUDGET = 30_000
#: Planners compared with their default parameters (plan time, P_F).
DEFAULTS_COMPARED = ("gp-bandit", "gp-gpis-opt", "gp-p")
#: A shared outline is scaled so that it is at most this long and this wide (m), so
#: that it fits the gripper's 12 cm opening across its width, on a 40 x 40 grid of 5 mm.
OUTLINE_LENGTH = 0.16
OUTLINE_WIDTH = 0.08
#: ... and reaches at most this far from its centroid (the grid keeps 2 cells clear).
OUTLINE_REACH = 0.085


@dataclass(frozen=True)
class Settings:
    """The study's size: ``seeds`` per scene (0 skips the study), the first of them
    (another first seed gives held-out runs), the ``scenes`` (None: the library and the
    shared outlines), the ``candidates`` of every run; ``shared_draws`` and
    ``prior_draws`` add Thompson sampling with each of these values of shared evidence
    and of the model prior's weight (sensitivity studies)."""

    seeds: int = SEEDS
    scenes: tuple | None = None
    candidates: int = CANDIDATES
    first_seed: int = 0
    shared_draws: tuple = ()
    prior_draws: tuple = ()

    def names(self) -> list[str]:
        """The scenes, each checked (InputError for an unknown one) before any work."""
        names = list(self.scenes) if self.scenes is not None else study_scenes()
        for name in names:
            scene_of(name)
        return names


def allocations(shared_draws=(), prior_draws=()) -> dict:
    """The study's allocations (ALLOCATIONS), plus Thompson sampling with each of
    ``shared_draws`` (values of gp-bandit's ``shared_draws``), labelled SHARED_PREFIX and
    the value, and with each of ``prior_draws``, labelled PRIOR_PREFIX and the value (the
    other parameter at its default): sensitivity studies of shared evidence and of the
    model prior."""
    table = dict(ALLOCATIONS)
    for prefix, values in ((SHARED_PREFIX, shared_draws), (PRIOR_PREFIX, prior_draws)):
        for value in values:
            value = float(value) + 0.0  # -0.0 becomes 0.0, so that its label is "...-0"
            table[f"{prefix}{value:g}"] = ("thompson", value, None) if prefix == SHARED_PREFIX else \
                ("thompson", None, value)
    return table


def study_scenes() -> list[str]:
    """Names of the study's scenes: the library, then ``shared_<outline>`` for every
    outline in ../shared/objects (none when that folder is absent)."""
    shared = sorted(p.stem for p in SHARED_OBJECTS.glob("*.csv")) if SHARED_OBJECTS.is_dir() else []
    return library_names() + [f"shared_{name}" for name in shared]


def scene_of(name: str) -> Scene:
    """A library scene, or ``shared_<outline>``: the outline on a 40 x 40 grid of 5 mm,
    scaled to fit OUTLINE_LENGTH x OUTLINE_WIDTH, read with the sensor and gripper of
    examples/shared_objects/tape.toml."""
    if not name.startswith("shared_"):
        return load_scene(name)
    path = SHARED_OBJECTS / f"{name.removeprefix('shared_')}.csv"
    if not path.is_file():
        raise InputError("--scenes", None, f"no outline {path} for scene '{name}'")
    vertices = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    size = np.sort(vertices.max(axis=0) - vertices.min(axis=0))
    reach = np.linalg.norm(vertices - np.asarray(Polygon(vertices).centroid.coords[0]), axis=1).max()
    scale = min(OUTLINE_LENGTH / size[1], OUTLINE_WIDTH / size[0], OUTLINE_REACH / reach)
    data = {"name": name, "description": f"shared outline {path.stem}, scaled by {scale:.4g} m per unit",
            "grid": {"size": 40, "extent": 0.2},
            "shape": {"type": "outline", "path": str(path), "scale": scale, "center": "centroid"},
            "sensor": {"noise": "0.5 cells", "interior_keep": 0.1},
            "physics": {"thickness": 0.025, "density": 900.0, "friction": 0.5},
            "gripper": {"opening": 0.12, "jaw_width": 0.01}}
    return parse_scene(data, source=str(path), base_dir=path.parent, default_name=name)


def run(name: str, seed: int, candidates: int = CANDIDATES, samples: int = 1000, budget: int = ADAPTIVE_BUDGET,
        batch: int | None = None, policies=None, defaults: bool = True, shared_draws=(), prior_draws=()) -> dict:
    """One run: every allocation's curve (``policies``: labels of :func:`allocations` of
    ``shared_draws`` and ``prior_draws``, by default all of them; draws, seconds, P_F of
    its best grasp so far on the evaluation draws, kept before the first round (0 draws),
    at the rounds where that P_F changes and at the last), gp-p's plan time and choice,
    the target, the P_F of the model's best candidate (``model_p_f``: the answer before
    any draw, from the first allocation with the model prior), and (``defaults``) the
    default planners' plan times and P_F."""
    scene = scene_of(name)
    belief = build_belief(scene, stream(seed, scene.name, 0, "sensor")).prepare()
    problem = Problem.for_belief(belief)
    evaluation = draw_evaluation(belief, EVALUATION_DRAWS, *default_streams(seed, f"{scene.name}-bandit-evaluation"))
    judged: dict = {}

    def p_f(grasp) -> float:
        key = np.asarray(grasp, dtype=float).tobytes()
        if key not in judged:
            judged[key] = estimate_p_f(grasp[None], evaluation, problem.settings, lift=False)[0].p_f
        return judged[key]

    planner_stream = ("planner", "gp-bandit-study")
    t0 = time.perf_counter()
    chunks: list = []
    gpp = GPP(candidates=candidates, samples=samples).plan(problem, stream(seed, scene.name, 0, *planner_stream),
                                                           record=chunks)
    gpp_s = time.perf_counter() - t0
    out = {"scene": scene.name, "seed": seed, "gp_p_s": gpp_s, "gp_p_draws": gpp.evaluations * samples,
           "curves": {}, "plan_s": {}, "seconds": {}}
    if gpp.status != "ok":
        out["skipped"] = f"gp-p: {gpp.status}"
        return out
    out["target"] = p_f(gpp.grasp.array)
    # How many candidates are nearly as good as gp-p's choice, by gp-p's own estimates.
    pool_p_f = np.concatenate([values for _, _, values in chunks])
    out["share_within"] = {f"{round(tol * 100)}pct": float(np.mean(pool_p_f >= (1 - tol) * pool_p_f.max()))
                           for tol in TOLERANCES}
    if defaults:
        out["defaults"] = _defaults(problem, scene.name, seed, p_f)
    extra = {} if batch is None else {"batch": batch}
    table = allocations(shared_draws, prior_draws)
    for policy in table if policies is None else policies:
        name, shared, prior = table[policy]
        full = name in ("uniform", "pruning")
        planner = GPBandit(candidates=candidates, samples=samples, policy=name, shared_draws=shared,
                           prior_draws=prior, budget_draws=candidates * samples if full else budget, **extra)
        record: list = []
        t0 = time.perf_counter()
        plan = planner.plan(problem, stream(seed, scene.name, 0, *planner_stream), record=record)
        out["plan_s"][policy] = time.perf_counter() - t0
        out["seconds"][policy] = dict(plan.seconds)
        curve = [(draws, seconds, p_f(grasp)) for seconds, draws, grasp in record]
        out["curves"][policy] = [point for k, point in enumerate(curve)
                                 if k in (0, len(curve) - 1) or point[2] != curve[k - 1][2]]
        if planner.model_ is not None and "model_p_f" not in out:
            out["model_p_f"] = p_f(planner.grasps_[int(np.argmax(planner.model_))])
        if policy == "uniform":
            out["uniform_is_gp_p"] = bool(np.array_equal(record[-1][2], gpp.grasp.array)) if full else None
    return out


def _defaults(problem: Problem, scene: str, seed: int, p_f) -> dict:
    """Plan time and P_F (on the study's evaluation draws) of gp-bandit, gp-gpis-opt and
    gp-p with their default parameters and their own streams, as in ``make eval``."""
    out = {}
    for name in DEFAULTS_COMPARED:
        planner = make_planner(name)
        t0 = time.perf_counter()
        plan = planner.plan(problem, stream(seed, scene, 0, "planner", name))
        seconds = time.perf_counter() - t0
        out[name] = {"plan_s": seconds, "p_f": p_f(plan.grasp.array) if plan.grasp is not None else 0.0,
                     "status": plan.status}
    return out


def scene_runs(name: str, seeds: int, candidates: int = CANDIDATES, first_seed: int = 0, shared_draws=(),
               prior_draws=(), **options) -> list[dict]:
    """The runs (:func:`run`) of seeds first_seed, ..., first_seed + seeds - 1 on one scene
    (one process per scene in the benchmark)."""
    from planners.allocation import gittins_table

    gittins_table(GPBandit().discount)  # computed once per process, before any clock starts
    return [run(name, seed, candidates=candidates, shared_draws=shared_draws, prior_draws=prior_draws, **options)
            for seed in range(first_seed, first_seed + seeds)]


def reached(curve: list, target: float, tolerance: float):
    """(draws, seconds) after which the best grasp's P_F stays within ``tolerance`` of
    ``target`` (relative) to the end of the run, or (None, None) when it ends outside."""
    inside = [p >= (1.0 - tolerance) * target for _, _, p in curve]
    if not inside or not inside[-1]:
        return None, None
    k = len(inside) - 1
    while k > 0 and inside[k - 1]:
        k -= 1
    return curve[k][0], curve[k][1]


def summarise(runs: list[dict], policies=None) -> dict:
    """Per policy and tolerance: the median and 90th percentile of the draws, and the
    median seconds, to reach it (a run that never does counts as infinitely many; an
    infinite statistic is None), how many runs reach it, the median over runs of
    uniform's draws (seconds) over the policy's, uniform's median draws over the policy's
    with its 95 % interval (``uniform_over_policy_of_medians``, see :func:`_of_medians`),
    and the share of runs within it after each of ANYTIME_BUDGETS draws (a budgeted
    planner's view). Per policy also its seconds per pull over gp-p's per draw, with the
    shape samples (``pull_over_gp_p_draw``) and without them (``judging_over_gp_p``, see
    :func:`_judging`), and its median plan time. ``candidates_within``: how many
    candidates are within each tolerance (see :func:`_candidates_within`). ``by_scenes``:
    the draws to each tolerance on the library scenes and on the shared outlines apart
    (see :func:`_by_scenes`).
    ``model``: the model's best candidate, before any draw (see :func:`_model`). Plus the
    default planners' plan times and P_F on the library scenes (``make eval``'s).
    ``policies``: the labels summarised, by default ALLOCATIONS' and then any other label
    the runs hold, in their order; a label is left out unless every run holds it."""
    runs = [r for r in runs if "skipped" not in r]
    if policies is None:
        policies = list(ALLOCATIONS) + [p for r in runs for p in r["curves"] if p not in ALLOCATIONS]
    table = {}
    for policy in (p for p in dict.fromkeys(policies) if all(p in r["curves"] for r in runs)):
        row = {}
        for tol in TOLERANCES:
            draws, seconds, ratio_d, ratio_s = _reaching(runs, policy, tol)
            within = {str(b): float(np.mean([at_draws(r["curves"][policy], b) >= (1 - tol) * r["target"]
                                             for r in runs])) for b in ANYTIME_BUDGETS}
            row[f"{round(tol * 100)}pct"] = {
                "median_draws": _quantile(draws, 0.5), "p90_draws": _quantile(draws, 0.9),
                "median_seconds": _quantile(seconds, 0.5), "reached": sum(math.isfinite(d) for d in draws),
                "runs": len(runs), "median_uniform_over_policy_draws": _quantile(ratio_d, 0.5),
                "median_uniform_over_policy_seconds": _quantile(ratio_s, 0.5), "within_after": within,
                "uniform_over_policy_of_medians": _of_medians(runs, policy, tol)}
        row["median_plan_s"] = _quantile([r["plan_s"][policy] for r in runs], 0.5)
        row["pull_over_gp_p_draw"] = _quantile(
            [(r["seconds"][policy]["allocation"] + r["seconds"][policy]["draws"]) / r["curves"][policy][-1][0]
             / (r["gp_p_s"] / r["gp_p_draws"]) for r in runs], 0.5)
        row["judging_over_gp_p"] = _quantile([_judging(r, policy) / _judging(r, "gp-p") for r in runs], 0.5)
        table[policy] = row
    library = set(library_names())
    defaults = {}
    for name in DEFAULTS_COMPARED:
        rows = [r["defaults"][name] for r in runs if r["scene"] in library and "defaults" in r]
        defaults[name] = {"median_plan_s": _quantile([d["plan_s"] for d in rows], 0.5),
                          "mean_plan_s": float(np.mean([d["plan_s"] for d in rows])) if rows else None,
                          "mean_p_f": float(np.mean([d["p_f"] for d in rows])) if rows else None, "runs": len(rows)}
    return {"policies": table, "model": _model(runs), "candidates_within": _candidates_within(runs),
            "by_scenes": _by_scenes(runs, list(table)),
            "median_gp_p_s": _quantile([r["gp_p_s"] for r in runs], 0.5),
            "uniform_is_gp_p": sum(bool(r.get("uniform_is_gp_p")) for r in runs), "runs": len(runs),
            "library_defaults": defaults}


def _model(runs: list[dict]) -> dict | None:
    """The answer of the model alone (the candidate of highest P~_F, before any draw), over
    the runs that hold it: the mean of its P_F over the target, and the share of runs in
    which it is within each tolerance of the target (None when no run holds it)."""
    runs = [r for r in runs if "model_p_f" in r]
    if not runs:
        return None
    ratio = np.array([r["model_p_f"] / r["target"] if r["target"] > 0 else 1.0 for r in runs])
    return {"runs": len(runs), "mean_over_target": float(ratio.mean()),
            "within": {f"{round(tol * 100)}pct": float(np.mean(ratio >= 1.0 - tol)) for tol in TOLERANCES}}


def _reaching(runs: list[dict], policy: str, tolerance: float):
    """Per run: the draws and seconds the policy needs to reach ``tolerance`` (infinite
    when it does not), and uniform's over the policy's (draws, seconds)."""
    draws, seconds, ratio_d, ratio_s = [], [], [], []
    for r in runs:
        d, s = reached(r["curves"][policy], r["target"], tolerance)
        du, su = reached(r["curves"]["uniform"], r["target"], tolerance)
        draws.append(math.inf if d is None else d)
        seconds.append(math.inf if s is None else s)
        ratio_d.append(_ratio(du, d))
        ratio_s.append(_ratio(su, s))
    return draws, seconds, ratio_d, ratio_s


def _of_medians(runs: list[dict], policy: str, tolerance: float) -> dict:
    """Uniform's median draws to ``tolerance`` over the policy's (``value``; a run that
    never gets there counts as infinitely many), with a 95 % interval (``ci95``) from
    BOOTSTRAP resamples of the scenes with replacement, each bringing all its runs (a
    cluster bootstrap, percentile interval). Infinite or undefined values are None."""
    draws = {label: np.array([math.inf if d is None else d
                              for d in (reached(r["curves"][label], r["target"], tolerance)[0] for r in runs)])
             for label in ("uniform", policy)}
    return _bootstrapped(runs, lambda idx: _median_ratio(draws["uniform"][idx], draws[policy][idx]))


def _bootstrapped(runs: list[dict], statistic) -> dict:
    """``statistic(run indices)`` on all the runs and its 95 % percentile interval over
    BOOTSTRAP resamples of the scenes (see :func:`_of_medians`); the resamples come from
    a stream of their own, so the interval is the same in every summary of the same runs."""
    scenes = sorted({r["scene"] for r in runs})
    members = [np.array([k for k, r in enumerate(runs) if r["scene"] == scene]) for scene in scenes]
    rng = stream(0, "bandit-study", "bootstrap")
    values = [statistic(np.concatenate([members[j] for j in rng.integers(0, len(scenes), len(scenes))]))
              for _ in range(BOOTSTRAP)] if runs else []

    def finite(v):
        return None if v is None or not math.isfinite(v) else float(v)

    return {"value": finite(statistic(np.arange(len(runs)))) if runs else None,
            "ci95": [_quantile(values, 0.025), _quantile(values, 0.975)]}


def _median_ratio(uniform: np.ndarray, policy: np.ndarray) -> float:
    """median(uniform) / median(policy), infinities as in :func:`_ratio` (NaN when both are
    infinite)."""
    a, b = np.median(uniform), np.median(policy)
    return _ratio(None if math.isinf(a) else float(a), None if math.isinf(b) else float(b))


def _by_scenes(runs: list[dict], policies: list[str]) -> dict:
    """For the library scenes and the shared outlines apart (a group without runs is
    left out): per policy and tolerance, the median draws to reach it, uniform's median,
    the median over runs of uniform's draws over the policy's, and uniform's median over
    the policy's with its 95 % interval (:func:`_of_medians`); and the share of
    candidates within each tolerance (:func:`_candidates_within`)."""
    library = set(library_names())
    groups = {"library": [r for r in runs if r["scene"] in library],
              "shared outlines": [r for r in runs if r["scene"] not in library]}
    out = {}
    for group, members in groups.items():
        if not members:
            continue
        uniform = {tol: _quantile(_reaching(members, "uniform", tol)[0], 0.5) for tol in TOLERANCES}
        rows = {}
        for policy in policies:
            rows[policy] = {}
            for tol in TOLERANCES:
                draws, _, ratio_d, _ = _reaching(members, policy, tol)
                rows[policy][f"{round(tol * 100)}pct"] = {
                    "median_draws": _quantile(draws, 0.5), "uniform_median_draws": uniform[tol],
                    "median_uniform_over_policy_draws": _quantile(ratio_d, 0.5),
                    "uniform_over_policy_of_medians": _of_medians(members, policy, tol)}
        out[group] = {"runs": len(members), "policies": rows, "candidates_within": _candidates_within(members)}
    return out


def _candidates_within(runs: list[dict]) -> dict:
    """Per tolerance, the median over runs of the share of candidates whose P_F on the
    planners' pool is within it of the best one's: how many candidates are nearly as
    good as gp-p's choice (the more, the sooner even uniform allocation meets one, and
    the less any allocation can gain). None without runs that hold it."""
    return {f"{round(tol * 100)}pct": _quantile([r["share_within"][f"{round(tol * 100)}pct"]
                                                  for r in runs if "share_within" in r], 0.5) for tol in TOLERANCES}


def _judging(run: dict, policy: str) -> float:
    """Seconds per pull (per draw for "gp-p") without the shape samples: a policy's
    allocation (choosing the pulls and judging them) over its pulls; gp-p's plan time less
    the pool of its shape samples (timed as uniform allocation's, which draws the same
    pool in full) over its draws."""
    if policy == "gp-p":
        if "uniform" not in run["seconds"]:
            return math.nan
        return (run["gp_p_s"] - run["seconds"]["uniform"]["draws"]) / run["gp_p_draws"]
    return run["seconds"][policy]["allocation"] / run["curves"][policy][-1][0]


def at_draws(curve: list, draws: int) -> float:
    """The P_F of the best grasp after the last round that ended within ``draws`` draws
    (the answer before any draw, at 0 draws, if the curve holds it; else 0 before its
    first point)."""
    value = 0.0
    for d, _, p in curve:
        if d > draws:
            break
        value = p
    return value


def _ratio(uniform, policy) -> float:
    """uniform / policy, where None (never reached) is infinitely many; a policy that
    needs no draw (within before any) is infinitely faster than a uniform that needs
    some, and as fast as one that needs none (1)."""
    if policy is None:
        return 0.0 if uniform is not None else math.nan
    if uniform is None:
        return math.inf
    if policy == 0:
        return 1.0 if uniform == 0 else math.inf
    return uniform / policy


def _quantile(values, q: float) -> float | None:
    """The q-quantile (the lower of two middle values' mean for the median), infinities
    counted as the largest values and NaN left out; None when there is nothing or the
    quantile is infinite (JSON has no infinity)."""
    values = sorted(v for v in values if not math.isnan(v))
    if not values:
        return None
    n = len(values)
    if q == 0.5 and n % 2 == 0:
        mid = 0.5 * (values[n // 2 - 1] + values[n // 2])
    else:
        mid = values[min(n - 1, math.ceil(q * n) - 1)]
    return float(mid) if math.isfinite(mid) else None


def benchmark(settings: Settings = Settings()) -> dict:
    """The study (one process per scene): per scene and seed, every gp-bandit policy's
    best grasp before any draw and after every round judged on 1000 evaluation draws
    against gp-p's choice; the draws (from 0) and seconds to within 1 % and 3 %, and the
    default planners' plan times."""
    shared_draws = [float(v) for v in settings.shared_draws]
    prior_draws = [float(v) for v in settings.prior_draws]
    names = settings.names()
    head = {"seeds": settings.seeds, "first_seed": settings.first_seed, "scenes": names,
            "candidates": settings.candidates, "shared_draws": shared_draws, "prior_draws": prior_draws}
    if settings.seeds == 0 or not names:
        return {**head, "runs": [], "summary": None}
    runs = [run for name in names
            for run in in_fresh_process(scene_runs, name, settings.seeds, settings.candidates, settings.first_seed,
                                        shared_draws, prior_draws)]
    return {**head, "tolerances": list(TOLERANCES), "adaptive_budget": ADAPTIVE_BUDGET,
            "runs": runs, "summary": summarise(runs)}


def format_lines(res: dict) -> list[str]:
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
                ratio = math.nan if mine is None or theirs is None else _ratio(theirs, mine)
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
