"""`gpis-harness bench sampling`: GP fit and posterior sampling times over grid sizes,
the exact sampler against the fast one, and what the active set changes."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from harness.bench.common import SAMPLES, in_fresh_process, peak_mb, sampling_overrides

#: Grid sizes of the sampling benchmark.
SIZES = (25, 40, 55, 70, 100, 200)
#: Scene whose physical size, sensor and GPIS settings are kept while M varies.
SCENE = "disk"
REPEATS = 3


@dataclass(frozen=True)
class Settings:
    """The grid sizes; the largest dense covariance (MB) the exact sampler may build; the scene."""

    sizes: tuple = SIZES
    exact_max_mb: float = 2500.0
    scene: str = SCENE


def _row(scene_name: str, size: int, exact_max_mb: float) -> dict:
    """One grid size, in a fresh process: fit and fast-sample (best of REPEATS, each on a
    fresh belief so the one-off basis set-up is included), then the exact sampler once."""
    from harness.belief import build_belief
    from harness.scene import load_scene
    from harness.seeding import stream

    scene = load_scene(scene_name, overrides=sampling_overrides(size, scene_name))
    fit_s, fast_s = math.inf, math.inf
    for r in range(REPEATS):
        t0 = time.perf_counter()
        belief = build_belief(scene, stream(0, "bench", size, "sensor"))
        t1 = time.perf_counter()
        belief.sample(SAMPLES, stream(0, "bench", size, "fast", r))
        t2 = time.perf_counter()
        fit_s, fast_s = min(fit_s, t1 - t0), min(fast_s, t2 - t1)
    fast_peak = peak_mb()
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
        "M": size, "fit_s": fit_s, "fast_s": fast_s, "exact_s": exact_s, "peak_mb": peak_mb(),
        "fast_peak_mb": fast_peak, "observations": len(belief.observations), "active": len(belief.active),
        "observed_scalars": len(belief.gp.targets_), "basis_rank": rank,
        "fast_method": belief.gp.fast_strategy(size, size, rank, rank, True, SAMPLES),
    }


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


def benchmark(settings: Settings = Settings()) -> dict:
    """Fit and sampling times over grid sizes, the exact/fast ratio at M = 55 and the
    growth exponent of the fast sampler."""
    from harness.scene import load_scene

    scene = settings.scene
    for m in settings.sizes:  # every size must make a valid scene, before any work
        load_scene(scene, overrides=sampling_overrides(m, scene))
    rows = [in_fresh_process(_row, scene, m, settings.exact_max_mb) for m in settings.sizes]
    ms = np.array([r["M"] for r in rows], dtype=float)
    fast = np.array([r["fast_s"] for r in rows])
    exponent = float(np.polyfit(np.log(ms), np.log(fast), 1)[0]) if len(rows) > 1 else None
    at55 = next((r for r in rows if r["M"] == 55 and r["exact_s"] is not None), None)
    return {
        "scene": scene, "samples": SAMPLES, "rows": rows,
        "ratio_exact_over_fast_at_55": at55["exact_s"] / at55["fast_s"] if at55 else None,
        "fast_growth_exponent": exponent,
        "active_set_effect": in_fresh_process(_active_set_effect, scene),
    }


def format_lines(res: dict) -> list[str]:
    lines = [f"sampling: {res['samples']} grid samples (values + gradients), scene '{res['scene']}'",
             f"{'M':>5} {'fit s':>8} {'fast s':>8} {'exact s':>9} {'peak MB':>9} {'D':>6} {'r':>4}  method"]
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
    return lines
