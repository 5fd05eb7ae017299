"""The grasp settings: one resolution from the scene, the overrides and the protocol; a
setting overridden twice is refused; the resolved value reaches quality and physics."""

from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from harness.cli import main
from harness.config import load_config
from harness.tasks import settings_of
from harness.physics.simulate import make_trials, truth_polygon
from harness.protocol import Protocol
from harness.scene import load_scene
from harness.settings import BOUNDS, override_problem, peak_load_factor, resolve


def test_settings_come_from_the_scene_unless_overridden():
    scene = load_scene("stapler")
    s = resolve(scene)
    assert (s.opening, s.jaw_width, s.sigma_g, s.force) == (scene.gripper.opening, scene.gripper.jaw_width,
                                                             scene.gripper.sigma_g, scene.gripper.force)
    assert (s.friction, s.thickness, s.density) == (0.45, 0.035, 1500.0)
    assert s.friction_spread == 0.0
    t = resolve(scene, {"sigma_g": 0.004, "force": 12.0})
    assert (t.sigma_g, t.force, t.friction) == (0.004, 12.0, 0.45)


def test_the_load_factor_is_the_minimum_jerk_lifts_peak():
    """A minimum-jerk rise h in T peaks at (10 / sqrt 3) h / T^2; checked by finite
    differences of the profile 10u^3 - 15u^4 + 6u^5."""
    h, T = 0.10, 0.4
    u = np.linspace(0.0, 1.0, 200_001)
    z = h * (10 * u**3 - 15 * u**4 + 6 * u**5)
    dt = T / (len(u) - 1)
    peak = np.max(np.diff(z, 2)) / dt**2
    assert peak_load_factor(h, T) == pytest.approx(1 + peak / 9.81, rel=1e-6)
    assert resolve(load_scene("disk")).load_factor == pytest.approx(1 + 5.7735 * 0.1 / 0.16 / 9.81, rel=1e-4)
    slow = resolve(load_scene("disk"), protocol=Protocol(lift_time=0.8))
    assert slow.load_factor - 1 == pytest.approx((resolve(load_scene("disk")).load_factor - 1) / 4, rel=1e-9)
    assert resolve(load_scene("disk"), {"load_factor": 1.0}).load_factor == 1.0


def test_an_override_out_of_its_range_is_refused():
    assert override_problem("sigma_g", -0.001).startswith("-0.001 is out of range")
    assert override_problem("opening", 0.0) is not None  # the low end is open
    assert override_problem("friction", 0.0) is None
    assert override_problem("bogus", 1.0).startswith("unknown setting")
    assert override_problem("force", math.nan) is not None
    with pytest.raises(ValueError, match="sigma_g"):
        resolve(load_scene("disk"), {"sigma_g": 2.0})
    assert set(BOUNDS) >= {"opening", "jaw_width", "sigma_g", "force", "friction", "friction_spread"}


def test_friction_per_draw_is_one_formula():
    s = resolve(load_scene("disk"), {"friction": 0.5, "friction_spread": 0.2})
    np.testing.assert_allclose(s.frictions([-3.0, 0.0, 1.0]), [0.0, 0.5, 0.7])


def _config(tmp_path, body: str):
    path = tmp_path / "x.toml"
    path.write_text(textwrap.dedent(body))
    return path


def test_a_setting_overridden_twice_in_a_config_is_one_line_and_exit_2(tmp_path, capsys):
    path = _config(tmp_path, """
        scenes = ["disk"]
        [evaluation]
        sigma_g = 0.002
        [gripper]
        sigma_g = 0.003
        [[planners]]
        name = "mean-shape"
        """)
    assert main(["eval", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "gripper.sigma_g: is also set in [evaluation]" in err


def test_the_configs_overrides_are_resolved_once_and_reach_the_physics(tmp_path):
    path = _config(tmp_path, """
        scenes = ["rectangle"]
        [evaluation]
        sigma_g = 0.001
        friction_spread = 0.1
        [gripper]
        force = 7.5
        jaw_width = 0.012
        [physics]
        lift_height = 0.05
        [[planners]]
        name = "mean-shape"
        """)
    config = load_config(path)
    s = settings_of(config, config.scenes[0])
    assert (s.sigma_g, s.friction_spread, s.force, s.jaw_width, s.lift_height) == (0.001, 0.1, 7.5, 0.012, 0.05)
    assert s.load_factor == pytest.approx(peak_load_factor(0.05, Protocol().lift_time))
    trial = make_trials(s, [[-0.045, 0.0], [0.045, 0.0]], [truth_polygon(load_scene("rectangle"))],
                        np.zeros((1, 2, 2)), np.array([1.0]))[0]
    assert trial.gripper.force == 7.5 and trial.gripper.pad_width == 0.012
    assert trial.friction == pytest.approx(0.6)
