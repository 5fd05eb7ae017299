"""The command line: parse, call, print. Bad input exits 2 with one line on stderr."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import sys
import time
import traceback
from pathlib import Path

from harness.errors import InputError
from harness.protocol import ENGINES

PROG = "gpis-harness"


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line (exit 2) instead of a usage block.

    Coordinates such as ``-9.1e-05`` (what ``plan --json`` prints) must read as numbers, not as
    options; argparse's own pattern knows only ``-1`` and ``-1.5``, so it is widened here.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")

    def error(self, message: str):
        command = self.prog.removeprefix(PROG).strip()
        raise InputError(f"command line{': ' + command if command else ''}", None, message)


def _checked(convert, accept, expected: str):
    """An argparse type: convert the text, then require ``accept(value)``."""

    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not accept(value):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text}")
        return value

    return parse


_seed = _checked(int, lambda v: v >= 0, "a non-negative integer seed")
_positive_int = _checked(int, lambda v: 1 <= v <= 1_000_000, "an integer from 1 to 1000000")
_non_negative = _checked(float, lambda v: math.isfinite(v) and v >= 0, "a finite number >= 0")
_positive_number = _checked(float, lambda v: math.isfinite(v) and v > 0, "a finite number > 0")
_coordinate = _checked(float, math.isfinite, "a finite coordinate in metres")
_sizes = _checked(lambda t: [int(v) for v in t.split(",")], lambda v: len(v) > 0 and all(8 <= m <= 1024 for m in v),
                  "comma-separated grid sizes from 8 to 1024, like 25,40,55")
_study_seeds = _checked(int, lambda v: 0 <= v <= 1000, "an integer from 0 to 1000")
_study_candidates = _checked(int, lambda v: 1 <= v <= 10_000, "an integer from 1 to 10000")
_draw_counts = _checked(lambda t: [float(v) for v in t.split(",")],
                        lambda v: all(0.0 <= x <= 100_000.0 for x in v),
                        "comma-separated numbers from 0 to 100000, like 0,10,30")
_names = _checked(lambda t: [v.strip() for v in t.split(",")], lambda v: all(v),
                  "comma-separated scene names like disk,tape")


def _scenes_list(args) -> int:
    from harness.scene import library_names, load_scene

    names = library_names()
    width = max((len(n) for n in names), default=0)
    for name in names:
        print(f"{name:<{width}}  {load_scene(name).description}")
    return 0


def _scenes_check(args) -> int:
    from harness.scene import load_scene

    for item in args.scene:
        scene = load_scene(item)
        print(f"{scene.source}: ok ({scene.name}, grid {scene.grid.size} x {scene.grid.size})")
    return 0


def _render(scene_arg: str, seed: int, out: Path) -> Path:
    """Observe, fit and draw one scene; returns the PNG written."""
    import matplotlib.pyplot as plt

    from harness.belief import build_belief
    from harness.outputs import output_folder, storage
    from harness.plots import scene_figure
    from harness.scene import load_scene
    from harness.seeding import stream

    scene = load_scene(scene_arg)
    output_folder(out.parent, "--out", "the pictures' folder")  # before any work: one line if it cannot be made
    belief = build_belief(scene, stream(seed, scene.name, 0, "sensor"))
    fig = scene_figure(belief, stream(seed, scene.name, 0, "picture"))
    try:
        with storage(out, "cannot write the picture"):
            fig.savefig(out, dpi=110)
    finally:
        plt.close(fig)
    return out


def _scenes_show(args) -> int:
    from harness.scene import load_scene

    scene = load_scene(args.scene)  # validate before any work
    out = Path(args.out) if args.out else Path("results") / "scenes" / f"{scene.name}.png"
    if out.suffix.lower() != ".png":
        raise InputError("--out", None, f"{out}: the picture is written as PNG; give a .png file name")
    print(_render(args.scene, args.seed, out))
    return 0


def _scenes_render(args) -> int:
    from harness.scene import library_names, load_scene

    names = library_names()
    for name in names:
        load_scene(name)
    for name in names:
        print(_render(name, args.seed, Path(args.out) / f"{name}.png"), flush=True)
    return 0


def _scenes_generate(args) -> int:
    from harness.procedural import object_set, write_set
    from harness.scene import load_scene

    paths = write_set(Path(args.out), object_set(args.per_family))
    for path in paths:  # each a valid scene, or the command says which is not
        load_scene(path)
    print(f"{len(paths)} procedural scenes in {args.out} (harness/procedural.py; docs/scenes.md)")
    return 0


def _scene_and_grasp(args):
    """The scene, the --grasp and the grasp settings of a command; a grasp the gripper
    cannot execute is bad input."""
    from harness.grasp import Grasp
    from harness.scene import load_scene

    scene = load_scene(args.scene)
    settings = _settings(args, scene)
    grasp = Grasp(tuple(args.grasp[:2]), tuple(args.grasp[2:]))
    problem = grasp.problem(scene.grid, settings.opening)
    if problem:
        raise InputError("--grasp", None, problem)
    return scene, grasp, settings


def _quality(args) -> int:
    from harness import pipeline
    from harness.memory import check_single

    scene, grasp, settings = _scene_and_grasp(args)
    check_single(scene, args.seed, args.samples, field="--samples")
    cell = pipeline.open_cell(scene, settings, args.seed, 0, args.samples)
    est = pipeline.judge(cell, grasp, args.samples).estimates[0]
    if args.json:
        out = est.as_dict() | {"scene": scene.name, "grasp": {"g1": list(grasp.g1), "g2": list(grasp.g2)},
                               "sigma_g": settings.sigma_g, "friction": settings.friction,
                               "friction_spread": settings.friction_spread, "force": settings.force,
                               "seed": args.seed}
        print(json.dumps(out))
    else:
        fails = ", ".join(f"{k} {v}" for k, v in est.failures.items())
        print(f"{scene.name}: P_F = {est.p_f:.3f} (95% CI {est.ci_low:.3f} to {est.ci_high:.3f}), "
              f"P_L = {est.p_l:.3f} (95% CI {est.p_l_ci_low:.3f} to {est.p_l_ci_high:.3f}) over "
              f"{est.samples} draws, sigma_g = {settings.sigma_g:g} m, friction = {settings.friction:g}, "
              f"force = {settings.force:g} N")
        print(f"failures: {fails}; the plates' squeeze settled {est.squeezed} draws out of force closure; "
              f"the weight turned the object in {est.pivots} draws; "
              f"mean Ferrari-Canny quality {est.ferrari_canny_mean:.4f}")
    return 0


def _simulate(args) -> int:
    from tqdm import tqdm

    from harness import pipeline
    from harness.memory import check_single
    from harness.outputs import output_folder, storage
    from harness.physics.simulate import SimulationSummary, make_trials
    from harness.physics.engines import make_runner
    from harness.physics.trace import Tracer
    from harness.protocol import Protocol

    scene, grasp, settings = _scene_and_grasp(args)
    if args.frames is not None:  # made now, before any trial: one line if it cannot be
        output_folder(Path(args.frames), "--frames", "the frames' folder")
    if args.trace is not None and (Path(args.trace).is_dir() or not Path(args.trace).parent.is_dir()):
        raise InputError("--trace", None, f"{args.trace} is a folder" if Path(args.trace).is_dir()
                         else f"{Path(args.trace).parent} is not a folder")
    if args.trace is not None:
        with storage(args.trace, "cannot write the trace"):
            Path(args.trace).touch()
    if args.shapes == "posterior":
        # As many draws as eval's default analytic draws: trial i is eval's posterior trial i.
        draws = pipeline.cell_draws(pipeline.DRAWS, args.trials)
        check_single(scene, args.seed, draws, field="--trials")
        inputs = pipeline.posterior_inputs(pipeline.open_cell(scene, settings, args.seed, 0, draws), args.trials)
    else:
        inputs = pipeline.truth_inputs(scene, args.seed, 0, args.trials)
    trials = make_trials(settings, grasp, inputs.polygons, inputs.approach, inputs.friction)
    start = time.perf_counter()
    bar = tqdm(total=len(trials), unit="trial", disable=None, file=sys.stderr)
    tracer = Tracer() if args.trace else None
    frames = storage(args.frames, "cannot write the frames") if args.frames else contextlib.nullcontext()
    with make_runner(Protocol.of(args.engine)) as runner, bar, frames:
        results = runner.run(trials, frames=Path(args.frames) if args.frames else None, progress=bar.update,
                             trace=tracer)
    if tracer is not None:
        with storage(args.trace, "cannot write the trace"):
            tracer.write(Path(args.trace))
    summary = SimulationSummary(tuple(results), time.perf_counter() - start)
    out = summary.as_dict()
    if args.json:
        print(json.dumps(out | {"scene": scene.name, "grasp": {"g1": list(grasp.g1), "g2": list(grasp.g2)},
                                "shapes": args.shapes, "engine": args.engine, "sigma_g": settings.sigma_g,
                                "friction": settings.friction, "friction_spread": settings.friction_spread,
                                "force": settings.force,
                                "seed": args.seed}))
    else:
        counts = ", ".join(f"{k} {v}" for k, v in out["outcomes"].items() if v)
        print(f"{scene.name} ({args.shapes}): success {out['successes']}/{out['trials']} = "
              f"{out['success_rate']:.3f} (95% CI {out['ci_low']:.3f} to {out['ci_high']:.3f}), "
              f"sigma_g = {settings.sigma_g:g} m, friction = {settings.friction:g}, force = {settings.force:g} N")
        print(f"outcomes: {counts}; {out['trials_per_s']:.1f} trials/s in {args.engine}")
        if args.frames:
            print(f"frames of the first trial in {args.frames}")
        if args.trace and tracer.rows:
            print(f"the first trial's trace in {args.trace} ({len(tracer.rows)} checks)")
        elif args.trace:
            print(f"the first trial ended {results[0].outcome} before its jaws closed: its trace in "
                  f"{args.trace} has no rows")
    return 0


def _eval(args) -> int:
    from harness.config import load_config
    from harness.executor import check_scheduler
    from harness.experiment import run_experiment
    from harness.memory import check_config
    from harness.outputs import command_line, folder_lock, output_folder, storage

    config = load_config(args.config)
    if args.engine is not None:
        config = config.with_engine(args.engine)
    warning = check_scheduler(args.scheduler)  # before any folder or ledger exists
    if warning:
        print(f"{PROG}: warning: {warning}", file=sys.stderr)
    workers = args.workers or os.cpu_count() or 1
    plan_memory = check_config(config, workers, args.memory_budget)
    out = output_folder(Path(args.out) if args.out else Path("results") / config.name)  # name-ENGINE if given

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    with folder_lock(out, command_line()):
        with storage(out, "cannot record the run"):
            stats = run_experiment(config, out, workers=workers, scheduler=args.scheduler, fresh=args.fresh,
                                   log=log, plan_memory=plan_memory)
        if stats.interrupted:
            log(f"interrupted after {stats.seconds:.0f} s; {stats.plans} plans and {stats.trials} trials were "
                f"recorded in {out}; run the same command again to resume")
            return 130
        log(f"{stats.plans} plans and {stats.trials} trials in {stats.seconds:.0f} s")
        if not args.no_report:
            _print_report(out, figures=True)
    return 1 if stats.errors else 0


def _report(args) -> int:
    from harness.outputs import command_line, folder_lock

    out = Path(args.dir)
    if not out.is_dir():
        raise InputError(str(out), None, "no such results folder")
    with folder_lock(out, command_line()):
        _print_report(out, figures=not args.no_figures)
        if args.draws:
            from harness.explain import write_draws
            from harness.outputs import storage

            with storage(out, "cannot write draws.csv"):
                path = write_draws(out)
            print(f"each posterior trial beside its draw's lift model in {path}", file=sys.stderr)
    return 0


def _print_report(out: Path, figures: bool) -> None:
    from harness.outputs import storage
    from harness.report import display_table, write_report

    with storage(out, "cannot write the report"):
        tables = write_report(out, figures=figures)
    print(display_table(tables["summary"]).to_markdown(index=False))
    if tables["budget_note"]:
        print(f"\nnote: {tables['budget_note']}", file=sys.stderr)
    print(f"\ntables and figures in {out}", file=sys.stderr)


def _compare(args) -> int:
    from harness.compare import as_json, as_markdown, compare

    result = compare(Path(args.dir_a), Path(args.dir_b), engines=args.engines)
    print(json.dumps(as_json(result), default=str) if args.json else as_markdown(result))
    return 0


def _planners_list(args) -> int:
    from planners.registry import available, range_text

    found, broken = available()
    for name in sorted(found):
        cls = found[name]
        params = ", ".join(f"{k}={v!r} {range_text(cls, k)}".rstrip() for k, v in cls.parameters().items())
        print(f"{name}: {cls.description}")
        print(f"    parameters: {params or 'none'}")
    for name, error in sorted(broken.items()):
        print(f"{name}: failed to load ({error})", file=sys.stderr)
    return 0


def _key_value(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    return key.strip(), value.strip()


def _settings(args, scene):
    """The scene's grasp settings with the command line's --sigma-g, --friction,
    --friction-spread and --force where given."""
    from harness.settings import override_problem, resolve

    options = {"sigma_g": args.sigma_g, "friction": args.friction, "friction_spread": args.friction_spread,
               "force": args.force}
    given = {k: v for k, v in options.items() if v is not None}
    for key, value in given.items():
        problem = override_problem(key, value)
        if problem:
            raise InputError(f"--{key.replace('_', '-')}", None, problem)
    return resolve(scene, given)


def _plan(args) -> int:
    from harness import pipeline
    from harness.memory import check_single
    from harness.scene import load_scene
    from planners.registry import make_planner

    scene = load_scene(args.scene)
    keys = [key for key, _ in args.param or []]
    twice = sorted({key for key in keys if keys.count(key) > 1})
    if twice:
        raise InputError("--param", None, f"{twice[0]} is given more than once")
    params = dict(args.param or [])
    planner = make_planner(args.planner, params)  # bad input stops here, before any work
    settings = _settings(args, scene)
    memory = check_single(scene, args.seed, pipeline.DRAWS, planner.shape_samples())
    cell = pipeline.open_cell(scene, settings, args.seed, 0, pipeline.DRAWS)
    # As eval records a cell's plan: the planner's label is its name as given.
    row, fault = pipeline.plan(cell, args.planner, args.planner, params, args.time_budget, memory)
    grasp = None if row["g1x"] is None else {"g1": [row["g1x"], row["g1y"]], "g2": [row["g2x"], row["g2y"]]}
    out = {"planner": args.planner, "scene": scene.name, "seed": args.seed, "status": row["status"], "grasp": grasp,
           "estimate": row["estimate"], "plan_time_s": row["plan_time_s"], "iterations": row["iterations"],
           "evaluations": row["evaluations"], "p_f": None, "ci_low": None, "ci_high": None, "p_l": None,
           "p_l_ci_low": None, "p_l_ci_high": None, "sigma_g": settings.sigma_g, "friction": settings.friction,
           "force": settings.force, "params": planner.get_params(), "message": row["message"]}
    if row["executed"]:  # judged on the evaluation draws every planner shares at this seed
        analytic = pipeline.analytic_row(cell, row, pipeline.DRAWS, 0)
        out.update({k: analytic[k] for k in ("p_f", "ci_low", "ci_high", "p_l", "p_l_ci_low", "p_l_ci_high")})
    if fault:  # the planner's own traceback, for its author
        print(fault.rstrip(), file=sys.stderr)
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{scene.name} / {args.planner}: {out['status']} in {out['plan_time_s']:.3f} s "
              f"({out['iterations']} iterations, {out['evaluations']} evaluations)")
        if row["executed"]:
            print(f"grasp g1 = ({grasp['g1'][0]:.4f}, {grasp['g1'][1]:.4f}) m, "
                  f"g2 = ({grasp['g2'][0]:.4f}, {grasp['g2'][1]:.4f}) m; "
                  f"P_F = {out['p_f']:.3f} (95% CI {out['ci_low']:.3f} to {out['ci_high']:.3f}), "
                  f"P_L = {out['p_l']:.3f} (95% CI {out['p_l_ci_low']:.3f} to {out['p_l_ci_high']:.3f}); "
                  f"planner's estimate {out['estimate'] if out['estimate'] is None else round(out['estimate'], 3)}")
        if out["message"]:
            print(out["message"])
    return 0


def _bench(args) -> int:
    from harness import bench
    from harness.bench.common import jsonable

    if args.which == "regimes":
        from harness.executor import check_scheduler

        warning = check_scheduler(args.scheduler)  # before any folder or ledger exists
        if warning:
            print(f"{PROG}: warning: {warning}", file=sys.stderr)
    results = bench.run(args.which, _bench_settings(args), log=lambda line: print(line, file=sys.stderr, flush=True))
    if args.json:
        print(json.dumps(results, indent=2, default=jsonable))
    else:
        print(bench.format_results(args.which, results))
    return 0


def _bench_settings(args) -> dict:
    """Each study's Settings from the command line (options a study does not take are
    not passed to it; options not given keep the study's defaults)."""
    from harness.bench import bandit_study, engines_study, planning_study, regimes_study, sampling_study

    scenes = tuple(args.scenes) if args.scenes is not None else None
    given = {k: v for k, v in {"seeds": args.seeds, "scenes": scenes, "candidates": args.candidates}.items()
             if v is not None}
    bandit = bandit_study.Settings(**given, first_seed=args.first_seed, shared_draws=tuple(args.shared_draws),
                                   prior_draws=tuple(args.prior_draws))
    sizes = {"sizes": tuple(args.sizes)} if args.sizes else {}
    return {"sampling": sampling_study.Settings(**sizes, exact_max_mb=args.exact_max_mb),
            "planning": planning_study.Settings(**sizes, bandit=bandit),
            "bandit": bandit,
            "engines": engines_study.Settings(out=Path(args.out or "results/engines"), workers=args.workers),
            "regimes": regimes_study.Settings(out=Path(args.out) if args.out else None, engines=tuple(args.engines),
                                              workers=args.workers, scheduler=args.scheduler, objects=args.objects,
                                              regimes=args.regimes)}


def _bench_names() -> list[str]:
    from harness.bench import STUDIES

    return list(STUDIES)


def _engine_list(text: str) -> tuple[str, ...]:
    from harness.protocol import ENGINES

    names = tuple(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))
    bad = [n for n in names if n not in ENGINES]
    if not names or bad:
        raise argparse.ArgumentTypeError(f"expected engines from {', '.join(ENGINES)}, comma-separated; got '{text}'")
    return names


def _regime_list(text: str) -> tuple[str, ...]:
    from harness.bench.regimes_study import regimes_named

    names = tuple(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))
    try:
        return tuple(r.name for r in regimes_named(names))
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


_GRASP = {"nargs": 4, "type": _coordinate, "required": True, "metavar": ("X1", "Y1", "X2", "Y2"),
          "help": "jaw start points g1 and g2 in metres"}


def _add_problem_options(p: argparse.ArgumentParser) -> None:
    """--seed, --sigma-g, --friction, --friction-spread and --force, shared by plan, quality and simulate."""
    p.add_argument("--seed", type=_seed, default=0, help="experiment seed (default 0)")
    p.add_argument("--sigma-g", type=_non_negative, default=None,
                   help="approach noise std per jaw start, metres (default: the scene's gripper.sigma_g)")
    p.add_argument("--friction", type=_non_negative, default=None,
                   help="jaw-object friction coefficient (default: the scene's physics.friction)")
    p.add_argument("--friction-spread", type=_non_negative, default=None,
                   help="std of the friction coefficient across draws (default 0)")
    p.add_argument("--force", type=float, default=None, metavar="NEWTONS",
                   help="the gripper's grip force, N (default: the scene's gripper.force)")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description="Grasp planning under shape uncertainty, validated by physics.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    scenes = sub.add_parser("scenes", help="the scene library: list, check, show, render, generate")
    ssub = scenes.add_subparsers(dest="scenes_command", required=True, parser_class=_Parser)
    p = ssub.add_parser("list", help="name and description of every library scene")
    p.set_defaults(func=_scenes_list)
    p = ssub.add_parser("check", help="validate scene files (or library names)")
    p.add_argument("scene", nargs="+", help="library name or path to a scene file")
    p.set_defaults(func=_scenes_check)
    p = ssub.add_parser("show", help="picture of one scene's belief (PNG)")
    p.add_argument("scene", help="library name or path to a scene file")
    p.add_argument("--seed", type=_seed, default=0, help="experiment seed (default 0)")
    p.add_argument("--out", help="PNG file (default results/scenes/NAME.png)")
    p.set_defaults(func=_scenes_show)
    p = ssub.add_parser("render", help="pictures of every library scene into a folder")
    p.add_argument("--out", default="results/scenes", help="folder (default results/scenes)")
    p.add_argument("--seed", type=_seed, default=0, help="experiment seed (default 0)")
    p.set_defaults(func=_scenes_render)
    p = ssub.add_parser("generate", help="write the procedural object set as scene files into a folder")
    p.add_argument("--out", default="results/procedural", help="folder (default results/procedural)")
    p.add_argument("--per-family", type=_positive_int, default=20,
                   help="objects of each of the six families (default 20: 120 objects)")
    p.set_defaults(func=_scenes_generate)

    p = sub.add_parser("quality", help="Monte-Carlo probabilities of force closure (P_F) and lift (P_L) of one grasp")
    p.add_argument("scene", help="library name or path to a scene file")
    p.add_argument("--grasp", **_GRASP)
    p.add_argument("--samples", type=_positive_int, default=1000, help="paired draws (default 1000)")
    _add_problem_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_quality)

    p = sub.add_parser("simulate", help="physics trials of one grasp (pybullet or MuJoCo)")
    p.add_argument("scene", help="library name or path to a scene file")
    p.add_argument("--grasp", **_GRASP)
    p.add_argument("--trials", type=_positive_int, default=100, help="number of trials (default 100)")
    p.add_argument("--shapes", choices=["truth", "posterior"], default="posterior",
                   help="the true shape, or a new posterior sample per trial (default posterior)")
    _add_problem_options(p)
    p.add_argument("--frames", metavar="DIR", default=None,
                   help="write PNG snapshots of each phase of the first trial into DIR")
    p.add_argument("--trace", metavar="FILE", default=None,
                   help="write the first trial's trace, check by check (its turn, its slide in the jaws, "
                        "each jaw's contact points), as CSV to FILE (docs/physics.md)")
    p.add_argument("--engine", choices=ENGINES, default=ENGINES[0],
                   help="the physics engine (default pybullet; docs/physics.md)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_simulate)

    planners = sub.add_parser("planners", help="the available planners")
    psub = planners.add_subparsers(dest="planners_command", required=True, parser_class=_Parser)
    p = psub.add_parser("list", help="name, description and parameters of every planner")
    p.set_defaults(func=_planners_list)

    p = sub.add_parser("plan", help="plan a grasp on one scene with one planner")
    p.add_argument("scene", help="library name or path to a scene file")
    p.add_argument("--planner", required=True, help="planner name (see planners list)")
    p.add_argument("--param", type=_key_value, action="append", metavar="KEY=VALUE",
                   help="planner parameter (repeatable)")
    _add_problem_options(p)
    p.add_argument("--time-budget", type=_non_negative, default=None, help="seconds the planner may use")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_plan)

    p = sub.add_parser("eval", help="run (or resume) an experiment, then write its report")
    p.add_argument("config", nargs="?", default="experiments/default.toml",
                   help="experiment config (default experiments/default.toml)")
    p.add_argument("--out", default=None, help="results folder (default results/<config name>)")
    p.add_argument("--workers", type=_positive_int, default=None,
                   help="worker processes (default: the number of cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a Dask scheduler (tcp://HOST:PORT, or tls://HOST:PORT with Dask's TLS config), "
                        "or 'local' for a Dask LocalCluster")
    p.add_argument("--memory-budget", type=_positive_number, default=None, metavar="GIB",
                   help="memory one worker may use, GiB (default: 75%% of this machine's over the workers); "
                        "a config whose largest cell needs more is refused before any work")
    p.add_argument("--engine", choices=ENGINES, default=None,
                   help="simulate in this engine instead of the config's [physics] engine; the run is named "
                        "NAME-ENGINE (its own results folder by default)")
    p.add_argument("--fresh", action="store_true", help="discard this experiment's ledger rows and start over")
    p.add_argument("--no-report", action="store_true", help="skip the report at the end")
    p.set_defaults(func=_eval)

    p = sub.add_parser("report", help="tables and figures from a results folder's ledger")
    p.add_argument("dir", help="results folder written by eval")
    p.add_argument("--no-figures", action="store_true", help="tables only")
    p.add_argument("--draws", action="store_true",
                   help="also draws.csv: each posterior trial beside the lift model's quantities on its own draw "
                        "(the cells are drawn again: about a second each)")
    p.set_defaults(func=_report)

    p = sub.add_parser("compare", help="paired comparison of two runs of one experiment (B - A)")
    p.add_argument("dir_a", metavar="DIR_A", help="results folder of run A (the reference)")
    p.add_argument("dir_b", metavar="DIR_B", help="results folder of run B (the same experiment, changed)")
    p.add_argument("--engines", action="store_true",
                   help="a cross-engine comparison: refuse unless the runs differ in the physics engine alone")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_compare)

    bench = sub.add_parser("bench", help="benchmarks, measured as ratios in one run")
    bench.add_argument("which", nargs="?", default="all",
                       choices=[*_bench_names(), "all"])
    bench.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    bench.add_argument("--exact-max-mb", type=float, default=2500.0,
                       help="skip the dense exact sampler when its covariance exceeds this (default 2500)")
    bench.add_argument("--sizes", type=_sizes, default=None,
                       help="grid sizes M, comma-separated (defaults: sampling 25,40,55,70,100,200; "
                            "planning 25,50,100,200)")
    bench.add_argument("--seeds", type=_study_seeds, default=None,
                       help="seeds per scene of the bandit convergence study (bench bandit, part of bench "
                            "planning; default 3; 0 skips the study)")
    bench.add_argument("--scenes", type=_names, default=None,
                       help="the bandit study's scenes, comma-separated: library names or shared_<outline> "
                            "(default: the library and every outline in ../shared/objects)")
    bench.add_argument("--candidates", type=_study_candidates, default=None,
                       help="candidate grasps (arms) per run of the bandit study (default 100, gp-p's; "
                            "Laskey et al. used 1000)")
    bench.add_argument("--first-seed", type=_seed, default=0,
                       help="the bandit study's first seed (default 0; its runs use seeds FIRST_SEED to "
                            "FIRST_SEED + seeds - 1, so another value gives held-out runs)")
    bench.add_argument("--shared-draws", type=_draw_counts, default=(),
                       help="also run Thompson sampling with each of these values of gp-bandit's "
                            "shared_draws (comma-separated; labelled thompson-shared-VALUE): a sensitivity "
                            "study of shared evidence")
    bench.add_argument("--prior-draws", type=_draw_counts, default=(),
                       help="also run Thompson sampling with each of these values of gp-bandit's "
                            "prior_draws (comma-separated; labelled thompson-prior-VALUE): a sensitivity "
                            "study of the model prior's weight")
    bench.add_argument("--out", default=None,
                       help="bench engines: the folder of its two runs, its frames and study.json "
                            "(default results/engines); bench regimes: the folder of its runs, objects, "
                            "regimes.csv, verdicts.csv, regimes.json and regime_map.png (default results/regimes)")
    bench.add_argument("--workers", type=_positive_int, default=None,
                       help="bench engines and regimes: worker processes of each run (default: one per core)")
    bench.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="bench regimes: run on a Dask cluster ('local' or tcp://host:8786), as eval does")
    bench.add_argument("--objects", choices=("sweep", "fresh"), default="sweep",
                       help="bench regimes: the object set: 'sweep' (the 24 objects the lift model and the "
                            "planners were settled on, six held out; default) or 'fresh' (24 other objects of "
                            "the same families, all held out; default folder results/regimes-fresh)")
    bench.add_argument("--engines", type=_engine_list, default=("pybullet",),
                       help="bench regimes: the engines to run the sweep in, comma-separated "
                            "(default pybullet; pybullet,mujoco runs both)")
    bench.add_argument("--regimes", type=_regime_list, default=None, metavar="NAMES",
                       help="bench regimes: run only these regimes, comma-separated (default: all eleven); "
                            "each is the run the whole sweep makes, so a later run of all of them into the "
                            "same --out resumes these")
    bench.set_defaults(func=_bench)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``gpis-harness``; returns the exit code. Pins the numeric code
    paths first (harness.provenance), before anything loads numpy."""
    from harness.provenance import pin_code_paths

    pin_code_paths()
    try:
        args = build_parser().parse_args(argv)
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (e.g. `| head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except Exception:  # an internal error: the traceback helps the bug report
        traceback.print_exc()
        print(f"{PROG}: internal error (please report it with the traceback above)", file=sys.stderr)
        return 1
