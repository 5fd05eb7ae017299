"""Compiled loops (numba) for the field reads at the heart of contact finding: the
march's bilinear reads along the plate lines, the bicubic Hermite interpolant and the
Newton refinement of a crossing on it (harness.grasp).

Each kernel does, element by element, exactly the arithmetic of the array expressions
it replaced, in the same order and the same precision (single precision for the march,
as numpy computes a float32 array with a Python float: NEP 50), so that every contact,
plan and row stays bit for bit what it was (tests/test_kernels.py checks it against the
array formulation on random fields and lines). What they save is numpy's temporaries:
the reads cost most of a lift planner's time (docs/performance.md).

Compiled once per machine and kept in numba's cache beside this file (``cache=True``);
a process that finds no cache compiles them in a second or two on first use.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: A float of magnitude at least this has no int64 value; numpy's cast of it (and of
#: NaN) gives int64's lowest value, which the clip to the grid then maps to 0.
_NO_INT = 2.0**63


@njit(cache=True, error_model="numpy", inline="always")
def _node(u: float, top: int) -> int:
    """The lower node of the cell holding u (cells from the first node), as
    ``np.clip(np.floor(u).astype(np.int64), 0, top)``."""
    f = math.floor(u) if abs(u) < _NO_INT else -_NO_INT
    i = int(f) if f > -_NO_INT else 0
    return min(max(i, 0), top)


@njit(cache=True, error_model="numpy", inline="always")
def _clip_node(u: np.float32, top: int) -> int:
    """``np.clip(u.astype(np.intp), 0, top)`` of a float32 u (truncation towards 0)."""
    if not abs(u) < _NO_INT:
        return 0
    return min(max(int(u), 0), top)


@njit(cache=True, error_model="numpy", inline="always")
def _basis(t: float):
    """The cubic Hermite basis on [0, 1] (harness.grasp._hermite_basis), term for term."""
    t2 = t * t
    t3 = t2 * t
    h1 = 3 * t2 - 2 * t3
    d1 = 6 * (t - t2)
    return 1 - h1, h1, t - 2 * t2 + t3, t3 - t2, -d1, d1, 1 - 4 * t + 3 * t2, 3 * t2 - 2 * t


@njit(cache=True, error_model="numpy", inline="always")
def _bicubic(values, gx, gy, twist, m: int, c0: float, cell: float, f: int, x: float, y: float):
    """Value and gradient (dx, dy, each divided by the cell at the end) of field f at
    (x, y): harness.grasp.interpolate for one point."""
    h = cell
    h32 = np.float32(h)
    hh32 = np.float32(h * h)
    ux = (x - c0) / cell
    uy = (y - c0) / cell
    ix = _node(ux, m - 2)
    iy = _node(uy, m - 2)
    s = ux - ix
    r = uy - iy
    base = f * (m * m) + iy * m + ix
    h0s, h1s, g0s, g1s, dh0s, dh1s, dg0s, dg1s = _basis(s)
    h0r, h1r, g0r, g1r, dh0r, dh1r, dg0r, dg1r = _basis(r)
    along0 = along1 = along_y0 = along_y1 = 0.0
    slope0 = slope1 = slope_y0 = slope_y1 = 0.0
    for row in range(2):
        k = base + row * m
        f0, f1 = np.float64(values[k]), np.float64(values[k + 1])
        fx0, fx1 = np.float64(gx[k] * h32), np.float64(gx[k + 1] * h32)
        fy0, fy1 = np.float64(gy[k] * h32), np.float64(gy[k + 1] * h32)
        fxy0, fxy1 = np.float64(twist[k] * hh32), np.float64(twist[k + 1] * hh32)
        along = h0s * f0 + h1s * f1 + g0s * fx0 + g1s * fx1
        along_y = h0s * fy0 + h1s * fy1 + g0s * fxy0 + g1s * fxy1
        slope = dh0s * f0 + dh1s * f1 + dg0s * fx0 + dg1s * fx1
        slope_y = dh0s * fy0 + dh1s * fy1 + dg0s * fxy0 + dg1s * fxy1
        if row == 0:
            along0, along_y0, slope0, slope_y0 = along, along_y, slope, slope_y
        else:
            along1, along_y1, slope1, slope_y1 = along, along_y, slope, slope_y
    value = h0r * along0 + h1r * along1 + g0r * along_y0 + g1r * along_y1
    dx = h0r * slope0 + h1r * slope1 + g0r * slope_y0 + g1r * slope_y1
    dy = dh0r * along0 + dh1r * along1 + dg0r * along_y0 + dg1r * along_y1
    return value, dx / h, dy / h


@njit(cache=True, error_model="numpy")
def interpolate(values, gx, gy, twist, m, c0, cell, fidx, points):
    """Value (B,) and gradient (B, 2) of field fidx[b] at points (B, 2); the fields
    flattened (F * M * M,) in float32."""
    b = len(fidx)
    value = np.empty(b)
    grad = np.empty((b, 2))
    for i in range(b):
        value[i], grad[i, 0], grad[i, 1] = _bicubic(values, gx, gy, twist, m, c0, cell, fidx[i],
                                                    points[i, 0], points[i, 1])
    return value, grad


@njit(cache=True, error_model="numpy")
def refine(values, gx, gy, twist, m, c0, cell, fidx, start, d, t, dt, newton_steps, min_gradient):
    """harness.grasp._refine: ``newton_steps`` Newton steps on the interpolant along
    start + t d (B,), each clipped to one march step dt either side of the first t;
    the parameters, points, unit normals (the gradient at the last iterate) and whether
    the gradient there is long enough."""
    b = len(fidx)
    t_out = np.empty(b)
    point = np.empty((b, 2))
    normal = np.empty((b, 2))
    valid = np.empty(b, dtype=np.bool_)
    for i in range(b):
        ti = t[i]
        lo, hi = ti - dt[i], ti + dt[i]
        sx, sy, dx, dy = start[i, 0], start[i, 1], d[i, 0], d[i, 1]
        gxi = gyi = np.nan
        for _ in range(newton_steps):
            value, gxi, gyi = _bicubic(values, gx, gy, twist, m, c0, cell, fidx[i], sx + ti * dx, sy + ti * dy)
            slope = gxi * dx + gyi * dy
            step = value / slope if abs(slope) > 1e-12 else 0.0
            ti = ti - step
            # np.clip: a NaN parameter or bound gives NaN.
            if ti == ti and lo == lo and hi == hi:
                ti = min(max(ti, lo), hi)
            else:
                ti = np.nan
        norm = math.sqrt(gxi * gxi + gyi * gyi)
        t_out[i] = ti
        point[i, 0], point[i, 1] = sx + ti * dx, sy + ti * dy
        normal[i, 0], normal[i, 1] = gxi / norm, gyi / norm
        valid[i] = math.isfinite(norm) and norm >= min_gradient
    return t_out, point, normal, valid


@njit(cache=True, error_model="numpy")
def read_lines(values, m, c0, cell, fidx, starts, d, ts):
    """Bilinear values (B, K, T), in float32, along starts[b, k] + ts[b] * d[b] of field
    fidx[b] (harness.grasp.read_lines); ts (B, T), float32. 1 outside the grid's nodes."""
    b, k = starts.shape[0], starts.shape[1]
    n = ts.shape[1]
    out = np.empty((b, k, n), dtype=np.float32)
    top = np.float32(m - 1)
    zero, one = np.float32(0.0), np.float32(1.0)
    for i in range(b):
        base = fidx[i] * (m * m)
        ddx = np.float32(d[i, 0] / cell)
        ddy = np.float32(d[i, 1] / cell)
        for j in range(k):
            sx = np.float32((starts[i, j, 0] - c0) / cell)
            sy = np.float32((starts[i, j, 1] - c0) / cell)
            for q in range(n):
                t = ts[i, q]
                ux = sx + t * ddx
                uy = sy + t * ddy
                if not (ux >= zero and ux <= top and uy >= zero and uy <= top):
                    out[i, j, q] = one
                    continue
                ix = _clip_node(ux, m - 2)
                iy = _clip_node(uy, m - 2)
                fx = np.float32(ux - np.float32(ix))
                fy = np.float32(uy - np.float32(iy))
                at = base + iy * m + ix
                lower = values[at]
                lower = lower + fx * (values[at + 1] - lower)
                upper = values[at + m]
                upper = upper + fx * (values[at + m + 1] - upper)
                out[i, j, q] = (upper - lower) * fy + lower
    return out


@njit(cache=True, error_model="numpy")
def deepest_pairs(patch1, patch2, n1, n2):
    """harness.grasp.plate_closure's choice of contact pair: for each b, the pair (i, j)
    of a point of patch1[b] (K1, 2) and one of patch2[b] (K2, 2) whose unit line lies
    deepest inside both friction cones, min(-line . n1, line . n2); the first such pair in
    row-major order, as np.argmax, non-finite depths counting as -inf, (0, 0) if all are."""
    b, k1, k2 = patch1.shape[0], patch1.shape[1], patch2.shape[1]
    first = np.empty(b, dtype=np.int64)
    second = np.empty(b, dtype=np.int64)
    for r in range(b):
        best, bi, bj = -np.inf, 0, 0
        for i in range(k1):
            for j in range(k2):
                lx = patch2[r, j, 0] - patch1[r, i, 0]
                ly = patch2[r, j, 1] - patch1[r, i, 1]
                norm = math.sqrt(lx * lx + ly * ly)
                lx = lx / norm
                ly = ly / norm
                a = -(lx * n1[r, 0] + ly * n1[r, 1])
                c = lx * n2[r, 0] + ly * n2[r, 1]
                # np.minimum: NaN if either is.
                depth = a if a < c else c
                if a != a or c != c:
                    depth = np.nan
                if not math.isfinite(depth):
                    depth = -np.inf
                if depth > best:
                    best, bi, bj = depth, i, j
        first[r], second[r] = bi, bj
    return first, second


@njit(cache=True, error_model="numpy")
def spans_wrenches(w, count, tolerance):
    """Whether the first count[b] wrenches w[b] (B, M, 3) positively span the wrench space
    (the origin strictly inside their convex hull: force closure). They do not exactly when
    some direction v has v . w_i <= 0 for every wrench; such a plane through the origin can
    be turned until it holds two of the wrenches (or all of them lie in one plane), so the
    candidates v are the cross products of the pairs, both signs. ``tolerance`` is relative
    to the wrenches' lengths: a wrench that close to the plane counts as on it."""
    b = w.shape[0]
    out = np.zeros(b, dtype=np.bool_)
    for r in range(b):
        n = count[r]
        if n < 4:
            continue
        spans = True
        planes = 0
        for i in range(n):
            for j in range(i + 1, n):
                vx = w[r, i, 1] * w[r, j, 2] - w[r, i, 2] * w[r, j, 1]
                vy = w[r, i, 2] * w[r, j, 0] - w[r, i, 0] * w[r, j, 2]
                vz = w[r, i, 0] * w[r, j, 1] - w[r, i, 1] * w[r, j, 0]
                size = math.sqrt(vx * vx + vy * vy + vz * vz)
                if size <= 1e-12 * (w[r, i, 0] ** 2 + w[r, i, 1] ** 2 + w[r, i, 2] ** 2 + w[r, j, 0] ** 2
                                    + w[r, j, 1] ** 2 + w[r, j, 2] ** 2):
                    continue  # a parallel pair spans no plane
                planes += 1
                for sign in (1.0, -1.0):
                    separates = True
                    for k in range(n):
                        dot = sign * (vx * w[r, k, 0] + vy * w[r, k, 1] + vz * w[r, k, 2])
                        scale = size * math.sqrt(w[r, k, 0] ** 2 + w[r, k, 1] ** 2 + w[r, k, 2] ** 2)
                        if dot > tolerance * scale:
                            separates = False
                            break
                    if separates:
                        spans = False
                        break
                if not spans:
                    break
            if not spans:
                break
        out[r] = spans and planes > 0
    return out
