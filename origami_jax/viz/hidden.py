"""Hidden lines: the parts of creases that the sheet's faces hide from an orthographic camera."""

from __future__ import annotations

import numpy as np


def _occluded(points: np.ndarray, corners: np.ndarray, view: np.ndarray) -> np.ndarray:
    """(N,) whether the ray from each point (N, 3) towards the camera (direction ``view``) hits
    one of the triangles ``corners`` (T, 3, 3).

    The rays are parallel, so points and triangles are projected on the image plane and binned
    in a grid of cells about a triangle wide; each point is tested (Moller-Trumbore) only
    against the triangles whose image box overlaps its cell: O(N) tests, not O(N T).
    """
    helper = np.array([0.0, 0.0, 1.0]) if abs(view[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e_u = np.cross(view, helper)
    e_u /= np.linalg.norm(e_u)
    basis = np.stack([e_u, np.cross(view, e_u)], axis=1)  # (3, 2): image-plane coordinates
    p2, c2 = points @ basis, corners @ basis
    lo, hi = c2.min(axis=1), c2.max(axis=1)
    origin = np.minimum(lo.min(axis=0), p2.min(axis=0))
    extent = np.maximum(hi.max(axis=0), p2.max(axis=0)) - origin
    cell = max(float(np.median((hi - lo).max(axis=1))), float(extent.max()) / 2000, 1e-300)
    ny = int(extent[1] // cell) + 1
    first, last = ((lo - origin) // cell).astype(np.int64), ((hi - origin) // cell).astype(np.int64)
    span = last - first + 1  # (T, 2) cells each triangle's box covers
    count = span[:, 0] * span[:, 1]
    tri = np.repeat(np.arange(len(corners)), count)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    cx = first[tri, 0] + local % span[tri, 0]
    cy = first[tri, 1] + local // span[tri, 0]
    order = np.argsort(cx * ny + cy, kind="stable")
    cell_ids, tri = (cx * ny + cy)[order], tri[order]
    # Moller-Trumbore pieces that depend on the triangle only (the direction is shared)
    a = corners[:, 0]
    e1, e2 = corners[:, 1] - a, corners[:, 2] - a
    pvec = np.cross(view, e2)
    det = np.sum(e1 * pvec, axis=1)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    out = np.zeros(len(points), bool)
    pc = ((p2 - origin) // cell).astype(np.int64)
    pid = pc[:, 0] * ny + pc[:, 1]
    start = np.searchsorted(cell_ids, pid, side="left")
    n_cand = np.searchsorted(cell_ids, pid, side="right") - start
    chunk = 200_000
    for s in range(0, len(points), chunk):
        idx = np.arange(s, min(s + chunk, len(points)))
        k = n_cand[idx]
        pt = np.repeat(idx, k)
        t_ = tri[np.repeat(start[idx], k) + np.arange(len(pt)) - np.repeat(np.cumsum(k) - k, k)]
        tvec = points[pt] - a[t_]
        qvec = np.cross(tvec, e1[t_])
        u = np.sum(tvec * pvec[t_], axis=1) * inv[t_]
        w = (qvec @ view) * inv[t_]
        t = np.sum(qvec * e2[t_], axis=1) * inv[t_]
        hit = ok[t_] & (u > 1e-9) & (w > 1e-9) & (u + w < 1 - 1e-9) & (t > 0)
        out[pt[hit]] = True
    return out


def visible_pieces(segments: np.ndarray, corners: np.ndarray, view: np.ndarray) -> np.ndarray:
    """The parts of ``segments`` (n, 2, 3) that no triangle hides from an orthographic camera
    looking along ``-view``, as (m, 2, 3) segments (sampled at 16 points a segment, 8 on large
    meshes: a part shorter than that spacing may be missed)."""
    n = len(segments)
    if n == 0:
        return segments
    samples = 16 if n * len(corners) < 1e7 else 8
    size = float(np.ptp(corners.reshape(-1, 3), axis=0).max()) or 1.0
    s = (np.arange(samples) + 0.5) / samples
    start, step = segments[:, :1], segments[:, 1:2] - segments[:, :1]
    # lifted a hair towards the camera: the segment's own triangles are then behind it
    points = (start + s[None, :, None] * step).reshape(-1, 3) + 1e-7 * size * view
    visible = ~_occluded(points, corners, view).reshape(n, samples)
    if visible.all():
        return segments
    padded = np.pad(visible, ((0, 0), (1, 1)))
    change = np.diff(padded.astype(np.int8), axis=1)  # +1 where a visible run starts, -1 ends
    rows, begin = np.nonzero(change == 1)
    _, end = np.nonzero(change == -1)  # row-major order: the k-th end closes the k-th start
    a = start[rows, 0] + (begin / samples)[:, None] * step[rows, 0]
    b = start[rows, 0] + (end / samples)[:, None] * step[rows, 0]
    return np.stack([a, b], axis=1)
