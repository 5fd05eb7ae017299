"""The command line as a user meets it: pictures written, benchmark JSON, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

from harness.cli import main


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
                 ["bench", "sampling", "--sizes", "5"], ["bench", "sampling", "--sizes", "2x"]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and err.startswith("gpis-harness: error: "), (argv, err)


def test_bench_sampling_json_has_the_contracted_fields():
    proc = subprocess.run([sys.executable, "-m", "harness", "bench", "sampling", "--sizes", "20,25", "--json"],
                          capture_output=True, text=True, timeout=600, check=True)
    result = json.loads(proc.stdout)
    assert [r["M"] for r in result["rows"]] == [20, 25]
    for row in result["rows"]:
        assert {"M", "fit_s", "fast_s", "exact_s", "peak_mb"} <= set(row)
        assert row["fast_s"] > 0 and row["exact_s"] > 0 and row["peak_mb"] > 0
    assert result["ratio_exact_over_fast_at_55"] is None  # M = 55 not measured here
    assert isinstance(result["fast_growth_exponent"], float)


def test_input_errors_survive_a_trip_between_processes():
    import pickle

    from harness.errors import InputError

    err = pickle.loads(pickle.dumps(InputError("scene.toml", "grid.size", "5 is out of range [8, 1024]")))
    assert (err.source, err.field, str(err)) == ("scene.toml", "grid.size", "scene.toml: grid.size: 5 is out of range [8, 1024]")
