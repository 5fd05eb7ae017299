"""What a run's manifest records about the software and the machine."""

from __future__ import annotations

from pathlib import Path


def environment() -> dict:
    """Package versions, the git commit and the machine, for the manifest."""
    import platform
    import subprocess
    import sys
    from importlib.metadata import PackageNotFoundError, version

    from harness.provenance import reproducibility

    versions = {}
    for pkg in ("gpis-harness", "numpy", "scipy", "osqp", "pandas", "pybullet", "mujoco", "shapely", "matplotlib"):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            versions[pkg] = None
    try:
        root = Path(__file__).resolve().parent.parent
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=False, timeout=10).stdout.strip() or None
        dirty = bool(subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                    capture_output=True, text=True, check=False, timeout=10).stdout.strip())
    except (OSError, subprocess.SubprocessError):
        commit, dirty = None, None
    return {"python": sys.version.split()[0], "packages": versions, "git_commit": commit, "git_dirty": dirty,
            "machine": {"platform": platform.platform(), "processor": platform.machine(),
                        "cpus": __import__("os").cpu_count()}, "reproducibility": reproducibility()}
