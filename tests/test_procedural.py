"""The procedural object set (harness/procedural.py, `gpis-harness scenes generate`):
every object a valid scene of its drawn size, settings inside their stated ranges,
reproducible, a larger set extending a smaller one."""

from __future__ import annotations

import numpy as np
import pytest

from harness import procedural as pr
from harness.cli import main
from harness.scene import load_scene


def test_every_object_is_a_scene_of_its_size_with_its_drawn_settings(tmp_path):
    objects = pr.object_set(per_family=3)
    assert len(objects) == 18 and [o.obj.name for o in objects[:3]] == ["blob_000", "blob_001", "blob_002"]
    for o, path in zip(objects, pr.write_set(tmp_path, objects)):
        assert pr.SIZE_RANGE[0] <= o.size <= pr.SIZE_RANGE[1]
        assert pr.DENSITY_RANGE[0] <= o.density <= pr.DENSITY_RANGE[1]
        lo, hi = pr.THICKNESS_OVER_SIZE_RANGE
        assert lo * o.size - 1e-4 <= o.thickness <= hi * o.size + 1e-4
        assert pr.FRICTION_RANGE[0] <= o.friction <= pr.FRICTION_RANGE[1]
        assert o.interior_keep is None or pr.INTERIOR_KEEP_RANGE[0] <= o.interior_keep <= pr.INTERIOR_KEEP_RANGE[1]
        scene = load_scene(path)
        hull = np.asarray(scene.shape.convex_hull.exterior.coords)
        longest = np.linalg.norm(hull[:, None] - hull[None], axis=-1).max()
        assert 0.7 * o.size <= longest <= 1.25 * o.size, (o.obj.name, o.size, longest)
        assert (scene.physics.density, scene.physics.thickness, scene.physics.friction) == (
            o.density, pytest.approx(o.thickness), pytest.approx(o.friction))
        assert scene.sensor.noise == pytest.approx(o.noise_cells * scene.grid.cell)
        assert scene.sensor.interior_keep == (1.0 if o.interior_keep is None else pytest.approx(o.interior_keep))
    # Reproducible, and object k of a family is the same in a larger set.
    larger = pr.object_set(per_family=5)
    assert [o.scene_text() for o in larger if o.obj.index < 3] == [o.scene_text() for o in objects]


def test_the_generated_sets_draws_cover_their_ranges():
    """Over the default 120 objects: about half keep every interior reading, and each
    drawn setting spans most of its range (a draw stuck at one value would not)."""
    objects = pr.object_set()
    assert len(objects) == 120 and len({o.obj.name for o in objects}) == 120
    assert 0.35 <= np.mean([o.interior_keep is None for o in objects]) <= 0.65
    for values, (lo, hi) in (([o.size for o in objects], pr.SIZE_RANGE),
                             ([o.friction for o in objects], pr.FRICTION_RANGE),
                             ([o.density for o in objects], pr.DENSITY_RANGE)):
        assert np.ptp(values) >= 0.8 * (hi - lo)


def test_scenes_generate_writes_the_set_and_refuses_a_file_as_folder(tmp_path, capsys):
    assert main(["scenes", "generate", "--out", str(tmp_path / "set"), "--per-family", "2"]) == 0
    assert sorted(p.name for p in (tmp_path / "set").glob("*.toml"))[:2] == ["blob_000.toml", "blob_001.toml"]
    assert len(list((tmp_path / "set").glob("*.toml"))) == 12
    (tmp_path / "file").write_text("x")
    capsys.readouterr()
    assert main(["scenes", "generate", "--out", str(tmp_path / "file")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a folder" in err[0]


def test_the_committed_set_is_the_generators_output():
    """scenes/procedural (the benchmark tiers' objects, experiments/benchmark-*.toml) holds
    exactly the files `gpis-harness scenes generate` writes, byte for byte: the set is
    the project's own making and regenerates from harness/procedural.py alone."""
    folder = pr.LIBRARY_SET
    objects = pr.object_set()
    assert sorted(p.name for p in folder.glob("*")) == sorted(f"{o.obj.name}.toml" for o in objects)
    for o in objects:
        assert (folder / f"{o.obj.name}.toml").read_text() == o.scene_text(), o.obj.name
