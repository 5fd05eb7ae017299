"""From a scene and a grasp to physics trials and their summary.

Trial i is paired with draw i of the analytic P_F (:mod:`harness.quality`): it uses
the same standard-normal approach deviates (scaled by sigma_g, narrowed to the
opening) and, for ``shapes="posterior"``, the same shape sample, both from the
experiment's named streams. So a physics outcome can be set against the force-closure
verdict of the same draw.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Polygon

from harness.canonical import canonical
from harness.geometry import largest_region
from harness.physics.bodies import simplified_outline
from harness.physics.gripper import GripperAdapter, GripperSpec
from harness.physics.trial import OUTCOMES, Trial
from harness.quality import as_starts, executed_starts, wilson_interval
from harness.scene import Scene
from harness.settings import GraspSettings

SHAPE_SOURCES = ("truth", "posterior")


def truth_polygon(scene: Scene) -> Polygon:
    """The true shape's largest region, canonical and simplified like a sample's."""
    return simplified_outline(largest_region(scene.shape), scene.grid.cell)


def make_trials(settings: GraspSettings, grasp, polygons: list[Polygon], approach: np.ndarray,
                friction_deviates: np.ndarray | None = None, gripper: GripperAdapter | None = None) -> list[Trial]:
    """Trial i: ``polygons[i]`` (or the one polygon for all) extruded with the settings'
    thickness and density, the grasp executed under ``approach[i]`` (standard-normal
    deviates (n, 2, 2) for g1 and g2), jaw-object friction from ``friction_deviates[i]``
    (the settings' friction when None), the settings' gripper unless ``gripper`` is given.

    The planned jaw starts are made canonical (harness.canonical) first: a plan that
    differs between hosts by much less than the grid executes the same. What follows
    them to Bullet (the executed starts, the closing direction, the friction) is computed
    elementwise from them and the deviates, without BLAS, so the same on every host; the
    polygons come canonical from :func:`truth_polygon` and
    :func:`~harness.physics.bodies.field_polygon`."""
    planned = canonical(as_starts(grasp)[0])
    n = len(approach)
    frictions = np.broadcast_to(settings.frictions(0.0 if friction_deviates is None else friction_deviates), (n,))
    if len(polygons) not in (1, n):
        raise ValueError("one polygon, or one per approach draw")
    g1, g2 = executed_starts(planned, approach, settings)
    nominal = (planned[1] - planned[0]) / np.hypot(*(planned[1] - planned[0]))
    gripper = gripper or GripperSpec.from_settings(settings).adapter()
    trials = []
    for i in range(n):
        d = g2[i] - g1[i]
        length = float(np.hypot(*d))
        axis = d / length if length > 1e-9 else nominal
        trials.append(Trial(polygons[i if len(polygons) > 1 else 0], tuple(g1[i]), tuple(g2[i]), tuple(axis),
                            settings.thickness, settings.density, float(frictions[i]), gripper))
    return trials


@dataclass(frozen=True)
class SimulationSummary:
    """Success rate of one grasp over physics trials, its Wilson 95 % interval, counts by
    outcome, throughput, and the per-trial results."""

    results: tuple
    seconds: float

    @property
    def trials(self) -> int:
        return len(self.results)

    @property
    def successes(self) -> int:
        return sum(r.outcome == "success" for r in self.results)

    @property
    def outcomes(self) -> dict:
        return outcome_counts(self.results)

    def as_dict(self) -> dict:
        lo, hi = wilson_interval(self.successes, self.trials)
        return {"trials": self.trials, "successes": self.successes,
                "success_rate": self.successes / self.trials if self.trials else math.nan,
                "ci_low": float(lo), "ci_high": float(hi), "outcomes": self.outcomes,
                "trials_per_s": self.trials / self.seconds if self.seconds > 0 else math.inf}


def outcome_counts(results) -> dict:
    """Counts of TrialResults by outcome, every outcome present."""
    counts = Counter(r.outcome for r in results)
    return {name: counts.get(name, 0) for name in OUTCOMES}
