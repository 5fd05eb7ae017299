"""The benchmark's tiers (experiments/benchmark-*.toml, docs/benchmark.md): each a valid
experiment over the committed procedural set, make eval's planners, the hard tier over
at least 100 distinct objects, and the tiers ordered from easy to hard in every setting
they change."""

from __future__ import annotations

from pathlib import Path

import pytest

from harness import procedural as pr
from harness.config import load_config

ROOT = Path(__file__).resolve().parents[1]
TIERS = ("easy", "standard", "hard")


@pytest.fixture(scope="module")
def tiers():
    return {t: load_config(ROOT / "experiments" / f"benchmark-{t}.toml") for t in TIERS}


def test_every_tier_runs_make_evals_planners_on_the_procedural_set(tiers):
    default = load_config(ROOT / "experiments" / "default.toml")
    for tier, config in tiers.items():
        assert config.name == f"benchmark-{tier}"
        assert config.planners == default.planners, tier
        assert all(Path(p).resolve().parent == pr.LIBRARY_SET for p in config.scenes), tier
        assert len(set(config.scene_names)) == len(config.scenes), tier
    assert len(set(tiers["hard"].scene_names)) >= 100
    # The objects the hard tier's settings were chosen on (docs/benchmark.md) are in it.
    assert {f"{f}_{k:03d}" for f in pr.FAMILIES for k in range(4)} <= set(tiers["hard"].scene_names)


def test_the_tiers_get_harder_in_every_setting_they_change(tiers):
    easy, standard, hard = (tiers[t].settings for t in TIERS)
    assert easy["force"] > standard["force"] > hard["force"]
    assert easy["sigma_g"] < standard["sigma_g"] < hard["sigma_g"]
