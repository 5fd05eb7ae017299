"""The compiled field reads (harness.kernels, through harness.grasp) against the array
formulation they replaced, written out here as the reference: every value, gradient,
refined parameter, point and normal must be the same bit for bit, so that contacts and
plans do not move (tolerance: none)."""

import numpy as np
import pytest

from harness.belief import build_belief
from harness.grasp import (MIN_GRADIENT, NEWTON_STEPS, SDFBatch, _refine, find_contacts, interpolate, march_steps,
                           read_lines)
from harness.scene import load_scene
from harness.seeding import stream

# -- the reference: the array formulation (numpy, NEP 50 scalar rules) --------------------


def ref_cell_coordinates(grid, points):
    m = grid.size
    ux = (points[..., 0] - grid.coords[0]) / grid.cell
    uy = (points[..., 1] - grid.coords[0]) / grid.cell
    with np.errstate(invalid="ignore"):
        ix = np.clip(np.floor(ux).astype(np.int64), 0, m - 2)
        iy = np.clip(np.floor(uy).astype(np.int64), 0, m - 2)
    return ix, iy, ux - ix, uy - iy


def ref_hermite_basis(t):
    t2 = t * t
    t3 = t2 * t
    h1 = 3 * t2 - 2 * t3
    d1 = 6 * (t - t2)
    return (1 - h1, h1), (t - 2 * t2 + t3, t3 - t2), (-d1, d1), (1 - 4 * t + 3 * t2, 3 * t2 - 2 * t)


def ref_interpolate(fields, fidx, points):
    m, h = fields.grid.size, fields.grid.cell
    ix, iy, s, r = ref_cell_coordinates(fields.grid, points)
    i00 = fidx * (m * m) + iy * m + ix
    corners = (i00 + np.array([0, 1, m, m + 1])[:, None]).reshape(2, 2, -1)
    f = fields.values.reshape(-1).take(corners)
    fx = fields.gx.reshape(-1).take(corners) * h
    fy = fields.gy.reshape(-1).take(corners) * h
    fxy = fields.twist.reshape(-1).take(corners) * (h * h)
    (h0s, h1s), (g0s, g1s), (dh0s, dh1s), (dg0s, dg1s) = ref_hermite_basis(s)
    (h0r, h1r), (g0r, g1r), (dh0r, dh1r), (dg0r, dg1r) = ref_hermite_basis(r)
    along = h0s * f[:, 0] + h1s * f[:, 1] + g0s * fx[:, 0] + g1s * fx[:, 1]
    along_y = h0s * fy[:, 0] + h1s * fy[:, 1] + g0s * fxy[:, 0] + g1s * fxy[:, 1]
    slope = dh0s * f[:, 0] + dh1s * f[:, 1] + dg0s * fx[:, 0] + dg1s * fx[:, 1]
    slope_y = dh0s * fy[:, 0] + dh1s * fy[:, 1] + dg0s * fxy[:, 0] + dg1s * fxy[:, 1]
    value = h0r * along[0] + h1r * along[1] + g0r * along_y[0] + g1r * along_y[1]
    dx = h0r * slope[0] + h1r * slope[1] + g0r * slope_y[0] + g1r * slope_y[1]
    dy = dh0r * along[0] + dh1r * along[1] + dg0r * along_y[0] + dg1r * along_y[1]
    return value, np.column_stack([dx, dy]) / h


def ref_refine(fields, fidx, start, d, t, dt):
    lo, hi = t - dt, t + dt
    for _ in range(NEWTON_STEPS):
        value, grad = ref_interpolate(fields, fidx, start + t[:, None] * d)
        slope = np.einsum("ij,ij->i", grad, d)
        with np.errstate(invalid="ignore", divide="ignore"):
            step = np.where(np.abs(slope) > 1e-12, value / slope, 0.0)
        t = np.clip(t - step, lo, hi)
    norm = np.linalg.norm(grad, axis=1)
    valid = np.isfinite(norm) & (norm >= MIN_GRADIENT)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal = grad / norm[:, None]
    return t, start + t[:, None] * d, normal, valid


def ref_read_lines(fields, fidx, starts, d, ts):
    grid, m = fields.grid, fields.grid.size
    ts = np.asarray(ts)
    t32 = ts.astype(np.float32)[None, None, :] if ts.ndim == 1 else ts.astype(np.float32)[:, None, :]

    def grid_units(axis):
        u = np.repeat(((starts[..., axis] - grid.coords[0]) / grid.cell).astype(np.float32)[..., None],
                      ts.shape[-1], axis=2)
        u += t32 * (d[:, axis] / grid.cell).astype(np.float32)[:, None, None]
        return u

    ux, uy = grid_units(0), grid_units(1)
    inside = (ux >= 0) & (ux <= m - 1) & (uy >= 0) & (uy <= m - 1)
    ix = np.clip(ux.astype(np.intp), 0, m - 2)
    iy = np.clip(uy.astype(np.intp), 0, m - 2)
    ux -= ix
    uy -= iy
    i00 = iy * m
    i00 += ix
    i00 += (fidx * (m * m))[:, None, None]
    flat = fields.values.reshape(-1)
    lower = flat.take(i00)
    lower += ux * (flat.take(i00 + 1) - lower)
    i00 += m
    upper = flat.take(i00)
    upper += ux * (flat.take(i00 + 1) - upper)
    upper -= lower
    upper *= uy
    upper += lower
    return np.where(inside, upper, np.float32(1.0))


# -- the cases -----------------------------------------------------------------------------


@pytest.fixture(scope="module", params=["stapler", "disk"])
def fields(request):
    """A library scene's posterior samples (and its mean), as the planners read them."""
    scene = load_scene(request.param)
    belief = build_belief(scene, stream(7, scene.name, 0, "sensor"))
    samples = belief.sample(6, stream(7, scene.name, 0, "test-kernels"))
    return SDFBatch(scene.grid, samples.values, samples.gradients)


def _points(grid, rng, n):
    """Points over the grid and a margin beyond it (its border cells and outside)."""
    half = 0.5 * grid.extent
    return rng.uniform(-1.1 * half, 1.1 * half, (n, 2))


def test_interpolate_is_the_array_formulation(fields):
    rng = np.random.default_rng(1)
    points = _points(fields.grid, rng, 5000)
    points[:3] = [[np.nan, 0.0], [np.inf, 0.0], [0.0, -np.inf]]
    points[3:6] = fields.grid.coords[[0, -1, 5]][:, None]  # on nodes, where the cell's choice matters
    fidx = rng.integers(0, len(fields), len(points))
    value, grad = interpolate(fields, fidx, points)
    with np.errstate(invalid="ignore"):
        ref_value, ref_grad = ref_interpolate(fields, fidx, points)
    np.testing.assert_array_equal(value, ref_value)
    np.testing.assert_array_equal(grad, ref_grad)
    assert np.isfinite(value[6:]).all()


def test_refine_is_the_array_formulation(fields):
    rng = np.random.default_rng(2)
    n = 3000
    start = _points(fields.grid, rng, n) * 0.6
    angle = rng.uniform(0, 2 * np.pi, n)
    d = 0.12 * np.column_stack([np.cos(angle), np.sin(angle)])
    t = rng.uniform(0.0, 1.0, n)
    dt = rng.uniform(0.005, 0.05, n)
    t[:2], dt[2:4] = np.nan, np.nan  # NaN parameters and bounds stay NaN, as np.clip leaves them
    fidx = rng.integers(0, len(fields), n)
    got = _refine(fields, fidx, start, d, t, dt)
    with np.errstate(invalid="ignore"):
        ref = ref_refine(fields, fidx, start, d, t, dt)
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_array_equal(a, b)
    assert got[3].mean() > 0.9  # most gradients define a normal: the case is not vacuous


@pytest.mark.parametrize("shared", [True, False])
def test_read_lines_is_the_array_formulation(fields, shared):
    rng = np.random.default_rng(3)
    b, k = 400, 5
    starts = _points(fields.grid, rng, b * k).reshape(b, k, 2)
    angle = rng.uniform(0, 2 * np.pi, b)
    d = 0.2 * np.column_stack([np.cos(angle), np.sin(angle)])
    fidx = rng.integers(0, len(fields), b)
    steps = march_steps(np.linalg.norm(d, axis=1), fields.grid.cell)
    if shared:
        ts = np.linspace(0.0, 1.0, int(steps.max()))
    else:
        ts = np.minimum(np.arange(int(steps.max()))[None, :] / (steps - 1)[:, None], 1.0)
    got = read_lines(fields, fidx, starts, d, ts)
    ref = ref_read_lines(fields, fidx, starts, d, ts)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, ref)
    assert 0.01 < (ref < 0).mean() < 0.9  # lines through the object and beside it


def test_contacts_on_samples_are_deterministic_and_found(fields):
    """A second path to the same contacts: a grasp's contacts do not depend on the other
    grasps in its batch (each row alone gives the batch's row)."""
    rng = np.random.default_rng(4)
    b = 60
    angle = rng.uniform(0, np.pi, b)
    u = np.column_stack([np.cos(angle), np.sin(angle)])
    centre = rng.normal(0.0, 0.005, (b, 2))
    g1, g2 = centre - 0.09 * u, centre + 0.09 * u
    fidx = rng.integers(0, len(fields), b)
    batch = find_contacts(fields, g1, g2, 0.01, field_index=fidx)
    assert (batch.status == 0).mean() > 0.8
    for i in range(0, b, 7):
        one = find_contacts(fields, g1[i:i + 1], g2[i:i + 1], 0.01, field_index=fidx[i:i + 1])
        np.testing.assert_array_equal(one.c1[0], batch.c1[i])
        np.testing.assert_array_equal(one.n2[0], batch.n2[i])


def test_refine_on_a_flat_field_has_no_normal():
    """Zero gradient: no Newton step, a NaN normal and no valid contact, as the arrays give."""
    grid = load_scene("disk").grid
    flat = SDFBatch(grid, np.full((grid.size, grid.size), 0.01), np.zeros((grid.size, grid.size, 2)))
    n = 5
    start, d = np.zeros((n, 2)), np.tile([[0.05, 0.0]], (n, 1))
    t, dt = np.linspace(0.1, 0.9, n), np.full(n, 0.02)
    got = _refine(flat, np.zeros(n, dtype=np.int64), start, d, t, dt)
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = ref_refine(flat, np.zeros(n, dtype=np.int64), start, d, t, dt)
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not got[3].any() and np.isnan(got[2]).all()
    np.testing.assert_array_equal(got[0], t)


def ref_deepest_pairs(patch1, patch2, n1, n2):
    """plate_closure's pair choice as array code (the formulation the kernel replaced)."""
    b = len(patch1)
    line = patch2[:, None, :, :] - patch1[:, :, None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        line /= np.linalg.norm(line, axis=-1, keepdims=True)
    depth = np.minimum(-np.einsum("bijk,bk->bij", line, n1), np.einsum("bijk,bk->bij", line, n2))
    best = np.argmax(np.where(np.isfinite(depth), depth, -np.inf).reshape(b, -1), axis=1)
    return np.divmod(best, patch2.shape[1])


def test_the_deepest_pair_is_the_array_formulations(fields):
    """On contacts found on posterior samples (flat patches give near-ties between pairs,
    NaN where a plate line does not touch) and on random patches with NaN, repeated and
    infinite points."""
    from harness.kernels import deepest_pairs

    rng = np.random.default_rng(5)
    b = 400
    angle = rng.uniform(0, np.pi, b)
    u = np.column_stack([np.cos(angle), np.sin(angle)])
    centre = rng.normal(0.0, 0.01, (b, 2))
    found = find_contacts(fields, centre - 0.09 * u, centre + 0.09 * u, 0.01,
                          field_index=rng.integers(0, len(fields), b))
    cases = [(np.concatenate([found.c1[:, None], found.patch1], axis=1),
              np.concatenate([found.c2[:, None], found.patch2], axis=1), found.n1, found.n2)]
    p1, p2 = rng.normal(size=(b, 6, 2)), rng.normal(size=(b, 6, 2))
    p1[rng.random((b, 6)) < 0.2] = np.nan
    p2[:, 3] = p1[:, 3]  # zero-length lines
    p2[::17, 1] = np.inf
    cases.append((p1, p2, rng.normal(size=(b, 2)), rng.normal(size=(b, 2))))
    flush = 0
    for p1, p2, n1, n2 in cases:
        p1, p2, n1, n2 = (np.ascontiguousarray(a, dtype=float) for a in (p1, p2, n1, n2))
        i, j = deepest_pairs(p1, p2, n1, n2)
        ref_i, ref_j = ref_deepest_pairs(p1.copy(), p2, n1, n2)
        np.testing.assert_array_equal(i, ref_i)
        np.testing.assert_array_equal(j, ref_j)
        flush += int(((i > 0) | (j > 0)).sum())
    assert flush > 50  # pairs other than the first contacts were chosen: the case is not vacuous
