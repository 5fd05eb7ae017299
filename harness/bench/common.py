"""What the studies of :mod:`harness.bench` share: a fresh process per measurement, the
peak memory, and a scene moved to another grid size with its physics kept."""

from __future__ import annotations

import multiprocessing
import resource

import numpy as np

#: Shape samples (and paired draws) of the sampling and planning timings.
SAMPLES = 1000


def peak_mb() -> float:
    """This process's peak resident memory (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def in_fresh_process(func, *args):
    """``func(*args)`` in a new interpreter (spawn): its timings and peak memory are its own."""
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(1, maxtasksperchild=1) as pool:
        return pool.apply(func, args)


def sampling_overrides(size: int, scene_name: str) -> dict:
    """Overrides that put a scene on an M x M grid while its physical quantities (SDF
    truncation, sensor noise and bands, GPIS hyperparameters) keep their values in metres
    at the scene's own grid; numerical settings given in cells (the active band) follow
    the grid. Sensor regions' parameters are not held (none of the benchmark scenes'
    regions has any given in cells)."""
    from harness.scene import load_scene

    native = load_scene(scene_name)
    sensor, gpis = native.sensor, native.gpis
    metres = lambda v: f"{v!r} m"  # noqa: E731
    return {"grid": {"size": size, "truncation": metres(native.truncation)},
            "sensor": {"noise": metres(sensor.noise), "surface_band": metres(sensor.surface_band),
                       "interior_depth": metres(sensor.interior_depth)},
            "gpis": {"lengthscale": metres(gpis.lengthscale), "scale": f"{gpis.scale!r} m^2",
                     "prior_mean": metres(gpis.prior_mean)}}


def jsonable(value):
    """``json.dumps``'s default for the studies' results: numpy scalars as numbers,
    anything else as its text."""
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    return str(value)
