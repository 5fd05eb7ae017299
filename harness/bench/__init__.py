"""Benchmarks and studies behind ``gpis-harness bench``: speeds measured as ratios within
one run, and the studies that set the model against the simulators.

One module per study, each with the same face:

- ``Settings``: the study's settings as one frozen value (its defaults are the study's);
- ``benchmark(settings) -> dict``: runs it and returns a JSON-ready result;
- ``format_lines(result) -> list[str]``: the result as text.

:func:`run` and :func:`format_results` dispatch by the study's name, so nothing guesses
which study a result came from.
"""

from __future__ import annotations

import importlib
import inspect

#: Every study by its name on the command line, and its module.
STUDIES = {
    "sampling": "harness.bench.sampling_study",
    "planning": "harness.bench.planning_study",
    "bandit": "harness.bench.bandit_study",
    "quality": "harness.bench.quality_study",
    "physics": "harness.bench.physics_study",
    "lift": "harness.bench.lift_study",
    "engines": "harness.bench.engines_study",
    "regimes": "harness.bench.regimes_study",
}
#: What ``bench all`` (and plain ``bench``) runs: the benchmarks that need no experiment.
ALL = ("sampling", "planning", "quality", "physics", "lift")


def study(name: str):
    """The module of study ``name`` (a key of STUDIES)."""
    return importlib.import_module(STUDIES[name])


def run(which: str = "all", settings: dict | None = None, log=print) -> dict:
    """Run study ``which`` (or every study of ALL) with ``settings`` (study name ->
    its module's ``Settings``; a study not named gets its defaults). ``log`` receives the
    progress lines of the studies that run experiments (engines, regimes). Returns the
    study's result, or for "all" a dict of results by study name."""
    settings = settings or {}
    names = ALL if which == "all" else (which,)
    results = {}
    for name in names:
        module = study(name)
        value = settings.get(name, module.Settings())
        takes_log = "log" in inspect.signature(module.benchmark).parameters
        results[name] = module.benchmark(value, log=log) if takes_log else module.benchmark(value)
    return results if which == "all" else results[which]


def format_results(which: str, results: dict) -> str:
    """The result of study ``which`` (or of "all": a dict by study name) as text."""
    if which != "all":
        return "\n".join(study(which).format_lines(results))
    return "\n\n".join("\n".join(study(name).format_lines(res)) for name, res in results.items())
