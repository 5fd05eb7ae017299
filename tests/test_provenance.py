"""Provenance: the code paths are pinned only where they can run and never over a user's
choice, and the manifest's reproducibility record has what a rerun needs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from importlib.metadata import version

import harness.provenance as provenance
from harness.canonical import GRID
from harness.provenance import CODE_PATHS, pin_code_paths, reproducibility


def test_pinning_sets_only_the_variables_not_already_set(monkeypatch):
    monkeypatch.setattr(provenance, "_has_avx2_and_fma", lambda: True)
    environ = {"OPENBLAS_CORETYPE": "Zen"}
    assert pin_code_paths(environ) == {"NPY_DISABLE_CPU_FEATURES": CODE_PATHS["NPY_DISABLE_CPU_FEATURES"]}
    assert environ == {**CODE_PATHS, "OPENBLAS_CORETYPE": "Zen"}


def test_nothing_is_pinned_on_a_cpu_without_avx2_and_fma(monkeypatch):
    monkeypatch.setattr(provenance, "_has_avx2_and_fma", lambda: False)
    environ = {}
    assert pin_code_paths(environ) == {} and environ == {}


def test_the_command_line_runs_numpy_and_blas_on_the_pinned_code_paths(tmp_path):
    # A fresh process: the pins act only before numpy loads. Where they cannot apply,
    # the record says so (no pinned variables, the CPU's own kernels).
    code = ("import json, sys; from harness.cli import main; from harness.provenance import reproducibility; "
            "main(['planners', 'list']); json.dump(reproducibility(), sys.stderr)")
    env = {k: v for k, v in os.environ.items() if k not in CODE_PATHS}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    record = json.loads(out.stderr)
    if provenance._has_avx2_and_fma():
        assert record["code_paths"] == CODE_PATHS
        assert {blas["architecture"] for blas in record["blas"]} == {"Haswell"}
        assert "X86_V4" not in record["numpy_simd"]
    else:
        assert record["code_paths"] == dict.fromkeys(CODE_PATHS)


def test_the_reproducibility_record_names_versions_blas_grid_and_platform():
    record = reproducibility()
    assert json.loads(json.dumps(record)) == record
    assert record["packages"]["numpy"] == version("numpy") and record["packages"]["pybullet"] == version("pybullet")
    assert set(record["constraints"]) == {"file", "differ"}
    assert record["constraints"]["file"] == "constraints.txt"
    assert all(set(d) == {"pinned", "installed"} for d in record["constraints"]["differ"].values())
    assert record["blas"] and all(b["internal_api"] and b["version"] and b["num_threads"] >= 1 for b in record["blas"])
    assert record["cell_blas_threads"] == [1] and record["canonical_grid_m"] == GRID
    assert record["python"].count(".") == 2 and record["platform"]["machine"]


def test_the_manifest_reads_git_without_rewriting_the_index(tmp_path):
    """A plain `git status` on a checkout whose files' stat data changed rewrites
    .git/index (under .git/index.lock, which a killed run would leave behind); the
    manifest's read must not. Checked against git itself: the plain command does rewrite
    it here, the manifest's leaves it as it was and still sees the commit and a clean tree."""
    from harness.manifest import git_state

    def git(*args):
        subprocess.run(["git", "-C", str(tmp_path), *args], check=True, capture_output=True,
                       env={**os.environ, "GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
                            "GIT_COMMITTER_EMAIL": "t@t"})

    git("init", "-q")
    (tmp_path / "a.txt").write_text("a\n")
    git("add", "a.txt")
    git("commit", "-q", "-m", "a")
    index = tmp_path / ".git" / "index"

    def touch_and_read(read):
        os.utime(tmp_path / "a.txt", ns=(index.stat().st_mtime_ns + 5_000_000_000,) * 2)
        before = index.read_bytes()
        out = read()
        return out, index.read_bytes() != before

    commit_dirty, rewritten = touch_and_read(lambda: git_state(tmp_path))
    assert commit_dirty[0] and len(commit_dirty[0]) == 40 and commit_dirty[1] is False
    assert not rewritten
    _, rewritten = touch_and_read(lambda: git("status", "--porcelain"))
    assert rewritten, "plain git status did not refresh the index: the check above proves nothing"
