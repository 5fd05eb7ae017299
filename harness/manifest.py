"""What a run's manifest records about the software and the machine."""

from __future__ import annotations

from pathlib import Path


def environment() -> dict:
    """Package versions, the git commit and the machine, for the manifest."""
    import platform
    import sys
    from importlib.metadata import PackageNotFoundError, version

    from harness.provenance import reproducibility

    versions = {}
    for pkg in ("gpis-harness", "numpy", "scipy", "osqp", "pandas", "pybullet", "mujoco", "shapely", "matplotlib"):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            versions[pkg] = None
    commit, dirty = git_state(Path(__file__).resolve().parent.parent)
    return {"python": sys.version.split()[0], "packages": versions, "git_commit": commit, "git_dirty": dirty,
            "machine": {"platform": platform.platform(), "processor": platform.machine(),
                        "cpus": __import__("os").cpu_count()}, "reproducibility": reproducibility()}


def git_state(root: Path) -> tuple[str | None, bool | None]:
    """The commit checked out at ``root`` and whether tracked files differ from it (None,
    None without git; None, False outside a repository). Read without git's optional locks: a plain
    ``git status`` refreshes the index under .git/index.lock, and a run killed meanwhile
    (an interrupted experiment, the timeout here) would leave the lock behind and block the
    user's next git command."""
    import subprocess

    git = ["git", "--no-optional-locks", "-C", str(root)]
    try:
        commit = subprocess.run(git + ["rev-parse", "HEAD"], capture_output=True, text=True, check=False,
                                timeout=10).stdout.strip() or None
        dirty = bool(subprocess.run(git + ["status", "--porcelain", "--untracked-files=no"], capture_output=True,
                                    text=True, check=False, timeout=10).stdout.strip())
    except (OSError, subprocess.SubprocessError):
        return None, None
    return commit, dirty
