"""Figures: the scene picture (observations, GPIS-Blur, posterior uncertainty)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from shapely.geometry import box  # noqa: E402

from harness.belief import Belief  # noqa: E402
from harness.geometry import Grid, polygons, zero_contours  # noqa: E402
from harness.sensor import KIND_NAMES  # noqa: E402

#: GPIS-Blur resolution: samples are drawn on a lattice this many times finer than the
#: grid (odd, so that the cell centres are lattice points).
BLUR_REFINE = 3
REGION_STYLE = {"occluded": ("0.55", "//"), "transparent": ("tab:cyan", ".."), "specular": ("tab:orange", "xx")}


def _outline(ax, geometry, **style):
    for poly in polygons(geometry):
        for ring in [poly.exterior, *poly.interiors]:
            xy = np.asarray(ring.coords)
            ax.plot(xy[:, 0] * 1e3, xy[:, 1] * 1e3, **style)


def _contours(ax, field, grid, **style):
    for line in zero_contours(field, grid):
        ax.plot(line[:, 0] * 1e3, line[:, 1] * 1e3, **style)


def inside_probability(belief: Belief, n: int, rng: np.random.Generator, refine: int = BLUR_REFINE):
    """Fraction of ``n`` posterior shapes covering each point of a lattice ``refine``
    times finer than the grid (the paper's GPIS-Blur); returns (probability, fine grid)."""
    grid = belief.grid
    fine = Grid(grid.size * refine, grid.extent)
    values, _ = belief.gp.sample_grid(fine.coords, fine.coords, n, rng)
    return (values < 0).mean(axis=0), fine


def scene_figure(belief: Belief, rng: np.random.Generator, n_blur: int = 100, title: str | None = None):
    """Three panels: what the sensor saw, the GPIS-Blur with the mean and true shapes,
    and the posterior standard deviation of the SDF."""
    scene, grid, obs = belief.scene, belief.grid, belief.observations
    half = 0.5 * grid.extent * 1e3
    extent_mm = (-half, half, -half, half)
    fig, axes = plt.subplots(1, 3, figsize=(15.5, 5.4), constrained_layout=True)

    ax = axes[0]
    std_mm = np.full((grid.size, grid.size), np.nan)
    std_mm[obs.cells[:, 1], obs.cells[:, 0]] = np.sqrt(obs.noise_var) * 1e3
    lo = np.nanmin(std_mm)
    im = ax.imshow(std_mm, origin="lower", extent=extent_mm, cmap="viridis", interpolation="nearest",
                   norm=LogNorm(vmin=lo, vmax=max(np.nanmax(std_mm), 10 * lo)))
    fig.colorbar(im, ax=ax, shrink=0.8, label="reading noise std (mm); blank: not observed")
    frame = box(-grid.extent / 2, -grid.extent / 2, grid.extent / 2, grid.extent / 2)
    handles = {}
    for region in scene.sensor.regions:
        colour, hatch = REGION_STYLE[region.kind]
        for poly in polygons(region.geometry.intersection(frame)):
            xy = np.asarray(poly.exterior.coords) * 1e3
            ax.fill(xy[:, 0], xy[:, 1], facecolor="none", edgecolor=colour, hatch=hatch, lw=1.0, zorder=3)
        handles[region.kind] = Patch(facecolor="none", edgecolor=colour, hatch=hatch, label=f"{region.kind} region")
    _outline(ax, scene.shape, color="crimson", lw=1.4, zorder=4)
    counts = np.bincount(obs.kind, minlength=len(KIND_NAMES))
    seen = ", ".join(f"{counts[k]} {KIND_NAMES[k]}" for k in range(len(KIND_NAMES)) if counts[k])
    ax.set_title(f"Observations ({len(obs)} of {grid.size**2} cells)\n{seen}", fontsize=10)
    legend = [*handles.values(), plt.Line2D([], [], color="crimson", lw=1.4, label="true shape")]
    ax.legend(handles=legend, loc="lower left", fontsize=8, framealpha=0.85)

    ax = axes[1]
    prob, fine = inside_probability(belief, n_blur, rng)
    ax.imshow(prob, origin="lower", extent=extent_mm, cmap="Greys", vmin=0, vmax=1, interpolation="bilinear")
    _contours(ax, belief.mean, grid, color="tab:red", lw=1.6)
    _outline(ax, scene.shape, color="tab:blue", lw=1.1, ls="--")
    ax.set_title(f"GPIS-Blur: {n_blur} posterior shapes\nred: mean zero level, blue dashed: truth", fontsize=10)

    ax = axes[2]
    im = ax.imshow(np.sqrt(belief.var) * 1e3, origin="lower", extent=extent_mm, cmap="magma",
                   interpolation="nearest")
    _contours(ax, belief.mean, grid, color="white", lw=1.2)
    _outline(ax, scene.shape, color="tab:cyan", lw=1.0, ls="--")
    com = belief.center_of_mass * 1e3
    ax.plot(*com, marker="+", color="white", ms=10, mew=2)
    fig.colorbar(im, ax=ax, shrink=0.8, label="posterior SDF std (mm)")
    ax.set_title("Posterior uncertainty\nwhite: mean zero level, +: mean-shape centre of mass", fontsize=10)

    for ax in axes:
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_aspect("equal")
        ax.set_xlabel("x (mm)")
    axes[0].set_ylabel("y (mm)")
    gp = belief.gp
    fig.suptitle(
        (title or f"{scene.name}: {scene.description}") + "\n"
        f"grid {grid.size} x {grid.size} over {grid.extent * 1e3:.0f} mm; GPIS l = {gp.lengthscale_ * 1e3:.2f} mm, "
        f"scale = ({np.sqrt(gp.scale_) * 1e3:.2f} mm)^2, prior mean = {gp.prior_mean_ * 1e3:.2f} mm; "
        f"fitted on {len(belief.active)} readings",
        fontsize=10,
    )
    return fig


# ---------------------------------------------------------------------------
# Report figures (harness.report)

PLANNER_COLOURS = ("tab:gray", "tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown")
OUTCOME_COLOURS = {"success": "tab:green", "slipped": "tab:orange", "dropped": "tab:red", "no_contact": "tab:gray",
                   "approach_collision": "tab:purple", "unstable": "black", "empty_shape": "tab:cyan",
                   "no_plan": "lightgray"}


def grasps_figure(belief: Belief, grasps: dict, rng: np.random.Generator, jaw_width: float, n_blur: int = 64,
                  title: str = ""):
    """The GPIS-Blur of one belief with each planner's grasp: jaw starts joined by the
    closing line, a bar across each jaw of the plate's width ``jaw_width``."""
    grid, scene = belief.grid, belief.scene
    half = 0.5 * grid.extent * 1e3
    fig, ax = plt.subplots(figsize=(6.2, 6.2), constrained_layout=True)
    prob, _ = inside_probability(belief, n_blur, rng)
    ax.imshow(prob, origin="lower", extent=(-half, half, -half, half), cmap="Greys", vmin=0, vmax=1,
              interpolation="bilinear")
    _outline(ax, scene.shape, color="tab:blue", lw=1.0, ls="--")
    w = jaw_width * 1e3 / 2
    for k, (label, grasp) in enumerate(grasps.items()):
        colour = PLANNER_COLOURS[k % len(PLANNER_COLOURS)]
        if grasp is None:
            ax.plot([], [], color=colour, lw=2, label=f"{label}: no grasp")
            continue
        g = np.asarray(grasp, dtype=float) * 1e3
        axis = (g[1] - g[0]) / max(np.linalg.norm(g[1] - g[0]), 1e-9)
        normal = np.array([-axis[1], axis[0]])
        ax.plot(g[:, 0], g[:, 1], color=colour, lw=1.5, label=label)
        for p in g:
            ends = np.array([p - w * normal, p + w * normal])
            ax.plot(ends[:, 0], ends[:, 1], color=colour, lw=4, solid_capstyle="butt")
    ax.set_xlim(-half, half)
    ax.set_ylim(-half, half)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.legend(loc="lower left", fontsize=8, framealpha=0.85)
    ax.set_title(title, fontsize=10)
    return fig


def success_figure(summary):
    """Physical success per scene and planner (posterior samples, bars; true shape,
    rings on the planner's bar) with Wilson 95 % intervals."""
    scenes = list(dict.fromkeys(summary.scene))
    planners = list(dict.fromkeys(summary.planner))
    fig, ax = plt.subplots(figsize=(max(7.5, 1.0 * len(scenes) + 2), 5.0), constrained_layout=True)
    width = 0.8 / len(planners)
    for k, planner in enumerate(planners):
        s = summary[summary.planner == planner].set_index("scene").loc[scenes]
        x = np.arange(len(scenes)) + (k - (len(planners) - 1) / 2) * width
        colour = PLANNER_COLOURS[k % len(PLANNER_COLOURS)]
        err = np.vstack([s.success_rate - s.success_ci_low, s.success_ci_high - s.success_rate])
        ax.bar(x, s.success_rate, width * 0.92, color=colour, label=f"{planner} (posterior)")
        ax.errorbar(x, s.success_rate, yerr=np.nan_to_num(err), fmt="none", ecolor="black", lw=0.8, capsize=2)
        # Black rings on white: visible on every bar colour, inside a bar or above it; the
        # planner is the bar the ring sits on.
        ax.plot(x, s.truth_success_rate, ls="none", marker="o", mfc="white", mec="black", mew=1.2, ms=6,
                label="true shape" if k == 0 else None)
    ax.set_xticks(np.arange(len(scenes)), scenes, rotation=30, ha="right")
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("physical success rate")
    ax.legend(fontsize=7, ncol=len(planners) + 1, loc="upper center", bbox_to_anchor=(0.5, -0.22))
    ax.set_title("Success in physics trials\nbars: posterior samples with 95% CI; circles: true shape",
                 fontsize=10)
    return fig


def failures_figure(fails):
    """Trial outcomes per planner (posterior samples and true shape), stacked fractions."""
    outcomes = [c for c in OUTCOME_COLOURS if c in fails.columns]
    rows = fails.assign(name=fails.planner + "\n" + fails.shapes)
    counts = rows[outcomes].to_numpy(dtype=float)
    frac = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
    fig, ax = plt.subplots(figsize=(max(5.5, 0.9 * len(rows) + 2.5), 4.2), constrained_layout=True)
    bottom = np.zeros(len(rows))
    for j, outcome in enumerate(outcomes):
        ax.bar(np.arange(len(rows)), frac[:, j], 0.7, bottom=bottom, color=OUTCOME_COLOURS[outcome], label=outcome)
        bottom += frac[:, j]
    ax.set_xticks(np.arange(len(rows)), rows.name, fontsize=8)
    ax.set_ylabel("fraction of trials")
    ax.set_ylim(0, 1)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.set_title("Trial outcomes by planner", fontsize=10)
    return fig


def calibration_figure(bins):
    """Reliability diagram: plans binned by their analytic P_F and, separately, by their
    P_L, against their physical success on posterior samples."""
    fig, ax = plt.subplots(figsize=(5.0, 5.0), constrained_layout=True)
    ax.plot([0, 1], [0, 1], color="0.6", ls="--", lw=1, label="perfect calibration")
    styles = {"p_f": ("o", "tab:blue", "P_F (force closure)", -10), "p_l": ("s", "tab:red", "P_L (and lifted)", 5)}
    for metric, (marker, colour, name, dy) in styles.items():
        b = bins[bins.metric == metric] if len(bins) else bins
        if not len(b):
            continue
        err = np.vstack([b.success_rate - b.ci_low, b.ci_high - b.success_rate])
        ax.errorbar(b.mean_estimate, b.success_rate, yerr=err, fmt=marker, color=colour, capsize=3,
                    label=f"plans binned by {name} (95% CI)")
        for _, row in b.iterrows():
            ax.annotate(f"{int(row.plans)}", (row.mean_estimate, row.success_rate), textcoords="offset points",
                        xytext=(5, dy), fontsize=7, color=colour)
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    ax.set_aspect("equal")
    ax.set_xlabel("analytic estimate of the plan")
    ax.set_ylabel("physical success on posterior samples")
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title("Calibration (numbers: plans per bin)", fontsize=10)
    return fig


def calibration_by_regime_figure(bins):
    """The reliability diagram of P_L, one panel per regime (bins with a ``regime``
    column, from harness.report.calibration_by_regime)."""
    regimes = list(dict.fromkeys(bins.regime))
    cols = min(3, len(regimes))
    rows = int(np.ceil(len(regimes) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.6 * rows), squeeze=False, constrained_layout=True)
    for ax, regime in zip(axes.ravel(), regimes):
        ax.plot([0, 1], [0, 1], color="0.6", ls="--", lw=1)
        b = bins[(bins.regime == regime) & (bins.metric == "p_l")]
        err = np.vstack([b.success_rate - b.ci_low, b.ci_high - b.success_rate])
        ax.errorbar(b.mean_estimate, b.success_rate, yerr=err, fmt="s", color="tab:red", capsize=3)
        for _, row in b.iterrows():
            ax.annotate(f"{int(row.plans)}", (row.mean_estimate, row.success_rate), textcoords="offset points",
                        xytext=(5, 5), fontsize=7, color="tab:red")
        ax.set_xlim(0, 1.02)
        ax.set_ylim(0, 1.02)
        ax.set_aspect("equal")
        ax.set_title(regime, fontsize=8)
        ax.set_xlabel("analytic P_L of the plan", fontsize=8)
        ax.set_ylabel("success on posterior samples", fontsize=8)
    for ax in axes.ravel()[len(regimes):]:
        ax.axis("off")
    fig.suptitle("Calibration of P_L per regime (numbers: plans per bin; 95% CI)", fontsize=10)
    return fig


def leaderboard_figure(board):
    """Success on posterior samples (Wilson 95 % intervals) against median plan time
    (log scale), one point per planner, labelled with its rank."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    t = np.maximum(board.plan_time_median_s.to_numpy(dtype=float), 1e-3)
    y = board.success_rate.to_numpy(dtype=float)
    err = np.vstack([y - board.success_ci_low.to_numpy(dtype=float), board.success_ci_high.to_numpy(dtype=float) - y])
    ax.errorbar(t, y, yerr=err, fmt="o", color="tab:blue", ms=5, capsize=3, lw=1)
    # A label goes right of its point, or left when the next point to the right is close
    # (within half a decade of plan time and 5 % of the success range), so that it does
    # not run over that point.
    span = max(np.ptp(y[np.isfinite(y)]) if np.isfinite(y).any() else 0.0, 0.05)
    order = np.argsort(t, kind="stable")
    left = np.zeros(len(t), dtype=bool)
    for a, b in zip(order[:-1], order[1:]):
        left[a] = np.log10(t[b] / t[a]) < 0.5 and abs(y[b] - y[a]) < 0.05 * span
    for k, r in enumerate(board.itertuples()):
        ax.annotate(f"{r.rank}. {r.planner}", (t[k], y[k]), textcoords="offset points", fontsize=8,
                    xytext=(-6, 3) if left[k] else (6, 3), ha="right" if left[k] else "left",
                    bbox={"boxstyle": "square,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7})
    ax.set_xscale("log")
    ax.set_xlim(t.min() / (5 if left.any() else 1.5), t.max() * 5)  # room for the labels
    ax.set_xlabel("median plan time (s)")
    ax.set_ylabel("success on posterior samples")
    ax.set_title("Leaderboard: success against plan time (95 % intervals)", fontsize=10)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def convergence_figure(bench: dict):
    """Like the supplement's Fig. 1 (from ``bench planning``): the analytic P_F of gp-p's
    best grasp so far against its planning time (steps), and of gp-gpis-opt's answer for
    runs with 1, 2, 3, 5 and 10 initialisations against their time (points); one line per
    seed."""
    fig, ax = plt.subplots(figsize=(6.0, 4.2), constrained_layout=True)
    for k, run in enumerate(bench["convergence"]):
        gpp = np.asarray(run.get("gp-p", []), dtype=float)
        opt = np.asarray(run.get("gp-gpis-opt", []), dtype=float)
        if len(gpp):
            ax.step(gpp[:, 0], gpp[:, 2], where="post", color="tab:blue", alpha=0.8,
                    label="gp-p (best of the candidates so far)" if k == 0 else None)
        if len(opt):
            ax.plot(opt[:, 0], opt[:, 2], "o-", color="tab:red", alpha=0.8, ms=4,
                    label="gp-gpis-opt (1, 2, 3, 5, 10 initialisations)" if k == 0 else None)
    ax.set_xlabel("planning time (s)")
    ax.set_ylabel("analytic P_F of the grasp (1000 draws)")
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(f"Convergence on the {bench.get('scene', 'plane')} (bench planning; one line per seed)", fontsize=10)
    return fig


def runtime_figure(bench: dict):
    """Like the supplement's Fig. 2: time per SCP initialisation and per GP-P candidate,
    and per P_F estimate, against the grid size M (log-log)."""
    fig, ax = plt.subplots(figsize=(6.0, 4.2), constrained_layout=True)
    for key, label, colour in (("scp_s_per_init", "GP-GPIS-OPT: one SCP initialisation", "tab:red"),
                               ("gpp_s_per_candidate", "GP-P: one candidate (1000 samples)", "tab:blue")):
        sizes = sorted(int(m) for m in bench.get(key, {}))
        if sizes:
            ax.loglog(sizes, [bench[key][str(m)] for m in sizes], "o-", color=colour, label=label)
    rows = bench.get("rows", [])
    if rows:
        ax.loglog([r["M"] for r in rows], [r["p_f_s"] for r in rows], "s--", color="0.4",
                  label="one P_F estimate (1000 draws)")
    ax.set_xlabel("grid size M (cells per side)")
    ax.set_ylabel("seconds")
    ax.legend(fontsize=8)
    ax.set_title("Runtime against grid size (bench planning)", fontsize=10)
    return fig


#: Colours of the bandit policies in the study's figure.
POLICY_COLOURS = {"thompson": "tab:red", "thompson-no-model": "tab:brown", "thompson-alone": "tab:pink",
                  "gittins": "tab:purple", "ucb": "tab:orange", "uniform": "tab:blue", "uniform-model": "tab:cyan",
                  "pruning": "tab:green"}


def bandit_figure(study: dict):
    """Like Laskey et al.'s convergence plots (from the bandit study of ``bench planning``
    or ``bench bandit``): against the draws spent, the P_F of each policy's best grasp so
    far as a fraction of the best candidate's (gp-p's choice), averaged over the study's
    runs, and the share of runs within 1 % and 3 % of it. The axis of draws is linear up
    to the first round (FIRST_ROUND) and logarithmic beyond, so that the answer before any
    draw (0 draws) shows."""
    from planners.allocation import FIRST_ROUND

    runs = [r for r in study.get("runs", []) if "skipped" not in r and r.get("target", 0) > 0]
    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.2), constrained_layout=True)
    policies = [p for p in POLICY_COLOURS if runs and all(p in r["curves"] for r in runs)]
    if policies:
        first = min(d for r in runs for p in policies for d, _, _ in r["curves"][p] if d > 0)
        last = max(r["curves"][p][-1][0] for r in runs for p in policies)
        grid = np.unique(np.concatenate([[0.0], np.geomspace(first, max(last, first), 300).round()]))
        lowest, below = 1.0, {}
        for policy in policies:
            fractions = np.empty((len(runs), len(grid)))
            for k, r in enumerate(runs):
                curve = np.asarray(r["curves"][policy], dtype=float)
                # A step function: each round's answer stands until the next (and after the last).
                at = np.searchsorted(curve[:, 0], grid, side="right") - 1
                fractions[k] = np.where(at >= 0, curve[np.maximum(at, 0), 2] / r["target"], np.nan)
            started = np.isfinite(fractions).all(axis=0)  # once every run has an answer
            colour = POLICY_COLOURS[policy]
            mean = fractions[:, started].mean(axis=0)
            # The axis is scaled to the rounds; an answer before any draw far below them is
            # named in the panel instead of stretching it.
            lowest = min(lowest, float(mean[grid[started] > 0].min()))
            if grid[started][0] == 0:
                below[policy] = float(mean[0])
            axes[0].step(grid[started], mean, where="post", color=colour, label=policy)
            for tol, style in ((0.01, "-"), (0.03, "--")):
                share = (fractions[:, started] >= 1.0 - tol).mean(axis=0)
                axes[1].step(grid[started], share, where="post", color=colour, ls=style)
        for level, style in ((0.99, "-"), (0.97, "--")):
            axes[0].axhline(level, color="0.6", ls=style, lw=0.8)
        floor = max(0.0, lowest - 0.01)
        axes[0].set_ylim(floor, 1.005)
        off = {policy: v for policy, v in below.items() if v < floor}
        if off:  # the policies under the uniform prior all answer gp-p's first candidate
            values = " or ".join(sorted({f"{v:.2f}" for v in off.values()}))
            axes[0].set_title(f"before any draw, below the axis: {len(off)} policies at {values}", fontsize=8)
    for ax in axes:
        ax.set_xscale("symlog", linthresh=FIRST_ROUND, linscale=0.5)
        ax.set_xlim(left=0.0)
        ax.set_xlabel("draws spent (pulls; 0: before any draw)")
    axes[0].set_ylabel("P_F of the best grasp so far / best candidate's (mean)")
    axes[0].legend(fontsize=8, loc="lower right", title="policy", title_fontsize=8)
    axes[1].set_ylabel("share of runs within 1 % (solid), 3 % (dashed)")
    axes[1].set_ylim(0.0, 1.02)
    fig.suptitle(f"Bandit allocation of draws (bench planning): {len(runs)} runs, "
                 f"{len(study.get('scenes', []))} scenes x {study.get('seeds', '?')} seeds, "
                 f"{study.get('candidates', 100)} candidates each; grey lines: 99 % and 97 %", fontsize=10)
    return fig
