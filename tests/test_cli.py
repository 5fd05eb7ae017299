"""The command line as a user meets it: pictures written, benchmark JSON, one-line errors."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from scipy import stats

from harness.cli import main

REPO = Path(__file__).resolve().parents[1]


def test_scenes_show_writes_a_png(tmp_path, capsys):
    out = tmp_path / "disk.png"
    assert main(["scenes", "show", "disk", "--seed", "1", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out.stat().st_size > 20_000
    assert capsys.readouterr().out.strip() == str(out)


def test_scenes_list_names_every_library_scene(capsys):
    from harness.scene import library_names

    assert main(["scenes", "list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines] == library_names()


def test_bad_command_line_gets_one_line_and_exit_code_2(capsys):
    for argv in (["scenes", "show"], ["bogus"], ["scenes", "show", "disk", "--seed", "-3"],
                 ["scenes", "show", "no_such_scene"], ["scenes", "show", "disk", "--out", "x.jpg"],
                 ["bench", "sampling", "--sizes", "5"], ["bench", "sampling", "--sizes", "2x"],
                 ["quality", "disk", "--grasp", "-0.06", "0", "0.06", "0"],  # wider than the opening
                 ["quality", "disk", "--grasp", "-0.3", "0", "0", "0"],  # outside the grid
                 ["quality", "disk", "--grasp", "0", "0", "0"], ["quality", "disk", "--grasp", "0", "0", "0", "x"],
                 ["quality", "disk", "--grasp", "-0.04", "0", "0.04", "0", "--sigma-g", "-1"],
                 ["quality", "disk", "--grasp", "-0.04", "0", "0.04", "0", "--samples", "0"],
                 ["quality", "disk", "--grasp", "-0.04", "0", "0.04", "0", "--force", "0"],
                 ["quality", "disk", "--grasp", "-0.04", "0", "0.04", "0", "--force", "nan"],
                 ["simulate", "disk", "--grasp", "-0.04", "0", "0.04", "0", "--force", "-5"],
                 ["plan", "disk", "--planner", "gp-p", "--param", "candidates=5", "--param", "candidates=6"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and err.startswith("gpis-harness: error: "), (argv, err)


def test_output_paths_that_cannot_be_written_get_one_line_before_any_work(tmp_path, capsys):
    """A frames folder, a trace file or a picture where one cannot be made: exit 2 and one
    line naming the path, found before any trial runs (a trial would print its summary);
    a trace that fails only when written (a full device) is one line too, and no summary."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    grasp = ["--grasp", "-0.045", "0", "0.045", "0", "--trials", "1", "--shapes", "truth"]
    cases = [(["simulate", "rectangle", *grasp, "--frames", str(blocker / "frames")], str(blocker / "frames")),
             (["simulate", "rectangle", *grasp, "--frames", str(blocker)], "--frames"),
             (["scenes", "show", "rectangle", "--out", str(blocker / "x.png")], "--out"),
             (["scenes", "render", "--out", str(blocker)], "--out")]
    if Path("/dev/full").exists():  # writes there fail with ENOSPC
        cases.append((["simulate", "rectangle", *grasp, "--trace", "/dev/full"], "/dev/full"))
    for argv, named in cases:
        assert main(argv) == 2, argv
        captured = capsys.readouterr()
        assert captured.out == "", argv
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"gpis-harness: error: {named}"), (argv, lines)


def test_bench_sampling_json_has_the_contracted_fields():
    proc = subprocess.run([sys.executable, "-m", "harness", "bench", "sampling", "--sizes", "20,25", "--json"],
                          capture_output=True, text=True, timeout=600, check=True)
    result = json.loads(proc.stdout)
    assert [r["M"] for r in result["rows"]] == [20, 25]
    for row in result["rows"]:
        assert {"M", "fit_s", "fast_s", "exact_s", "peak_mb"} <= set(row)
        assert row["fast_s"] > 0 and row["exact_s"] > 0 and row["peak_mb"] > 0
    assert result["ratio_exact_over_fast_at_55"] is None  # M = 55 not measured here
    # Two sizes: the least-squares slope of log time on log M is the slope through both.
    fast = [r["fast_s"] for r in result["rows"]]
    assert result["fast_growth_exponent"] == pytest.approx(math.log(fast[1] / fast[0]) / math.log(25 / 20), abs=1e-9)


def test_input_errors_survive_a_trip_between_processes():
    import pickle

    from harness.errors import InputError

    err = pickle.loads(pickle.dumps(InputError("scene.toml", "grid.size", "5 is out of range [8, 1024]")))
    assert (err.source, err.field, str(err)) == ("scene.toml", "grid.size",
                                                 "scene.toml: grid.size: 5 is out of range [8, 1024]")


def test_quality_json_holds_the_estimate_its_interval_and_failures(capsys):
    argv = ["quality", "disk", "--grasp", "-0.045", "0", "0.045", "0", "--samples", "300", "--seed", "2",
            "--sigma-g", "0.002", "--friction", "0.5", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"p_f", "ci_low", "ci_high", "p_l", "p_l_ci_low", "p_l_ci_high", "samples", "failures",
            "squeezed", "ferrari_canny_mean"} <= set(out)
    assert out["samples"] == 300 and out["ci_low"] <= out["p_f"] <= out["ci_high"]
    assert out["p_l_ci_low"] <= out["p_l"] <= out["p_l_ci_high"]
    for key, low, high in (("p_f", "ci_low", "ci_high"), ("p_l", "p_l_ci_low", "p_l_ci_high")):
        wilson = stats.binomtest(round(out[key] * 300), 300).proportion_ci(method="wilson")  # scipy's own
        assert (out[low], out[high]) == (pytest.approx(wilson.low, abs=1e-9), pytest.approx(wilson.high, abs=1e-9))
    assert out["p_l"] <= out["p_f"] + out["squeezed"] / 300
    planar = ("too_wide", "missed", "degenerate_normal", "friction_cone")
    assert set(out["failures"]) == set(planar) | {"weight_slip", "weight_torque", "edge_turn"}
    # P_F loses the planar reasons' draws and those the plates' squeeze brought into closure.
    assert round(out["p_f"] * 300) + sum(out["failures"][k] for k in planar) + out["squeezed"] == 300
    assert round(out["p_l"] * 300) + sum(out["failures"].values()) == 300
    assert main(argv) == 0  # the same seed gives the same numbers
    assert json.loads(capsys.readouterr().out) == out


def test_bench_planning_json_reports_seconds_per_estimate(monkeypatch, capsys):
    # --seeds 0 skips the bandit study (tests/test_bandit.py runs it small). The lift
    # planners' comparison runs on two scenes and one seed instead of the library and
    # three, the convergence study on one seed instead of three: the whole study took
    # 250 s of the suite.
    import harness.scene
    from harness.bench import planning_study

    monkeypatch.setattr(harness.scene, "library_names", lambda: ["disk", "rectangle"])
    monkeypatch.setattr(planning_study, "CONVERGENCE_SEEDS", 1)
    monkeypatch.setattr(planning_study, "LIFT_SEEDS", 1)
    monkeypatch.setattr(planning_study, "CHUNK_SCENES", ("disk",))  # gp-p-lift's search timed on one scene
    monkeypatch.setattr(planning_study, "CHUNK_ROUNDS", 1)
    assert main(["bench", "planning", "--sizes", "20,25", "--seeds", "0", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert [r["scene"] for r in result["lift_planners"]["rows"]] == ["disk", "rectangle"]
    assert result["bandit"] == {"seeds": 0, "first_seed": 0, "scenes": result["bandit"]["scenes"], "candidates": 100,
                                "shared_draws": [], "prior_draws": [], "runs": [], "summary": None}
    assert [r["M"] for r in result["rows"]] == [20, 25]
    assert all(r["p_f_s"] > 0 and 0 <= r["p_f"] <= 1 for r in result["rows"])
    assert result["p_f_s_at_50"] is None and isinstance(result["p_f_growth_exponent"], float)
    (chunks,) = result["search_chunks"]
    assert chunks["scene"] == "disk" and chunks["same_plan"] and chunks["chunks"] == 2
    assert chunks["speedup"] == pytest.approx(chunks["tens_s"] / chunks["chunks_s"])




def test_simulate_prints_the_json_contract_and_writes_frames(tmp_path, capsys):
    frames = tmp_path / "frames"
    # Coordinates in exponent notation (as plan --json prints them) are numbers, not options.
    assert main(["simulate", "rectangle", "--grasp", "-4.5e-2", "-1e-9", "0.045", "0", "--trials", "2",
                 "--shapes", "truth", "--sigma-g", "0", "--frames", str(frames), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"trials", "successes", "success_rate", "ci_low", "ci_high", "outcomes", "trials_per_s"} <= set(out)
    assert out["successes"] == 2 and out["success_rate"] == 1.0
    assert 0.0 < out["ci_low"] < 1.0 == out["ci_high"]
    assert out["ci_low"] == pytest.approx(stats.binomtest(2, 2).proportion_ci(method="wilson").low, abs=1e-9)
    pictures = sorted(p.name for p in frames.glob("*.png"))
    assert pictures == ["1-placed.png", "2-closed.png", "3-lifted.png", "4-shaken.png"]
    assert all((frames / p).read_bytes()[:4] == b"\x89PNG" for p in pictures)


def test_force_overrides_the_scenes_grip_in_quality_and_simulate(capsys):
    """--force sets the grip: the rectangle (6 x 3 x 3 cm, 400 kg/m^3: 0.21 N) gripped
    through its centre with mu 0.5 is lifted at the scene's 20 N and slides out at 0.1 N,
    where the plates' friction 2 mu N = 0.1 N is less than its weight: P_L 1 and 0, and
    in the simulator success and `slipped`; the JSON reports the force used."""
    grasp = ["--grasp", "0", "-0.03", "0", "0.03", "--sigma-g", "0"]
    for force, p_l in ((None, 1.0), (0.1, 0.0)):
        extra = [] if force is None else ["--force", str(force)]
        assert main(["quality", "rectangle", *grasp, "--samples", "50", "--json", *extra]) == 0
        out = json.loads(capsys.readouterr().out)
        assert out["force"] == (20.0 if force is None else force) and out["p_l"] == p_l
        assert main(["simulate", "rectangle", *grasp, "--trials", "1", "--shapes", "truth", "--json", *extra]) == 0
        out = json.loads(capsys.readouterr().out)
        assert out["force"] == (20.0 if force is None else force)
        assert out["outcomes"]["success" if force is None else "slipped"] == 1


def test_simulate_bad_input_gets_one_line_and_exit_code_2(tmp_path, capsys):
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("x")
    for argv in (["simulate", "rectangle", "--grasp", "-0.06", "0", "0.06", "0"],  # wider than the opening
                 ["simulate", "no_such_scene", "--grasp", "-0.045", "0", "0.045", "0"],
                 ["simulate", "rectangle", "--grasp", "-0.045", "0", "0.045", "0", "--shapes", "mean"],
                 ["simulate", "rectangle", "--grasp", "-0.045", "0", "0.045", "0", "--trials", "0"],
                 ["simulate", "rectangle", "--grasp", "-0.045", "0", "0.045", "0", "--frames", str(not_a_folder)],
                 ["simulate", "rectangle", "--grasp", "-0.045", "0", "0.045", "0", "--trace", str(tmp_path)],
                 ["simulate", "rectangle", "--grasp", "-0.045", "0", "0.045", "0", "--trace",
                  str(not_a_folder / "trace.csv")]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and err.startswith("gpis-harness: error: "), (argv, err)


def _closed_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("scheduler, complaint", [
    ("nonsense", "expected 'local' or SCHEME://HOST:PORT"),
    ("tcp://127.0.0.1:99999", "port 99999 is out of range [1, 65535]"),
    ("tls://127.0.0.1:8786", "needs Dask's TLS settings"),
    ("tcp://127.0.0.1:{closed}", "cannot connect to a Dask scheduler at tcp://127.0.0.1:{closed}"),
])
def test_eval_refuses_a_bad_scheduler_in_one_line_before_the_ledger_records_a_run(tmp_path, capsys, monkeypatch,
                                                                                  scheduler, complaint):
    import dask
    import distributed  # noqa: F401 - its config defaults first, then the test's TLS-free settings

    from harness import executor

    monkeypatch.setattr(executor, "CONNECT_TIMEOUT", "0.5s")
    closed = _closed_port()
    scheduler, complaint = scheduler.format(closed=closed), complaint.format(closed=closed)
    out = tmp_path / "out"
    with dask.config.set({"distributed.comm.tls.ca-file": None, "distributed.comm.tls.client.cert": None}):
        assert main(["eval", str(REPO / "experiments" / "quick.toml"), "--out", str(out),
                     "--scheduler", scheduler]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and err.startswith("gpis-harness: error: --scheduler: "), err
    assert complaint in err, err
    assert not out.exists()  # no ledger, so no run left marked 'running'
