"""What the sampling planners share: candidates, the no-surface check, and a chunked
search that records a trace and honours the time budget."""

from __future__ import annotations

import numpy as np

from harness.grasp import Grasp
from planners import candidates as cand
from planners.base import Plan, Problem, Stopwatch

#: Candidates scored in the first chunk, and in every chunk of an unbounded search.
CHUNK = 10
#: A bounded search (a score that takes a floor) scores, after its first chunk, as many
#: candidates at once as the rate of the chunks so far says fit in this share of the time
#: budget left (all that are left without a budget): each call of a Monte-Carlo score has
#: a fixed cost (the push's and the squeeze's contact searches, about 1 ms a step however
#: few the draws), so ten calls cost far more than one (docs/planners.md, "Helpers").
BUDGET_SHARE = 0.5


def _chunk_size(clock: Stopwatch, searching: float, done: int, left: int, bounded: bool) -> int:
    """How many candidates the next chunk scores: CHUNK first and in an unbounded search;
    then all that are ``left`` without a budget, else as many as fit, at the rate of the
    chunks so far (``done`` candidates since ``searching``, seconds on the clock), in
    BUDGET_SHARE of the budget left, and at least CHUNK."""
    if not bounded or done == 0:
        return min(CHUNK, left)
    if clock.budget is None:
        return left
    rate = (clock.elapsed() - searching) / done
    room = BUDGET_SHARE * (clock.budget - clock.elapsed())
    fits = left if rate <= 0 else int(room / rate)
    return max(min(CHUNK, left), min(left, fits))


def search(problem: Problem, rng: np.random.Generator, count: int, angular_noise_deg: float, score, setup=None,
           estimate_of=None, record=None, bounded: bool = False, fixed_chunks: bool = False) -> Plan:
    """Generate ``count`` candidates, score them in chunks with
    ``score(grasps (k, 2, 2), state) -> (values (k,), tie_break (k,))`` (higher is better,
    compared as pairs; ``state`` is what ``setup(problem, rng)`` returned), keep the best,
    and stop early when the time budget is spent. ``estimate_of(best_value)`` gives the
    plan's estimate of P_F (or None). ``record``, a list, receives (seconds, grasps,
    values) for every chunk (for convergence studies). ``bounded``: score is called with
    ``floor=`` the best value so far (-inf at first) and may give -inf to candidates it
    proves cannot reach it (harness.quality.ranking_scores); not while recording, whose
    studies read every candidate's value. Chunks hold CHUNK candidates, except in a
    bounded search after the first (:func:`_chunk_size`). The best is the first candidate
    with the highest (value, tie-break) however the chunks fall, so the plan does not
    depend on them unless the budget stops the search. ``fixed_chunks``: CHUNK candidates
    a chunk in a bounded search too (as before 2026-11-29; `bench planning` times both)."""
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
    searching = clock.elapsed()
    start = 0
    while start < len(grasps):
        size = _chunk_size(clock, searching, start, len(grasps) - start, bounded and not fixed_chunks)
        chunk = grasps[start:start + size]
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
        start = done
    clock.lap("search")
    g = grasps[best]
    return Plan(Grasp(tuple(g[0]), tuple(g[1])), status, estimate_of(best_value) if estimate_of else None,
                iterations=done, evaluations=done, seconds=clock.phases, trace=tuple(trace))
