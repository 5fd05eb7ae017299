"""Shared test options and fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_OBJECTS = REPO.parent / "shared" / "objects"


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False, help="also run tests marked slow")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow (make test-all)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="module")
def beliefs():
    """beliefs(name): the library scene's belief at seed 0, prepared, built once per test
    module (test_belief.py keeps its own, unprepared)."""
    from harness.belief import build_belief
    from harness.scene import load_scene
    from harness.seeding import stream

    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = build_belief(load_scene(name), stream(0, name, 0, "sensor")).prepare()
        return cache[name]

    return get
