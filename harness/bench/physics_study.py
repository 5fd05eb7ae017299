"""The trial set of the fidelity study and the physics benchmark, and the measures
taken on it: outcome agreement with a finer time step, and throughput of the batched
runner against a naive one (a new world per trial, no early stop).

The set: for every library scene, one belief (seed, realisation 0), candidate grasps
drawn on its mean shape by the planners' shared generator (the kind of grasps the
planners consider, good and bad), and per grasp two trials, one on the true shape and
one on a posterior sample, each under its own approach-noise draw.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from harness.belief import build_belief
from harness.physics.simulate import make_trials, truth_polygon
from harness.physics.engines import make_runner
from harness.physics.trial import Trial, TrialResult
from harness.protocol import Protocol
from harness.scene import library_names, load_scene
from harness.settings import resolve
from harness.seeding import stream


#: Candidates drawn per scene for the ranked set, and the analytic draws ranking them.
RANKED_CANDIDATES = 100
RANKED_DRAWS = 100


@dataclass(frozen=True)
class TrialSet:
    """Trials with, per trial, its scene, whether it is on the true shape, and the
    analytic verdict of the same draw: force closure of the executed grasp's plate
    patches (the scene's friction) on the same shape field."""

    trials: list[Trial]
    scenes: list[str]
    on_truth: list[bool]
    force_closure: list[bool]

    def __len__(self) -> int:
        return len(self.trials)


def library_trials(grasps_per_scene: int = 12, seed: int = 0, ranked: bool = True) -> TrialSet:
    """2 x grasps_per_scene trials per library scene (truth, posterior), in a fixed order.

    ``ranked``: the grasps are the best of RANKED_CANDIDATES candidates by analytic P_F
    (what GP-P returns, and what the experiments mostly execute); otherwise the first
    candidates as drawn (good and bad alike, a harder set).
    """
    from harness.grasp import SDFBatch, find_contacts, plate_closure
    from harness.physics.bodies import field_polygon
    from harness.quality import draw_evaluation, estimate_p_f, executed_starts
    from planners.candidates import generate

    out = TrialSet([], [], [], [])
    for name in library_names():
        scene = load_scene(name)
        belief = build_belief(scene, stream(seed, name, 0, "sensor"))
        settings = resolve(scene)
        count = RANKED_CANDIDATES if ranked else grasps_per_scene
        grasps = generate(belief, count, stream(seed, name, 0, "study", "grasps"), settings)
        if ranked:
            draws = draw_evaluation(belief, RANKED_DRAWS, *(stream(seed, name, 0, "study", k)
                                                            for k in ("rank-shapes", "rank-approach", "rank-friction",
                                                                      "rank-pressure")))
            p_f = [e.p_f for e in estimate_p_f(grasps, draws, settings)]
            grasps = grasps[np.argsort(p_f, kind="stable")[::-1][:grasps_per_scene]]
        n = len(grasps)
        samples = belief.sample(n, stream(seed, name, 0, "study", "shapes"))
        fields = SDFBatch(scene.grid, np.concatenate([scene.true_sdf[None], samples.values]),
                          np.concatenate([scene.true_sdf_gradient[None], samples.gradients]))
        approach = stream(seed, name, 0, "study", "approach").standard_normal((n, 2, 2, 2))
        truth = truth_polygon(scene)
        for k, grasp in enumerate(grasps):
            for on_truth, polygon, field in ((True, truth, 0),
                                             (False, field_polygon(samples.values[k], scene.grid), k + 1)):
                deviates = approach[k, 0 if on_truth else 1][None]
                out.trials.extend(make_trials(settings, grasp, [polygon], deviates))
                g1, g2 = executed_starts(grasp, deviates, settings)
                contacts = find_contacts(fields, g1, g2, settings.jaw_width, field_index=np.array([field]))
                closure = bool(plate_closure(contacts, settings.friction, np.zeros(2), 1.0)[0][0])
                out.scenes.append(name)
                out.on_truth.append(on_truth)
                out.force_closure.append(closure)
    return out


@dataclass(frozen=True)
class Timed:
    results: list[TrialResult]
    seconds: float

    @property
    def simulated(self) -> int:
        """Trials that needed the simulator (not decided by geometry alone)."""
        return sum(r.outcome not in ("approach_collision", "empty_shape") for r in self.results)

    @property
    def rate(self) -> float:
        return len(self.results) / self.seconds


def run_batched(trials: list[Trial], protocol: Protocol, batch_size: int = 16) -> Timed:
    start = time.perf_counter()
    with make_runner(protocol, batch_size=batch_size) as runner:
        results = runner.run(trials)
    return Timed(results, time.perf_counter() - start)


def run_naive(trials: list[Trial], protocol: Protocol) -> Timed:
    """The reference: a new pybullet world (client) for every trial, which then runs
    the whole protocol (no early stop); same step, same solver, same checks."""
    start = time.perf_counter()
    results = []
    for trial in trials:
        with make_runner(protocol, batch_size=1, early_stop=False) as runner:
            results += runner.run([trial])
    return Timed(results, time.perf_counter() - start)


#: Trials per block and rounds of the interleaved timing (:func:`interleaved`); a block is
#: three of Bullet's batches of 16, so its batches are those of a run over every trial.
INTERLEAVE_BLOCK = 48
INTERLEAVE_ROUNDS = 3


def interleaved(trials: list[Trial], protocols: tuple[Protocol, Protocol], rounds: int = INTERLEAVE_ROUNDS,
                block: int = INTERLEAVE_BLOCK) -> tuple[np.ndarray, list[list[TrialResult]]]:
    """Seconds (rounds, 2) each of two engines takes over the same trials, with every
    shape's body or model built first, the trials run block by block in the two engines
    in turn (which engine runs a block first alternates): on a shared machine whose speed
    drifts during a run, the drift falls on both engines alike, where timing one engine's
    whole pass and then the other's lets it fall on one. Also each engine's results of
    the last round."""
    seconds = np.zeros((rounds, 2))
    with make_runner(protocols[0]) as first, make_runner(protocols[1]) as second:
        runners = (first, second)
        for runner in runners:
            runner.run(trials)
        results: list[list[TrialResult]] = [[], []]
        for r in range(rounds):
            results = [[], []]
            for k, start in enumerate(range(0, len(trials), block)):
                chunk = trials[start:start + block]
                for e in ((0, 1) if (r + k) % 2 == 0 else (1, 0)):
                    t0 = time.perf_counter()
                    results[e] += runners[e].run(chunk)
                    seconds[r, e] += time.perf_counter() - t0
    return seconds, results


def agreement(a: list[TrialResult], b: list[TrialResult]) -> float:
    """Fraction of trials with the same outcome."""
    return float(np.mean([x.outcome == y.outcome for x, y in zip(a, b, strict=True)]))


def confusion(a: list[TrialResult], b: list[TrialResult]) -> dict:
    """Counts of (outcome in a, outcome in b) pairs that differ."""
    pairs: dict = {}
    for x, y in zip(a, b, strict=True):
        if x.outcome != y.outcome:
            key = f"{x.outcome} -> {y.outcome}"
            pairs[key] = pairs.get(key, 0) + 1
    return dict(sorted(pairs.items(), key=lambda kv: -kv[1]))


#: Candidate grasps per library scene in the physics benchmark (two trials each).
GRASPS_PER_SCENE = 12


@dataclass(frozen=True)
class Settings:
    """Grasps per library scene (two trials each) and the seed of the trial set."""

    grasps_per_scene: int = GRASPS_PER_SCENE
    seed: int = 0


def benchmark(settings: Settings = Settings()) -> dict:
    """Trials per second of Bullet's batched runner and of a naive one (a new world per
    trial, no early stop) on the same trials, and the outcome agreement with a 4x finer
    step; the same for MuJoCo on the same trials in the same run (its trials per second
    over Bullet's batched runner, its agreement with its own 4x finer step and with
    Bullet, trial by trial); and both engines' rates on a second pass over the trials,
    with the shapes' bodies and models built in the first, and timed block by block in
    turn (:func:`interleaved`; each pass's results the same)."""
    from harness.physics.simulate import outcome_counts

    trials = library_trials(settings.grasps_per_scene, settings.seed).trials
    protocol = Protocol()
    batched = run_batched(trials, protocol)
    naive = run_naive(trials, protocol)
    fine = run_batched(trials, protocol.finer(4))
    mj = Protocol.of("mujoco")
    mujoco, mujoco_fine = run_batched(trials, mj), run_batched(trials, mj.finer(4))
    # A second pass of each engine with every shape's body or model already built in
    # this process, as in an experiment, where every planner's trials meet the same
    # posterior samples.
    batched_again, mujoco_again = run_batched(trials, protocol), run_batched(trials, mj)
    # Both engines again, block by block in turn, so that the machine's drift falls on both.
    turns, turn_results = interleaved(trials, (protocol, mj))
    same = [[r.as_dict() for r in x.results] for x in (batched, mujoco)]
    if [[r.as_dict() for r in x.results] for x in (batched_again, mujoco_again)] != same \
            or [[r.as_dict() for r in x] for x in turn_results] != same:
        raise RuntimeError("another pass over the same trials gave other results")
    per_round = turns[:, 0] / turns[:, 1]
    return {
        "mujoco": {"time_step": mj.time_step, "solver_iterations": mj.solver_iterations,
                   "trials_per_s": mujoco.rate, "over_pybullet": mujoco.rate / batched.rate,
                   "trials_per_s_built": mujoco_again.rate,
                   "over_pybullet_built": mujoco_again.rate / batched_again.rate,
                   "interleaved": {"rounds": len(turns), "block": INTERLEAVE_BLOCK,
                                   "pybullet_trials_per_s": len(trials) * len(turns) / float(turns[:, 0].sum()),
                                   "trials_per_s": len(trials) * len(turns) / float(turns[:, 1].sum()),
                                   "over_pybullet": float(turns[:, 0].sum() / turns[:, 1].sum()),
                                   "over_pybullet_per_round": [float(x) for x in per_round]},
                   "fine_step_agreement": agreement(mujoco.results, mujoco_fine.results),
                   "fine_step_disagreements": confusion(mujoco.results, mujoco_fine.results),
                   "agreement_with_pybullet": agreement(mujoco.results, batched.results),
                   "against_pybullet": confusion(batched.results, mujoco.results),
                   "outcomes": outcome_counts(mujoco.results),
                   "outcomes_fine_step": outcome_counts(mujoco_fine.results),
                   "seconds": {"batched": mujoco.seconds, "fine_step": mujoco_fine.seconds}},
        "trials": len(trials), "time_step": protocol.time_step, "solver_iterations": protocol.solver_iterations,
        "batched_trials_per_s": batched.rate, "naive_trials_per_s": naive.rate, "speedup": batched.rate / naive.rate,
        "batched_trials_per_s_built": batched_again.rate,
        "fine_step_agreement": agreement(batched.results, fine.results),
        "fine_step_disagreements": confusion(batched.results, fine.results),
        "naive_agreement": agreement(batched.results, naive.results),
        "outcomes": outcome_counts(batched.results), "outcomes_fine_step": outcome_counts(fine.results),
        "seconds": {"batched": batched.seconds, "naive": naive.seconds, "fine_step": fine.seconds},
    }


def format_lines(res: dict) -> list[str]:
    mj = res["mujoco"]
    return [f"physics: {res['trials']} trials from the library scenes, step {res['time_step']:.6g} s, "
            f"{res['solver_iterations']} solver iterations",
            f"batched {res['batched_trials_per_s']:.2f} trials/s, naive (a new world per trial) "
            f"{res['naive_trials_per_s']:.2f} trials/s: speedup {res['speedup']:.2f}",
            f"agreement with a 4x finer step: {res['fine_step_agreement']:.3f}; "
            f"differences: {res['fine_step_disagreements'] or 'none'}",
            "outcomes: " + ", ".join(f"{k} {v}" for k, v in res["outcomes"].items() if v),
            f"MuJoCo, the same trials: step {mj['time_step']:.6g} s, {mj['solver_iterations']} "
            f"iterations, {mj['trials_per_s']:.2f} trials/s, {mj['over_pybullet']:.2f}x Bullet's batched "
            f"runner; a second pass with the bodies built: {mj['trials_per_s_built']:.2f} against "
            f"{res['batched_trials_per_s_built']:.2f}, {mj['over_pybullet_built']:.2f}x; "
            f"block by block in turn ({mj['interleaved']['rounds']} rounds): {mj['interleaved']['trials_per_s']:.2f} "
            f"against {mj['interleaved']['pybullet_trials_per_s']:.2f}, {mj['interleaved']['over_pybullet']:.2f}x "
            f"(rounds {min(mj['interleaved']['over_pybullet_per_round']):.2f}-"
            f"{max(mj['interleaved']['over_pybullet_per_round']):.2f}x); "
            f"agreement with a 4x finer step {mj['fine_step_agreement']:.3f}, with Bullet "
            f"{mj['agreement_with_pybullet']:.3f}",
            "MuJoCo outcomes: " + ", ".join(f"{k} {v}" for k, v in mj["outcomes"].items() if v)
            + "; Bullet -> MuJoCo: " + (", ".join(f"{k} {v}" for k, v in mj["against_pybullet"].items())
                                         or "no difference")]
