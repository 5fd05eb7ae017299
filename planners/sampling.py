"""What the sampling planners share: candidates, the no-surface check, and a chunked
search that records a trace and honours the time budget."""

from __future__ import annotations

import numpy as np

from harness.grasp import Grasp
from planners import candidates as cand
from planners.base import Plan, Problem, Stopwatch

CHUNK = 10


def search(problem: Problem, rng: np.random.Generator, count: int, angular_noise_deg: float, score, setup=None,
           estimate_of=None, record=None, bounded: bool = False) -> Plan:
    """Generate ``count`` candidates, score them in chunks of CHUNK with
    ``score(grasps (k, 2, 2), state) -> (values (k,), tie_break (k,))`` (higher is better,
    compared as pairs; ``state`` is what ``setup(problem, rng)`` returned), keep the best,
    and stop early when the time budget is spent. ``estimate_of(best_value)`` gives the
    plan's estimate of P_F (or None). ``record``, a list, receives (seconds, grasps,
    values) for every chunk (for convergence studies). ``bounded``: score is called with
    ``floor=`` the best value so far (-inf at first) and may give -inf to candidates it
    proves cannot reach it (harness.quality.ranking_scores); not while recording, whose
    studies read every candidate's value."""
    clock = Stopwatch(problem.time_budget_s)
    belief = problem.belief
    if belief.mean_shape.is_empty:
        return Plan.without_grasp("no_surface", "the posterior mean has no inside", seconds=clock.phases)
    grasps = cand.generate(belief, count, rng, problem.settings, np.radians(angular_noise_deg))
    clock.lap("candidates")
    if len(grasps) == 0:
        return Plan.without_grasp("no_candidate", "no candidate grasp fits the gripper", seconds=clock.phases)
    state = setup(problem, rng) if setup else None
    clock.lap("setup")
    best, best_key, trace, done = 0, (-np.inf, -np.inf), [], 0
    status = "ok"
    bounded = bounded and record is None
    for start in range(0, len(grasps), CHUNK):
        chunk = grasps[start:start + CHUNK]
        scored = score(chunk, state, floor=best_key[0]) if bounded else score(chunk, state)
        values, tie = (np.asarray(a, dtype=float) for a in scored)
        if record is not None:
            record.append((clock.elapsed(), chunk, values))
        k = int(np.lexsort((-tie, -values))[0])
        if (values[k], tie[k]) > best_key:
            best, best_key = start + k, (float(values[k]), float(tie[k]))
        best_value = best_key[0]
        done = start + len(values)
        trace.append((clock.elapsed(), done, best_value))
        if clock.over_budget() and done < len(grasps):
            status = "budget"
            break
    clock.lap("search")
    g = grasps[best]
    return Plan(Grasp(tuple(g[0]), tuple(g[1])), status, estimate_of(best_value) if estimate_of else None,
                iterations=done, evaluations=done, seconds=clock.phases, trace=tuple(trace))
