"""Benchmarks behind ``gpis-harness bench``: speeds measured as ratios within one run."""

from __future__ import annotations

import math
import multiprocessing
import resource
import time

import numpy as np

#: Grid sizes of the sampling benchmark.
SAMPLING_SIZES = (25, 40, 55, 70, 100, 200)
#: Scene whose physical size, sensor and GPIS settings are kept while M varies.
SAMPLING_SCENE = "disk"
#: Physical quantities held fixed in metres while M varies (the disk's values at M = 40);
#: numerical ones given in cells (the active band) follow the grid.
SAMPLING_PHYSICAL = {"grid": {"truncation": "15 mm"}, "gpis": {"lengthscale": "13.5 mm", "scale": "100 mm^2",
                                                             "prior_mean": "-5 mm"}}
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


def _sampling_overrides(size: int) -> dict:
    return {"grid": {"size": size, **SAMPLING_PHYSICAL["grid"]}, "gpis": SAMPLING_PHYSICAL["gpis"]}


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

    scene = load_scene(scene_name, overrides=_sampling_overrides(size))
    belief = build_belief(scene, stream(0, "bench", size, "sensor"))
    t0 = time.perf_counter()
    draws = draw_evaluation(belief, SAMPLES, *default_streams(0, "bench", size))
    draws.shapes.twist, draws.shapes.center_of_mass  # noqa: B018  (set-up counted here)
    draws_s = time.perf_counter() - t0
    grasp = Grasp.from_centre((0.0, 0.0), 0.3, 0.09)
    gripper = scene.gripper
    args = (grasp, draws, gripper.sigma_g, scene.physics.friction, gripper.opening, gripper.jaw_width)
    estimate = estimate_p_f(*args)[0]
    best = math.inf
    for _ in range(PF_REPEATS):
        t0 = time.perf_counter()
        estimate_p_f(*args)
        best = min(best, time.perf_counter() - t0)
    return {"M": size, "p_f_s": best, "draws_s": draws_s, "p_f": estimate.p_f, "peak_mb": _peak_mb()}


def planning(sizes=PLANNING_SIZES, scene: str = SAMPLING_SCENE) -> dict:
    """Seconds per P_F estimate (1000 paired draws) over grid sizes, and its growth."""
    from harness.scene import load_scene

    for m in sizes:
        load_scene(scene, overrides=_sampling_overrides(m))
    rows = [_in_fresh_process(_p_f_row, scene, m) for m in sizes]
    ms = np.array([r["M"] for r in rows], dtype=float)
    times = np.array([r["p_f_s"] for r in rows])
    exponent = float(np.polyfit(np.log(ms), np.log(times), 1)[0]) if len(rows) > 1 else None
    at50 = next((r["p_f_s"] for r in rows if r["M"] == 50), None)
    return {"scene": scene, "draws": SAMPLES, "grasp": "through the centre at 0.3 rad, width 0.09 m",
            "rows": rows, "p_f_s_at_50": at50, "p_f_growth_exponent": exponent}


def run(which: str = "all", exact_max_mb: float = 2500.0, sizes=None) -> dict:
    """Run the named benchmark(s); returns a JSON-ready dict."""
    results = {}
    if which in ("sampling", "all"):
        results["sampling"] = sampling(tuple(sizes or SAMPLING_SIZES), exact_max_mb)
    if which in ("planning", "all"):
        results["planning"] = planning(tuple(sizes or PLANNING_SIZES))
    return results[which] if which != "all" else results


def format_results(results: dict) -> str:
    """A human-readable table of benchmark results."""
    if "rows" in results:
        results = {("sampling" if "active_set_effect" in results else "planning"): results}
    lines = []
    for name, res in results.items():
        if name == "planning":
            lines.append(f"planning: one P_F estimate with {res['draws']} paired draws, scene '{res['scene']}', "
                         f"grasp {res['grasp']}")
            lines.append(f"{'M':>5} {'P_F ms':>8} {'draws s':>8} {'P_F':>6} {'peak MB':>8}")
            for r in res["rows"]:
                lines.append(f"{r['M']:>5} {r['p_f_s'] * 1e3:>8.2f} {r['draws_s']:>8.2f} {r['p_f']:>6.3f} "
                             f"{r['peak_mb']:>8.0f}")
            if res["p_f_s_at_50"] is not None:
                lines.append(f"P_F estimate at M = 50: {res['p_f_s_at_50'] * 1e3:.2f} ms (the original: 1.1 to 2.5 s)")
            if res["p_f_growth_exponent"] is not None:
                lines.append(f"P_F growth exponent (log time vs log M): {res['p_f_growth_exponent']:.2f}")
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
