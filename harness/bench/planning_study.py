"""`gpis-harness bench planning`: seconds per P_F and P_L estimate, per SCP
initialisation and per gp-p candidate over grid sizes; the convergence study (the
supplement's Fig. 1); gp-gpis-opt against gp-p, both planning for the lift, over the
library; and the bandit study (:mod:`harness.bench.bandit_study`)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from harness.bench import bandit_study
from harness.bench.common import SAMPLES, in_fresh_process, peak_mb, sampling_overrides
from harness.bench.quality_study import scene_quality

#: Grid sizes of the P_F timing.
SIZES = (25, 50, 100, 200)
#: The scene of the P_F timing (its physics kept while M varies).
SCENE = "disk"
PF_REPEATS = 15
#: Scene of the planner timings (tilted, partly hidden: the optimiser has work to do).
PLANNER_SCENE = "marker"
#: The supplement's Fig. 1 object, at its own grid.
CONVERGENCE_SCENE = "plane"
CONVERGENCE_SEEDS = 3
CONVERGENCE_INITS = (1, 2, 3, 5, 10)
#: The lift variants compared (label, registry name, parameters).
LIFT_PLANNERS = (("gp-p-lift", "gp-p", {"quality": "lift"}), ("gp-gpis-opt-lift", "gp-gpis-opt", {"quality": "lift"}))
LIFT_SEEDS = 3
#: Scenes on which gp-p-lift is timed with its candidates ten at a time and in chunks sized
#: by the budget (planners.sampling.search): samples in pieces one time in two (the can
#: opener), candidates that spread (the tape, the stapler), and none that can be dropped
#: (the disk).
CHUNK_SCENES = ("can_opener", "tape", "stapler", "disk")
CHUNK_ROUNDS = 2


@dataclass(frozen=True)
class Settings:
    """The grid sizes, the P_F timing's scene and the bandit study's settings."""

    sizes: tuple = SIZES
    scene: str = SCENE
    bandit: bandit_study.Settings = field(default_factory=bandit_study.Settings)


def _p_f_row(scene_name: str, size: int) -> dict:
    """One grid size, in a fresh process: draw the evaluation once, then time one P_F
    estimate with 1000 paired draws (best of PF_REPEATS after a warm-up)."""
    from harness.belief import build_belief
    from harness.grasp import Grasp
    from harness.quality import default_streams, draw_evaluation, estimate_p_f
    from harness.scene import load_scene
    from harness.seeding import stream
    from harness.settings import resolve

    scene = load_scene(scene_name, overrides=sampling_overrides(size, scene_name))
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
            "draws_s": draws_s, "p_f": estimate.p_f, "p_l": estimate.p_l, "peak_mb": peak_mb()}


def _planner_row(scene_name: str, size: int) -> dict:
    """Seconds per SCP initialisation of gp-gpis-opt and per candidate of gp-p (1000
    draws), belief already built (its grid fields too), each the best of 3 plans."""
    from harness.belief import build_belief
    from harness.scene import load_scene
    from harness.seeding import stream
    from planners.base import Problem
    from planners.registry import make_planner

    scene = load_scene(scene_name, overrides=sampling_overrides(size, scene_name))
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


def _chunks_row(scene_name: str) -> dict:
    """gp-p-lift on the scene's first cell (make eval's seed and realisation 0, no budget),
    in a fresh process: its candidates scored ten at a time and in the search's chunks,
    in turn, CHUNK_ROUNDS times each (best of each), and whether both give the same grasp
    and estimate."""
    from harness.belief import build_belief
    from harness.grasp import load_kernels
    from harness.scene import load_scene
    from harness.seeding import stream
    from planners.base import Problem
    from planners.gp_p import GPP

    load_kernels()
    scene = load_scene(scene_name)
    belief = build_belief(scene, stream(0, scene_name, 0, "sensor")).prepare()
    problem = Problem.for_belief(belief)
    planner = GPP(quality="lift")
    best = {True: math.inf, False: math.inf}
    plans = {}
    for r in range(CHUNK_ROUNDS):
        for fixed in ((True, False) if r % 2 == 0 else (False, True)):
            t0 = time.perf_counter()
            plans[fixed] = planner.plan(problem, stream(0, scene_name, 0, "planner", "gp-p-lift"), fixed_chunks=fixed)
            best[fixed] = min(best[fixed], time.perf_counter() - t0)
    same = plans[True].grasp == plans[False].grasp and plans[True].estimate == plans[False].estimate
    return {"scene": scene_name, "tens_s": best[True], "chunks_s": best[False], "speedup": best[True] / best[False],
            "chunks": len(plans[False].trace), "same_plan": bool(same)}


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


def _lift_summary(rows: list[dict]) -> dict:
    """gp-gpis-opt with the lift against gp-p with the lift over the library: mean P_L
    and mean plan time of each, and their ratios."""
    gpp, opt = (label for label, _, _ in LIFT_PLANNERS)
    p_l = {label: float(np.mean([np.mean(r["p_l"][label]) for r in rows])) for label in (opt, gpp)}
    seconds = {label: float(np.mean([np.mean(r["plan_s"][label]) for r in rows])) for label in (opt, gpp)}
    return {"seeds": LIFT_SEEDS, "rows": rows, "mean_p_l": p_l, "mean_plan_s": seconds,
            "p_l_ratio": p_l[opt] / p_l[gpp], "time_ratio": seconds[opt] / seconds[gpp]}


def benchmark(settings: Settings = Settings()) -> dict:
    """Seconds per P_F and per P_L estimate (1000 paired draws), per SCP initialisation and
    per GP-P candidate over grid sizes, with their growth; the convergence study; gp-gpis-opt
    against gp-p, both planning for the lift, over the library; and the bandit study
    (``settings.bandit``; 0 seeds skips it)."""
    from harness.scene import library_names, load_scene

    settings.bandit.names()  # every scene of the bandit study checked before any work
    for m in settings.sizes:
        load_scene(settings.scene, overrides=sampling_overrides(m, settings.scene))
        load_scene(PLANNER_SCENE, overrides=sampling_overrides(m, PLANNER_SCENE))
    rows = [in_fresh_process(_p_f_row, settings.scene, m) for m in settings.sizes]
    planners = [in_fresh_process(_planner_row, PLANNER_SCENE, m) for m in settings.sizes]
    lift_rows = [in_fresh_process(scene_quality, name, LIFT_PLANNERS, "p_l", LIFT_SEEDS)
                 for name in library_names()]
    convergence = [in_fresh_process(_convergence, seed) for seed in range(CONVERGENCE_SEEDS)]
    chunks = [in_fresh_process(_chunks_row, name) for name in CHUNK_SCENES]
    ms = np.array([r["M"] for r in rows], dtype=float)

    def growth(values):
        return float(np.polyfit(np.log(ms), np.log(values), 1)[0]) if len(rows) > 1 else None

    at50 = next((r["p_f_s"] for r in rows if r["M"] == 50), None)
    ratio50 = next((r["p_l_over_p_f"] for r in rows if r["M"] == 50), None)
    scp = {str(r["M"]): r["gp-gpis-opt"] for r in planners}
    gpp = {str(r["M"]): r["gp-p"] for r in planners}
    return {"scene": settings.scene, "draws": SAMPLES, "grasp": "through the centre at 0.3 rad, width 0.09 m",
            "rows": rows, "p_f_s_at_50": at50, "p_l_over_p_f_at_50": ratio50,
            "p_f_growth_exponent": growth([r["p_f_s"] for r in rows]),
            "planner_scene": PLANNER_SCENE, "scp_s_per_init": scp, "gpp_s_per_candidate": gpp,
            "scp_over_gpp": {m: scp[m] / gpp[m] for m in scp},
            "scp_growth_exponent": growth(list(scp.values())), **_convergence_summary(convergence),
            "lift_planners": _lift_summary(lift_rows), "search_chunks": chunks,
            "bandit": bandit_study.benchmark(settings.bandit)}


def format_lines(res: dict) -> list[str]:
    lines = [f"planning: one P_F estimate and one P_L estimate (P_F and the lift) with {res['draws']} "
             f"paired draws, scene '{res['scene']}', grasp {res['grasp']}",
             f"{'M':>5} {'P_F ms':>8} {'P_L ms':>8} {'ratio':>6} {'draws s':>8} {'P_F':>6} {'P_L':>6} {'peak MB':>8}"]
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
    speedup = res["speedup_to_95pct"]
    lines.append(f"convergence on the {CONVERGENCE_SCENE} (sigma_g 1.5 cells, friction 0.4), mean of "
                 f"{len(res['convergence'])} seeds: seconds to 95 % of gp-p's best-of-100: gp-p "
                 f"{np.mean(t['gp-p']):.3f}, gp-gpis-opt {np.nanmean(t['gp-gpis-opt']):.3f}; speed-up "
                 f"{speedup if speedup is None else round(speedup, 1)}")
    lines.append("final P_F: " + ", ".join(f"{k} {v:.3f}" for k, v in res["final_p_f"].items()))
    lift = res["lift_planners"]
    lines.append(f"lift planners over the library ({lift['seeds']} seeds, P_L on 1000 evaluation draws): "
                 + ", ".join(f"{k} P_L {v:.3f} in {lift['mean_plan_s'][k]:.3f} s" for k, v in lift["mean_p_l"].items())
                 + f"; gp-gpis-opt-lift / gp-p-lift: P_L {lift['p_l_ratio']:.3f}, time {lift['time_ratio']:.3f}")
    if res.get("search_chunks"):
        lines.append("gp-p-lift's search, ten candidates at a time against chunks sized by the budget (none here), "
                     f"best of {CHUNK_ROUNDS} in turn, one process per scene:")
        for r in res["search_chunks"]:
            lines.append(f"  {r['scene']:<12} {r['tens_s']:.2f} s -> {r['chunks_s']:.2f} s ({r['speedup']:.2f}x, "
                         f"{r['chunks']} chunks); same plan: {'yes' if r['same_plan'] else 'NO'}")
    if res.get("bandit"):
        lines += bandit_study.format_lines(res["bandit"])
    return lines
