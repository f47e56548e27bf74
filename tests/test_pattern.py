"""CreasePattern validation, defaults, triangulation, hinges and cuts (pure NumPy, no JAX)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from origami_jax.pattern import ASSIGNMENTS, CreasePattern, Mesh, PatternError

PI = math.pi

# ---------------------------------------------------------------------------------------------
# helpers


def square(**overrides) -> dict:
    """Unit square folded along its diagonal 0-2: edges 0..3 border, edge 4 the diagonal."""
    kw = dict(
        vertices=[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]],
        faces=[[0, 1, 2], [0, 2, 3]],
    )
    kw.update(overrides)
    return kw


def sides_of(faces) -> list[tuple[int, int]]:
    """The faces' sides as edges, each once, in order of first appearance."""
    seen: dict[tuple[int, int], tuple[int, int]] = {}
    for f in faces:
        for s in range(len(f)):
            a, b = int(f[s]), int(f[(s + 1) % len(f)])
            seen.setdefault((min(a, b), max(a, b)), (a, b))
    return list(seen.values())


def from_faces(vertices, faces, **kw) -> CreasePattern:
    return CreasePattern(vertices=vertices, edges=sides_of(faces), faces=faces, **kw)


def grid(n: int, m: int | None = None):
    """An n x m sheet of unit squares (quad faces): vertices, edges, faces, index(x, y)."""
    m = n if m is None else m
    vertices = [(x, y) for y in range(m + 1) for x in range(n + 1)]

    def idx(x, y):
        return y * (n + 1) + x

    faces = [
        [idx(x, y), idx(x + 1, y), idx(x + 1, y + 1), idx(x, y + 1)]
        for y in range(m)
        for x in range(n)
    ]
    return vertices, sides_of(faces), faces, idx


def edge_index(cp: CreasePattern, a: int, b: int) -> int:
    hit = np.flatnonzero(
        ((cp.edges[:, 0] == a) & (cp.edges[:, 1] == b))
        | ((cp.edges[:, 0] == b) & (cp.edges[:, 1] == a))
    )
    assert len(hit) == 1
    return int(hit[0])


def signed_area(points) -> float:
    p = np.asarray(points, dtype=float)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def cross2(o, u, v) -> float:
    return float((u[0] - o[0]) * (v[1] - o[1]) - (u[1] - o[1]) * (v[0] - o[0]))


def inside(point, polygon) -> bool:
    """Strictly inside a simple polygon (even-odd ray casting; boundary points are avoided)."""
    x, y = point
    poly = np.asarray(polygon, dtype=float)
    hit = False
    for s in range(len(poly)):
        (x0, y0), (x1, y1) = poly[s], poly[(s + 1) % len(poly)]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            hit = not hit
    return hit


def check_mesh(cp: CreasePattern) -> Mesh:
    """Invariants every mesh must satisfy; returns the mesh."""
    m = cp.mesh
    v, tri = m.vertices, m.triangles
    assert v.shape == (m.num_vertices, 3) and np.all(v[:, 2] == 0)
    assert tri.shape == (len(m.triangle_face), 3)
    E = m.num_edges
    assert m.edges.shape == (E, 2) and m.hinges.shape == (E, 4)
    assert m.source_edge.shape == m.role.shape == m.target.shape == (E,)
    # triangles: counterclockwise, positive area, and the faces' areas are preserved
    areas = np.array([signed_area(v[t, :2]) for t in tri])
    assert np.all(areas > 0)
    for k, face in enumerate(cp.faces):
        assert areas[m.triangle_face == k].sum() == pytest.approx(
            signed_area(cp.vertices[list(face), :2]), rel=1e-12
        )
    # the pattern's vertices come first; later ones are copies of pattern vertices
    np.testing.assert_array_equal(v[: cp.num_vertices], cp.vertices)
    # every triangle side is exactly one mesh edge, with no edge repeated
    keys = [tuple(sorted(map(int, e))) for e in m.edges]
    assert len(set(keys)) == E
    sides = {(int(t[s]), int(t[(s + 1) % 3])) for t in tri for s in range(3)}
    assert len(sides) == 3 * len(tri)  # no directed side twice: consistent orientation
    assert {tuple(sorted(s)) for s in sides} == set(keys)
    # hinges: (i, j) is the edge, k the apex of the triangle on the left, l on the right
    np.testing.assert_array_equal(m.hinges[:, :2], m.edges)
    for e, (i, j, k, l) in enumerate(m.hinges):
        assert ((i, j) in sides) == (k >= 0) and ((j, i) in sides) == (l >= 0)
        if k >= 0:
            assert (j, k) in sides and (k, i) in sides
            assert cross2(v[i], v[j], v[k]) > 0  # left of i -> j
        if l >= 0:
            assert (i, l) in sides and (l, j) in sides
            assert cross2(v[i], v[j], v[l]) < 0  # right of i -> j
        assert (m.role[e] == "border") == (k < 0 or l < 0)
        assert k >= 0 or l >= 0
    assert np.all(m.target[m.role != "driven"] == 0)
    # the pattern's edges first, in order
    num_cut_sides = int((cp.assignments == "C").sum())
    np.testing.assert_array_equal(m.source_edge[: cp.num_edges], np.arange(cp.num_edges))
    for k, (a, b) in enumerate(cp.edges):
        mv = m.vertices[m.edges[k]]
        pv = cp.vertices[[a, b]]
        assert np.allclose(mv, pv) or np.allclose(mv, pv[::-1]), k
        if m.num_vertices == cp.num_vertices:  # no cuts: the very same vertices
            assert sorted(m.edges[k]) == sorted([a, b])
    # then the cut's second sides, then the triangulation edges (facets, source -1)
    second = m.source_edge[cp.num_edges : cp.num_edges + num_cut_sides]
    assert sorted(second) == sorted(np.flatnonzero(cp.assignments == "C"))
    added = slice(cp.num_edges + num_cut_sides, None)
    assert np.all(m.source_edge[added] == -1)
    assert np.all(m.role[added] == "facet") and np.all(m.target[added] == 0)
    n_added = sum(len(f) - 3 for f in cp.faces)
    assert E == cp.num_edges + num_cut_sides + n_added
    assert len(tri) == sum(len(f) - 2 for f in cp.faces)
    return m


# ---------------------------------------------------------------------------------------------
# a valid pattern


def test_square_pattern_basics():
    cp = CreasePattern(**square(), assignments="BBBBV", fold_angles=[0, 0, 0, 0, 1.0], name="sq")
    assert (cp.num_vertices, cp.num_edges, cp.num_faces) == (4, 5, 2)
    assert cp.vertices.shape == (4, 3) and cp.vertices.dtype == np.float64
    assert cp.edges.dtype == np.int64
    assert list(cp.assignments) == list("BBBBV")
    np.testing.assert_array_equal(cp.fold_angles, [0, 0, 0, 0, 1.0])
    assert cp.faces == ((0, 1, 2), (0, 2, 3))
    m = check_mesh(cp)
    assert list(m.role) == ["border"] * 4 + ["driven"]
    assert m.target[4] == 1.0
    assert m.num_vertices == 4 and m.num_edges == 5
    np.testing.assert_array_equal(m.edges_with_role("driven"), [4])
    np.testing.assert_array_equal(m.edges_with_role("border"), [0, 1, 2, 3])


def test_pattern_error_is_value_error():
    assert issubclass(PatternError, ValueError)
    with pytest.raises(ValueError):
        CreasePattern(**square(edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 9]]))


def test_accepts_3d_flat_vertices_and_lowercase_letters_and_sequences():
    v3 = [[0, 0, 0], [1, 0, 0], [1, 1, 1e-17], [0, 1, 0]]
    cp = CreasePattern(**square(vertices=v3), assignments="bbbbm")
    assert list(cp.assignments) == list("BBBBM")
    assert np.all(cp.vertices[:, 2] == 0)
    cp = CreasePattern(**square(), assignments=["B", "B", "B", "B", "V"])
    assert cp.fold_angles[4] == PI
    cp = CreasePattern(**square(edges=np.array([[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]], float)))
    assert cp.edges.dtype == np.int64


def test_fold_angle_just_beyond_pi_is_clipped():
    cp = CreasePattern(**square(), assignments="BBBBV", fold_angles=[0, 0, 0, 0, PI * (1 + 1e-13)])
    assert cp.fold_angles[4] == PI
    cp = CreasePattern(**square(), assignments="BBBBM", fold_angles=[0, 0, 0, 0, -PI])
    assert cp.fold_angles[4] == -PI


# ---------------------------------------------------------------------------------------------
# validation: each error names the element at fault and the problem

NAN, INF = float("nan"), float("inf")
SQ_V = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
SQ_E = [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]]

INVALID = {
    # vertices
    "vertices 1-D": (dict(vertices=[0.0, 1.0, 2.0, 3.0]), r"^vertices: expected shape \(V, 2\)"),
    "vertices 4 columns": (
        dict(vertices=[[0, 0, 0, 0]] * 4),
        r"^vertices: expected shape \(V, 2\) or \(V, 3\), got \(4, 4\)",
    ),
    "vertices ragged": (dict(vertices=[[0, 0], [1]]), r"^vertices: cannot be read"),
    "vertices text": (dict(vertices=[["a", "b"]] * 4), r"^vertices: cannot be read"),
    "two vertices": (dict(vertices=[[0, 0], [1, 0]]), r"^vertices: .*at least 3 vertices, got 2"),
    "vertex NaN": (
        dict(vertices=[[0, 0], [1, 0], [1, NAN], [0, 1]]),
        r"^vertex 2: non-finite coordinate",
    ),
    "vertex inf": (
        dict(vertices=[[0, 0], [INF, 0], [1, 1], [0, 1]]),
        r"^vertex 1: non-finite coordinate",
    ),
    "vertex not flat": (
        dict(vertices=[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.5]]),
        r"^vertex 3: z = 0\.5, but a crease pattern must be flat",
    ),
    # edges
    "edges 3 columns": (
        dict(edges=[[0, 1, 2], [2, 3, 0]]),
        r"^edges: expected shape \(E, 2\) with E > 0, got \(2, 3\)",
    ),
    "edges empty": (dict(edges=[]), r"^edges: expected shape \(E, 2\)"),
    "edges ragged": (dict(edges=[[0, 1], [1]]), r"^edges: cannot be read"),
    "edge index not integer": (
        dict(edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2.5]]),
        r"^edge 4: vertex indices must be integers, got \[0\.0, 2\.5\]",
    ),
    "edge index NaN": (
        dict(edges=[[0, 1], [1, 2], [2, NAN], [3, 0], [0, 2]]),
        r"^edge 2: vertex indices must be integers",
    ),
    "edge index text": (dict(edges=[["a", "b"]] * 5), r"^edges: cannot be read"),
    "edge names missing vertex": (
        dict(edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 9]]),
        r"^edge 4 \(vertices 0, 9\): names vertex 9, but there are only 4 vertices$",
    ),
    "edge names negative vertex": (
        dict(edges=[[0, 1], [1, 2], [2, 3], [-1, 0], [0, 2]]),
        r"^edge 3 \(vertices -1, 0\): names vertex -1",
    ),
    "edge joins vertex to itself": (
        dict(edges=[[0, 1], [1, 2], [2, 2], [3, 0], [0, 2]]),
        r"^edge 2 \(vertices 2, 2\): joins a vertex to itself",
    ),
    "duplicate edge": (
        dict(edges=SQ_E + [[2, 0]]),
        r"^edge 5 \(vertices 2, 0\): duplicates edge 4$",
    ),
    "zero-length edge": (
        # vertex 4 sits on vertex 0
        dict(vertices=SQ_V + [[0.0, 0.0]], edges=SQ_E + [[0, 4]]),
        r"^edge 5 \(vertices 0, 4\): has zero length",
    ),
    "edge almost zero": (
        # vertex 4 sits 1e-14 from vertex 0, on the bottom side, with a valley to vertex 2
        dict(
            vertices=SQ_V + [[1e-14, 0.0]],
            edges=[[0, 4], [4, 1], [1, 2], [2, 3], [3, 0], [4, 2]],
            faces=[[0, 4, 2, 3], [4, 1, 2]],
            assignments="BBBBBV",
        ),
        r"^edge 0 \(vertices 0, 4\): is 1e-14 long, under 1e-12 of the longest edge \(1\.41\): "
        r"its two vertices nearly coincide$",
    ),
    "vertex far out": (
        # a triangle out to 1e20 beside the unit square: its sides are not zero, it is too far
        dict(
            vertices=SQ_V + [[1e20, 0.0]],
            edges=SQ_E + [[1, 4], [4, 2]],
            faces=[[0, 1, 2], [0, 2, 3], [1, 4, 2]],
            assignments="BMBBVBB",
        ),
        r"^edge 0 \(vertices 0, 1\): is 1 long, under 1e-12 of the longest edge \(1e\+20\): "
        r"vertex 4 at \(1e\+20, 0, 0\) lies that far from the others",
    ),
    # faces
    "faces missing": (dict(faces=None), r"^faces: missing"),
    "faces empty": (dict(faces=[]), r"^faces: the pattern has no faces"),
    "faces not a sequence": (dict(faces=5), r"^faces: expected a sequence of polygons"),
    "face index not integer": (
        dict(faces=[[0, 1, 2], [0, 2, 3.5]]),
        r"^face 1: vertex indices must be integers",
    ),
    "face not a polygon": (dict(faces=[[0, 1, 2], 3]), r"^face 1: vertex indices must be integers"),
    "face with two vertices": (
        dict(faces=[[0, 1, 2], [0, 2]]),
        r"^face 1: has 2 vertices, needs at least 3",
    ),
    "face names missing vertex": (
        dict(faces=[[0, 1, 2], [0, 2, 7]]),
        r"^face 1: names vertex 7, but there are only 4 vertices",
    ),
    "face repeats a vertex": (
        dict(faces=[[0, 1, 2, 1], [0, 2, 3]]),
        r"^face 0: repeats a vertex \[0, 1, 2, 1\]",
    ),
    "face side not an edge": (
        dict(edges=SQ_E[:4]),
        r"^face 0: side \(2, 0\) is not an edge of the pattern",
    ),
    "edge in no face": (
        dict(edges=SQ_E + [[1, 3]]),
        r"^edge 5 \(vertices 1, 3\): belongs to no face",
    ),
    "edge in three faces": (
        dict(
            vertices=[[0, 0], [1, 0], [0.5, 1], [0.5, -1], [0.5, 2]],
            edges=[[0, 1], [1, 2], [2, 0], [1, 3], [3, 0], [1, 4], [4, 0]],
            faces=[[0, 1, 2], [0, 3, 1], [0, 1, 4]],
        ),
        r"^edge 0 \(vertices 0, 1\): belongs to 3 faces \[0, 1, 2\], at most 2 allowed",
    ),
    "zero-area face": (
        dict(
            vertices=[[0, 0], [1, 0], [2, 0], [1, 1]],
            edges=[[0, 1], [1, 2], [2, 0], [2, 3], [3, 0]],
            faces=[[0, 1, 2], [0, 2, 3]],
        ),
        r"^face 0: has zero area \(vertices \[0, 1, 2\]\)",
    ),
    # assignments
    "unknown assignment": (
        dict(assignments="BBBBX"),
        r"^edge 4: unknown assignment 'X' \(expected one of BMVFUCJ\)",
    ),
    "two-letter assignment": (
        dict(assignments=["B", "B", "B", "MV", "B"]),
        r"^edge 3: unknown assignment 'MV'",
    ),
    "empty assignment": (
        dict(assignments=["", "B", "B", "B", "V"]),
        r"^edge 0: unknown assignment ''",
    ),
    "assignments not a sequence": (dict(assignments=5), r"^assignments: expected one letter"),
    "too few assignments": (
        dict(assignments="BBBB"),
        r"^assignments: expected 5 letters \(one per edge\), got 4",
    ),
    "too many assignments": (
        dict(assignments="BBBBVV"),
        r"^assignments: expected 5 letters \(one per edge\), got 6",
    ),
    "border between two faces": (
        dict(assignments="BBBBB"),
        r"^edge 4 \(vertices 0, 2\): is a border \(B\) but lies between faces \[0, 1\]",
    ),
    "mountain on the border": (
        dict(assignments="MBBBV"),
        r"^edge 0 \(vertices 0, 1\): is assigned M but lies on the border \(one face\)",
    ),
    "unassigned on the border": (
        dict(assignments="BBUBV"),
        r"^edge 2 \(vertices 2, 3\): is assigned U but lies on the border",
    ),
    "cut on the border": (
        dict(assignments="BCBBV"),
        r"^edge 1 \(vertices 1, 2\): is assigned C but lies on the border",
    ),
    # fold angles
    "too few fold angles": (
        dict(fold_angles=[0, 0, 0, 0]),
        r"^fold_angles: expected shape \(5,\), got \(4,\)",
    ),
    "fold angles 2-D": (
        dict(fold_angles=[[0] * 5]),
        r"^fold_angles: expected shape \(5,\), got \(1, 5\)",
    ),
    "fold angle scalar": (dict(fold_angles=1.0), r"^fold_angles: expected shape \(5,\), got \(\)"),
    "fold angle text": (dict(fold_angles=["a"] * 5), r"^fold_angles: cannot be read"),
    "fold angle NaN": (dict(fold_angles=[0, 0, 0, 0, NAN]), r"^edge 4: fold angle is nan"),
    "fold angle inf": (dict(fold_angles=[0, 0, 0, 0, -INF]), r"^edge 4: fold angle is -inf"),
    "fold angle above pi": (
        dict(assignments="BBBBV", fold_angles=[0, 0, 0, 0, 3.2]),
        r"^edge 4: fold angle 3\.2 rad is outside \[-pi, pi\]",
    ),
    "fold angle below -pi": (
        dict(assignments="BBBBU", fold_angles=[0, 0, 0, 0, -4]),
        r"^edge 4: fold angle -4 rad is outside \[-pi, pi\]",
    ),
    "mountain with positive angle": (
        dict(assignments="BBBBM", fold_angles=[0, 0, 0, 0, 1.0]),
        r"^edge 4: assignment M but fold angle 1 rad \(mountains are negative, valleys positive\)",
    ),
    "valley with negative angle": (
        dict(assignments="BBBBV", fold_angles=[0, 0, 0, 0, -0.5]),
        r"^edge 4: assignment V but fold angle -0\.5 rad",
    ),
    "flat crease with angle": (
        dict(assignments="BBBBF", fold_angles=[0, 0, 0, 0, 0.5]),
        r"^edge 4: assignment F takes no fold angle, got 0\.5 rad",
    ),
    "join with angle": (
        dict(assignments="BBBBJ", fold_angles=[0, 0, 0, 0, -0.5]),
        r"^edge 4: assignment J takes no fold angle",
    ),
    "border with angle": (
        dict(assignments="BBBBV", fold_angles=[0, 0, 0.25, 0, 1.0]),
        r"^edge 2: assignment B takes no fold angle, got 0\.25 rad",
    ),
}


@pytest.mark.parametrize("overrides, message", INVALID.values(), ids=INVALID.keys())
def test_invalid_pattern_names_element_and_problem(overrides, message):
    with pytest.raises(PatternError, match=message):
        CreasePattern(**square(**overrides))


def test_cut_with_angle_is_rejected():
    vertices, edges, faces, idx = grid(2)
    cp = CreasePattern(vertices, edges, faces)
    k = edge_index(cp, idx(0, 1), idx(1, 1))
    letters = list(cp.assignments)
    letters[k] = "C"
    rho = np.zeros(len(edges))
    rho[k] = 0.3
    with pytest.raises(PatternError, match=rf"^edge {k}: assignment C takes no fold angle"):
        CreasePattern(vertices, edges, faces, letters, rho)


def test_cut_that_cannot_open_is_rejected():
    # a single-edge slit with both ends inside the paper: no vertex can be split, so the two
    # sides would be the same bar
    vertices, edges, faces, idx = grid(4)
    cp = CreasePattern(vertices, edges, faces)
    a, b = idx(1, 2), idx(2, 2)
    k = edge_index(cp, a, b)
    letters = list(cp.assignments)
    letters[k] = "C"
    name = rf"edge {k} \(vertices {cp.edges[k][0]}, {cp.edges[k][1]}\)"
    with pytest.raises(PatternError, match=rf"^{name}: is a cut \(C\) that cannot open"):
        CreasePattern(vertices, edges, faces, letters)


def test_first_error_wins_and_input_is_not_modified():
    v = np.array(SQ_V)
    e = np.array(SQ_E)
    CreasePattern(**square(vertices=v, edges=e))
    assert v.flags.writeable and e.flags.writeable  # the caller's arrays are left alone
    v[0, 0] = NAN
    with pytest.raises(PatternError, match=r"^vertex 0:"):
        CreasePattern(**square(vertices=v, edges=[[0, 9]] * 5))


# ---------------------------------------------------------------------------------------------
# defaults


def test_default_assignments_border_and_unassigned():
    cp = CreasePattern(**square())
    assert list(cp.assignments) == list("BBBBU")
    np.testing.assert_array_equal(cp.fold_angles, np.zeros(5))
    assert list(cp.mesh.role) == ["border"] * 4 + ["free"]

    vertices, edges, faces, _ = grid(3)
    cp = CreasePattern(vertices, edges, faces)
    xy = cp.vertices[cp.edges][:, :, :2]  # (E, 2 ends, 2)
    on_side = np.any(
        (xy[:, 0, :] == xy[:, 1, :]) & ((xy[:, 0, :] == 0) | (xy[:, 0, :] == 3)), axis=1
    )
    np.testing.assert_array_equal(cp.assignments == "B", on_side)
    np.testing.assert_array_equal(cp.assignments == "U", ~on_side)
    assert int(on_side.sum()) == 12


@pytest.mark.parametrize(
    "letter, angle", [("M", -PI), ("V", PI), ("F", 0.0), ("U", 0.0), ("J", 0.0)]
)
def test_default_fold_angles(letter, angle):
    cp = CreasePattern(**square(), assignments="BBBB" + letter)
    np.testing.assert_array_equal(cp.fold_angles, [0, 0, 0, 0, angle])
    assert cp.fold_angles.dtype == np.float64


# ---------------------------------------------------------------------------------------------
# triangulation

POLYGONS = {
    "quad": [(0, 0), (2, 0), (2.5, 1), (0.2, 1.3)],
    "convex hexagon": [(math.cos(a), math.sin(a)) for a in np.linspace(0, 2 * PI, 7)[:-1]],
    "L-shape": [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)],
    "comb": [
        (0, 0),
        (5, 0),
        (5, 2),
        (4, 2),
        (4, 1),
        (3, 1),
        (3, 2),
        (2, 2),
        (2, 1),
        (1, 1),
        (1, 2),
        (0, 2),
    ],  # fmt: skip
    "star": [
        (
            (1.0 if s % 2 == 0 else 0.35) * math.cos(s * PI / 5 + 0.1),
            (1.0 if s % 2 == 0 else 0.35) * math.sin(s * PI / 5 + 0.1),
        )
        for s in range(10)
    ],  # fmt: skip
    "collinear side": [(0, 0), (1, 0), (2, 0), (3, 0), (3, 1), (0, 1)],
    # Origami Simulator's cuts.svg has such a face: ear clipping left a 3e-6 sliver
    "nearly collinear side": [(1e-5, 1.0), (0.0, 0.72), (0.0, 0.62), (1e-5, 0.0), (0.25, 0.0)],
    "spiral notch": [
        (0, 0),
        (4, 0),
        (4, 4),
        (1, 4),
        (1, 2),
        (2, 2),
        (2, 3),
        (3, 3),
        (3, 1),
        (0, 1),
    ],  # fmt: skip
}


def _check_polygon_triangulation(points, reverse=False):
    points = [tuple(map(float, p)) for p in points]
    n = len(points)
    face = list(range(n))[::-1] if reverse else list(range(n))
    cp = from_faces(points, [face])
    assert signed_area([points[i] for i in cp.faces[0]]) > 0  # re-oriented counterclockwise
    assert sorted(cp.faces[0]) == list(range(n))
    m = check_mesh(cp)
    assert m.triangles.shape == (n - 2, 3)
    assert np.all(m.triangle_face == 0)
    assert sum(signed_area(m.vertices[t, :2]) for t in m.triangles) == pytest.approx(
        abs(signed_area(points)), rel=1e-12
    )
    assert list(m.role[:n]) == ["border"] * n
    added = m.edges[n:]
    assert len(added) == n - 3
    ccw = [points[i] for i in cp.faces[0]]
    for a, b in added:
        # the added edges are proper diagonals: their midpoints lie inside the polygon
        mid = 0.5 * (np.asarray(points[a]) + np.asarray(points[b]))
        assert inside(mid, ccw), (a, b)
    for t in m.triangles:
        assert inside(m.vertices[t, :2].mean(axis=0), ccw)
    return cp, m


@pytest.mark.parametrize("reverse", [False, True], ids=["ccw", "cw"])
@pytest.mark.parametrize("points", POLYGONS.values(), ids=POLYGONS.keys())
def test_polygon_face_triangulation(points, reverse):
    _check_polygon_triangulation(points, reverse)


def test_clockwise_faces_are_reoriented():
    cp = CreasePattern(**square(faces=[[2, 1, 0], [3, 2, 0]]))
    assert cp.faces == ((0, 1, 2), (0, 2, 3))
    check_mesh(cp)
    cp = from_faces(SQ_V, [[3, 2, 1, 0]])
    assert signed_area(cp.vertices[list(cp.faces[0]), :2]) == pytest.approx(1.0)
    m = check_mesh(cp)
    assert m.triangles.shape == (2, 3) and m.num_edges == 5
    assert m.role[4] == "facet" and m.source_edge[4] == -1 and m.target[4] == 0


def test_t_junction_between_faces():
    # two unit squares under a 2 x 1 rectangle whose bottom side passes through vertex 4
    vertices = [(0, 0), (1, 0), (2, 0), (2, 1), (1, 1), (0, 1), (2, 2), (0, 2)]
    faces = [[0, 1, 4, 5], [1, 2, 3, 4], [5, 4, 3, 6, 7]]
    cp = from_faces(vertices, faces, assignments=None)
    m = check_mesh(cp)
    assert np.bincount(m.triangle_face).tolist() == [2, 2, 3]
    for a, b in [(1, 4), (3, 4), (4, 5)]:  # the inner edges, between two faces
        k = edge_index(cp, a, b)
        assert cp.assignments[k] == "U" and m.role[k] == "free"
    assert int((cp.assignments == "B").sum()) == cp.num_edges - 3
    # the added edges are facets, after the pattern's
    assert m.num_edges == cp.num_edges + 1 + 1 + 2
    assert np.all(m.role[cp.num_edges :] == "facet")


def test_pattern_edges_are_kept_first_in_order():
    vertices, edges, faces, _ = grid(3, 2)
    rng = np.random.default_rng(0)
    order = rng.permutation(len(edges))
    edges = [edges[i][::-1] if i % 2 else edges[i] for i in order]
    cp = CreasePattern(vertices, edges, faces)
    m = check_mesh(cp)
    for k, (a, b) in enumerate(edges):
        assert sorted(m.edges[k].tolist()) == sorted([a, b])
    assert m.num_edges == len(edges) + len(faces)


def test_a_face_that_ear_clipping_leaves_a_sliver_gets_its_best_triangulation():
    """Where the best-ear-first clipping leaves a sliver (bars hardly keep it open), the face
    takes the triangulation whose worst triangle is best; others keep the ear clipping's."""
    from origami_jax.pattern import _clip_ears
    from origami_jax.pattern import triangle_quality as _quality

    points = np.array(POLYGONS["nearly collinear side"])
    clipped = np.array(_clip_ears(points, 0))
    assert np.min(_quality(points[clipped])) < 1e-4
    cp, m = _check_polygon_triangulation(points)
    assert np.min(_quality(m.vertices[m.triangles][:, :, :2])) > 0.03
    star = POLYGONS["star"]
    cp, m = _check_polygon_triangulation(star)
    np.testing.assert_array_equal(m.triangles, _clip_ears(np.array(star), 0))
    # a quad too: ear clipping keeps its best ear, a sliver of 0.007; the other diagonal 0.30
    quad = np.array([[0.033, 0.990], [0.245, 0.041], [0.626, 0.552], [0.389, 0.733]])
    clipped = np.array(_clip_ears(quad, 0))
    assert np.min(_quality(quad[clipped])) < 0.01
    cp, m = _check_polygon_triangulation(quad)
    assert np.min(_quality(m.vertices[m.triangles][:, :, :2])) > 0.29


def test_a_diagonal_on_the_line_of_a_distant_side_is_inside():
    """Collinear with a side that it does not touch, a diagonal is still a diagonal (the four
    orientation signs all vanish on one line: only an overlap is a hit)."""
    from origami_jax.pattern import _diagonals

    points = [(0, 0), (2.5, 0), (3, 1), (3.5, 0), (6, 0), (6, 1), (5, 1), (5, 2), (6, 2), (6, 4),
              (0, 4), (0, 2), (1, 2), (1, 1), (0, 1)]  # fmt: skip
    ok = _diagonals(np.array(points, float))
    assert ok[2, 13] and ok[13, 2]  # (3, 1)-(1, 1), on the line of side (6, 1)-(5, 1)
    assert ok[2, 6]  # (3, 1)-(5, 1): up to that side's end
    assert not ok[2, 5] and not ok[13, 6]  # through the vertex (5, 1), through (3, 1)


def _all_triangulations(n: int):
    """Every triangulation of a convex n-gon (vertices 0..n-1), as lists of triangles."""

    def chain(i, j):
        if j - i < 2:
            yield []
            return
        for k in range(i + 1, j):
            for left in chain(i, k):
                for right in chain(k, j):
                    yield [*left, (i, k, j), *right]

    yield from chain(0, n - 1)


@settings(max_examples=30, deadline=None)
@given(
    gaps=st.lists(st.floats(0.05, 1.0), min_size=5, max_size=8),
    squash=st.floats(0.01, 1.0),
)
def test_max_min_triangulation_is_the_best_of_all(gaps, squash):
    """On random convex polygons (squashed ellipses: thin triangles) the search finds the
    triangulation whose worst triangle is best, against all of them enumerated."""
    from origami_jax.pattern import _max_min_triangulation
    from origami_jax.pattern import triangle_quality as _quality

    angles = np.cumsum(np.asarray(gaps) * (2 * PI / sum(gaps)))
    points = np.stack([np.cos(angles), squash * np.sin(angles)], axis=1)
    found = np.array(_max_min_triangulation(points))
    assert found.shape == (len(points) - 2, 3)
    best = max(np.min(_quality(points[np.array(t)])) for t in _all_triangulations(len(points)))
    assert np.min(_quality(points[found])) == pytest.approx(best, rel=1e-12)
    assert sum(signed_area(points[t]) for t in found) == pytest.approx(signed_area(points))


@settings(max_examples=80, deadline=None)
@given(
    gaps=st.lists(st.floats(0.2, 1.0), min_size=3, max_size=14),
    radii=st.lists(st.floats(0.25, 1.0), min_size=14, max_size=14),
    rotation=st.floats(0, 2 * PI),
    reverse=st.booleans(),
)
def test_star_shaped_polygons_triangulate(gaps, radii, rotation, reverse):
    """Random star-shaped polygons (convex or not) give n - 2 CCW triangles covering the face."""
    gaps = np.asarray(gaps) * (2 * PI / sum(gaps))
    assume(gaps.max() < 0.9 * PI)  # the origin sees every side: a simple polygon
    angles = rotation + np.cumsum(gaps)
    points = [(r * math.cos(a), r * math.sin(a)) for r, a in zip(radii, angles, strict=False)]
    _check_polygon_triangulation(points, reverse)
    # the max-min search on its own (the face above takes it only after a sliver): it uses
    # inner diagonals only, also where the polygon is not convex
    from origami_jax.pattern import _max_min_triangulation

    points = np.array(points)
    found = np.array(_max_min_triangulation(points))
    assert found.shape == (len(points) - 2, 3)
    assert all(signed_area(points[t]) > 0 for t in found)
    assert sum(signed_area(points[t]) for t in found) == pytest.approx(signed_area(points))
    sides = {tuple(sorted(t[[i, (i + 1) % 3]])) for t in found for i in range(3)}
    for a, b in sides:
        if (b - a) % len(points) not in (1, len(points) - 1):
            assert inside(0.5 * (points[a] + points[b]), points), (a, b)


# ---------------------------------------------------------------------------------------------
# hinges and roles


def test_hinge_roles_from_assignments():
    # a 3 x 1 strip of squares, each cut by a diagonal; inner edges get every assignment
    vertices, _, quads, idx = grid(3, 1)
    faces = []
    for q in quads:
        faces += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    cp0 = from_faces(vertices, faces)
    inner = np.flatnonzero(cp0.assignments == "U")
    assert len(inner) == 5  # 3 diagonals + 2 vertical edges
    letters = list(cp0.assignments)
    rho = np.zeros(cp0.num_edges)
    spec = [("M", -1.0, "driven"), ("V", 0.0, "driven"), ("U", 0.7, "driven"),
            ("F", 0.0, "facet"), ("J", 0.0, "facet")]  # fmt: skip
    for k, (a, r, _) in zip(inner, spec, strict=True):
        letters[k], rho[k] = a, r
    cp = CreasePattern(cp0.vertices, cp0.edges, faces, letters, rho)
    m = check_mesh(cp)
    for k, (_, r, role) in zip(inner, spec, strict=True):
        assert m.role[k] == role and m.target[k] == r
        assert m.hinges[k, 2] >= 0 and m.hinges[k, 3] >= 0
    assert np.all(m.role[cp.assignments == "B"] == "border")
    assert np.all(m.hinges[cp.assignments == "B"][:, 3] == -1)
    assert np.all(m.hinges[cp.assignments == "B"][:, 2] >= 0)
    # U with zero angle is a free hinge
    letters[inner[2]], rho[inner[2]] = "U", 0.0
    m = check_mesh(CreasePattern(cp0.vertices, cp0.edges, faces, letters, rho))
    assert m.role[inner[2]] == "free" and m.target[inner[2]] == 0


def test_hinge_apexes_on_square_diagonal():
    cp = CreasePattern(**square(), assignments="BBBBV")
    i, j, k, l = cp.mesh.hinges[4]
    assert {i, j} == {0, 2}
    # vertex 1 = (1, 0) is right of 0 -> 2, vertex 3 = (0, 1) left of it
    assert (k, l) == ((3, 1) if (i, j) == (0, 2) else (1, 3))
    for e in range(4):
        assert cp.mesh.hinges[e, 3] == -1 and cp.mesh.hinges[e, 2] >= 0


# ---------------------------------------------------------------------------------------------
# cuts


def _slit(n, path, m=None):
    """An n x m grid sheet with C edges along the vertex path [(x, y), ...]."""
    vertices, edges, faces, idx = grid(n, m)
    cp = CreasePattern(vertices, edges, faces)
    letters = list(cp.assignments)
    cut = []
    for (x0, y0), (x1, y1) in zip(path[:-1], path[1:], strict=True):
        k = edge_index(cp, idx(x0, y0), idx(x1, y1))
        letters[k] = "C"
        cut.append(k)
    return CreasePattern(vertices, edges, faces, letters), cut, idx


@pytest.mark.parametrize(
    "n, m, path, copied",
    [
        (2, 2, [(0, 1), (1, 1)], [(0, 1)]),  # border to centre: the border end splits
        (3, 3, [(0, 1), (1, 1), (2, 1)], [(0, 1), (1, 1)]),  # longer: the middle one too
        (4, 4, [(1, 2), (2, 2), (3, 2)], [(2, 2)]),  # inside the sheet: the middle one only
        (2, 1, [(1, 0), (1, 1)], [(1, 0), (1, 1)]),  # across the sheet: two pieces
        (3, 3, [(0, 1), (1, 1), (1, 2), (1, 3)], [(0, 1), (1, 1), (1, 2), (1, 3)]),  # corner off
    ],
    ids=["border slit", "long slit", "inner slit", "cut through", "corner off"],
)
def test_slit_sheet(n, m, path, copied):
    cp, cut, idx = _slit(n, path, m)
    mesh = check_mesh(cp)
    V = cp.num_vertices
    assert mesh.num_vertices == V + len(copied)
    # the copies are of the expected vertices, at the same coordinates
    originals = []
    for c in range(V, mesh.num_vertices):
        match = np.flatnonzero(np.all(cp.vertices == mesh.vertices[c], axis=1))
        assert len(match) == 1
        originals.append(int(match[0]))
    assert sorted(originals) == sorted(idx(x, y) for x, y in copied)
    # each cut edge becomes two border edges: its first side at its own index, then its second
    second = mesh.source_edge[cp.num_edges : cp.num_edges + len(cut)]
    assert sorted(second) == sorted(cut)
    for k in cut:
        sides = np.flatnonzero(mesh.source_edge == k)
        assert len(sides) == 2 and sides[0] == k
        assert np.all(mesh.role[sides] == "border") and np.all(mesh.target[sides] == 0)
        h = mesh.hinges[sides]
        assert np.all(h[:, 2] >= 0) and np.all(h[:, 3] == -1)
        # the two sides are different bars along the same segment, with apexes either side
        assert sorted(mesh.edges[sides[0]]) != sorted(mesh.edges[sides[1]])
        a, b = mesh.vertices[h[0, :2]], mesh.vertices[h[1, :2]]
        assert np.allclose(a, b[::-1])
        assert cross2(a[0], a[1], mesh.vertices[h[1, 2]]) < 0
    # no triangle uses both a vertex and its copy
    for t in mesh.triangles:
        base = [int(v) if v < V else originals[v - V] for v in t]
        assert len(set(base)) == 3
    # the quads' diagonals stay facets
    assert np.all(mesh.role[cp.num_edges + len(cut) :] == "facet")


def test_cut_through_separates_the_sheet():
    cp, cut, idx = _slit(2, [(1, 0), (1, 1)], 1)
    mesh = cp.mesh
    # the left square's triangles and the right square's share no vertex after the cut
    left = set(mesh.triangles[mesh.triangle_face == 0].ravel().tolist())
    right = set(mesh.triangles[mesh.triangle_face == 1].ravel().tolist())
    assert not left & right


# ---------------------------------------------------------------------------------------------
# with_fold_angles, diameter, repr, immutability


def test_with_fold_angles():
    cp = CreasePattern(**square(faces=[[2, 1, 0], [0, 2, 3]]), assignments="BBBBV", name="sq")
    new = cp.with_fold_angles([0, 0, 0, 0, 0.5])
    assert new is not cp and new.name == "sq"
    assert new.fold_angles[4] == 0.5 and cp.fold_angles[4] == PI
    assert cp.mesh.target[4] == PI and new.mesh.target[4] == 0.5
    assert new.faces == cp.faces
    np.testing.assert_array_equal(new.assignments, cp.assignments)
    with pytest.raises(PatternError, match=r"^edge 4: assignment V but fold angle -0\.5 rad"):
        cp.with_fold_angles([0, 0, 0, 0, -0.5])
    with pytest.raises(PatternError, match=r"^fold_angles: expected shape \(5,\)"):
        cp.with_fold_angles([0.5])


def test_diameter():
    assert CreasePattern(**square()).diameter == pytest.approx(math.sqrt(2))
    cp = CreasePattern(**square(vertices=[[0, 0], [3, 0], [3, 4], [0, 4]]))
    assert cp.diameter == pytest.approx(5.0)
    # a large sheet: the bounding-box diagonal (exact for a rectangle)
    vertices, edges, faces, _ = grid(50, 40)
    assert CreasePattern(vertices, edges, faces).diameter == pytest.approx(math.hypot(50, 40))


def test_repr():
    cp = CreasePattern(**square(), assignments="BBBBM", name="fold")
    assert repr(cp) == "CreasePattern('fold': 4 vertices, 5 edges [B=4 M=1], 2 faces)"
    assert repr(CreasePattern(**square())) == (
        "CreasePattern('pattern': 4 vertices, 5 edges [B=4 U=1], 2 faces)"
    )
    assert set(ASSIGNMENTS) == set("BMVFUCJ")


def test_arrays_are_read_only():
    cp, _, _ = _slit(2, [(0, 1), (1, 1)])
    for arr in (cp.vertices, cp.edges, cp.assignments, cp.fold_angles):
        assert not arr.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = arr[1]
    m = cp.mesh
    assert cp.mesh is m  # cached
    for name in ("vertices", "edges", "source_edge", "triangles", "triangle_face", "role",
                 "target", "hinges"):  # fmt: skip
        arr = getattr(m, name)
        assert not arr.flags.writeable, name
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = arr[-1]
    assert isinstance(cp.faces, tuple) and all(isinstance(f, tuple) for f in cp.faces)
    with pytest.raises(AttributeError):
        cp.name = "other"  # type: ignore[misc]
    # the caller's arrays are copied: changing them later does not change the pattern
    v = np.array(SQ_V)
    cp = CreasePattern(**square(vertices=v))
    v[0] = [5, 5]
    assert cp.vertices[0, 0] == 0
    assert re.search("4 vertices", repr(cp))
