"""Paired comparison of two runs of one experiment (``gpis-harness compare DIR_A DIR_B``).

Two runs that share the seed, the scenes, the realisations and the evaluation settings
drew the same beliefs, shape samples, approach noise and friction, so trial i of a plan
in run A and trial i of the same plan in run B differ only in what the runs changed: the
physics settings (``[physics]``, ``batch_size``), a planner's parameters, the code. The
comparison pairs the trials on (scene, realisation, planner, shapes, trial) and reports,
per scene, planner and shape source, the change in success (B - A) with a paired bootstrap
interval and McNemar's p; the spread of that change over the cells; how each planner
comparison of the report moved; and the outcome cross-table.

The ledger keeps the scene files' content only inside the config hash, so a scene file
edited between the runs goes unnoticed by the config check; the count of identical plans
shows it (a physics-only change leaves every plan the same).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from harness.errors import InputError
from harness.report import (ALL, comparison_pairs, expected, linked_difference, load, mcnemar, paired_difference,
                            row_groups)
from harness.seeding import stream

#: Config fields that decide the draws: runs that differ in one are not paired.
PAIRING_FIELDS = ("seed", "realisations", "analytic_draws", "posterior_trials", "truth_trials", "settings")
#: Config fields that change no result.
IGNORED_FIELDS = ("name", "source")
KEYS = ["scene", "realisation", "planner", "shapes", "trial"]
SHAPES = ("posterior", "truth")
GRASP = ["g1x", "g1y", "g2x", "g2y"]


def compare(dir_a: Path, dir_b: Path, engines: bool = False) -> dict:
    """The paired comparison of the latest experiments in two results folders (B - A).
    ``engines``: a cross-engine comparison, refused unless the runs differ in the physics
    engine and in nothing else (:func:`check_engines_only`)."""
    a, b = load(Path(dir_a)), load(Path(dir_b))
    if engines:
        check_engines_only(a, b, dir_a, dir_b)
    for name in PAIRING_FIELDS:
        va, vb = a["config"].get(name), b["config"].get(name)
        if va != vb:
            raise InputError(str(dir_b), f"config.{name}",
                             f"is {vb!r} here and {va!r} in {dir_a}: the runs did not draw the same shapes "
                             "and noise, so their trials are not paired")
    trials = a["trials"][KEYS + ["outcome"]].merge(b["trials"][KEYS + ["outcome"]], on=KEYS,
                                                   suffixes=("_a", "_b"))
    if trials.empty:
        raise InputError(str(dir_b), None, f"no trial in common with {dir_a} (scenes or planners differ)")
    trials["a"] = (trials.outcome_a == "success").astype(int)
    trials["b"] = (trials.outcome_b == "success").astype(int)
    scenes = [s for s in expected(a["config"])[0] if s in set(trials.scene)]
    planners = [p for p in expected(a["config"])[1] if p in set(trials.planner)]
    seed = int(a["config"]["seed"])
    cells = _cells(trials, scenes, planners, seed)
    per_cell = cells[(cells.scene != ALL) & (cells.planner != ALL) & (cells.shapes != ALL)]
    worst = per_cell.difference.abs().idxmax()
    return {
        "a": str(dir_a), "b": str(dir_b),
        "differences": config_differences(a["config"], b["config"]),
        "trials": {"a": len(a["trials"]), "b": len(b["trials"]), "paired": len(trials)},
        "plans": _plans(a["plans"], b["plans"], planners),
        "cells": cells,
        "spread": {"cells": len(per_cell), "rms": float(np.sqrt((per_cell.difference ** 2).mean())),
                   "max": float(per_cell.difference[worst]),
                   "max_at": " / ".join(per_cell.loc[worst, ["scene", "planner", "shapes"]])},
        "planner_shifts": _planner_shifts(trials, a["config"], planners, seed),
        "outcomes": pd.crosstab(trials.outcome_a, trials.outcome_b, rownames=["A"], colnames=["B"]),
    }


def check_engines_only(a: dict, b: dict, dir_a, dir_b) -> None:
    """InputError unless the two runs' configs (scene contents included, by the config
    hash less the engine) differ in ``[physics] engine`` alone: then every plan, shape
    sample, approach draw and friction draw is the same, and a difference is the
    simulator's."""
    engine_a, engine_b = ((c["config"].get("physics") or {}).get("engine", "pybullet") for c in (a, b))
    if engine_a == engine_b:
        raise InputError(str(dir_b), "config.physics.engine",
                         f"is {engine_b} in both runs: a cross-engine comparison needs two engines")
    differences = config_differences(a["config"], b["config"])
    physics = differences.pop("physics", None)
    if physics is not None:
        rest = [{k: v for k, v in (p or {}).items() if k != "engine"} for p in physics]
        if rest[0] != rest[1]:
            differences["physics"] = rest
    differences.pop("batch_size", None)  # how trials are grouped, no result (tested for both engines)
    if differences:
        name = sorted(differences)[0]
        raise InputError(str(dir_b), f"config.{name}",
                         f"is {differences[name][1]!r} here and {differences[name][0]!r} in {dir_a}: "
                         "a cross-engine comparison needs runs that differ in the engine alone")
    hashes = [_content_hash(run) for run in (a, b)]
    if None not in hashes and hashes[0] != hashes[1]:
        raise InputError(str(dir_b), "config.scenes", f"a scene file's content differs from {dir_a}'s")


def _content_hash(run: dict) -> str | None:
    """The hash of a run's config less its engine, the scene files' content included;
    None when a scene file is no longer where the run read it (the count of identical
    plans then shows an edit)."""
    from harness.config import ExperimentConfig

    config = dict(run["config"])
    config["physics"] = {k: v for k, v in (config.get("physics") or {}).items() if k != "engine"}
    try:
        return ExperimentConfig.from_dict(config).hash
    except (OSError, InputError):  # a scene file, or an outline it reads, gone or no longer readable
        return None


def config_differences(a: dict, b: dict) -> dict:
    """What the two configs set differently, as {field: [value in A, value in B]}: scenes
    present in one run only, planners by label, every other field but the name and the
    source."""
    out = {}
    for name in sorted(set(a) | set(b)):
        if name in IGNORED_FIELDS or name in ("scenes", "scene_names", "planners") or a.get(name) == b.get(name):
            continue
        out[name] = [a.get(name), b.get(name)]
    sa, sb = (set(expected(c)[0]) for c in (a, b))
    if sa != sb:
        out["scenes"] = [sorted(sa - sb), sorted(sb - sa)]
    pa, pb = ({p["label"]: p for p in c["planners"]} for c in (a, b))
    for label in sorted(set(pa) | set(pb)):
        ea, eb = pa.get(label), pb.get(label)
        if ea != eb:
            out[f"planners.{label}"] = [ea, eb]
    return out


def _cells(trials: pd.DataFrame, scenes: list[str], planners: list[str], seed: int) -> pd.DataFrame:
    """Per scene, planner and shape source, then pooled over scenes (scene 'all'), over
    shape sources, and over everything; each interval from its own bootstrap stream."""
    rows = []
    selections = [(s, p, sh) for s in scenes for p in planners for sh in SHAPES]
    selections += [(ALL, p, sh) for p in planners for sh in (*SHAPES, ALL)]
    selections += [(ALL, ALL, sh) for sh in (*SHAPES, ALL)]
    for scene, planner, shapes in selections:
        mask = np.ones(len(trials), bool)
        for column, value in (("scene", scene), ("planner", planner), ("shapes", shapes)):
            if value != ALL:
                mask &= (trials[column] == value).to_numpy()
        t = trials[mask]
        if t.empty:
            continue
        # The planners of one cell share trial i's draws: pooled over planners, a cell's
        # trials are resampled together (linked_difference); per planner, within its plan.
        frame = t.assign(d=(t.b - t.a).astype(float))
        rng = stream(seed, "bootstrap", "compare", scene, planner, shapes)
        diff = linked_difference(frame, ["scene", "realisation", "shapes"], "planner", rng)
        only_a, only_b, p = mcnemar(t.a.to_numpy(), t.b.to_numpy())
        rows.append({"scene": scene, "planner": planner, "shapes": shapes, "pairs": diff.pop("pairs"),
                     "success_a": float(t.a.mean()), "success_b": float(t.b.mean()), **diff,
                     "only_a": only_a, "only_b": only_b, "mcnemar_p": p,
                     "agreement": float((t.outcome_a == t.outcome_b).mean())})
    return pd.DataFrame(rows)


def _planner_shifts(trials: pd.DataFrame, config: dict, planners: list[str], seed: int) -> pd.DataFrame:
    """How each planner comparison of the report (planner - versus, pooled over scenes)
    moved from A to B, on posterior samples, on the true shape and on both, paired on
    (scene, realisation, shapes, trial)."""
    keys = ["scene", "realisation", "shapes", "trial"]
    rows = []
    for x, y in comparison_pairs(config):
        if x not in planners or y not in planners:
            continue
        for shapes in (*SHAPES, ALL):
            t = trials if shapes == ALL else trials[trials.shapes == shapes]
            m = t[t.planner == x][keys + ["a", "b"]].merge(t[t.planner == y][keys + ["a", "b"]], on=keys,
                                                           suffixes=("_x", "_y"))
            if m.empty:
                continue
            da, db = (m.a_x - m.a_y).to_numpy(), (m.b_x - m.b_y).to_numpy()
            rng = stream(seed, "bootstrap", "compare-shift", x, y, shapes)
            shift = paired_difference(db - da, row_groups(m, ["scene", "realisation", "shapes"]), rng)
            rows.append({"planner": x, "versus": y, "shapes": shapes, "pairs": shift["pairs"],
                         "difference_a": float(da.mean()), "difference_b": float(db.mean()),
                         "shift": shift["difference"], "shift_ci_low": shift["ci_low"],
                         "shift_ci_high": shift["ci_high"]})
    return pd.DataFrame(rows)


def _plans(a: pd.DataFrame, b: pd.DataFrame, planners: list[str]) -> dict:
    """Per planner: plans in both runs, and how many chose the same grasp (or failed alike)."""
    m = a.merge(b, on=["scene", "realisation", "planner"], suffixes=("_a", "_b"))
    out = {}
    for planner in planners:
        g = m[m.planner == planner]
        ga, gb = (g[[f"{c}_{s}" for c in GRASP]].to_numpy(dtype=float) for s in "ab")
        same = np.all((ga == gb) | (np.isnan(ga) & np.isnan(gb)), axis=1) & (g.status_a == g.status_b).to_numpy()
        out[planner] = {"plans": len(g), "identical": int(same.sum())}
    return out


def as_json(result: dict) -> dict:
    """The comparison as plain JSON types."""
    out = dict(result)
    for name in ("cells", "planner_shifts"):
        out[name] = result[name].to_dict(orient="records")
    out["outcomes"] = {a: {b: int(n) for b, n in row.items()} for a, row in result["outcomes"].iterrows()}
    return out


def as_markdown(result: dict) -> str:
    """The comparison for reading: what differs, the overall and per-cell change, the
    planner comparisons' shifts, the outcome cross-table."""
    t, spread = result["trials"], result["spread"]
    lines = [f"# {result['b']} (B) against {result['a']} (A)", ""]
    lines += ["What the runs set differently (A -> B):", ""]
    lines += [f"- {name}: {va!r} -> {vb!r}" for name, (va, vb) in result["differences"].items()] or ["- nothing"]
    plans = ", ".join(f"{p} {v['identical']}/{v['plans']}" for p, v in result["plans"].items())
    change = (f"Change per cell (scene, planner, shapes; {spread['cells']} cells): {spread['rms']:.3f} rms, "
              f"at most {spread['max']:+.3f} ({spread['max_at']}).")
    lines += ["", f"Paired trials: {t['paired']} (A has {t['a']}, B has {t['b']}). Identical plans: {plans}.",
              change, "", "## Success, B - A, paired", ""]
    c = result["cells"]
    shown = pd.DataFrame({
        "scene": c.scene, "planner": c.planner, "shapes": c.shapes, "pairs": c.pairs,
        "A": c.success_a.map("{:.3f}".format), "B": c.success_b.map("{:.3f}".format),
        "B - A [95% CI]": [f"{d:+.3f} [{lo:+.3f}, {hi:+.3f}]" for d, lo, hi in zip(c.difference, c.ci_low,
                                                                                   c.ci_high)],
        "only A / only B": [f"{x} / {y}" for x, y in zip(c.only_a, c.only_b)],
        "McNemar p": c.mcnemar_p.map("{:.3g}".format), "same outcome": c.agreement.map("{:.3f}".format),
    })
    lines += [shown.to_markdown(index=False), ""]
    s = result["planner_shifts"]
    if not s.empty:
        lines += ["## Planner comparisons (planner - versus, all scenes) in A and in B", "",
                  pd.DataFrame({
                      "planner": s.planner, "versus": s.versus, "shapes": s.shapes, "pairs": s.pairs,
                      "A": s.difference_a.map("{:+.3f}".format), "B": s.difference_b.map("{:+.3f}".format),
                      "shift [95% CI]": [f"{d:+.3f} [{lo:+.3f}, {hi:+.3f}]"
                                         for d, lo, hi in zip(s["shift"], s.shift_ci_low, s.shift_ci_high)],
                  }).to_markdown(index=False), ""]
    lines += ["## Outcomes (rows: A, columns: B)", "", result["outcomes"].to_markdown(), ""]
    return "\n".join(lines)
