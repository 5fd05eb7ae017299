"""What a run's numbers depend on beyond its config and code, pinned where it can be and
recorded in the manifest: exact package versions (constraints.txt), the code paths of
OpenBLAS and numpy, the canonical grid (harness.canonical), the platform. Importing it
loads no numeric library, so the code paths can be pinned before numpy loads."""

from __future__ import annotations

import importlib
import os
import platform
import re
from importlib.metadata import PackageNotFoundError, requires, version
from pathlib import Path

#: The constraints file of a source checkout: every package at the version that made
#: results/reference.
CONSTRAINTS = Path(__file__).resolve().parent.parent / "constraints.txt"

#: Numeric code paths pinned to the AVX2 level (x86-64-v3): OpenBLAS's Haswell kernels
#: and numpy's loops without their AVX-512 variants. Left to choose by CPU, they differ
#: between hosts in the last bits of a product or an exp, which the planners' optimisers
#: and the single-precision shape sampler amplify to 1e-8 m (docs/experiments.md).
CODE_PATHS = {"OPENBLAS_CORETYPE": "Haswell", "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"}


def pin_code_paths(environ=None) -> dict:
    """Set each CODE_PATHS variable that is not set already, on an x86-64 Linux CPU with
    AVX2 and FMA (forcing Haswell kernels on a CPU without them would crash); elsewhere
    nothing. The variables act when numpy and scipy load their libraries: in this process
    if it has not imported them yet, and in every process it starts afterwards (the
    experiment's workers). Returns what was set."""
    environ = os.environ if environ is None else environ
    if not _has_avx2_and_fma():
        return {}
    pinned = {name: value for name, value in CODE_PATHS.items() if name not in environ}
    environ.update(pinned)
    return pinned


def _has_avx2_and_fma() -> bool:
    """Whether this is an x86-64 CPU with AVX2 and FMA (by /proc/cpuinfo; Linux only)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    match = re.search(r"^flags\s*:(.*)$", text, re.MULTILINE)
    return bool(match) and {"avx2", "fma"} <= set(match.group(1).split())


def reproducibility() -> dict:
    """What the manifest records to reproduce a run: the installed version of every
    pinned package and those that differ from the constraints, the Python version, the
    BLAS libraries as threadpoolctl sees them in this process (API, version, kernels,
    threads) and their threads inside a cell (a product's summation order can depend on
    how many threads share it), numpy's active SIMD targets, the
    code-path variables, the canonical grid and the platform (machine, C library, CPU).
    JSON-ready, and in a stable order: two runs' records compare as dicts."""
    from threadpoolctl import threadpool_info

    for module in ("numpy", "scipy.linalg"):  # loaded, so that threadpoolctl sees their BLAS libraries
        importlib.import_module(module)

    from harness.canonical import GRID
    from harness.gpis import single_threaded_blas

    pins = _pins()
    names = sorted(pins) if pins else _requirements()
    packages = {name: _installed(name) for name in names}
    return {
        "python": platform.python_version(),
        "packages": packages,
        "constraints": {"file": CONSTRAINTS.name if pins else None,
                        "differ": {n: {"pinned": pins[n], "installed": packages[n]}
                                   for n in sorted(pins) if packages[n] != pins[n]}},
        "blas": _blas(threadpool_info()),
        "cell_blas_threads": _cell_blas_threads(single_threaded_blas, threadpool_info),
        "numpy_simd": _numpy_simd(),
        "code_paths": {name: os.environ.get(name) for name in CODE_PATHS},
        "canonical_grid_m": GRID,
        "platform": {"system": platform.system(), "machine": platform.machine(),
                     "libc": " ".join(platform.libc_ver()).strip() or None, "cpu": _cpu_model()},
    }


def _blas(libraries: list[dict]) -> list[dict]:
    """The BLAS libraries of threadpoolctl's list, sorted (its order follows the loader's)."""
    keys = ("internal_api", "version", "architecture", "num_threads", "prefix")
    found = [{key: lib.get(key) for key in keys} for lib in libraries if lib.get("user_api") == "blas"]
    return sorted(found, key=lambda lib: (str(lib["prefix"]), str(lib["version"])))


def _cell_blas_threads(limit, threadpool_info) -> list[int]:
    """The BLAS thread counts under a cell's limit (harness.experiment.run_cell)."""
    with limit():
        return sorted({lib["num_threads"] for lib in _blas(threadpool_info())})


def _pins() -> dict:
    """name -> version of each ``name==version`` line of the constraints file ({} without one)."""
    if not CONSTRAINTS.is_file():
        return {}
    pins = {}
    for line in CONSTRAINTS.read_text().splitlines():
        name, sep, pinned = line.split("#")[0].strip().partition("==")
        if sep:
            pins[name.strip()] = pinned.strip()
    return pins


def _requirements() -> list[str]:
    """The project's own requirements, by name (an installed copy without its constraints file)."""
    try:
        specs = requires("gpis-harness") or []
    except PackageNotFoundError:
        return []
    return sorted({re.split(r"[\s\[<>=!~;]", spec, maxsplit=1)[0] for spec in specs})


def _installed(name: str) -> str | None:
    try:
        return version(name)
    except PackageNotFoundError:
        return None


def _numpy_simd() -> list[str] | None:
    """The SIMD targets numpy dispatches to in this process (those its CPU has, less the
    disabled ones); None where numpy does not say."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:
        return None
    return [target for target in __cpu_dispatch__ if __cpu_features__.get(target)]


def _cpu_model() -> str | None:
    try:
        match = re.search(r"^model name\s*:\s*(.*)$", Path("/proc/cpuinfo").read_text(), re.MULTILINE)
    except OSError:
        return platform.processor() or None
    return match.group(1).strip() if match else platform.processor() or None
