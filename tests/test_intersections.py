"""intersecting_pairs: crossings counted and not, its grid against a brute-force reference,
folded sheets, and FoldResult.intersections."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

import origami_jax as oj
from origami_jax import intersections, patterns
from origami_jax.intersections import INTERSECTION_DEPTH, intersecting_pairs
from origami_jax.kinematics import rigid_fold

UNIT = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # triangle 0, in z = 0
TWO = np.array([[0, 1, 2], [3, 4, 5]])


def pairs(b: np.ndarray, depth: float = 1e-6, a: np.ndarray = UNIT) -> list[list[int]]:
    """The crossings of triangle ``a`` and triangle ``b`` (3, 3), as a list."""
    return intersecting_pairs(np.concatenate([a, b]), TWO, depth).tolist()


# -- two triangles ---------------------------------------------------------------------------


def test_crossing_counted_and_moved_apart_not():
    # an upright triangle in x = 0.3 whose top edges pass through the unit triangle
    b = np.array([[0.3, -0.5, -0.5], [0.3, 0.25, 0.5], [0.3, 1.0, -0.5]])
    assert pairs(b) == [[0, 1]]
    assert pairs(b, 0.0) == [[0, 1]]
    x = np.concatenate([b, UNIT])  # the other order: still (0, 1)
    assert intersecting_pairs(x, TWO, 1e-6).tolist() == [[0, 1]]
    assert pairs(b + [5.0, 0.0, 0.0]) == []  # beside it
    assert pairs(b + [0.0, 0.0, 0.6]) == []  # above it
    assert pairs(b + [0.8, 0.0, 0.0]) == []  # its plane crosses the unit triangle's, outside


def test_rounding_depth_counts_only_at_zero_depth():
    # one corner 1e-9 below the unit triangle, inside it: a touch at rounding depth
    b = np.array([[0.25, 0.25, -1e-9], [0.5, 0.1, 1.0], [0.1, 0.5, 1.0]])
    assert pairs(b, 1e-6) == []
    assert pairs(b, 1e-10) == [[0, 1]]
    assert pairs(b, 0.0) == [[0, 1]]
    b[0, 2] = 0.0  # resting on it exactly: no crossing at all
    assert pairs(b, 0.0) == []


def test_end_points_must_be_deeper_than_depth_on_both_sides():
    depth = 1e-3
    for below, above, counted in [(2, 2, True), (0.5, 2, False), (2, 0.5, False)]:
        b = np.array([[0.3, 0.3, -below * depth], [0.3, 0.3, above * depth], [5.0, 5.0, 0.0]])
        assert pairs(b, depth) == ([[0, 1]] if counted else []), (below, above)


def test_sharing_a_vertex_is_excluded():
    # triangle 1 has corner 0 of the unit triangle and its far edge passes through it
    x = np.concatenate([UNIT, [[0.5, 0.3, -0.5], [0.3, 0.5, 0.5]]])
    assert intersecting_pairs(x, np.array([[0, 1, 2], [0, 3, 4]]), 0.0).tolist() == []
    # the same geometry with its own copy of that corner is a crossing
    x = np.concatenate([x, UNIT[:1]])
    assert intersecting_pairs(x, np.array([[0, 1, 2], [5, 3, 4]]), 1e-6).tolist() == [[0, 1]]


def test_coplanar_layers_are_not_counted():
    rng = np.random.default_rng(0)
    b = np.array([[0.2, 0.2, 0.0], [1.2, 0.3, 0.0], [0.1, 0.9, 0.0]])  # overlapping, in z = 0
    assert pairs(b, 0.0) == []
    noisy = b + [0.0, 0.0, 1.0] * rng.normal(0.0, 1e-12, (3, 3))  # rounding off the plane
    assert pairs(noisy) == []
    assert pairs(b + [0.0, 0.0, 1e-3], 0.0) == []  # a layer above: stacked, not crossing


def test_long_edge_through_the_interior_is_counted():
    small = UNIT * 0.01  # a small triangle; the crossing point (0.003, 0.003) is inside it
    upright = np.array([[0.003, 0.003, -10.0], [0.003, 0.003, 10.0], [20.0, 0.0, 0.0]])
    assert pairs(upright, 1e-6, small) == [[0, 1]]
    # a long edge at a shallow angle (0.006 degrees) still passes through
    shallow = np.array([[-9.997, 0.003, -1e-3], [10.003, 0.003, 1e-3], [0.003, 30.0, 5.0]])
    assert pairs(shallow, 1e-6, small) == [[0, 1]]
    assert pairs(shallow, 2e-3, small) == []  # its ends are within that depth of the plane


def test_piercing_near_the_boundary_needs_depth_from_it():
    depth = 1e-3
    for x0, counted in [(2e-3, True), (5e-4, False), (0.0, False), (-5e-4, False)]:
        # an upright edge at distance x0 inside the unit triangle's edge x = 0
        b = np.array([[x0, 0.3, -1.0], [x0, 0.3, 1.0], [-3.0, 0.3, 0.0]])
        assert pairs(b, depth) == ([[0, 1]] if counted else []), x0
    # near a corner: inside both edges but too close to the hypotenuse x + y = 1
    b = np.array([[0.4995, 0.4995, -1.0], [0.4995, 0.4995, 1.0], [3.0, 3.0, 0.0]])
    assert pairs(b, depth) == []
    assert pairs(b, 1e-4) == [[0, 1]]


def test_degenerate_inputs():
    empty = intersecting_pairs(np.zeros((0, 3)), np.zeros((0, 3), int), 0.0)
    assert empty.shape == (0, 2) and empty.dtype == np.int64
    assert intersecting_pairs(UNIT, np.array([[0, 1, 2]]), 0.0).shape == (0, 2)
    points = np.zeros((6, 3))  # triangles of zero size
    assert intersecting_pairs(points, TWO, 0.0).shape == (0, 2)
    # a collapsed (zero-area) triangle has no plane, but its edges can still cross
    b = np.array([[0.3, 0.3, -1.0], [0.3, 0.3, 1.0], [0.3, 0.3, 0.0]])
    assert pairs(b) == [[0, 1]]
    nan = np.array([[0.3, -0.5, -0.5], [0.3, 0.25, 0.5], [np.nan, 1.0, -0.5]])
    assert pairs(nan) == []  # skipped, no error
    with pytest.raises(ValueError, match="depth"):
        intersecting_pairs(UNIT, np.array([[0, 1, 2]]), -1.0)
    with pytest.raises(ValueError, match="positions"):
        intersecting_pairs(UNIT[:, :2], np.array([[0, 1, 2]]), 0.0)
    with pytest.raises(ValueError, match="index"):
        intersecting_pairs(UNIT, np.array([[0, 1, 3]]), 0.0)


# -- the grid against a brute-force reference --------------------------------------------------


def _edge_crosses(p, q, tri, depth: float) -> bool:
    """Plain-float reference of the docstring's test: does segment ``pq`` cross ``tri``?"""
    a, b, c = tri
    u = [b[k] - a[k] for k in range(3)]
    w = [c[k] - a[k] for k in range(3)]
    n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]]
    size = math.sqrt(sum(v * v for v in n))
    if size == 0.0:
        return False
    n = [v / size for v in n]
    dp = sum(n[k] * (p[k] - a[k]) for k in range(3))
    dq = sum(n[k] * (q[k] - a[k]) for k in range(3))
    if not ((dp > depth and dq < -depth) or (dp < -depth and dq > depth)):
        return False
    t = dp / (dp - dq)
    x = [p[k] + t * (q[k] - p[k]) for k in range(3)]
    for s, e in ((a, b), (b, c), (c, a)):
        # signed distance inside edge se: ((e - s) x (x - s)) . n / |e - s|
        f = [e[k] - s[k] for k in range(3)]
        g = [x[k] - s[k] for k in range(3)]
        cross = [f[1] * g[2] - f[2] * g[1], f[2] * g[0] - f[0] * g[2], f[0] * g[1] - f[1] * g[0]]
        inside = sum(cross[k] * n[k] for k in range(3)) / math.sqrt(sum(v * v for v in f))
        if not inside > depth:
            return False
    return True


def brute_force(x: np.ndarray, tri: np.ndarray, depth: float) -> list[list[int]]:
    """All O(T^2) pairs through the plain-float reference."""
    corners = [[list(map(float, x[v])) for v in t] for t in tri]
    found = []
    for i, j in itertools.combinations(range(len(tri)), 2):
        if set(tri[i].tolist()) & set(tri[j].tolist()):
            continue
        if any(
            _edge_crosses(one[s], one[e], other, depth)
            for one, other in ((corners[i], corners[j]), (corners[j], corners[i]))
            for s, e in ((0, 1), (1, 2), (2, 0))
        ):
            found.append([i, j])
    return found


def soup(
    seed: int,
    num: int = 200,
    size: float = 0.08,
    share: float = 0.0,
    collapse: float = 0.0,
    box: tuple[float, float, float] = (1.0, 1.0, 1.0),
):
    """``num`` random triangles of about ``size`` in a box; a fraction ``collapse`` of them
    collapsed to a segment, a fraction ``share`` taking one corner of another triangle's
    (shared index, kept nearby)."""
    rng = np.random.default_rng(seed)
    x = rng.random((num, 1, 3)) * box + rng.normal(0.0, size, (num, 3, 3)) * box
    flat = rng.random(num) < collapse
    x[flat, 2] = 0.5 * (x[flat, 0] + x[flat, 1])  # corner 2 on edge 01
    x = x.reshape(-1, 3)
    tri = np.arange(3 * num).reshape(num, 3)
    for k in np.flatnonzero(rng.random(num) < share):
        other = int(rng.integers(num))
        if other != k:
            tri[k, 0] = tri[other, int(rng.integers(3))]
    return x, tri


@pytest.mark.parametrize(
    "seed, box",
    [(0, (1.0, 1.0, 1.0)), (1, (1.0, 1.0, 1.0)), (2, (1.0, 1.0, 0.01))],  # a cube, a thin slab
)
def test_matches_brute_force_on_random_soups(seed, box):
    x, tri = soup(seed, size=0.08, share=0.3, collapse=0.1, box=box)
    for depth in (0.0, 1e-4):
        expected = brute_force(x, tri, depth)
        assert len(expected) > 20
        assert intersecting_pairs(x, tri, depth).tolist() == expected


def test_matches_brute_force_on_mixed_sizes_and_far_clusters():
    # a few large triangles among small ones (cells grown), a far cluster (a sparse grid)
    x, tri = soup(3, num=150, size=0.03)
    big, _ = soup(4, num=4, size=0.6)
    far, far_tri = soup(5, num=40, size=0.15)
    x = np.concatenate([x, big, far * 0.1 + 1e7])
    tri = np.concatenate([tri, np.arange(450, 462).reshape(4, 3), far_tri + 462])
    expected = brute_force(x, tri, 0.0)
    assert any(i < 150 <= j < 154 for i, j in expected)  # large triangles cross small ones
    assert any(i >= 154 for i, j in expected)  # the far cluster crosses itself
    assert intersecting_pairs(x, tri, 0.0).tolist() == expected


def test_small_chunks_give_the_same_pairs(monkeypatch):
    x, tri = soup(6, size=0.1)
    expected = intersecting_pairs(x, tri, 0.0).tolist()
    monkeypatch.setattr(intersections, "_CHUNK", 7)
    assert intersecting_pairs(x, tri, 0.0).tolist() == expected
    # triangles all around one point: (nearly) all pairs are candidates, in many chunks
    stacked = np.random.default_rng(7).normal(0.0, 1.0, (360, 3))
    assert intersecting_pairs(stacked, tri[:120], 0.0).tolist() == brute_force(
        stacked, tri[:120], 0.0
    )


# -- folded sheets ---------------------------------------------------------------------------


def strip() -> oj.CreasePattern:
    """Three unit squares in a row, valley creases at x = 1 and x = 2."""
    v = np.array([[x, y] for y in (0, 1) for x in range(4)], float)
    faces = [(0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6)]
    edges = [(0, 1), (1, 2), (2, 3), (4, 5), (5, 6), (6, 7), (0, 4), (1, 5), (2, 6), (3, 7)]
    return oj.CreasePattern(v, edges, faces, "BBBBBBBVVB", name="strip")


def folded_strip(cp: oj.CreasePattern, first: float, second: float) -> np.ndarray:
    angles = np.zeros(cp.mesh.num_edges)
    angles[7], angles[8] = np.radians(first), np.radians(second)  # the creases (pattern edges)
    return rigid_fold(cp, angles)


def test_folded_strip_flaps_through_each_other():
    cp = strip()
    depth = INTERSECTION_DEPTH * cp.diameter
    tri = cp.mesh.triangles
    # both end flaps folded over the middle by 170 degrees meet halfway and cross there
    crossing = intersecting_pairs(folded_strip(cp, 170, 170), tri, depth)
    assert len(crossing)
    end = {0: tri[:2], 2: tri[4:]}  # the triangles of the end squares
    first = {k for k, t in enumerate(tri) if any((t == u).all() for u in end[0])}
    last = {k for k, t in enumerate(tri) if any((t == u).all() for u in end[2])}
    assert all(i in first and j in last for i, j in crossing.tolist())
    # one flap folded through the middle square (200 degrees) and the other under it
    assert intersecting_pairs(folded_strip(cp, 200, -170), tri, depth).tolist() == crossing.tolist()
    # upright flaps, flaps folded exactly flat (coplanar layers), one flap folded through
    # (past 180 degrees it meets the middle square only along the crease: through_pi's case)
    for first_angle, second_angle in [(90, 90), (180, 180), (200, 0)]:
        x = folded_strip(cp, first_angle, second_angle)
        assert intersecting_pairs(x, tri, depth).shape == (0, 2), (first_angle, second_angle)


@pytest.mark.parametrize("fold_angle", [0.5, np.pi / 2, 3.0])
def test_rigid_miura_ori_is_clean(fold_angle):
    cp = patterns.miura_ori(3, 3, fold_angle=fold_angle)
    found = intersecting_pairs(rigid_fold(cp), cp.mesh.triangles, INTERSECTION_DEPTH * cp.diameter)
    assert found.shape == (0, 2)


def test_fold_result_intersections():
    cp = patterns.miura_ori(2, 2)
    result = oj.fold(cp)
    assert result.intersections.shape == (0, 2)
    assert "intersecting" not in result.summary()
    # the same report for another pattern's crossing state
    other = strip()
    crossed = dataclasses.replace(result, pattern=other, positions=folded_strip(other, 170, 170))
    found = crossed.intersections
    assert len(found)
    row = f"{len(found)} triangle pairs: " + ", ".join(f"{i}-{j}" for i, j in found)
    assert row in crossed.summary()


# -- shared patterns (skipped without ../shared) ---------------------------------------------


def test_largest_shared_pattern_flat_bumped_and_crumpled(shared_patterns):
    """The 2,601-vertex sheet: flat and smoothly bumped, no pair; crumpled at random, pairs."""
    path = shared_patterns / "origami-simulator" / "Pleating" / "BoxPleatInOutWave.fold"
    if not path.is_file():
        pytest.skip(f"{path} is not present")
    cp = oj.load(path)
    flat, tri = cp.mesh.vertices, cp.mesh.triangles
    depth = INTERSECTION_DEPTH * cp.diameter
    rng = np.random.default_rng(0)
    centred = flat[:, :2] - flat[:, :2].mean(axis=0)
    bump = flat + np.array([0.0, 0.0, 0.3]) * np.exp(-(centred**2).sum(axis=1) / 0.3)[:, None]
    size = np.median(np.linalg.norm(flat[tri[:, 1]] - flat[tri[:, 0]], axis=1))
    crumpled = flat + rng.normal(0.0, size, flat.shape)
    cases = [("flat", flat, True), ("bump", bump, True), ("crumpled", crumpled, False)]
    for name, x, clean in cases:
        found = intersecting_pairs(x, tri, depth)
        assert (len(found) == 0) == clean, name
