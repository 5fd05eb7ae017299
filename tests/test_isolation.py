"""A plugin under development cannot touch anything but its own rows (issue 30): each plan
in a process of its own (harness.isolation), read-only problems (harness.readonly),
deadlines kept from outside, a memory cap per plan; Ctrl-C still interrupts the run."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from harness import isolation
from harness.readonly import InputsChanged, changes, fingerprint, freeze

ROOT = Path(__file__).resolve().parent.parent
BUILTINS = ("mean-shape", "gp-p", "gp-gpis-opt")
#: Each hostile plugin, its status and a piece of its message.
HOSTILE = {
    "WritesVariance": ("raised", "read-only"),
    "ScalesGP": ("raised", "read-only"),
    "ReplacesGP": ("raised", "problem.belief.gp.L_"),
    "SetsSettings": ("raised", "problem.settings.friction"),
    "Exits": ("crashed", "exited with code 1"),
    "KillsItself": ("crashed", "SIGKILL"),
    "RaisesKeyboardInterrupt": ("crashed", "KeyboardInterrupt"),
    "RaisesBaseException": ("crashed", "Deliberate: not an Exception"),
    "SleepsUnderExcept": ("overtime", "killed after"),
    "EatsMemory": ("crashed", "ran out of memory"),
}
CONFIG = """
name = "hostile"
seed = 11
scenes = ["disk"]
realisations = 2

[evaluation]
analytic_draws = 30
posterior_trials = 3
truth_trials = 1
time_budget_s = 2.0

[physics]
batch_size = 2
{planners}
"""
PARAMS = {"mean-shape": "{ candidates = 20 }", "gp-p": "{ candidates = 10, samples = 40 }",
          "gp-gpis-opt": "{ initialisations = 2, screen = 10, max_iterations = 5 }"}


def _config(tmp_path: Path, hostile: bool | tuple = False) -> Path:
    """The built-ins, and with ``hostile`` every hostile plugin (or those named) around them
    (before, between and after, so that a leak would reach a built-in planned after it in
    the same cell, or in the next cell of the same worker)."""
    names = list(BUILTINS)
    if hostile:
        plugins = [f"hostile_planners:{cls}" for cls in (HOSTILE if hostile is True else hostile)]
        names = plugins[:4] + names[:1] + plugins[4:7] + names[1:2] + plugins[7:] + names[2:]
    entries = []
    for name in names:
        label = name.split(":")[-1]
        params = f"params = {PARAMS[name]}\n" if name in PARAMS else ""
        entries.append(f'\n[[planners]]\nname = "{name}"\nlabel = "{label}"\n{params}')
    path = tmp_path / ("hostile.toml" if hostile else "builtins.toml")
    path.write_text(CONFIG.format(planners="".join(entries)))
    return path


def _run(config: Path, out: Path, *extra: str) -> tuple[int, float]:
    start = time.monotonic()
    env = dict(os.environ, PYTHONPATH=f"{ROOT / 'tests'}{os.pathsep}{ROOT}")
    proc = subprocess.run([sys.executable, "-m", "harness", "eval", str(config), "--out", str(out), "--no-report",
                           "--memory-budget", "1", *extra], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.returncode, time.monotonic() - start


def _rows(out: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    with closing(sqlite3.connect(out / "ledger.sqlite")) as db:
        plans = pd.read_sql_query("SELECT * FROM plans ORDER BY scene, realisation, planner", db)
        trials = pd.read_sql_query("SELECT * FROM trials ORDER BY scene, realisation, planner, shapes, trial", db)
    # The config hash differs with the planners listed; times differ from run to run.
    return plans.drop(columns=["config_hash", "plan_time_s", "trace"]), trials.drop(columns=["config_hash"])


@pytest.fixture(scope="module")
def alone(tmp_path_factory):
    """The built-in planners' rows without any plugin beside them."""
    tmp = tmp_path_factory.mktemp("alone")
    out = tmp / "out"
    _run(_config(tmp, hostile=False), out, "--workers", "2")
    return _rows(out)


@pytest.mark.parametrize("executor", [("--workers", "1"), ("--workers", "2"),
                                      ("--workers", "2", "--scheduler", "local")],
                         ids=["1 worker", "2 workers", "dask local"])
def test_hostile_plugins_cost_only_their_own_rows(alone, tmp_path, executor):
    _, seconds = _run(_config(tmp_path, hostile=True), tmp_path / "out", *executor)
    plans, trials = _rows(tmp_path / "out")
    mine = plans[plans.planner.isin(BUILTINS)].reset_index(drop=True)
    pd.testing.assert_frame_equal(mine, alone[0].reset_index(drop=True))
    pd.testing.assert_frame_equal(trials[trials.planner.isin(BUILTINS)].reset_index(drop=True),
                                  alone[1].reset_index(drop=True))
    for cls, (status, message) in HOSTILE.items():
        rows = plans[plans.planner == cls]
        assert len(rows) == 2 and (rows.status == status).all(), (cls, rows[["status", "message"]].to_dict("records"))
        assert rows.message.str.contains(message, regex=False).all(), (cls, rows.message.tolist())
        theirs = trials[trials.planner == cls]
        assert len(theirs) == 2 * 4 and (theirs.outcome == "no_plan").all()
    # Bounded: the sleeper is killed at 1.5 x 2 s + 1 s in each of the two cells; the rest
    # is start-up and a few seconds of planning and physics.
    assert seconds < 240


def test_ctrl_c_interrupts_the_run_and_it_resumes(tmp_path):
    """SIGINT to the whole process group (what Ctrl-C in a terminal sends) while a plan
    sleeps: exit 130, nothing left running, and the rerun completes."""
    config = _config(tmp_path, hostile=("SleepsUnderExcept",))
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=f"{ROOT / 'tests'}{os.pathsep}{ROOT}")
    command = [sys.executable, "-m", "harness", "eval", str(config), "--out", str(out), "--no-report",
               "--memory-budget", "1", "--workers", "1"]
    # SIGINT's default action restored in the run: a shell without job control starts
    # background commands (`make test &`) with SIGINT ignored, which the run would inherit.
    proc = subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while not _sleeping_child(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before the sleeper planned"
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err.decode()[-2000:]
    assert "run the same command again to resume" in err.decode()
    time.sleep(1.0)
    assert _descendants(proc.pid) == []
    done = subprocess.run(command[:-1] + ["2"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    plans, _ = _rows(out)
    assert len(plans) == 2 * (len(BUILTINS) + 1) and (plans[plans.planner == "SleepsUnderExcept"].status ==
                                                      "overtime").all()


def _descendants(pid: int) -> list[int]:
    """Processes whose parent chain reaches ``pid`` (Linux /proc), or that are still in
    its session."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if fields[0] != "Z" and int(fields[3]) == pid:  # same session (the group we signalled)
            found.append(int(entry.name))
    return found


def _sleeping_child(session: int) -> bool:
    """Whether a process of the run's session is the sleeper's isolated plan: a
    grandchild of a worker, alive for a while (a plan process that lives > 0.5 s)."""
    return any(_age(pid) > 0.5 and _depth(pid, session) >= 3 for pid in _descendants(session))


def _depth(pid: int, root: int) -> int:
    depth = 0
    while pid not in (root, 0, 1) and depth < 10:
        stat = Path(f"/proc/{pid}/stat").read_text()
        pid = int(stat[stat.rindex(")") + 2:].split()[1])
        depth += 1
    return depth if pid == root else -1


def _age(pid: int) -> float:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return 0.0
    start = int(stat[stat.rindex(")") + 2:].split()[19]) / os.sysconf("SC_CLK_TCK")
    uptime = float(Path("/proc/uptime").read_text().split()[0])
    return uptime - start


def test_kill_9_of_the_main_process_leaves_no_worker_running(tmp_path):
    """kill -9 of eval's main process alone: its workers and forkserver end too."""
    config = _config(tmp_path, hostile=("SleepsUnderExcept",))
    env = dict(os.environ, PYTHONPATH=f"{ROOT / 'tests'}{os.pathsep}{ROOT}")
    proc = subprocess.Popen([sys.executable, "-m", "harness", "eval", str(config), "--out", str(tmp_path / "out"),
                             "--no-report", "--memory-budget", "1", "--workers", "2"], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 120
    while not _sleeping_child(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None and len(_descendants(proc.pid)) >= 3  # main, forkserver, workers, plans
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    time.sleep(5.0)
    assert _descendants(proc.pid) == []


# -- the isolated call itself -----------------------------------------------------------------


def _returns(x):
    return {"twice": 2 * x}


def _raises():
    raise RuntimeError("deliberate")


def _exits():
    sys.exit(3)


def _segfaults():
    import ctypes
    import faulthandler

    faulthandler.disable()  # pytest's handler would print every thread's stack
    ctypes.string_at(0)


def _sleeps():
    while True:
        try:
            time.sleep(0.05)
        except Exception:  # noqa: BLE001
            pass


def _mutates(array):
    array[0] = 99.0
    return float(array[0])


@pytest.mark.parametrize(("fn", "args", "kind", "message"), [
    (_returns, (4,), "returned", ""),
    (_raises, (), "raised", "RuntimeError: deliberate"),
    (_exits, (), "crashed", "raised SystemExit: 3"),
    (_segfaults, (), "crashed", "killed by SIGSEGV (11)"),
    (os._exit, (7,), "crashed", "exited with code 7"),
])
def test_an_isolated_call_reports_how_it_ended(fn, args, kind, message):
    outcome = isolation.call(fn, *args, deadline_s=30)
    assert outcome.kind == kind and outcome.message == message
    if kind == "returned":
        assert outcome.value == {"twice": 8}
    if kind == "raised":
        assert "_raises" in outcome.traceback


def test_an_isolated_call_is_killed_at_its_deadline_whatever_it_catches():
    outcome = isolation.call(_sleeps, deadline_s=0.5)
    assert outcome.kind == "overtime" and 0.5 <= outcome.seconds < 5.0


def test_an_isolated_call_writes_into_its_own_copy_only():
    array = np.zeros(3)
    assert isolation.call(_mutates, array).value == 99.0
    assert array[0] == 0.0


def _watch_a_process_that_ends(seconds: float, pidfd: bool) -> None:
    """In an isolated call: start a process that is not this one's child (init adopts and
    reaps it: no zombie to look alive) and ends after ``seconds``, watch it with
    die_with, and sleep: the call ends only if die_with ends it."""
    read_fd, write_fd = os.pipe()
    middle = os.fork()
    if middle == 0:
        watched = os.fork()
        if watched == 0:
            time.sleep(seconds)
            os._exit(0)
        os.write(write_fd, str(watched).encode())
        os._exit(0)
    os.waitpid(middle, 0)
    watched = int(os.read(read_fd, 32))
    if not pidfd:
        del os.pidfd_open  # this process's own copy of the module: the polling fallback
    isolation.die_with(watched)
    time.sleep(10)


@pytest.mark.parametrize("pidfd", [True, False], ids=["pidfd", "polling"])
def test_a_process_ends_when_the_process_it_watches_ends(pidfd):
    outcome = isolation.call(_watch_a_process_that_ends, 0.5, pidfd, deadline_s=8)
    assert outcome.kind == "crashed" and outcome.message == "exited with code 1", outcome
    assert 0.4 < outcome.seconds < 3.0


def test_memory_beyond_the_cap_is_a_crash_of_the_call_only():
    outcome = isolation.call(np.ones, 2**30 // 8 * 2, memory_bytes=2**30)  # 2 GiB against a 1 GiB cap
    assert outcome.kind == "crashed" and "ran out of memory" in outcome.message


# -- read-only problems ------------------------------------------------------------------------


def test_a_problem_refuses_writes_into_every_array_it_reaches(beliefs):
    from planners.base import Problem

    problem = Problem.for_belief(beliefs("disk"))
    before = fingerprint(problem)
    arrays = [(path, value) for path, value in _arrays(problem)]
    assert len(arrays) > 20 and {".belief.var", ".belief.gp.L_", ".belief.observations.values"} <= \
        {path.replace("._fields[1]", ".var") for path, _ in arrays}
    for path, array in arrays:
        if array.size:
            with pytest.raises(ValueError, match="read-only"):
                array.flat[0] = 1.0
    assert changes(before, fingerprint(problem)) == []


def _arrays(obj):
    from harness.readonly import _walk

    return [(p, v) for p, v in _walk(obj, "", set()) if isinstance(v, np.ndarray)]


def test_a_fingerprint_sees_a_replaced_array_and_a_frozen_field_set_anyway(beliefs):
    from planners.base import Problem

    problem = Problem.for_belief(beliefs("rectangle"))
    before = fingerprint(problem, contents=False)
    gp = problem.belief.gp
    saved_factor, saved_friction = gp.L_, problem.settings.friction
    try:
        gp.L_ = gp.L_ * 1.5
        object.__setattr__(problem.settings, "friction", 0.05)
        changed = changes(before, fingerprint(problem, contents=False))
        assert changed == [".belief.gp.L_", ".settings.friction"]
        assert "problem.belief.gp.L_" in str(InputsChanged(changed))
    finally:
        gp.L_ = saved_factor
        object.__setattr__(problem.settings, "friction", saved_friction)
    assert changes(before, fingerprint(problem, contents=False)) == []


def test_freeze_reaches_cached_fields_and_leaves_foreign_objects_alone():
    from harness.geometry import Grid

    class Holder:
        pass

    holder = Holder()  # a test's own class: its attributes are not the harness's to walk
    holder.array = np.zeros(2)
    grid = Grid(4, 0.1)
    grid.coords  # noqa: B018 - a cached property, computed before the freeze
    freeze([holder, {"grid": grid, "array": np.ones(2)}])
    assert holder.array.flags.writeable
    assert not grid.coords.flags.writeable


# -- the conformance kit ----------------------------------------------------------------------


@pytest.mark.parametrize(("cls", "complaint"), [
    ("WritesVariance", "writes into its inputs (ValueError: output array is read-only)"),
    ("ScalesGP", "writes into its inputs (ValueError: output array is read-only)"),
    ("ReplacesGP", "plan() changed its inputs: problem.belief.gp.L_"),
    ("SetsSettings", "plan() changed its inputs: problem.settings.friction, problem.settings.sigma_g"),
    ("SleepsUnderExcept", "ignores its deadline: still planning"),
])
def test_the_conformance_kit_fails_a_planner_that_writes_into_its_inputs_or_ignores_its_deadline(cls, complaint):
    import hostile_planners

    from harness.testing import check_planner

    with pytest.raises(AssertionError) as err:
        check_planner(getattr(hostile_planners, cls), scenes=("disk",), seeds=(0,), time_budget=0.5, slack=1.0)
    assert complaint in str(err.value)


def test_the_conformance_kit_passes_the_same_planner_when_it_behaves():
    import hostile_planners

    from harness.testing import check_planner

    assert len(check_planner(hostile_planners.Polite, scenes=("disk",), seeds=(0,))) == 1
