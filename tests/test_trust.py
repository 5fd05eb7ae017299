"""What a skeptical user found (issue 18): scene identity, one run per output folder,
one width tolerance, one line for every storage failure, confined names and paths."""

from __future__ import annotations

import ast
import errno
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from edge_planners import ROUNDED, TOO_WIDE
from harness.cli import main

ROOT = Path(__file__).resolve().parent.parent
DISK = (ROOT / "scenes" / "disk.toml").read_text()
SMALL = """
name = "small"
seed = 1
scenes = [{scenes}]
realisations = 1

[evaluation]
analytic_draws = 20
posterior_trials = 2
truth_trials = 1
time_budget_s = 20.0

[[planners]]
name = "{planner}"
{params}
"""


def _config(tmp_path: Path, scenes: list[str], planner: str = "mean-shape",
            params: str = "params = { candidates = 10 }", name: str = "small.toml") -> Path:
    path = tmp_path / name
    path.write_text(SMALL.format(scenes=", ".join(json.dumps(s) for s in scenes), planner=planner, params=params))
    return path


def _scene_file(folder: Path, file_name: str, scene_name: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / file_name
    path.write_text(DISK.replace('name = "disk"', f'name = "{scene_name}"'))
    return path


def _one_line(capsys, after_progress: bool = False) -> str:
    """The one error line on stderr (after the run's progress lines, if it started)."""
    lines = capsys.readouterr().err.strip().splitlines()
    errors = [line for line in lines if "error" in line or "Traceback" in line]
    assert len(errors) == 1 and errors[0] == lines[-1] and (after_progress or len(lines) == 1), lines
    assert lines[-1].startswith("gpis-harness: error: "), lines
    return lines[-1]


# -- 1. scene identity --------------------------------------------------------------


def test_a_scene_named_unlike_its_file_outside_the_repository_resumes_and_reports(tmp_path, capsys):
    scene = _scene_file(tmp_path / "elsewhere", "outline_7.toml", "my_disk")
    config = _config(tmp_path, [str(scene)])
    out = tmp_path / "out"
    assert main(["eval", str(config), "--out", str(out), "--workers", "1"]) == 0
    summary = pd.read_csv(out / "summary.csv").set_index("scene")
    row = summary.loc["my_disk"]
    assert row.n_trials == 2 and row.plans_ok == "1/1" and bool(row.complete)
    assert (out / "figures" / "grasps-my_disk.png").is_file()
    capsys.readouterr()
    # The second run finds everything done: nothing is planned or simulated again.
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0
    err = capsys.readouterr().err
    assert "resuming with 1 plans and 3 trials done" in err and "0 plans and 0 trials" in err, err


def test_two_scenes_with_one_name_are_refused_before_any_work(tmp_path, capsys):
    a = _scene_file(tmp_path / "a", "first.toml", "same")
    b = _scene_file(tmp_path / "b", "second.toml", "same")
    config = _config(tmp_path, [str(a), str(b)])
    assert main(["eval", str(config), "--out", str(tmp_path / "out")]) == 2
    err = _one_line(capsys)
    assert "both named 'same'" in err and str(a) in err and str(b) in err
    assert not (tmp_path / "out").exists()


def test_a_config_without_scenes_is_refused(tmp_path, capsys):
    path = tmp_path / "noscenes.toml"
    path.write_text('[[planners]]\nname = "mean-shape"\n')
    assert main(["eval", str(path), "--out", str(tmp_path / "out")]) == 2
    assert ": scenes: missing" in _one_line(capsys)


# -- 2. one run per output folder ---------------------------------------------------

_HOLD = """
import sys, time
from pathlib import Path
from harness.outputs import folder_lock
with folder_lock(Path(sys.argv[1]), "gpis-harness eval held-by-test"):
    print("locked", flush=True)
    time.sleep(600)
"""


def _holder(folder: Path) -> subprocess.Popen:
    folder.mkdir(parents=True, exist_ok=True)
    proc = subprocess.Popen([sys.executable, "-c", _HOLD, str(folder)], stdout=subprocess.PIPE, text=True,
                            cwd=ROOT)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_eval_on_a_folder_in_use_names_the_holder(tmp_path, capsys):
    config = _config(tmp_path, ["disk"])
    out = tmp_path / "out"
    holder = _holder(out)
    try:
        assert main(["eval", str(config), "--out", str(out)]) == 2
        err = _one_line(capsys)
        assert f"pid {holder.pid}" in err and "held-by-test" in err, err
        assert main(["report", str(out)]) == 2
        assert f"pid {holder.pid}" in _one_line(capsys)
        assert not (out / "ledger.sqlite").exists()  # the refused eval touched nothing
    finally:
        holder.kill()
        holder.wait()


def test_a_lock_left_by_kill_9_does_not_block_the_resume(tmp_path):
    config = _config(tmp_path, ["disk"])
    out = tmp_path / "out"
    holder = _holder(out)
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait()
    assert (out / ".lock").exists()
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0


# -- 3. one width tolerance ---------------------------------------------------------


def _evaluated(tmp_path: Path, planner: str) -> tuple[list, int]:
    """Run the small experiment with ``planner`` on the disk: (status, executed) of its
    plan, and how many of its trials are no_plan."""
    config = _config(tmp_path, ["disk"], planner=planner, params="")
    out = tmp_path / "out"
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0
    with sqlite3.connect(out / "ledger.sqlite") as db:
        return (db.execute("SELECT status, executed FROM plans").fetchall(),
                db.execute("SELECT count(*) FROM trials WHERE outcome = 'no_plan'").fetchone()[0])


def test_a_grasp_as_wide_as_the_opening_up_to_rounding_is_executed_everywhere(tmp_path, capsys):
    assert _evaluated(tmp_path, "edge_planners:WideByRounding") == ([("ok", 1)], 0)
    capsys.readouterr()
    assert main(["plan", "disk", "--planner", "edge_planners:WideByRounding", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "ok"
    grasp = [str(v) for point in ROUNDED for v in point]
    assert main(["simulate", "disk", "--grasp", *grasp, "--trials", "1", "--json"]) == 0
    assert main(["quality", "disk", "--grasp", *grasp, "--samples", "10", "--json"]) == 0


def test_a_grasp_wider_than_the_opening_is_rejected_everywhere(tmp_path, capsys):
    assert _evaluated(tmp_path, "edge_planners:WiderThanOpening") == ([("invalid", 0)], 3)
    capsys.readouterr()
    assert main(["plan", "disk", "--planner", "edge_planners:WiderThanOpening", "--json"]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["status"] == "invalid" and "exceeds the gripper opening" in plan["message"]
    grasp = [str(v) for point in TOO_WIDE for v in point]
    for command in ("simulate", "quality"):
        assert main([command, "disk", "--grasp", *grasp]) == 2
        assert "exceeds the gripper opening 0.1 m" in _one_line(capsys)


def test_a_planner_calling_sys_exit_in_plan_is_an_outcome(tmp_path):
    # SystemExit is no Exception: the plan's process ends, its status is 'crashed'.
    assert _evaluated(tmp_path, "edge_planners:ExitsInPlan") == ([("crashed", 0)], 3)
    with sqlite3.connect(tmp_path / "out" / "ledger.sqlite") as db:
        assert db.execute("SELECT message FROM plans").fetchall() == [("raised SystemExit: 3",)]


# -- 6. storage failures are one line; nothing recorded is lost -----------------------


def test_out_below_a_regular_file_is_one_line(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert main(["eval", str(_config(tmp_path, ["disk"])), "--out", str(tmp_path / "file" / "out")]) == 2
    assert "cannot create the results folder" in _one_line(capsys)


@pytest.mark.parametrize("code", [errno.EACCES, errno.EROFS])
def test_an_output_folder_that_cannot_be_created_is_one_line(tmp_path, capsys, monkeypatch, code):
    def refuse(path, *args, **kwargs):
        raise OSError(code, os.strerror(code), str(path))

    config = _config(tmp_path, ["disk"])
    monkeypatch.setattr(os, "mkdir", refuse)
    assert main(["eval", str(config), "--out", str(tmp_path / "new" / "out")]) == 2
    assert os.strerror(code) in _one_line(capsys)


def test_a_read_only_ledger_is_one_line(tmp_path, capsys, monkeypatch):
    """Opened read-only by SQLite itself (a read-only file or file system; as root, file
    modes do not stop writes, so the test opens it read-only the way SQLite would)."""
    config = _config(tmp_path, ["disk"])
    out = tmp_path / "out"
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0
    connect = sqlite3.connect
    monkeypatch.setattr(sqlite3, "connect", lambda path, **kw: connect(f"file:{path}?mode=ro", uri=True, **kw))
    capsys.readouterr()
    assert main(["eval", str(config), "--out", str(out), "--fresh"]) == 2
    assert "readonly database" in _one_line(capsys)


def _fill_after(monkeypatch, writes: int) -> None:
    """The ledger's disk fills after ``writes`` transactions: the next write fails as
    SQLite reports a full disk (SQLITE_FULL), after its transaction was rolled back."""
    from harness import ledger

    add, count = ledger.Ledger.add, [0]

    def filling(self, *args, **kwargs):
        count[0] += 1
        if count[0] > writes:
            raise sqlite3.OperationalError("database or disk is full")
        return add(self, *args, **kwargs)

    monkeypatch.setattr(ledger.Ledger, "add", filling)


def test_a_full_disk_during_the_run_is_one_line_and_the_rerun_completes(tmp_path, capsys, monkeypatch):
    config = _config(tmp_path, ["disk", "rectangle"])
    full = tmp_path / "full"
    with monkeypatch.context() as m:
        _fill_after(m, 2)
        assert main(["eval", str(config), "--out", str(full), "--workers", "1"]) == 2
        err = _one_line(capsys, after_progress=True)
        assert "disk is full" in err and "run the same command again" in err, err
    with sqlite3.connect(full / "ledger.sqlite") as db:  # what was recorded before the disk filled is there
        assert db.execute("SELECT count(*) FROM plans").fetchone()[0] >= 1
    assert main(["eval", str(config), "--out", str(full), "--workers", "1", "--no-report"]) == 0
    clean = tmp_path / "clean"
    assert main(["eval", str(config), "--out", str(clean), "--workers", "1", "--no-report"]) == 0
    key = ["scene", "realisation", "planner", "shapes", "trial"]
    rows = [pd.read_sql("SELECT * FROM trials", sqlite3.connect(d / "ledger.sqlite")).sort_values(key)
            .reset_index(drop=True) for d in (full, clean)]
    pd.testing.assert_frame_equal(*rows)
    assert len(rows[0]) == 2 * 3


def test_a_full_disk_during_the_report_is_one_line_and_loses_nothing(tmp_path, capsys, monkeypatch):
    config = _config(tmp_path, ["disk"])
    out = tmp_path / "out"
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0

    def full(self, path, *args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    with monkeypatch.context() as m:
        m.setattr(pd.DataFrame, "to_parquet", full)
        capsys.readouterr()
        assert main(["report", str(out)]) == 2
        assert "No space left on device" in _one_line(capsys)
    assert not list(out.glob(".*.tmp"))  # no half-written file is left behind
    assert main(["report", str(out), "--no-figures"]) == 0
    assert len(pd.read_parquet(out / "trials.parquet")) == 3


def test_a_ledger_with_a_table_dropped_is_one_line(tmp_path, capsys):
    config = _config(tmp_path, ["disk"])
    out = tmp_path / "out"
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0
    with sqlite3.connect(out / "ledger.sqlite") as db:
        db.execute("DROP TABLE trials")
    for argv in (["eval", str(config), "--out", str(out)], ["report", str(out)]):
        capsys.readouterr()
        assert main(argv) == 2
        assert "table 'trials' is missing" in _one_line(capsys)


@pytest.mark.parametrize(("table", "column", "value", "complaint"), [
    ("trials", "grip_width", "'abc'", "table trials, row 1 (scene 'disk', realisation 0, planner 'mean-shape', "
                                      "shapes 'posterior', trial 0), column grip_width: expected a number, got 'abc'"),
    ("plans", "iterations", "2.5", "column iterations: expected an integer, got 2.5"),
    ("plans", "trace", "'[1, 2'", "column trace: is not valid JSON"),
    ("runs", "config", "'not json'", "table runs, row 1 (run 1), column config: is not valid JSON"),
])
def test_a_hand_edited_ledger_row_is_one_line_naming_table_row_and_column(tmp_path, capsys, table, column, value,
                                                                         complaint):
    config = _config(tmp_path, ["disk"])
    out = tmp_path / "out"
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0
    with sqlite3.connect(out / "ledger.sqlite") as db:
        db.execute(f"UPDATE {table} SET {column} = {value} WHERE rowid = 1")
    assert (out / "ledger.sqlite").exists()
    for argv in (["report", str(out)], ["eval", str(config), "--out", str(out)]):
        capsys.readouterr()
        assert main(argv) == 2
        line = _one_line(capsys)
        assert complaint in line and "changed by hand or is damaged" in line, line


# -- issue 30: configs that fit the machine, absolute globs ---------------------------


def test_an_absolute_glob_is_read_from_the_root_and_one_that_matches_nothing_is_one_line(tmp_path, capsys):
    folder = tmp_path / "mine"
    _scene_file(folder, "a.toml", "disk_a")
    _scene_file(folder, "b.toml", "disk_b")
    from harness.config import load_config

    config = load_config(_config(tmp_path, [str(folder / "*.toml")]))
    assert config.scene_names == ("disk_a", "disk_b")
    capsys.readouterr()
    assert main(["eval", str(_config(tmp_path, ["/no-such-folder-here/*.toml"]))]) == 2
    assert "scenes[0]: '/no-such-folder-here/*.toml' matches no scene" in _one_line(capsys)


def _big_grid(tmp_path: Path, size: int) -> Path:
    return _write_scene(tmp_path / "big.toml", DISK.replace('name = "disk"', 'name = "big_disk"'), size)


def _write_scene(path: Path, text: str, size: int) -> Path:
    import re

    path.write_text(re.sub(r"(?m)^size = .*$", f"size = {size}", text, count=1))
    return path


def test_a_grid_that_cannot_fit_the_machine_is_refused_before_any_work(tmp_path, capsys):
    scene = _big_grid(tmp_path, 1024)
    out = tmp_path / "out"
    assert main(["eval", str(_config(tmp_path, [str(scene)])), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert f"{scene}: grid.size: scene 'big_disk' needs about" in line and "TiB (fitting the GP: 1024 x 1024 grid" \
        in line and "more than the budget of" in line, line
    assert not out.exists()  # before any work: no folder, no ledger
    assert main(["report", str(out)]) == 2 and "no such results folder" in _one_line(capsys)
    assert main(["plan", str(_write_scene(tmp_path / "mid.toml", DISK, 256)), "--planner", "gp-p"]) == 2
    assert "grid.size: scene 'disk' needs about" in _one_line(capsys)


@pytest.mark.parametrize("argv, where", [
    (["quality", "disk", "--grasp", "-0.05", "0", "0.05", "0", "--samples", "1000000"], "--samples: scene 'disk'"),
    (["simulate", "disk", "--grasp", "-0.05", "0", "0.05", "0", "--trials", "1000000"], "--trials: scene 'disk'"),
])
def test_draws_that_cannot_fit_the_machine_are_refused_before_any_work(capsys, argv, where):
    assert main(argv) == 2
    line = _one_line(capsys)
    assert where in line and "GiB (judging a plan" in line, line


def test_analytic_draws_that_cannot_fit_a_worker_are_refused_naming_the_field(tmp_path, capsys):
    config = tmp_path / "draws.toml"
    config.write_text(SMALL.format(scenes='"disk"', planner="mean-shape", params="").replace(
        "analytic_draws = 20", "analytic_draws = 1000000"))
    assert main(["eval", str(config), "--out", str(tmp_path / "out"), "--workers", "2"]) == 2
    line = _one_line(capsys)
    assert f"{config}: evaluation.analytic_draws: scene 'disk' needs about" in line and "over 2 workers" in line
    # A budget given on the command line is the one that counts.
    assert main(["eval", str(_config(tmp_path, ["disk"])), "--out", str(tmp_path / "o2"), "--memory-budget",
                 "0.1", "--no-report"]) == 2
    assert "more than the budget of 0.10 GiB per worker (--memory-budget)" in _one_line(capsys)


# -- 8. scene names -----------------------------------------------------------------


@pytest.mark.parametrize("name", ["", "a/b", "../../x", "two\nlines", ".hidden", "x" * 65, "a b"])
def test_unusable_scene_names_are_refused_with_one_line(tmp_path, capsys, name):
    path = tmp_path / "scene.toml"
    path.write_text(DISK.replace('name = "disk"', f"name = {json.dumps(name)}"))
    assert main(["scenes", "check", str(path)]) == 2
    err = _one_line(capsys)
    assert f"{path}: name: scene name" in err and "letters, digits" in err, err


def test_a_file_name_that_cannot_name_a_scene_asks_for_a_name(tmp_path, capsys):
    path = tmp_path / "my scene.toml"
    path.write_text(DISK.replace('name = "disk"\n', ""))
    assert main(["scenes", "check", str(path)]) == 2
    assert "set `name` in the file" in _one_line(capsys)


# -- 9. outline paths ---------------------------------------------------------------


def _outline_scene(tmp_path: Path, target: str) -> Path:
    path = tmp_path / "outline.toml"
    path.write_text(f'[grid]\nsize = 40\nextent = 0.2\n[shape]\ntype = "outline"\npath = {json.dumps(target)}\n'
                    "scale = 0.001\n")
    return path


@pytest.mark.parametrize(("make", "message"), [
    (lambda d: "/dev/zero", "not a regular file"),
    (lambda d: str(d), "not a regular file"),
    (lambda d: (d / "png.csv").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256))) and "png.csv",
     "not a text file (invalid UTF-8)"),
    (lambda d: (d / "nul.csv").write_bytes(b"x,y\n0,0\x00\n") and "nul.csv", "not a text file (it contains NUL"),
    (lambda d: (d / "big.csv").write_bytes(b"x,y\n" + b"1.0,2.0\n" * (2**20 + 1)) and "big.csv", "MiB"),
])
def test_outline_paths_read_regular_text_files_only(tmp_path, capsys, make, message):
    scene = _outline_scene(tmp_path, make(tmp_path))
    start = time.perf_counter()
    assert main(["scenes", "check", str(scene)]) == 2
    err = _one_line(capsys)
    assert ": shape.path: outline " in err and message in err, err
    assert time.perf_counter() - start < 30  # /dev/zero is refused, not read


def test_a_config_that_is_a_device_is_one_line(capsys):
    assert main(["eval", "/dev/zero"]) == 2
    _one_line(capsys)


# -- 10. outputs are written in place, never through a planted link -------------------


def test_a_symlink_planted_in_the_output_folder_is_replaced_not_followed(tmp_path, capsys):
    config = _config(tmp_path, ["disk"])
    out = tmp_path / "out"
    assert main(["eval", str(config), "--out", str(out), "--workers", "1", "--no-report"]) == 0
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    (out / "summary.csv").symlink_to(target)
    assert main(["report", str(out), "--no-figures"]) == 0
    assert target.read_text() == "keep me"
    assert not (out / "summary.csv").is_symlink() and "success_rate" in (out / "summary.csv").read_text()
    (out / "ledger.sqlite").rename(out / "real.sqlite")
    (out / "ledger.sqlite").symlink_to(out / "real.sqlite")
    capsys.readouterr()
    assert main(["report", str(out)]) == 2
    assert "symbolic link" in _one_line(capsys)


# -- 13. the house: physics sits below planners; figures know nothing of runs ---------


@pytest.mark.parametrize(("modules", "forbidden"), [
    (["harness.physics.bodies", "harness.physics.gripper", "harness.physics.trial", "harness.physics.simulate"],
     ["planners", "harness.bench", "harness.experiment", "harness.tasks"]),
    (["harness.plots"], ["harness.bench", "harness.experiment", "harness.tasks", "harness.config"]),
    # Writing and checking a planner needs no physics engine.
    (["harness.settings", "planners.base", "harness.testing"], ["pybullet", "harness.physics"]),
])
def test_layers_import_only_what_is_below_them(modules, forbidden):
    probe = (f"import importlib, sys\nfor m in {modules!r}: importlib.import_module(m)\n"
             f"print(sorted(m for m in sys.modules if any(m == f or m.startswith(f + '.') for f in {forbidden!r})))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, check=True).stdout
    assert out.strip() == "[]", out


def _imports(path: Path, module: str, modules: set[str]) -> set[str]:
    """The project's modules that ``module`` (its file ``path``) imports, at its top or
    inside a function alike, each importing its packages too (a package's __init__ runs
    first), except the packages that hold ``module`` (a package's __init__ importing its
    own submodules is no circle)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            names = [base] + [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        for name in names:
            parts = name.split(".")
            found.update(".".join(parts[:k]) for k in range(1, len(parts) + 1))
    own = {".".join(module.split(".")[:k]) for k in range(1, module.count(".") + 2)}
    return (found & modules) - own


def test_no_module_imports_another_in_a_circle():
    files = {}
    for root in ("harness", "planners"):
        for path in (ROOT / root).rglob("*.py"):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            files[name.removesuffix(".__init__")] = path
    graph = {name: _imports(path, name, set(files)) for name, path in files.items()}
    # Depth-first search for a back edge; the first circle found is reported.
    state: dict[str, int] = {}
    circle: list[str] = []

    def visit(node: str, trail: list[str]) -> bool:
        state[node] = 1
        for child in sorted(graph[node]):
            if state.get(child) == 1:
                circle.extend(trail[trail.index(child):] + [node, child] if child in trail else [node, child])
                return True
            if child not in state and visit(child, trail + [node]):
                return True
        state[node] = 2
        return False

    for start in sorted(graph):
        if start not in state and visit(start, []):
            break
    assert not circle, " -> ".join(circle)
    assert len(graph) > 40 and sum(map(len, graph.values())) > 100  # the graph was really read
