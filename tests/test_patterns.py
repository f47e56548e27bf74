"""Tests of the crease-pattern generators (origami_jax.patterns)."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from origami_jax.kinematics import check_rigid, rigid_fold
from origami_jax.pattern import CreasePattern, PatternError
from origami_jax.patterns import (
    SEED_WATERBOMB_ENERGY,
    SEED_WATERBOMB_STIFFNESS,
    degree4_vertex,
    kresling,
    kresling_states,
    miura_ori,
    seed_waterbomb,
    single_crease,
    square_twist,
    waterbomb,
    yoshimura,
)

jax.config.update("jax_enable_x64", True)

TOL = 1e-12


def count(cp: CreasePattern, letter: str) -> int:
    return int((cp.assignments == letter).sum())


def edge_lengths(cp: CreasePattern) -> np.ndarray:
    return np.linalg.norm(cp.vertices[cp.edges[:, 1]] - cp.vertices[cp.edges[:, 0]], axis=1)


def sheet_area(cp: CreasePattern) -> float:
    total = 0.0
    for f in cp.faces:
        p = cp.vertices[list(f), :2]
        total += 0.5 * float(
            np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(np.roll(p[:, 0], -1), p[:, 1])
        )
    return total


def sectors(cp: CreasePattern, v: int) -> tuple[np.ndarray, np.ndarray]:
    """Edges at vertex ``v`` sorted counterclockwise, and the sector angles between them."""
    at = np.flatnonzero((cp.edges == v).any(axis=1))
    other = np.where(cp.edges[at, 0] == v, cp.edges[at, 1], cp.edges[at, 0])
    d = cp.vertices[other, :2] - cp.vertices[v, :2]
    ang = np.arctan2(d[:, 1], d[:, 0])
    order = np.argsort(ang)
    ang = ang[order]
    return at[order], np.diff(np.concatenate([ang, [ang[0] + 2 * np.pi]]))


def check_assignments_match_signs(cp: CreasePattern) -> None:
    a, rho = cp.assignments, cp.fold_angles
    assert (rho[a == "V"] >= 0).all() and (rho[a == "M"] <= 0).all()
    assert (rho[np.isin(a, ["B", "F"])] == 0).all()


# -- single crease ---------------------------------------------------------------------------


def test_single_crease_layout():
    cp = single_crease(fold_angle=1.0, width=3.0, height=2.0)
    assert (cp.num_vertices, cp.num_edges, cp.num_faces) == (6, 7, 2)
    assert count(cp, "V") == 1 and count(cp, "B") == 6
    k = int(np.flatnonzero(cp.assignments == "V")[0])
    assert cp.fold_angles[k] == 1.0
    assert edge_lengths(cp)[k] == pytest.approx(2.0)
    assert sheet_area(cp) == pytest.approx(6.0)
    m = single_crease(fold_angle=-0.5)
    assert count(m, "M") == 1 and m.fold_angles.min() == -0.5
    assert "single_crease" in m.name


# -- degree-4 vertex -------------------------------------------------------------------------


@pytest.mark.parametrize("branch", [1, 2])
def test_degree4_layout_and_assignments(branch):
    alpha, beta = 1.0, 0.6
    cp = degree4_vertex(alpha=alpha, beta=beta, fold_angle=1.2, branch=branch, radius=2.0)
    assert cp.num_faces == 4
    # the four creases are edges 0..3, from the origin, with the stated sector angles
    assert (cp.edges[:4] == 0).any(axis=1).all()
    assert set(cp.assignments[:4]) <= {"M", "V"} and count(cp, "M") + count(cp, "V") == 4
    edges, sec = sectors(cp, 0)
    assert list(edges) != [] and len(edges) == 4
    start = list(edges).index(0)
    sec = np.roll(sec, -start)
    np.testing.assert_allclose(sec, [alpha, beta, np.pi - alpha, np.pi - beta], atol=1e-12)
    # faces convex: the sheet is the square [-r, r]^2
    assert sheet_area(cp) == pytest.approx(16.0)
    assert np.abs(cp.vertices[:, :2]).max() == pytest.approx(2.0)
    rho = cp.fold_angles[:4]
    assert rho[0] == 1.2
    if branch == 1:
        assert rho[2] == rho[0] and rho[3] == -rho[1]
    else:
        assert rho[2] == -rho[0] and rho[3] == rho[1]
    # Maekawa: M - V = +-2
    assert abs(count(cp, "M") - count(cp, "V")) == 2
    check_assignments_match_signs(cp)


def test_degree4_special_cases():
    # a ray through a square corner: the corner is not duplicated
    cp = degree4_vertex(alpha=np.pi / 4, beta=np.pi / 3)
    assert cp.num_vertices == 1 + 4 + 3
    # alpha + beta = pi on branch I: creases 2 and 4 stay flat (rho2 = 0)
    cp = degree4_vertex(alpha=1.0, beta=np.pi - 1.0, fold_angle=1.0, branch=1)
    assert abs(cp.fold_angles[1]) < 1e-15 and abs(cp.fold_angles[3]) < 1e-15


# -- Miura-ori -------------------------------------------------------------------------------


def test_miura_layout_and_assignments():
    nx, ny, gamma, rho = 4, 3, np.radians(60), 1.0
    cp = miura_ori(nx=nx, ny=ny, a=1.5, b=0.8, sector_angle=gamma, fold_angle=rho)
    assert cp.num_vertices == (nx + 1) * (ny + 1) and cp.num_faces == nx * ny
    n_zig = nx * (ny - 1)
    n_straight = (nx - 1) * ny
    assert count(cp, "M") + count(cp, "V") == n_zig + n_straight
    lengths = edge_lengths(cp)
    rho_s = 2 * np.arctan(np.cos(gamma) * np.tan(rho / 2))
    zig = (cp.assignments != "B") & np.isclose(lengths, 0.8)
    straight = (cp.assignments != "B") & np.isclose(lengths, 1.5)
    assert zig.sum() == n_zig and straight.sum() == n_straight
    np.testing.assert_allclose(np.abs(cp.fold_angles[zig]), rho, atol=1e-15)
    np.testing.assert_allclose(np.abs(cp.fold_angles[straight]), rho_s, rtol=1e-14)
    # each zig-zag line one assignment, alternating between lines (line 1 valley)
    y = cp.vertices[cp.edges, 1].mean(axis=1)
    for j in range(1, ny):
        on_line = zig & (np.abs(y - j * 1.5 - 0.4 * np.cos(gamma)) < 0.5)
        assert on_line.sum() == nx
        assert set(cp.assignments[on_line]) == {"V" if j % 2 else "M"}
    # straight lines alternate at every vertex: the two straight creases at a vertex differ
    for v in range(cp.num_vertices):
        at = np.flatnonzero(straight & (cp.edges == v).any(axis=1))
        if len(at) == 2:
            assert cp.fold_angles[at[0]] == -cp.fold_angles[at[1]]
    # Maekawa at the interior vertices
    interior = 0
    for v in range(cp.num_vertices):
        at = np.flatnonzero((cp.edges == v).any(axis=1))
        if (cp.assignments[at] == "B").any():
            continue
        interior += 1
        letters = cp.assignments[at]
        assert abs((letters == "M").sum() - (letters == "V").sum()) == 2
    assert interior == (nx - 1) * (ny - 1)
    check_assignments_match_signs(cp)
    flipped = miura_ori(nx=nx, ny=ny, a=1.5, b=0.8, sector_angle=gamma, fold_angle=-rho)
    np.testing.assert_array_equal(flipped.fold_angles, -cp.fold_angles)


def _unit_cell(cp: CreasePattern, nx: int, x: np.ndarray, i: int = 1, j: int = 1):
    """H, S, L, V of the folded Miura unit cell at vertex (i, j) (Schenk & Guest 2013)."""

    def p(ii, jj):
        return x[jj * (nx + 1) + ii]

    px = p(i + 2, j) - p(i, j)  # period along the zig-zag lines: 2 S
    py = p(i, j + 2) - p(i, j)  # period along the straight lines: 2 L
    e1, e2 = px / np.linalg.norm(px), py / np.linalg.norm(py)
    assert abs(e1 @ e2) < 1e-12  # the periods are orthogonal
    e3 = np.cross(e1, e2)
    zig = p(i + 1, j) - p(i, j)
    straight = p(i, j + 1) - p(i, j)
    assert abs(zig @ e3) < 1e-12  # the zig-zag lines lie in planes normal to e3
    assert abs(straight @ e1) < 1e-12  # the straight lines lie in planes normal to e1
    h = abs(straight @ e3)
    s = abs(zig @ e1)
    length = np.linalg.norm(py) / 2
    v = abs(zig @ e2)
    assert np.linalg.norm(px) / 2 == pytest.approx(s, abs=1e-12)
    return h, s, length, v, e3


@pytest.mark.parametrize(
    "a,b,gamma,rho",
    [
        (1.0, 1.0, np.radians(60), np.pi / 2),
        (1.3, 0.7, np.radians(40), 2.0),
        (0.6, 1.8, np.radians(75), 0.7),
        (1.0, 2.0, 1.0, -1.2),
        (2.0, 0.5, np.radians(55), 3.0),
    ],
)
def test_miura_unit_cell_matches_schenk_guest(a, b, gamma, rho):
    nx = 4
    cp = miura_ori(nx=nx, ny=4, a=a, b=b, sector_angle=gamma, fold_angle=rho)
    x = rigid_fold(cp)
    theta = abs(rho) / 2
    ct, tg = np.cos(theta), np.tan(gamma)
    h, s, length, v, e3 = _unit_cell(cp, nx, x)
    assert h == pytest.approx(a * np.sin(theta) * np.sin(gamma), abs=1e-12)
    assert s == pytest.approx(b * ct * tg / np.sqrt(1 + ct**2 * tg**2), abs=1e-12)
    assert length == pytest.approx(
        a * np.sqrt(1 - np.sin(theta) ** 2 * np.sin(gamma) ** 2), abs=1e-12
    )
    assert v == pytest.approx(b / np.sqrt(1 + ct**2 * tg**2), abs=1e-12)
    # theta is the facets' angle to the plane of the folded sheet
    tri = cp.mesh.triangles
    n = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])
    n /= np.linalg.norm(n, axis=1)[:, None]
    np.testing.assert_allclose(np.abs(n @ e3), np.cos(theta), atol=1e-12)


# -- the seed's waterbomb --------------------------------------------------------------------


def test_seed_waterbomb_counts():
    cp = seed_waterbomb()
    assert cp.num_vertices == 32
    assert cp.num_faces == 42  # 21 unit squares, each split by its diagonal
    assert sheet_area(cp) == pytest.approx(21.0)
    assert count(cp, "V") == 16 and count(cp, "M") == 32 and count(cp, "F") == 5
    assert count(cp, "B") == 20 and cp.num_edges == 73
    lengths = edge_lengths(cp)
    mv = cp.assignments
    np.testing.assert_allclose(lengths[mv == "M"], 1.0)
    np.testing.assert_allclose(lengths[mv == "B"], 1.0)
    np.testing.assert_allclose(lengths[mv == "V"], np.sqrt(2))
    np.testing.assert_allclose(lengths[mv == "F"], np.sqrt(2))
    np.testing.assert_allclose(cp.fold_angles[mv == "M"], -np.pi / 2)
    np.testing.assert_allclose(cp.fold_angles[mv == "V"], np.pi)
    assert (cp.fold_angles[mv == "F"] == 0).all()
    # the bounding box is 5 x 5 without its corners
    v = cp.vertices[:, :2]
    assert v.min() == 0 and v.max() == 5
    for corner in [(0, 0), (5, 0), (0, 5), (5, 5)]:
        assert not (np.abs(v - corner).sum(axis=1) < 1e-12).any()
    # four waterbomb centres, each meeting four valley diagonals; the mesh adds nothing
    for centre in [(1, 2), (3, 1), (4, 3), (2, 4)]:
        k = int(np.flatnonzero(np.abs(v - centre).sum(axis=1) < 1e-12)[0])
        at = (cp.edges == k).any(axis=1)
        assert (at & (mv == "V")).sum() == 4 and (at & (mv == "M")).sum() == 4
    valley_vertices = np.unique(cp.edges[mv == "V"])
    assert len(valley_vertices) == 4 + 16  # centres + the far ends of their diagonals
    assert cp.mesh.num_edges == cp.num_edges
    assert (cp.mesh.role == "facet").sum() == 5 and (cp.mesh.role == "driven").sum() == 48


def test_seed_waterbomb_stiffness_reproduces_the_seed_energy():
    cp = seed_waterbomb()
    mesh = cp.mesh
    k = SEED_WATERBOMB_STIFFNESS
    assert k["axial"] == pytest.approx(400 * k["crease"], rel=1e-15)
    assert k["facet"] == pytest.approx(20 * k["crease"], rel=1e-15)
    l0 = np.linalg.norm(mesh.vertices[mesh.edges[:, 1]] - mesh.vertices[mesh.edges[:, 0]], axis=1)
    driven = mesh.role == "driven"
    energy = float(np.sum(k["crease"] * l0[driven] / 2 * mesh.target[driven] ** 2))
    assert energy == pytest.approx(0.009890, rel=1e-14)
    assert SEED_WATERBOMB_ENERGY == 0.009890
    # closed form: lt * pi^2 (4 + 8 sqrt 2)
    assert k["crease"] == pytest.approx(0.009890 / (np.pi**2 * (4 + 8 * np.sqrt(2))), rel=1e-14)


def test_seed_waterbomb_is_not_rigid_foldable():
    cp = seed_waterbomb()
    strain, err = check_rigid(cp, rigid_fold(cp))
    assert strain > 1e-2 or err > 1e-2


# -- waterbomb tessellation ------------------------------------------------------------------


@pytest.mark.parametrize("n,m", [(1, 1), (2, 2), (3, 2), (2, 3)])
def test_waterbomb_counts_and_targets(n, m):
    rho = 1.3
    cp = waterbomb(n=n, m=m, fold_angle=rho, size=0.5)
    assert cp.num_vertices == (2 * n + 1) * (2 * m + 1)
    assert cp.num_faces == 8 * n * m
    assert sheet_area(cp) == pytest.approx(4 * n * m * 0.25)
    assert count(cp, "V") == 4 * n * m
    assert count(cp, "M") == (2 * n - 1) * 2 * m + (2 * m - 1) * 2 * n
    assert count(cp, "B") == 4 * (n + m)
    lengths = edge_lengths(cp)
    np.testing.assert_allclose(lengths[cp.assignments == "V"], 0.5 * np.sqrt(2))
    np.testing.assert_allclose(lengths[cp.assignments == "M"], 0.5)
    np.testing.assert_allclose(cp.fold_angles[cp.assignments == "V"], rho)
    mid = cp.fold_angles[cp.assignments == "M"]
    np.testing.assert_allclose(np.tan(-mid / 2), np.tan(rho / 2) / np.sqrt(2), rtol=1e-14)
    # every base centre (row r at y = 2r + 1, offset rows) meets four valleys
    for r in range(m):
        for cx in range(1 - r % 2, 2 * n + 1, 2):
            k = (2 * r + 1) * (2 * n + 1) + cx
            at = (cp.edges == k).any(axis=1)
            expected = 4 if 0 < cx < 2 * n else 2
            assert (at & (cp.assignments == "V")).sum() == expected
    check_assignments_match_signs(cp)


def test_waterbomb_is_not_rigid_foldable():
    cp = waterbomb(n=2, m=2)
    strain, err = check_rigid(cp, rigid_fold(cp))
    assert strain > 1e-2 or err > 1e-2


# -- Yoshimura -------------------------------------------------------------------------------


def test_yoshimura_layout_and_targets():
    n, m, rho, w, h = 4, 3, 1.1, 1.0, 0.8
    cp = yoshimura(n=n, m=m, fold_angle=rho, width=w, height=h)
    odd_lines = (m + 1) // 2
    even_lines = m + 1 - odd_lines
    assert cp.num_vertices == even_lines * (n + 1) + odd_lines * (n + 2)
    assert cp.num_faces == m * (2 * n + 1)
    assert sheet_area(cp) == pytest.approx(n * w * m * h)
    lengths = edge_lengths(cp)
    diag = np.hypot(w / 2, h)
    v, mm = cp.assignments == "V", cp.assignments == "M"
    assert v.sum() == m * 2 * n
    assert mm.sum() == sum(n if k % 2 == 0 else n + 1 for k in range(1, m))
    np.testing.assert_allclose(lengths[v], diag)
    dy = np.abs(np.diff(cp.vertices[cp.edges, 1], axis=1)).ravel()
    assert (dy[mm] == 0).all()  # mountains are horizontal
    np.testing.assert_allclose(cp.fold_angles[v], rho)
    delta = np.arctan2(2 * h, w)
    np.testing.assert_allclose(
        np.tan(-cp.fold_angles[mm] / 2), np.cos(delta) * np.tan(rho / 2), rtol=1e-14
    )
    # for delta = 45 degrees the waterbomb base's relation
    wb = yoshimura(n=2, m=2, fold_angle=rho, width=2.0, height=1.0)
    mid = wb.fold_angles[wb.assignments == "M"]
    np.testing.assert_allclose(np.tan(-mid / 2), np.tan(rho / 2) / np.sqrt(2), rtol=1e-14)
    check_assignments_match_signs(cp)


# -- Kresling --------------------------------------------------------------------------------


def _rings(x: np.ndarray, n: int, stories: int):
    """Centroids and radii of the folded rings, and the seam mismatch."""
    centres, radii, seam = [], [], 0.0
    for s in range(stories + 1):
        ring = x[s * (n + 1) : s * (n + 1) + n]
        c = ring.mean(axis=0)
        centres.append(c)
        radii.append(np.linalg.norm(ring - c, axis=1))
        seam = max(seam, float(np.linalg.norm(x[s * (n + 1) + n] - x[s * (n + 1)])))
    return np.array(centres), np.array(radii), seam


def _turn(x, n, s, axis):
    """Signed turn of ring s + 1 relative to ring s about ``axis`` (radians)."""
    a = x[s * (n + 1)] - x[s * (n + 1) : s * (n + 1) + n].mean(axis=0)
    b = x[(s + 1) * (n + 1)] - x[(s + 1) * (n + 1) : (s + 1) * (n + 1) + n].mean(axis=0)
    return np.arctan2(np.cross(a, b) @ axis, a @ b)


@pytest.mark.parametrize(
    "n,stories,radius,height,twist,alternate",
    [
        (6, 1, 1.0, 1.5, np.pi / 2, False),
        (5, 3, 0.7, 0.9, 1.2, False),
        (8, 2, 1.0, 0.8, 1.2, True),
        (4, 3, 1.3, 1.0, -0.5, True),
    ],
)
def test_kresling_folds_into_the_tube(n, stories, radius, height, twist, alternate):
    cp = kresling(
        n=n, stories=stories, radius=radius, height=height, twist=twist, alternate=alternate
    )
    assert cp.num_vertices == (stories + 1) * (n + 1)
    assert cp.num_faces == 2 * n * stories
    # a strip cut along one crease per story: 2 outer polygons + 2 seam edges per story
    assert count(cp, "B") == 2 * n + 2 * stories
    assert count(cp, "B") + count(cp, "M") + count(cp, "V") + count(cp, "F") == cp.num_edges
    x = rigid_fold(cp)
    strain, err = check_rigid(cp, x)
    assert strain < TOL and err < TOL
    centres, radii, seam = _rings(x, n, stories)
    assert seam < 1e-12  # the cut closes
    np.testing.assert_allclose(radii, radius, rtol=1e-12)
    axis = centres[-1] - centres[0]
    axis /= np.linalg.norm(axis)
    for s in range(stories):
        step = centres[s + 1] - centres[s]
        np.testing.assert_allclose(step, height * axis, atol=1e-12)
        # each ring is a planar polygon normal to the axis
        ring = x[s * (n + 1) : s * (n + 1) + n] - centres[s]
        np.testing.assert_allclose(ring @ axis, 0, atol=1e-12)
        expected = -twist if (alternate and s % 2) else twist
        assert _turn(x, n, s, axis) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize(
    "n,radius,height,twist", [(6, 1.0, 1.5, np.pi / 2), (8, 1.0, 2.0, 1.5), (5, 0.8, 1.4, 1.6)]
)
def test_kresling_two_stress_free_states(n, radius, height, twist):
    (h0, phi0), (h1, phi1) = kresling_states(n, radius, height, twist)
    assert (h0, phi0) == (height, twist)
    assert phi0 + phi1 == pytest.approx(np.pi + 2 * np.pi / n, abs=1e-14)
    assert h1**2 == pytest.approx(h0**2 + 2 * radius**2 * (np.cos(phi1) - np.cos(phi0)), abs=1e-14)
    assert np.isfinite(h1) and h1 > 0 and abs(h1 - h0) > 1e-3
    a = kresling(n=n, radius=radius, height=h0, twist=phi0)
    b = kresling(n=n, radius=radius, height=h1, twist=phi1)
    # the same flat pattern (same crease lengths) ...
    np.testing.assert_array_equal(a.edges, b.edges)
    np.testing.assert_allclose(edge_lengths(a), edge_lengths(b), rtol=1e-12)
    # ... folds without strain into the other tube with the other state's targets
    x = rigid_fold(a, b.mesh.target)
    strain, err = check_rigid(a, x, b.mesh.target)
    assert strain < TOL and err < TOL
    centres, radii, seam = _rings(x, n, 1)
    assert seam < 1e-12
    np.testing.assert_allclose(radii, radius, rtol=1e-12)
    assert np.linalg.norm(centres[1] - centres[0]) == pytest.approx(h1, abs=1e-12)


def test_kresling_states_without_a_second_state():
    (_, _), (h1, phi1) = kresling_states(6, 1.0, 0.5, np.pi / 2)
    assert math.isnan(h1) and phi1 == pytest.approx(np.pi + np.pi / 3 - np.pi / 2)


# -- square twist ----------------------------------------------------------------------------


@pytest.mark.parametrize("a", [np.pi / 8, 0.3, np.pi / 4, 1.2, -0.4])
def test_square_twist_layout(a):
    rho = 1.1
    cp = square_twist(twist_angle=a, fold_angle=rho, size=1.0, sheet=3.0)
    assert (cp.num_vertices, cp.num_edges, cp.num_faces) == (16, 24, 9)
    assert count(cp, "M") == 4 and count(cp, "V") == 8 and count(cp, "B") == 12
    assert sheet_area(cp) == pytest.approx(9.0)
    np.testing.assert_allclose(np.abs(cp.fold_angles[cp.assignments != "B"]), rho)
    # the central square: side 1, turned by a, its sides valleys
    sq = cp.vertices[:4, :2]
    np.testing.assert_allclose(np.linalg.norm(sq - np.roll(sq, -1, axis=0), axis=1), 1.0)
    np.testing.assert_allclose(np.linalg.norm(sq, axis=1), 1 / np.sqrt(2))
    polar = np.arctan2(sq[:, 1], sq[:, 0]) - a - np.pi / 4  # corners at a + pi/4 + i pi/2
    off = (polar + np.pi / 4) % (np.pi / 2) - np.pi / 4
    np.testing.assert_allclose(off, 0, atol=1e-12)
    for i in range(4):
        edges, sec = sectors(cp, i)
        assert len(edges) == 4
        np.testing.assert_allclose(
            np.sort(sec),
            np.sort([np.pi / 2, np.pi / 2, np.pi / 2 - abs(a), np.pi / 2 + abs(a)]),
            atol=1e-12,
        )
        assert abs(sec[0] + sec[2] - np.pi) < 1e-12  # Kawasaki
        letters = cp.assignments[edges]
        assert (letters == "M").sum() == 1 and (letters == "V").sum() == 3
        k = int(np.argmin(sec))  # the smallest sector lies between edges k and k + 1
        pair = cp.fold_angles[edges[[k, (k + 1) % 4]]]
        assert pair[0] == -pair[1]
        # pleats are axis-parallel and reach the border
        for e in edges:
            o = cp.edges[e][cp.edges[e] != i][0]
            if o >= 4:
                d = cp.vertices[o, :2] - cp.vertices[i, :2]
                assert min(abs(d[0]), abs(d[1])) < 1e-12
                assert np.abs(cp.vertices[o, :2]).max() == pytest.approx(1.5)
    check_assignments_match_signs(cp)


def test_square_twist_is_not_rigid_foldable():
    cp = square_twist()
    strain, err = check_rigid(cp, rigid_fold(cp))
    assert strain > 1e-2 or err > 1e-2


# -- names, validation ----------------------------------------------------------------------


def test_every_generator_returns_a_named_validated_pattern():
    for cp in [
        single_crease(),
        degree4_vertex(),
        miura_ori(),
        seed_waterbomb(),
        waterbomb(),
        yoshimura(),
        kresling(),
        square_twist(),
    ]:
        assert isinstance(cp, CreasePattern)
        assert cp.name and cp.name != "pattern"
        assert np.isfinite(cp.fold_angles).all()
        assert np.abs(cp.fold_angles).max() <= np.pi
        check_assignments_match_signs(cp)


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: single_crease(fold_angle=4.0), "fold_angle"),
        (lambda: single_crease(width=0.0), "width"),
        (lambda: single_crease(height=-1.0), "height"),
        (lambda: single_crease(fold_angle=float("nan")), "finite"),
        (lambda: single_crease(fold_angle="x"), "number"),
        (lambda: degree4_vertex(alpha=0.0), "alpha"),
        (lambda: degree4_vertex(beta=np.pi), "beta"),
        (lambda: degree4_vertex(branch=3), "branch"),
        (lambda: degree4_vertex(alpha=1.0, beta=1.0, branch=2), "alpha != beta"),
        (lambda: degree4_vertex(radius=0), "radius"),
        (lambda: miura_ori(nx=0), "nx"),
        (lambda: miura_ori(ny=2.5), "ny"),
        (lambda: miura_ori(a=-1.0), "a"),
        (lambda: miura_ori(sector_angle=np.pi / 2 + 0.1), "sector_angle"),
        (lambda: miura_ori(sector_angle=0.0), "sector_angle"),
        (lambda: miura_ori(fold_angle=-3.5), "fold_angle"),
        (lambda: waterbomb(n=0), "n"),
        (lambda: waterbomb(m=True), "m"),
        (lambda: waterbomb(size=0.0), "size"),
        (lambda: yoshimura(n=0), "n"),
        (lambda: yoshimura(height=0.0), "height"),
        (lambda: kresling(n=2), "n"),
        (lambda: kresling(stories=0), "stories"),
        (lambda: kresling(height=0.0), "height"),
        (lambda: kresling(twist=np.pi), "twist"),
        (lambda: kresling(n=6, twist=-2.5), "twist"),
        (lambda: kresling(alternate="yes"), "alternate"),
        (lambda: kresling_states(2, 1.0, 1.0, 1.0), "n"),
        (lambda: square_twist(twist_angle=0.0), "twist_angle"),
        (lambda: square_twist(twist_angle=np.pi / 2), "twist_angle"),
        (lambda: square_twist(size=1.0, sheet=1.2), "sheet"),
        (lambda: square_twist(fold_angle=7.0), "fold_angle"),
    ],
)
def test_argument_validation(call, match):
    with pytest.raises(PatternError, match=match):
        call()


def test_one_pattern_keeps_its_triangulation_across_geometries():
    """A parallelogram's two ears tie; the tie goes to the first, not to rounding, so Miura-ori
    of other sector angles share one mesh topology (and fold_batch's shared index arrays)."""
    first = miura_ori(4, 4).mesh
    for gamma in np.radians(np.linspace(50, 85, 36)):
        mesh = miura_ori(4, 4, sector_angle=gamma, fold_angle=2.0).mesh
        np.testing.assert_array_equal(mesh.triangles, first.triangles)
        np.testing.assert_array_equal(mesh.edges, first.edges)
