"""`gpis-harness bench quality`: the analytic P_F of each built-in planner's grasp per
library scene, over several sensor readings."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from harness.bench.common import SAMPLES, in_fresh_process

SEEDS = 5
PLANNERS = ("mean-shape", "gp-p", "gp-gpis-opt")
#: A scene has heavy uncertainty when at least this fraction of its mean surface has a
#: posterior std above half a cell (seed 0's belief).
HEAVY_FRACTION = 0.10


@dataclass(frozen=True)
class Settings:
    """The scenes (None: the library)."""

    scenes: tuple | None = None


def scene_quality(name: str, variants=tuple((p, p, {}) for p in PLANNERS), metric: str = "p_f",
                  seeds: int = SEEDS) -> dict:
    """Analytic P_F, or P_L (``metric``; 1000 evaluation draws, the scene's settings), and
    plan time of each planner variant's grasp (label, registry name, parameters) on one
    scene, for ``seeds`` independent sensor readings."""
    from harness.belief import build_belief
    from harness.grasp import load_kernels
    from harness.quality import default_streams, draw_evaluation, estimate_p_f
    from harness.scene import load_scene
    from harness.seeding import stream
    from planners.base import Problem
    from planners.registry import make_planner

    load_kernels()  # as pipeline.plan does before a plan: no plan time pays for loading them
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


def benchmark(settings: Settings = Settings()) -> dict:
    """Mean analytic P_F of each planner per scene over SEEDS seeds, and the means over
    all scenes and over the scenes with heavy uncertainty."""
    from harness.scene import library_names

    rows = [in_fresh_process(scene_quality, name) for name in (settings.scenes or library_names())]
    mean = {p: float(np.mean([np.mean(r["p_f"][p]) for r in rows])) for p in PLANNERS}
    heavy = [r for r in rows if r["heavy"]]
    heavy_mean = {p: float(np.mean([np.mean(r["p_f"][p]) for r in heavy])) if heavy else None for p in PLANNERS}
    return {"seeds": SEEDS, "rows": rows, "mean_p_f": mean, "heavy_scenes": [r["scene"] for r in heavy],
            "heavy_mean_p_f": heavy_mean}


def format_lines(res: dict) -> list[str]:
    lines = [f"quality: mean analytic P_F over {res['seeds']} seeds (scene sigma_g and friction)",
             f"{'scene':<15}" + "".join(f"{p:>13}" for p in PLANNERS) + "  heavy"]
    for r in res["rows"]:
        lines.append(f"{r['scene']:<15}" + "".join(f"{np.mean(r['p_f'][p]):>13.3f}" for p in PLANNERS)
                     + f"  {'yes' if r['heavy'] else ''}")
    lines.append(f"{'mean':<15}" + "".join(f"{res['mean_p_f'][p]:>13.3f}" for p in PLANNERS))
    if res["heavy_scenes"]:
        lines.append(f"{'heavy mean':<15}" + "".join(f"{res['heavy_mean_p_f'][p]:>13.3f}" for p in PLANNERS))
    return lines
