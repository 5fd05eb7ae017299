"""Experiments: a TOML config -> cells (scene x realisation) -> tasks -> the ledger.

A cell is one scene and one sensor realisation (one belief). Its cell task builds the
belief, runs every planner that has no plan in the ledger yet, judges each plan by the
analytic P_F, and returns the polygons of the posterior shape samples that the physics
trials use. Each plan's trials then run as fixed batches (``batch_size`` consecutive
trials of one plan and one shape source, in one freshly reset pybullet world), so which trials
share a world is fixed by the config, never by the number of workers.

Random streams (harness.seeding) are named by (seed, scene, realisation, purpose):
``sensor`` for the belief, ``planner``/label for each planner, and the evaluation streams
``shapes``, ``approach``, ``friction`` (posterior draws) and ``truth-approach``,
``truth-friction`` (true-shape trials), which do not depend on the planner. Physics trial
i on posterior samples uses shape sample i, approach deviates i and friction deviate i of
the analytic P_F's draws: every planner meets the same shapes and the same noise, and a
plan's trial i and its analytic draw i are the same situation.
"""

from __future__ import annotations

import fnmatch
import hashlib
import json
import math
import signal
import threading
import time
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from harness.errors import InputError
from harness.scene import LIBRARY, Table, library_names, load_scene, read_toml, resolve

NO_PLAN = "no_plan"              # trial outcome when the plan gave nothing to execute
EXECUTABLE = ("ok", "budget")    # plan statuses whose grasp is executed
HARNESS_STATUSES = ("raised", "invalid", "overtime")
OVERTIME_SLACK = 1.5             # a plan may take this factor times its budget ...
OVERTIME_GRACE_S = 1.0           # ... plus this, before it counts as overtime
HARD_STOP_FACTOR = 3.0           # a planner still running at 3 x budget + 10 s is stopped
HARD_STOP_EXTRA_S = 10.0
SHAPES = ("posterior", "truth")

#: Protocol fields a config may override: whether zero is allowed (else strictly positive).
_PROTOCOL_KEYS = {"time_step": False, "lift_height": False, "lift_time": False, "hold_time": True,
                  "shake_time": True, "shake_frequency": False, "shake_amplitude": True, "shake_turn": True,
                  "table_friction": True}
#: Grasp settings (harness.settings) an experiment may override, by the table that holds them.
_SETTING_TABLES = {"evaluation": ("sigma_g", "friction", "friction_spread", "load_factor"),
                   "gripper": ("opening", "jaw_width", "sigma_g", "force", "closing_speed", "plate_height")}


@dataclass(frozen=True)
class PlannerEntry:
    """One planner of an experiment: its label in the tables, registry name, parameters."""

    label: str
    name: str
    params: dict


@dataclass(frozen=True)
class ExperimentConfig:
    """A validated experiment config (see docs/experiments.md)."""

    name: str
    source: str
    seed: int
    scenes: tuple[str, ...]            # scene files, resolved
    realisations: int
    planners: tuple[PlannerEntry, ...]
    analytic_draws: int
    posterior_trials: int
    truth_trials: int
    time_budget_s: float
    settings: dict = field(default_factory=dict)  # overrides of every scene's grasp settings
    physics: dict = field(default_factory=dict)   # overrides of the trial protocol
    batch_size: int = 16

    def content(self) -> dict:
        """What determines the results: the settings and the scene files' text."""
        d = asdict(self)
        d.pop("source")
        d.pop("name")
        d["scenes"] = {Path(p).stem: hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in self.scenes}
        return d

    @property
    def hash(self) -> str:
        text = json.dumps(self.content(), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ExperimentConfig":
        """The inverse of as_dict (the ledger keeps the config as JSON). Configs written
        before the settings were one field (sigma_g, friction, friction_spread and gripper
        side by side) read as their overrides."""
        d = dict(d)
        legacy = {k: d.pop(k) for k in ("sigma_g", "friction", "friction_spread") if k in d}
        settings = {**(d.pop("gripper", None) or {}), **{k: v for k, v in legacy.items() if v is not None},
                    **d.pop("settings", {})}
        return cls(**{**d, "settings": settings, "scenes": tuple(d["scenes"]),
                      "planners": tuple(PlannerEntry(**p) for p in d["planners"])})

    def protocol(self):
        from harness.physics.trial import Protocol

        return replace(Protocol(), **self.physics)

    def cells(self) -> list[tuple[str, int]]:
        return [(path, r) for path in self.scenes for r in range(self.realisations)]


def load_config(path: str | Path) -> ExperimentConfig:
    """Read and validate an experiment config; InputError (file, field, reason) on bad input."""
    path = Path(path)
    if not path.is_file():
        raise InputError(str(path), None, "no such experiment config")
    return parse_config(read_toml(path), source=str(path), base_dir=path.parent, default_name=path.stem)


def parse_config(data: dict, source: str, base_dir: Path, default_name: str = "experiment") -> ExperimentConfig:
    from planners.registry import make_planner

    root = Table(data, "", source)
    name = root.string("name", default_name)
    if not name or any(c in name for c in "/\\") or name.startswith("."):
        raise root.error("name", f"'{name}' cannot name a results folder")
    seed = root.integer("seed", 0, lo=0, hi=2**63 - 1)
    scenes = _scene_files(root, base_dir)
    realisations = root.integer("realisations", 3, lo=1, hi=1000)

    ev = root.table("evaluation", required=False)
    analytic = ev.integer("analytic_draws", 1000, lo=1, hi=1_000_000)
    posterior = ev.integer("posterior_trials", 100, lo=0, hi=100_000)
    truth = ev.integer("truth_trials", 50, lo=0, hi=100_000)
    budget = ev.number("time_budget_s", 60.0, lo=0.0, hi=86_400.0, lo_open=True)
    settings = _setting_overrides({"evaluation": ev, "gripper": root.table("gripper", required=False)})

    phys = root.table("physics", required=False)
    protocol = {key: phys.number(key, None, lo=0.0, lo_open=not zero_ok)
                for key, zero_ok in _PROTOCOL_KEYS.items() if key in phys.data}
    if "solver_iterations" in phys.data:
        protocol["solver_iterations"] = phys.integer("solver_iterations", None, lo=1, hi=10_000)
    if "time_step" in protocol and protocol["time_step"] > 0.01:
        raise phys.error("time_step", f"{protocol['time_step']} s is too coarse (at most 0.01 s)")
    for key in ("cone_friction", "table_hull"):
        if key in phys.data:
            protocol[key] = phys.boolean(key)
    batch = phys.integer("batch_size", 16, lo=1, hi=64)
    phys.finish()

    entries = []
    for t in root.tables("planners", min_count=1):
        pname = t.string("name")
        label = t.string("label", pname)
        params_t = t.table("params", required=False)
        params = dict(params_t.data)
        params_t.used.update(params)
        t.finish()
        try:
            make_planner(pname, params, source=source)
        except InputError as exc:
            raise InputError(source, f"{t.where}.{'params.' + exc.field if exc.field else 'name'}",
                             exc.message) from None
        if not label or any(c in label for c in "/\\\n"):
            raise t.error("label", f"'{label}' is not a usable label")
        if label in {e.label for e in entries}:
            raise t.error("label", f"'{label}' is used twice (give each planner entry its own label)")
        entries.append(PlannerEntry(label, pname, params))
    root.finish()

    config = ExperimentConfig(name, source, seed, tuple(scenes), realisations, tuple(entries), analytic,
                              posterior, truth, budget, settings, protocol, batch)
    for path in scenes:  # every scene must load, before any work starts
        load_scene(path)
    return config


def _setting_overrides(tables: dict) -> dict:
    """The grasp settings a config overrides, from [evaluation] and [gripper]; a setting
    given in both is an error (which one would win is not obvious)."""
    from harness.settings import BOUNDS

    found: dict = {}
    for table_name, keys in _SETTING_TABLES.items():
        t = tables[table_name]
        for key in keys:
            if key not in t.data:
                continue
            lo, hi, lo_open = BOUNDS[key]
            value = t.number(key, None, lo=lo, hi=hi, lo_open=lo_open)
            if key in found:
                raise t.error(key, f"is also set in [{found[key][0]}]: set each grasp setting once")
            found[key] = (table_name, value)
        t.finish()
    return {key: value for key, (_, value) in found.items()}


def _scene_files(root: Table, base_dir: Path) -> list[str]:
    entries = root.list("scenes", ["*"])
    if not entries:
        raise root.error("scenes", "needs at least one scene")
    files: list[str] = []
    for k, entry in enumerate(entries):
        if not isinstance(entry, str) or not entry:
            raise root.error(f"scenes[{k}]", f"expected a scene name, glob or path, got {entry!r}")
        looks_like_path = entry.endswith(".toml") or "/" in entry
        if any(c in entry for c in "*?["):
            matches = (sorted(str(p) for p in base_dir.glob(entry)) if looks_like_path
                       else [str(LIBRARY / f"{n}.toml") for n in library_names() if fnmatch.fnmatch(n, entry)])
            if not matches:
                raise root.error(f"scenes[{k}]", f"'{entry}' matches no scene")
        else:
            target = str(base_dir / entry) if looks_like_path and not Path(entry).is_absolute() else entry
            try:
                matches = [str(resolve(target))]
            except InputError as exc:
                raise root.error(f"scenes[{k}]", exc.message) from None
        files.extend(m for m in matches if m not in files)
    stems = [Path(f).stem for f in files]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise root.error("scenes", f"two scene files are both called '{twice[0]}'")
    return files


# ---------------------------------------------------------------------------
# Tasks (run in worker processes; pure functions of their arguments)


@lru_cache(maxsize=32)
def _scene(path: str):
    return load_scene(path)


def scene_of(config: ExperimentConfig, path: str):
    return _scene(path)


@lru_cache(maxsize=64)
def _settings(path: str, overrides_json: str, protocol):
    from harness.settings import resolve

    return resolve(_scene(path), json.loads(overrides_json), protocol)


def settings_of(config: ExperimentConfig, path: str):
    """The grasp settings of a scene in this experiment: the scene's, the config's
    overrides, and the lift of the config's physics protocol (resolved once per process)."""
    return _settings(path, json.dumps(config.settings, sort_keys=True), config.protocol())


@dataclass(frozen=True)
class CellResult:
    """What a cell task returns: plan and analytic rows for the planners it ran, the
    polygons of the posterior samples for the trials, and the trials' random deviates."""

    scene: str
    realisation: int
    plans: list
    analytic: list
    polygons: list
    approach: np.ndarray          # (posterior_trials, 2, 2)
    friction: np.ndarray          # (posterior_trials,)
    truth_approach: np.ndarray    # (truth_trials, 2, 2)
    truth_friction: np.ndarray    # (truth_trials,)
    seconds: float


def run_cell(config: ExperimentConfig, path: str, realisation: int, labels: tuple[str, ...]) -> CellResult:
    """Belief, plans of ``labels``, their analytic P_F, and the trials' shapes and noise,
    with one BLAS thread: the workers are the parallelism. On 2 cores, two workers with
    two BLAS threads each took 38.0-39.0 s for the 30 cells of make eval, one thread each
    31.4-34.1 s (four runs each); the plans and shapes are bit for bit the same."""
    from harness.gpis import single_threaded_blas

    with single_threaded_blas():
        return _cell(config, path, realisation, labels)


def _cell(config: ExperimentConfig, path: str, realisation: int, labels: tuple[str, ...]) -> CellResult:
    from harness.belief import build_belief
    from harness.physics.bodies import field_polygon
    from harness.quality import default_streams, draw_evaluation, evaluate_draws
    from harness.seeding import stream

    start = time.perf_counter()
    scene = scene_of(config, path)
    name = scene.name
    belief = build_belief(scene, stream(config.seed, name, realisation, "sensor")).prepare()
    settings = settings_of(config, path)
    n = max(config.analytic_draws, config.posterior_trials)
    draws = draw_evaluation(belief, n, *default_streams(config.seed, name, realisation))
    plans, analytic = [], []
    for entry in config.planners:
        if entry.label not in labels:
            continue
        row = _plan_row(config, entry, scene, belief, realisation, settings)
        plans.append(row)
        if row["executed"]:
            grasp = np.array([[row["g1x"], row["g1y"]], [row["g2x"], row["g2y"]]])
            outcomes = evaluate_draws(grasp, draws.first(config.analytic_draws), settings)
            est = outcomes.estimates[0]
            analytic.append({"scene": name, "realisation": realisation, "planner": entry.label,
                             "draws": est.samples, "p_f": est.p_f, "ci_low": est.ci_low, "ci_high": est.ci_high,
                             "ferrari_canny_mean": est.ferrari_canny_mean,
                             "failures": json.dumps(est.failures, sort_keys=True), "p_l": est.p_l,
                             "p_l_ci_low": est.p_l_ci_low, "p_l_ci_high": est.p_l_ci_high, "pivots": est.pivots,
                             "reasons": draw_reasons(outcomes.reason[0, :config.posterior_trials])})
    k = config.posterior_trials
    polygons = [field_polygon(f, belief.grid) for f in draws.shapes.values[:k]]
    truth_approach = stream(config.seed, name, realisation, "truth-approach").standard_normal(
        (config.truth_trials, 2, 2))
    truth_friction = stream(config.seed, name, realisation, "truth-friction").standard_normal(config.truth_trials)
    return CellResult(name, realisation, plans, analytic, polygons, draws.approach[:k].copy(),
                      draws.friction[:k].copy(), truth_approach, truth_friction, time.perf_counter() - start)


def draw_reasons(reason: np.ndarray) -> str:
    """The analytic verdicts of the draws that posterior trials 0, 1, ... share, as text
    for the ledger: one comma-separated name per draw ('lifted' or the failure reason)."""
    from harness.quality import FAILURE_REASONS

    return ",".join("lifted" if r < 0 else FAILURE_REASONS[r] for r in reason)


class _Overtime(Exception):
    pass


def _plan_row(config, entry: PlannerEntry, scene, belief, realisation, settings) -> dict:
    """Run one planner under the harness's checks; never raises for the planner's faults."""
    from harness.seeding import stream
    from planners.base import Problem
    from planners.registry import make_planner

    row = {"scene": scene.name, "realisation": realisation, "planner": entry.label, "planner_name": entry.name,
           "params": json.dumps(entry.params, sort_keys=True), "status": "error", "executed": 0, "message": "",
           "g1x": None, "g1y": None, "g2x": None, "g2y": None, "estimate": None, "plan_time_s": 0.0,
           "iterations": 0, "evaluations": 0, "trace": "[]"}
    budget = config.time_budget_s
    problem = Problem(belief, settings, time_budget_s=budget)
    rng = stream(config.seed, scene.name, realisation, "planner", entry.label)
    start = time.perf_counter()
    try:
        planner = make_planner(entry.name, entry.params)
        with _deadline(HARD_STOP_FACTOR * budget + HARD_STOP_EXTRA_S):
            plan = planner.plan(problem, rng)
    except _Overtime:
        row.update(status="overtime", message=f"stopped after {time.perf_counter() - start:.1f} s "
                                              f"(budget {budget:g} s)", plan_time_s=time.perf_counter() - start)
        return row
    except Exception as exc:  # noqa: BLE001 - a plugin's bug is an outcome, not the end of the experiment
        row.update(status="raised", message=f"{type(exc).__name__}: {exc}"[:500],
                   plan_time_s=time.perf_counter() - start)
        return row
    elapsed = time.perf_counter() - start
    row.update(plan_time_s=elapsed, status=str(plan.status), message=str(plan.message or "")[:500],
               iterations=int(plan.iterations or 0), evaluations=int(plan.evaluations or 0),
               trace=json.dumps([[float(v) for v in t] for t in (plan.trace or ())]))
    estimate = plan.estimate
    row["estimate"] = float(estimate) if estimate is not None and math.isfinite(float(estimate)) else None
    grasp = plan.grasp
    if grasp is None:
        return row
    coords = np.asarray([grasp.g1, grasp.g2], dtype=float)
    if coords.shape == (2, 2) and np.isfinite(coords).all():
        row.update(g1x=coords[0, 0], g1y=coords[0, 1], g2x=coords[1, 0], g2y=coords[1, 1])
    problem_text = grasp.problem(scene.grid, settings.opening) if np.isfinite(coords).all() else \
        "non-finite coordinates"
    if problem_text:
        row.update(status="invalid", message=f"grasp rejected: {problem_text}")
    elif elapsed > OVERTIME_SLACK * budget + OVERTIME_GRACE_S:
        row.update(status="overtime", message=f"took {elapsed:.1f} s (budget {budget:g} s)")
    row["executed"] = int(row["status"] in EXECUTABLE)
    return row


class _deadline:
    """Stop the planner (raise _Overtime in it) after ``seconds``, where Unix timers allow
    (the main thread of a worker process); elsewhere the overtime is only recorded."""

    def __init__(self, seconds: float):
        self.seconds = seconds
        self.armed = hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()

    def __enter__(self):
        if self.armed:
            self.previous = signal.signal(signal.SIGALRM, self._fire)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)

    def __exit__(self, *exc):
        if self.armed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self.previous)

    @staticmethod
    def _fire(signum, frame):
        raise _Overtime()


@dataclass(frozen=True)
class Batch:
    """One physics task: consecutive trials ``indices`` of one plan on one shape source."""

    scene_path: str
    scene: str
    realisation: int
    planner: str
    shapes: str
    indices: tuple[int, ...]
    grasp: tuple
    polygons: list
    approach: np.ndarray
    friction: np.ndarray


_THREAD = threading.local()


def _runner(protocol):
    """This thread's pybullet client for ``protocol``, kept between batches (a connect
    costs about 25 ms). One per thread, as a Dask worker may run tasks in several. Each
    batch starts from a reset world, so its outcomes do not depend on what ran before
    (tested)."""
    from harness.physics.trial import MAX_BATCH, Runner

    runners = _THREAD.__dict__.setdefault("runners", {})
    if protocol not in runners:
        runners[protocol] = Runner(protocol, batch_size=MAX_BATCH)
    return runners[protocol]


def run_batch(config: ExperimentConfig, batch: Batch) -> list[dict]:
    """The trials of one batch in one freshly reset pybullet world; rows for the ledger."""
    from harness.physics.simulate import make_trials

    trials = make_trials(settings_of(config, batch.scene_path), np.asarray(batch.grasp), batch.polygons,
                         batch.approach, batch.friction)
    results = _runner(config.protocol()).run(trials)
    return [_trial_row(batch, i, r.outcome, r.steps, r.grip_width, r.closing_turn, r.rise, r.pivot)
            for i, r in zip(batch.indices, results, strict=True)]


def _trial_row(b: Batch, index: int, outcome: str, steps: int = 0, grip_width=None, closing_turn=None,
               rise=None, pivot=None) -> dict:

    def num(v):
        return None if v is None or not math.isfinite(v) else float(v)

    return {"scene": b.scene, "realisation": b.realisation, "planner": b.planner, "shapes": b.shapes,
            "trial": int(index), "outcome": outcome, "steps": int(steps), "grip_width": num(grip_width),
            "closing_turn": num(closing_turn), "rise": num(rise), "pivot": num(pivot)}


def batches_of(config: ExperimentConfig, path: str, cell: CellResult, plan: dict,
               done: set[tuple[str, str, int]]) -> tuple[list[Batch], list[dict]]:
    """A plan's missing trials: batches to simulate, and ``no_plan`` rows when the plan
    has nothing to execute (those trials count as failures of the planner)."""
    from harness.physics.simulate import truth_polygon

    batches, rows = [], []
    label = plan["planner"]
    grasp = ((plan["g1x"], plan["g1y"]), (plan["g2x"], plan["g2y"]))
    for shapes, count in (("posterior", config.posterior_trials), ("truth", config.truth_trials)):
        for lo in range(0, count, config.batch_size):
            indices = tuple(i for i in range(lo, min(count, lo + config.batch_size)))
            if all((label, shapes, i) in done for i in indices):
                continue
            key = Batch(path, cell.scene, cell.realisation, label, shapes, indices, grasp, [], None, None)
            if not plan["executed"]:
                rows.extend(_trial_row(key, i, NO_PLAN) for i in indices if (label, shapes, i) not in done)
                continue
            sl = slice(indices[0], indices[-1] + 1)
            if shapes == "posterior":
                polygons, approach, friction = cell.polygons[sl], cell.approach[sl], cell.friction[sl]
            else:
                polygons = [truth_polygon(scene_of(config, path))]
                approach, friction = cell.truth_approach[sl], cell.truth_friction[sl]
            batches.append(replace(key, polygons=polygons, approach=approach, friction=friction))
    return batches, rows


# ---------------------------------------------------------------------------
# The main loop: the only writer of the ledger


def environment() -> dict:
    """Package versions, the git commit and the machine, for the manifest."""
    import platform
    import subprocess
    import sys
    from importlib.metadata import PackageNotFoundError, version

    from harness.provenance import reproducibility

    versions = {}
    for pkg in ("gpis-harness", "numpy", "scipy", "osqp", "pandas", "pybullet", "shapely", "matplotlib"):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            versions[pkg] = None
    try:
        root = Path(__file__).resolve().parent.parent
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, check=False,
                                timeout=10).stdout.strip() or None
        dirty = bool(subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                    capture_output=True, text=True, check=False, timeout=10).stdout.strip())
    except (OSError, subprocess.SubprocessError):
        commit, dirty = None, None
    return {"python": sys.version.split()[0], "packages": versions, "git_commit": commit, "git_dirty": dirty,
            "machine": {"platform": platform.platform(), "processor": platform.machine(),
                        "cpus": __import__("os").cpu_count()}, "reproducibility": reproducibility()}


@dataclass
class RunStats:
    plans: int = 0
    trials: int = 0
    seconds: float = 0.0
    interrupted: bool = False
    errors: list = field(default_factory=list)


def run_experiment(config: ExperimentConfig, out_dir: Path, workers: int | None = None,
                   scheduler: str | None = None, fresh: bool = False, log=print) -> RunStats:
    """Run (or resume) an experiment into ``out_dir``'s ledger."""
    from harness.executor import make_executor
    from harness.ledger import FILENAME, Ledger

    out_dir.mkdir(parents=True, exist_ok=True)
    stats = RunStats()
    start = time.perf_counter()
    key = config.hash
    with Ledger(out_dir / FILENAME) as ledger:
        if fresh:
            ledger.forget(key)
        run = ledger.start_run(key, config.name, config.as_dict(), environment())
        todo = []  # cells with work left: (path, realisation, labels to plan, plans already done, trials done)
        n_plans = n_trials = done_plans = done_trials = 0
        per_plan = config.posterior_trials + config.truth_trials
        for path, r in config.cells():
            name = Path(path).stem
            plans = ledger.plan_rows(key, name, r)
            trials = ledger.done_trials(key, name, r)
            labels = tuple(e.label for e in config.planners if e.label not in plans)
            n_plans += len(config.planners)
            n_trials += len(config.planners) * per_plan
            done_plans += len(config.planners) - len(labels)
            done_trials += len(trials)
            if labels or len(trials) < len(config.planners) * per_plan:
                todo.append((path, r, labels, plans, trials))
        executor = make_executor(workers, scheduler)
        log(f"{config.name}: {len(config.scenes)} scenes x {config.realisations} realisations x "
            f"{len(config.planners)} planners, {per_plan} trials per plan; config {key}; {executor.description}"
            + (f"; resuming with {done_plans} plans and {done_trials} trials done" if done_plans or done_trials
               else ""))
        bars = [_Progress("plans", n_plans, done_plans, 0, start, log),
                _Progress("trials", n_trials, done_trials, 1, start, log)]
        status = "interrupted"
        try:
            for path, r, labels, _, _ in todo:
                executor.submit(run_cell, config, path, r, labels, tag=("cell", path, r))
            known = {(path, r): (plans, trials) for path, r, _, plans, trials in todo}
            while executor.pending:
                tag, future = executor.next_done()
                try:
                    result = future.result()
                except Exception as exc:  # noqa: BLE001 - a task's failure is logged, the run goes on
                    stats.errors.append(f"{tag[0]} {tag[1:]}: {type(exc).__name__}: {exc}")
                    continue
                if tag[0] == "cell":
                    _, path, r = tag
                    plans, done = known[(path, r)]
                    ledger.add(key, {"plans": result.plans, "analytic": result.analytic})
                    stats.plans += len(result.plans)
                    bars[0].update(len(result.plans))
                    for row in list(plans.values()) + result.plans:
                        batches, rows = batches_of(config, path, result, row, done)
                        if rows:
                            ledger.add(key, {"trials": rows})
                            bars[1].update(len(rows))
                        for batch in batches:
                            executor.submit(run_batch, config, batch, tag=("batch", len(batch.indices)))
                else:
                    ledger.add(key, {"trials": result})
                    stats.trials += len(result)
                    bars[1].update(len(result))
            status = "complete" if not stats.errors else "errors"
        except KeyboardInterrupt:
            stats.interrupted = True
        finally:
            for bar in bars:
                bar.close()
            executor.close(cancel=status == "interrupted")
            ledger.end_run(run, status)
    stats.seconds = time.perf_counter() - start
    for error in stats.errors:
        log(f"task failed: {error}")
    return stats


class _Progress:
    """A tqdm bar on a terminal (counts, rate, time left); without one, a line when the
    phase completes."""

    def __init__(self, desc: str, total: int, initial: int, position: int, start: float, log):
        from tqdm import tqdm

        self.desc, self.total, self.n, self.start, self.log = desc, total, initial, start, log
        self.bar = tqdm(total=total, initial=initial, desc=desc, unit=desc[:-1], disable=None, position=position,
                        dynamic_ncols=True, smoothing=0.1)

    def update(self, n: int) -> None:
        self.n += n
        self.bar.update(n)
        if self.bar.disable and n and self.n >= self.total:
            self.log(f"{self.desc}: {self.n}/{self.total} done after {time.perf_counter() - self.start:.0f} s")

    def close(self) -> None:
        self.bar.close()
