"""Crease-pattern generators with exact target fold angles.

Every generator returns a validated :class:`~origami_jax.pattern.CreasePattern`. Conventions
(those of :mod:`origami_jax.pattern`):

* lengths in any unit (the generators' own parameters set the scale);
* fold angles in **radians**: valley positive, mountain negative, flat 0, fully folded +-pi;
* assignments follow the signs of the targets (``V`` for > 0, ``M`` for < 0); a crease whose
  exact target happens to be 0 keeps the letter of its design (the sign it takes for a
  positive ``fold_angle``), or ``F`` when even that is 0;
* a negative ``fold_angle`` mirrors every assignment (mountains and valleys swap);
* invalid arguments raise :class:`~origami_jax.pattern.PatternError`.

The generators whose targets are rigid-foldable (:func:`single_crease`, :func:`degree4_vertex`,
:func:`miura_ori`, :func:`yoshimura`, :func:`kresling`) fold exactly, with zero strain, to their
targets under :func:`origami_jax.kinematics.rigid_fold`. :func:`waterbomb`, :func:`square_twist`
and :func:`seed_waterbomb` are not rigid-foldable: their targets can only be approached with some
facet bending or stretching.

Example:
  >>> import numpy as np
  >>> from origami_jax.patterns import miura_ori
  >>> cp = miura_ori(nx=2, ny=2, fold_angle=np.pi / 2)
  >>> cp.num_vertices, cp.num_faces
  (9, 4)
"""

from __future__ import annotations

import math
import numbers
from collections import deque

import numpy as np

from origami_jax.kinematics import fold_angles_np
from origami_jax.pattern import CreasePattern, PatternError

__all__ = [
    "single_crease",
    "degree4_vertex",
    "degree4_fold_angles",
    "miura_ori",
    "miura_straight_angle",
    "seed_waterbomb",
    "SEED_WATERBOMB_STIFFNESS",
    "SEED_WATERBOMB_ENERGY",
    "waterbomb",
    "yoshimura",
    "kresling",
    "kresling_states",
    "square_twist",
]

# ---------------------------------------------------------------------------------------------
# argument checks


def _integer(name: str, value, minimum: int) -> int:
    if isinstance(value, (bool, np.bool_)):
        raise PatternError(f"{name}: expected an integer, got {value!r}")
    if not isinstance(value, numbers.Integral):
        if isinstance(value, numbers.Real) and float(value).is_integer():
            value = int(value)
        else:
            raise PatternError(f"{name}: expected an integer, got {value!r}")
    value = int(value)
    if value < minimum:
        raise PatternError(f"{name}: must be at least {minimum}, got {value}")
    return value


def _real(
    name: str,
    value,
    lo: float = -math.inf,
    hi: float = math.inf,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    what: str = "",
) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        try:
            value = float(np.asarray(value, dtype=np.float64).item())
        except (TypeError, ValueError):
            raise PatternError(f"{name}: expected a number, got {value!r}") from None
    value = float(value)
    if not math.isfinite(value):
        raise PatternError(f"{name}: must be finite, got {value}")
    bad_lo = value <= lo if lo_open else value < lo
    bad_hi = value >= hi if hi_open else value > hi
    if bad_lo or bad_hi:
        left = "(" if lo_open else "["
        right = ")" if hi_open else "]"
        text = what or f"{left}{lo:.6g}, {hi:.6g}{right}"
        raise PatternError(f"{name}: must be in {text}, got {value:.6g}")
    return value


def _positive(name: str, value) -> float:
    return _real(name, value, 0.0, lo_open=True, what="(0, inf) (a positive length)")


def _fold(name: str, value) -> float:
    return _real(name, value, -np.pi, np.pi, what="[-pi, pi] radians")


def _half_tan_scale(factor: float, rho: float) -> float:
    """The angle ``r`` with ``tan(r / 2) = factor * tan(rho / 2)``, exact at ``rho = +-pi``."""
    return 2.0 * math.atan2(factor * math.sin(rho / 2), math.cos(rho / 2))


def _sign(value: float) -> float:
    return -1.0 if value < 0 else 1.0


def _letter(rho: float, design: float = 0.0) -> str:
    """M/V from the sign of ``rho``; when ``rho == 0`` from ``design``; ``F`` if both are 0."""
    for s in (rho, design):
        if s > 0:
            return "V"
        if s < 0:
            return "M"
    return "F"


# ---------------------------------------------------------------------------------------------
# assembly


def _assemble(vertices, faces, creases: dict, name: str, first=()) -> CreasePattern:
    """Build a pattern: edges are the faces' sides, ``first`` ones first, then in order of first
    appearance in ``faces``.

    ``creases`` maps ``(min(a, b), max(a, b))`` to ``(letter, fold angle)`` for every side shared
    by two faces; sides of one face are borders.
    """
    order: list[tuple[int, int]] = list(first)
    count: dict[tuple[int, int], int] = {key: 0 for key in order}
    for face in faces:
        for s in range(len(face)):
            a, b = int(face[s]), int(face[(s + 1) % len(face)])
            key = (min(a, b), max(a, b))
            if key not in count:
                order.append(key)
                count[key] = 0
            count[key] += 1
    letters, angles = [], []
    for key in order:
        if count[key] == 1:
            letters.append("B")
            angles.append(0.0)
        else:
            letter, rho = creases[key]
            letters.append(letter)
            angles.append(float(rho) if letter in "MVU" else 0.0)
    return CreasePattern(
        vertices=np.asarray(vertices, dtype=np.float64),
        edges=np.array(order, dtype=np.int64),
        faces=[tuple(int(v) for v in f) for f in faces],
        assignments="".join(letters),
        fold_angles=np.array(angles),
        name=name,
    )


def _key(a: int, b: int) -> tuple[int, int]:
    return (min(a, b), max(a, b))


# ---------------------------------------------------------------------------------------------
# single crease


def single_crease(
    fold_angle: float = np.pi / 2, width: float = 1.0, height: float = 1.0
) -> CreasePattern:
    """A ``width`` x ``height`` rectangle with one crease down the middle.

    Layout: vertices ``0 (0, 0)``, ``1 (width/2, 0)``, ``2 (width, 0)``, ``3 (width, height)``,
    ``4 (width/2, height)``, ``5 (0, height)``; the crease is the vertical edge 1-4, the two
    faces are the left and right halves.

    Args:
      fold_angle: the crease's target fold angle in radians, in [-pi, pi]; valley (``V``) if
        >= 0, mountain (``M``) if negative.
      width, height: the rectangle's sides (length unit), positive.
    """
    rho = _fold("fold_angle", fold_angle)
    w = _positive("width", width)
    h = _positive("height", height)
    vertices = [[0, 0], [w / 2, 0], [w, 0], [w, h], [w / 2, h], [0, h]]
    faces = [(0, 1, 4, 5), (1, 2, 3, 4)]
    letter = "M" if rho < 0 else "V"
    return _assemble(vertices, faces, {(1, 4): (letter, rho)}, name="single_crease")


# ---------------------------------------------------------------------------------------------
# degree-4 vertex


def degree4_fold_angles(
    alpha: float, beta: float, fold_angle: float, branch: int = 1
) -> np.ndarray:
    """(4,) fold angles ``(rho1, rho2, rho3, rho4)`` of a flat-foldable degree-4 vertex.

    Sector angles ``alpha, beta, pi - alpha, pi - beta`` (radians) lie between creases
    (1, 2), (2, 3), (3, 4), (4, 1); ``rho1 = fold_angle``. Branch I (``branch=1``):
    ``rho3 = rho1``, ``rho4 = -rho2``,
    ``tan(rho2/2) = -cos((alpha+beta)/2) / cos((alpha-beta)/2) * tan(rho1/2)``.
    Branch II (``branch=2``): ``rho3 = -rho1``, ``rho4 = rho2``,
    ``tan(rho2/2) = sin((alpha+beta)/2) / sin((alpha-beta)/2) * tan(rho1/2)``.
    """
    alpha = _real("alpha", alpha, 0.0, np.pi, lo_open=True, hi_open=True, what="(0, pi)")
    beta = _real("beta", beta, 0.0, np.pi, lo_open=True, hi_open=True, what="(0, pi)")
    rho1 = _fold("fold_angle", fold_angle)
    if isinstance(branch, bool) or branch not in (1, 2):
        raise PatternError(f"branch: must be 1 (branch I) or 2 (branch II), got {branch!r}")
    if branch == 1:
        k = -math.cos((alpha + beta) / 2) / math.cos((alpha - beta) / 2)
        rho2 = _half_tan_scale(k, rho1)
        return np.array([rho1, rho2, rho1, -rho2])
    den = math.sin((alpha - beta) / 2)
    if abs(den) < 1e-9:
        raise PatternError(
            "branch: branch II needs alpha != beta (with alpha == beta creases 2 and 4 are "
            "collinear and only the straight fold along them remains)"
        )
    k = math.sin((alpha + beta) / 2) / den
    rho2 = _half_tan_scale(k, rho1)
    return np.array([rho1, rho2, -rho1, rho2])


def degree4_vertex(
    alpha: float = np.pi / 3,
    beta: float = np.pi / 4,
    fold_angle: float = np.pi / 2,
    branch: int = 1,
    radius: float = 1.0,
) -> CreasePattern:
    """A flat-foldable degree-4 vertex at the origin, folded along one of its two branches.

    Layout: vertex 0 is the origin; creases 1..4 are rays at angles ``0``, ``alpha``,
    ``alpha + beta`` and ``pi + beta`` (counterclockwise), so the sector angles are ``alpha``,
    ``beta``, ``pi - alpha``, ``pi - beta`` between creases (1, 2), (2, 3), (3, 4), (4, 1).
    Vertices 1..4 are the rays' ends on the square ``[-radius, radius]^2`` (the sheet's
    border), followed by the square's corners (a corner hit by a ray is not repeated). The four
    faces are the (convex) sectors of the square. Pattern edges 0..3 are creases 1..4.

    Targets (radians): :func:`degree4_fold_angles` (the exact closed forms of the two branches;
    ``rho1 = fold_angle``); assignments follow their signs.

    Args:
      alpha, beta: sector angles in radians, each in (0, pi).
      fold_angle: fold angle of crease 1 in radians, in [-pi, pi].
      branch: 1 (branch I: creases 1 and 3 alike) or 2 (branch II: creases 2 and 4 alike;
        needs ``alpha != beta``).
      radius: half the side of the square sheet (length unit), positive.
    """
    rho = degree4_fold_angles(alpha, beta, fold_angle, branch)
    design = degree4_fold_angles(alpha, beta, _sign(fold_angle), branch)
    r = _positive("radius", radius)
    ray_angles = [0.0, alpha, alpha + beta, np.pi + beta]
    tol = 1e-12
    ends = []
    for t in ray_angles:
        d = np.array([math.cos(t), math.sin(t)])
        ends.append(r * d / np.abs(d).max())
    corners = [np.array([r, r]), np.array([-r, r]), np.array([-r, -r]), np.array([r, -r])]
    corners = [c for c in corners if min(np.linalg.norm(c - e) for e in ends) > tol * r]
    vertices = [np.zeros(2)] + ends + corners
    polar = [math.atan2(p[1], p[0]) % (2 * np.pi) for p in vertices[1:]]
    polar = [0.0 if a > 2 * np.pi - tol else a for a in polar]
    ring = [1 + int(s) for s in np.argsort(polar, kind="stable")]  # boundary, ccw
    faces = []
    for c in range(4):
        start = ring.index(1 + c)
        stop = ring.index(1 + (c + 1) % 4)
        arc = [ring[(start + s) % len(ring)] for s in range((stop - start) % len(ring) + 1)]
        faces.append(tuple([0] + arc))
    creases = {(0, 1 + c): (_letter(rho[c], design[c]), rho[c]) for c in range(4)}
    name = f"degree4_vertex(branch {'I' if branch == 1 else 'II'})"
    return _assemble(np.array(vertices), faces, creases, name=name, first=list(creases))


# ---------------------------------------------------------------------------------------------
# Miura-ori


def miura_straight_angle(sector_angle: float, zigzag_angle: float) -> float:
    """Magnitude of the straight creases' fold angle: ``tan(rs/2) = cos(gamma) tan(rz/2)``.

    ``sector_angle`` is gamma in radians, ``zigzag_angle`` the zig-zag fold angle in radians;
    the result has the sign of ``zigzag_angle``.
    """
    return _half_tan_scale(math.cos(sector_angle), zigzag_angle)


def miura_ori(
    nx: int = 4,
    ny: int = 4,
    a: float = 1.0,
    b: float = 1.0,
    sector_angle: float = np.radians(60),
    fold_angle: float = np.pi / 2,
) -> CreasePattern:
    """A Miura-ori sheet of ``nx`` x ``ny`` parallelogram panels, rigid-foldable.

    Layout: vertex ``(i, j)``, ``0 <= i <= nx``, ``0 <= j <= ny``, has index
    ``j * (nx + 1) + i`` and sits at ``x = i b sin(gamma)``,
    ``y = j a + (b cos(gamma) if i is odd else 0)``. Edges ``(i, j)-(i+1, j)`` (length ``b``)
    form the **zig-zag** crease lines (along x, one per interior ``j``); edges
    ``(i, j)-(i, j+1)`` (length ``a``, along y) form the **straight** crease lines (one per
    interior ``i``). Panel ``(i, j)`` has corners ``(i, j), (i+1, j), (i+1, j+1), (i, j+1)``;
    ``gamma`` is the acute panel angle between a zig-zag edge and a straight edge.

    ``a`` and ``b`` are those of Schenk & Guest (2013): ``a`` is the panel side along the straight
    creases, ``b`` the side along the zig-zag creases. With ``theta = |fold_angle| / 2`` (the
    facets' angle to the plane of the folded sheet) the folded unit cell (2 x 2 panels) has
    height ``H = a sin(theta) sin(gamma)``, period ``2 S`` along the zig-zag lines with
    ``S = b cos(theta) tan(gamma) / sqrt(1 + cos^2(theta) tan^2(gamma))``, period ``2 L`` along
    the straight lines with ``L = a sqrt(1 - sin^2(theta) sin^2(gamma))`` and zig-zag amplitude
    ``V = b / sqrt(1 + cos^2(theta) tan^2(gamma))``.

    Targets (radians): zig-zag creases ``+-fold_angle``, line ``j`` a valley for odd ``j`` and a
    mountain for even ``j`` (for ``fold_angle > 0``); straight creases ``+-rho_s`` with
    ``tan(rho_s/2) = cos(gamma) tan(fold_angle/2)``, segment ``(i, j)-(i, j+1)`` a valley when
    ``i + j`` is even; so the straight lines alternate at every vertex. Panels are quads, split
    by the mesh into flat facet creases.

    Args:
      nx, ny: number of panels along x (across the straight lines) and y, each >= 1.
      a, b: panel sides (length unit), positive.
      sector_angle: gamma in radians, in (0, pi/2].
      fold_angle: the zig-zag creases' fold angle in radians, in [-pi, pi]; negative swaps M/V.
    """
    nx = _integer("nx", nx, 1)
    ny = _integer("ny", ny, 1)
    a = _positive("a", a)
    b = _positive("b", b)
    gamma = _real(
        "sector_angle", sector_angle, 0.0, np.pi / 2, lo_open=True, what="(0, pi/2] radians"
    )
    rho_z = _fold("fold_angle", fold_angle)
    sigma = _sign(rho_z)
    mag_z = abs(rho_z)
    mag_s = miura_straight_angle(gamma, mag_z)
    design_s = miura_straight_angle(gamma, 1.0)

    def index(i: int, j: int) -> int:
        return j * (nx + 1) + i

    vertices = [
        [i * b * math.sin(gamma), j * a + (b * math.cos(gamma) if i % 2 else 0.0)]
        for j in range(ny + 1)
        for i in range(nx + 1)
    ]
    faces = [
        (index(i, j), index(i + 1, j), index(i + 1, j + 1), index(i, j + 1))
        for j in range(ny)
        for i in range(nx)
    ]
    creases = {}
    for j in range(1, ny):
        s = sigma * (1.0 if j % 2 else -1.0)
        for i in range(nx):
            creases[_key(index(i, j), index(i + 1, j))] = (_letter(s * mag_z, s), s * mag_z)
    for i in range(1, nx):
        for j in range(ny):
            s = sigma * (1.0 if (i + j) % 2 == 0 else -1.0)
            creases[_key(index(i, j), index(i, j + 1))] = (
                _letter(s * mag_s, s * design_s),
                s * mag_s,
            )
    return _assemble(vertices, faces, creases, name=f"miura_ori_{nx}x{ny}")


# ---------------------------------------------------------------------------------------------
# the seed's waterbomb scene

SEED_WATERBOMB_ENERGY = 0.009890
"""The seed's initial (flat-sheet) energy of its waterbomb scene, in its units."""

_SEED_CENTRES = ((1, 2), (3, 1), (4, 3), (2, 4))
# the five squares outside the four bases and the diagonal drawn in each (C4-symmetric ring,
# the centre square's diagonal running from (2, 2) to (3, 3))
_SEED_FREE_DIAGONALS = {
    (1, 0): ((1, 0), (2, 1)),
    (4, 1): ((5, 1), (4, 2)),
    (3, 4): ((4, 5), (3, 4)),
    (0, 3): ((0, 4), (1, 3)),
    (2, 2): ((2, 2), (3, 3)),
}


def seed_waterbomb() -> CreasePattern:
    """The seed's scene: a 2x2 waterbomb tessellation on a plus-shaped sheet of 21 unit squares.

    Layout (unit squares; square ``(sx, sy)`` is ``[sx, sx+1] x [sy, sy+1]``, origin at the lower
    left of the 5 x 5 bounding box): the 5 x 5 grid without its 4 corner squares, 32 vertices
    (grid points ``(x, y)`` in row-major order, ``y`` major, the 4 box corners left out).
    Every square is split by exactly one diagonal into two triangular faces (42 faces).

    * four waterbomb centres at grid points (1, 2), (3, 1), (4, 3), (2, 4); the 4 squares around
      each take the diagonal through the centre: 16 valleys with target ``+pi``;
    * the 5 remaining squares (1, 0), (4, 1), (3, 4), (0, 3), (2, 2) take one diagonal each as a
      flat facet crease (``F``, target 0): (1,0)-(2,1), (5,1)-(4,2), (4,5)-(3,4), (0,4)-(1,3)
      (the 4-fold rotation of the first about (2.5, 2.5)) and (2,2)-(3,3);
    * the 32 interior unit grid edges are mountains with target ``-pi/2``; the 20 unit edges of
      the outline are borders.

    See :data:`SEED_WATERBOMB_STIFFNESS` for the seed's stiffnesses.
    """
    squares = [
        (sx, sy)
        for sy in range(5)
        for sx in range(5)
        if (sx, sy) not in {(0, 0), (4, 0), (0, 4), (4, 4)}
    ]
    points = sorted(
        {(sx + dx, sy + dy) for sx, sy in squares for dx in (0, 1) for dy in (0, 1)},
        key=lambda p: (p[1], p[0]),
    )
    index = {p: k for k, p in enumerate(points)}
    diagonals: dict[tuple[int, int], tuple[tuple[int, int], tuple[int, int], str]] = {}
    for cx, cy in _SEED_CENTRES:
        for sx, sy in ((cx - 1, cy - 1), (cx, cy - 1), (cx - 1, cy), (cx, cy)):
            opposite = (2 * sx + 1 - cx, 2 * sy + 1 - cy)
            diagonals[(sx, sy)] = ((cx, cy), opposite, "V")
    for sq, (p, q) in _SEED_FREE_DIAGONALS.items():
        diagonals[sq] = (p, q, "F")
    assert sorted(diagonals) == sorted(squares)
    faces, creases = [], {}
    for sx, sy in squares:
        p, q, letter = diagonals[(sx, sy)]
        corners = [(sx, sy), (sx + 1, sy), (sx + 1, sy + 1), (sx, sy + 1)]
        others = [c for c in corners if c not in (p, q)]
        for o in others:
            faces.append((index[p], index[q], index[o]))
        creases[_key(index[p], index[q])] = (letter, np.pi if letter == "V" else 0.0)
        for s in range(4):
            creases[_key(index[corners[s]], index[corners[(s + 1) % 4]])] = ("M", -np.pi / 2)
    return _assemble(np.array(points, dtype=np.float64), faces, creases, name="seed_waterbomb")


def _seed_stiffness() -> dict[str, float]:
    cp = seed_waterbomb()
    driven = np.isin(cp.assignments, ["M", "V"])
    l0 = np.linalg.norm(cp.vertices[cp.edges[:, 1]] - cp.vertices[cp.edges[:, 0]], axis=1)
    flat_energy_per_unit = float(np.sum(l0[driven] / 2 * cp.fold_angles[driven] ** 2))
    lt = SEED_WATERBOMB_ENERGY / flat_energy_per_unit
    return {"axial": 400.0 * lt, "facet": 20.0 * lt, "crease": lt}


SEED_WATERBOMB_STIFFNESS: dict[str, float] = _seed_stiffness()
"""The seed's stiffnesses for :func:`seed_waterbomb`: ``{"axial", "facet", "crease"}``.

``crease = lt`` is chosen so that the flat sheet's energy, the sum over the driven creases of
``lt * l0 / 2 * target^2``, equals the seed's initial energy 0.009890 (``lt ~ 6.544e-5``);
``facet = 20 lt`` and ``axial = 400 lt``, the seed's ~20x steps. Axial is per ``l0``
(energy ``axial / (2 l0) (l - l0)^2``), the torsion ones per length (``k l0 / 2 (rho - rho0)^2``).
"""


# ---------------------------------------------------------------------------------------------
# waterbomb tessellation


def waterbomb(
    n: int = 2, m: int = 2, fold_angle: float = np.pi / 2, size: float = 1.0
) -> CreasePattern:
    """A waterbomb tessellation: ``m`` offset rows of waterbomb bases on a grid of squares.

    Layout: a ``2n`` x ``2m`` grid of squares of side ``size`` on ``[0, 2n size] x [0, 2m size]``;
    grid point ``(x, y)`` has index ``y (2n + 1) + x``. Row ``r`` (``0 <= r < m``) has its base
    centres at height ``y = 2r + 1`` and at ``x = 1, 3, ..., 2n - 1`` for even ``r`` (``n`` whole
    bases) or ``x = 0, 2, ..., 2n`` for odd ``r`` (offset by one square: ``n - 1`` whole bases and
    a half base at each side border). Every square has exactly one base centre at a corner and
    is split by the diagonal through it (a valley), so each base centre has four valley
    diagonals and four mountain half lines.

    Targets (radians): diagonals ``fold_angle`` (valleys for ``fold_angle > 0``), every interior
    grid edge ``-rho_mid`` with ``tan(rho_mid/2) = tan(fold_angle/2) / sqrt(2)``, the waterbomb
    base's symmetric-mode relation, opposite in sign.

    These targets are **not rigid-foldable** in general (the degree-8 centres and the vertices
    where bases meet cannot all reach them with rigid facets): folding to them needs facet
    bending.

    Args:
      n, m: bases per row and number of rows, each >= 1.
      fold_angle: the diagonals' fold angle in radians, in [-pi, pi]; negative swaps M/V.
      size: side of the grid squares (length unit), positive.
    """
    n = _integer("n", n, 1)
    m = _integer("m", m, 1)
    rho_d = _fold("fold_angle", fold_angle)
    s = _positive("size", size)
    sigma = _sign(rho_d)
    rho_mid = -_half_tan_scale(1 / math.sqrt(2), rho_d)
    nxp = 2 * n + 1

    def index(x: int, y: int) -> int:
        return y * nxp + x

    vertices = [[x * s, y * s] for y in range(2 * m + 1) for x in range(nxp)]
    faces, creases = [], {}
    for sy in range(2 * m):
        row = sy // 2
        cy = 2 * row + 1
        parity = 1 if row % 2 == 0 else 0
        for sx in range(2 * n):
            cx = sx if sx % 2 == parity else sx + 1
            corners = [(sx, sy), (sx + 1, sy), (sx + 1, sy + 1), (sx, sy + 1)]
            p, q = (cx, cy), (2 * sx + 1 - cx, 2 * sy + 1 - cy)
            for o in corners:
                if o not in (p, q):
                    faces.append((index(*p), index(*q), index(*o)))
            creases[_key(index(*p), index(*q))] = (_letter(rho_d, sigma), rho_d)
            for t in range(4):
                u, w = corners[t], corners[(t + 1) % 4]
                creases[_key(index(*u), index(*w))] = (_letter(rho_mid, -sigma), rho_mid)
    return _assemble(vertices, faces, creases, name=f"waterbomb_{n}x{m}")


# ---------------------------------------------------------------------------------------------
# Yoshimura


def yoshimura(
    n: int = 4,
    m: int = 3,
    fold_angle: float = np.pi / 2,
    width: float = 1.0,
    height: float = 1.0,
) -> CreasePattern:
    """A Yoshimura (diamond) pattern of ``m`` rows of isosceles triangles, rigid-foldable.

    Layout: the sheet is ``[0, n width] x [0, m height]``; horizontal lines ``y = k height``,
    ``k = 0..m``. Line ``k`` holds the points ``x = i width`` (``i = 0..n``) for even ``k`` and
    ``x = 0, width/2, 3 width/2, ..., n width - width/2, n width`` for odd ``k``. Each row
    between two lines is a zig-zag of isosceles triangles (base ``width``, height ``height``)
    with a right half triangle at each side border; vertices are numbered line by line, left to
    right.

    Targets (radians): the diagonals (the triangles' slanted sides) are valleys with
    ``fold_angle``; the interior horizontal lines are mountains with ``-rho_h``,
    ``tan(rho_h/2) = cos(delta) tan(fold_angle/2)``, ``delta = atan(2 height / width)`` the angle
    between a diagonal and the horizontal. This is the symmetric mode of each degree-6 vertex
    (sectors delta, pi - 2 delta, delta, delta, pi - 2 delta, delta; for delta = 45 degrees
    the waterbomb base's ``tan(rho_mid/2) = tan(rho_diag/2) / sqrt(2)``), and it folds the whole
    sheet rigidly into an arch.

    Args:
      n: triangles' bases per line (columns), >= 1.
      m: rows of triangles, >= 1.
      fold_angle: the diagonals' fold angle in radians, in [-pi, pi]; negative swaps M/V.
      width, height: base and height of the triangles (length unit), positive.
    """
    n = _integer("n", n, 1)
    m = _integer("m", m, 1)
    rho_d = _fold("fold_angle", fold_angle)
    w = _positive("width", width)
    h = _positive("height", height)
    sigma = _sign(rho_d)
    delta = math.atan2(2 * h, w)
    rho_h = -_half_tan_scale(math.cos(delta), rho_d)
    lines: list[list[int]] = []
    vertices: list[list[float]] = []
    for k in range(m + 1):
        if k % 2 == 0:
            xs = [i * w for i in range(n + 1)]
        else:
            xs = [0.0] + [(i + 0.5) * w for i in range(n)] + [n * w]
        lines.append(list(range(len(vertices), len(vertices) + len(xs))))
        vertices.extend([x, k * h] for x in xs)
    faces, creases = [], {}
    for k in range(m):
        lo, hi = lines[k], lines[k + 1]
        i = j = 0
        while i < len(lo) - 1 or j < len(hi) - 1:
            if j == len(hi) - 1:
                take_lo = True
            elif i == len(lo) - 1:
                take_lo = False
            else:  # advance the side whose next point comes first (on a tie: lagging side)
                x_lo = (vertices[lo[i + 1]][0], vertices[lo[i]][0])
                x_hi = (vertices[hi[j + 1]][0], vertices[hi[j]][0])
                take_lo = x_lo < x_hi
            if take_lo:
                faces.append((lo[i], lo[i + 1], hi[j]))
                i += 1
            else:
                faces.append((lo[i], hi[j + 1], hi[j]))
                j += 1
            if 0 < vertices[lo[i]][0] < n * w or 0 < vertices[hi[j]][0] < n * w:
                creases[_key(lo[i], hi[j])] = (_letter(rho_d, sigma), rho_d)
    for k in range(1, m):
        for u, v in zip(lines[k][:-1], lines[k][1:], strict=True):
            creases[_key(u, v)] = (_letter(rho_h, -sigma), rho_h)
    return _assemble(vertices, faces, creases, name=f"yoshimura_{n}x{m}")


# ---------------------------------------------------------------------------------------------
# Kresling


def kresling_states(
    n: int, radius: float, height: float, twist: float
) -> tuple[tuple[float, float], tuple[float, float]]:
    """The two stress-free states ``((H0, phi0), (H1, phi1))`` of a Kresling story.

    For the story of :func:`kresling` with ``n`` sides, polygon radius ``radius``, height
    ``H0 = height`` and twist ``phi0 = twist`` (radians), the other state with the same crease
    lengths has ``phi1 = pi + 2 pi / n - phi0`` and ``H1^2 = H0^2 + 2 R^2 (cos phi1 - cos phi0)``.
    ``H1`` is NaN when ``H1^2 < 0`` (no second state); it is 0 when the second state is flat.
    """
    n = _integer("n", n, 3)
    r = _positive("radius", radius)
    h0 = _positive("height", height)
    phi0 = _real("twist", twist)
    phi1 = np.pi + 2 * np.pi / n - phi0
    h1_sq = h0**2 + 2 * r**2 * (math.cos(phi1) - math.cos(phi0))
    h1 = math.sqrt(h1_sq) if h1_sq >= 0 else math.nan
    return (h0, phi0), (h1, phi1)


def _unfold(points: np.ndarray, triangles: list[tuple[int, int, int]]) -> np.ndarray:
    """(V, 2) flat positions of a developable triangle mesh, by unfolding triangle by triangle."""
    flat = np.full((len(points), 2), np.nan)
    sides: dict[tuple[int, int], list[int]] = {}
    for t, tri in enumerate(triangles):
        for s in range(3):
            sides.setdefault(_key(tri[s], tri[(s + 1) % 3]), []).append(t)

    def dist(u: int, v: int) -> float:
        return float(np.linalg.norm(points[u] - points[v]))

    a, b, c = triangles[0]
    lab, lac, lbc = dist(a, b), dist(a, c), dist(b, c)
    along = (lac**2 - lbc**2 + lab**2) / (2 * lab)
    flat[a] = (0.0, 0.0)
    flat[b] = (lab, 0.0)
    flat[c] = (along, math.sqrt(max(lac**2 - along**2, 0.0)))
    done = {0}
    queue = deque([0])
    while queue:
        t = queue.popleft()
        tri = triangles[t]
        for s in range(3):
            u, w = tri[s], tri[(s + 1) % 3]
            q = tri[(s + 2) % 3]
            for o in sides[_key(u, w)]:
                if o in done:
                    continue
                r = [v for v in triangles[o] if v not in (u, w)][0]
                e = flat[w] - flat[u]
                length = float(np.linalg.norm(e))
                e_hat = e / length
                normal = np.array([-e_hat[1], e_hat[0]])
                du, dw = dist(r, u), dist(r, w)
                along = (du**2 - dw**2 + length**2) / (2 * length)
                perp = math.sqrt(max(du**2 - along**2, 0.0))
                side = -1.0 if np.dot(flat[q] - flat[u], normal) > 0 else 1.0
                position = flat[u] + along * e_hat + side * perp * normal
                if np.isnan(flat[r]).any():
                    flat[r] = position
                done.add(o)
                queue.append(o)
    return flat


def kresling(
    n: int = 6,
    stories: int = 1,
    radius: float = 1.0,
    height: float = 1.5,
    twist: float = np.pi / 2,
    alternate: bool = False,
) -> CreasePattern:
    """A Kresling tube, as a flat strip whose targets fold it exactly into the tube.

    The 3-D tube: ring ``s`` (``s = 0..stories``) is a regular ``n``-gon of circumradius
    ``radius`` at height ``s height``, vertex ``k`` at angle ``2 pi k / n + rot_s``; each story
    turns its top ring by ``+twist`` relative to its bottom (``rot_s = s twist``), or, with
    ``alternate=True``, by ``+twist`` and ``-twist`` in turn (mirror-image stories, so the tube
    does not twist overall). A story with turn ``+twist`` is split into the triangles
    ``(b_k, b_k+1, t_k)`` and ``(b_k+1, t_k+1, t_k)`` (creases ``b_k t_k`` and the diagonal
    ``b_k+1 t_k``, so that the two stress-free states obey :func:`kresling_states`); a mirrored
    story uses ``(b_k, b_k+1, t_k+1)`` and ``(b_k, t_k+1, t_k)``.

    The flat pattern is that tube cut along the crease ``b_0 t_0`` of every story and unfolded:
    a strip of ``2 n`` congruent triangles per story (a parallelogram strip for same-chirality
    stories). Vertex ``s (n + 1) + k`` (``k = 0..n``) is ring ``s``'s vertex ``k``; ``k = n`` is
    the copy of ``k = 0`` on the other side of the cut. Each crease's target is its exact 3-D
    fold angle in the tube (radians), so folding the strip to its targets gives the tube with
    zero strain (:func:`origami_jax.kinematics.rigid_fold`); the inner polygon edges between
    stories are creases too, the outer two polygons are borders. A target that is zero (to
    1e-12 rad) becomes a flat ``F`` crease.

    Args:
      n: polygon sides, >= 3.
      stories: number of stories, >= 1.
      radius: polygon circumradius ``R`` (length unit), positive.
      height: story height ``H`` (length unit), positive.
      twist: story twist ``phi`` in radians, in ``(2 pi / n - pi, pi)`` (so that no crease
        crosses the tube's axis).
      alternate: False: all stories turn the same way; True: alternating chirality.
    """
    n = _integer("n", n, 3)
    stories = _integer("stories", stories, 1)
    r = _positive("radius", radius)
    h = _positive("height", height)
    phi = _real(
        "twist",
        twist,
        2 * np.pi / n - np.pi,
        np.pi,
        lo_open=True,
        hi_open=True,
        what="(2 pi / n - pi, pi) radians",
    )
    if not isinstance(alternate, (bool, np.bool_)):
        raise PatternError(f"alternate: expected True or False, got {alternate!r}")

    def index(s: int, k: int) -> int:
        return s * (n + 1) + k

    points = np.zeros(((stories + 1) * (n + 1), 3))
    rot = 0.0
    turns = []
    for s in range(stories + 1):
        for k in range(n + 1):
            t = 2 * np.pi * (k % n) / n + rot
            points[index(s, k)] = (r * math.cos(t), r * math.sin(t), s * h)
        turn = -1.0 if (alternate and s % 2 == 1) else 1.0
        turns.append(turn)
        rot += turn * phi
    triangles: list[tuple[int, int, int]] = []
    for s in range(stories):
        for k in range(n):
            b0, b1 = index(s, k), index(s, k + 1)
            t0, t1 = index(s + 1, k), index(s + 1, k + 1)
            if turns[s] > 0:
                triangles += [(b0, b1, t0), (b1, t1, t0)]
            else:
                triangles += [(b0, b1, t1), (b0, t1, t0)]
    flat = _unfold(points, triangles)
    probe = _assemble(flat, triangles, _AnyCrease(), name="kresling")
    rho = fold_angles_np(points, probe.mesh.hinges[: probe.num_edges])
    creases = {}
    for e, (u, v) in enumerate(probe.edges):
        if probe.assignments[e] != "B":
            angle = 0.0 if abs(rho[e]) < 1e-12 else float(rho[e])
            creases[_key(int(u), int(v))] = (_letter(angle), angle)
    chirality = "alternating" if alternate else "same"
    name = f"kresling(n={n}, stories={stories}, {chirality} chirality)"
    return _assemble(flat, triangles, creases, name=name)


class _AnyCrease(dict):
    """A crease table that answers every edge with an unassigned, unfolded crease."""

    def __missing__(self, key):
        return ("U", 0.0)


# ---------------------------------------------------------------------------------------------
# square twist


def square_twist(
    twist_angle: float = np.pi / 8,
    fold_angle: float = np.pi / 2,
    size: float = 1.0,
    sheet: float | None = None,
) -> CreasePattern:
    """A square twist: a central square turned by ``twist_angle`` with four pleats.

    Layout: the sheet is the square ``[-sheet/2, sheet/2]^2`` (``sheet`` defaults to
    ``2 size``); the central square (side ``size``) is centred at the origin with its corners
    ``c_i`` (vertices 0..3) at angles ``twist_angle + pi/4 + i pi/2``. From ``c_i`` two pleat
    creases run straight to the sheet border along the directions ``i pi/2`` and
    ``(i + 1) pi/2`` (east and north from ``c_0``, ...), at 90 degrees to each other; the
    sectors around a corner are 90 (inside the square), ``90 - a``, 90, ``90 + a`` degrees
    (``a = twist_angle``, counterclockwise from the square), so Kawasaki's condition holds.
    The parallel pleat lines from neighbouring corners bound a pleat strip along each side of
    the square. A negative ``twist_angle`` gives the mirror image (``x -> -x``).

    Targets (radians), for ``fold_angle > 0``: the square's sides are valleys ``+fold_angle``;
    at each corner the pleat bounding the smallest sector (``90 - |a|``) is a mountain
    ``-fold_angle`` and the other pleat a valley ``+fold_angle`` (three valleys, one mountain).

    The square twist is **not rigid-foldable**: with flat panels it cannot leave the flat
    state, so these targets are reached only with facet bending.

    Args:
      twist_angle: turn of the central square in radians, ``0 < |twist_angle| < pi/2``.
      fold_angle: the creases' fold angle magnitude in radians, in [-pi, pi]; negative swaps
        M/V.
      size: side of the central square (length unit), positive.
      sheet: side of the square sheet (length unit); it must leave room for the pleats (more
        than the square's extent along x and y).
    """
    a = _real(
        "twist_angle",
        twist_angle,
        -np.pi / 2,
        np.pi / 2,
        lo_open=True,
        hi_open=True,
        what="(-pi/2, pi/2) radians, not 0",
    )
    if a == 0:
        raise PatternError("twist_angle: must not be 0 (the pattern would be a plain grid)")
    rho = _fold("fold_angle", fold_angle)
    s = _positive("size", size)
    sheet = 2 * s if sheet is None else _positive("sheet", sheet)
    sigma = _sign(rho)
    mag = abs(rho)
    corners = [
        s / math.sqrt(2) * np.array([math.cos(t), math.sin(t)])
        for t in (abs(a) + np.pi / 4 + i * np.pi / 2 for i in range(4))
    ]
    half = sheet / 2
    extent = max(float(np.abs(c).max()) for c in corners)
    if half <= extent * (1 + 1e-9):
        raise PatternError(
            f"sheet: must exceed {2 * extent:.6g} (the central square's extent) so that the "
            f"pleats reach the border, got {sheet:.6g}"
        )

    def ray_end(c: np.ndarray, direction: int) -> np.ndarray:
        d = direction % 4
        if d == 0:
            return np.array([half, c[1]])
        if d == 1:
            return np.array([c[0], half])
        if d == 2:
            return np.array([-half, c[1]])
        return np.array([c[0], -half])

    vertices = list(corners)
    end_a, end_b = [], []  # pleat ends of corner i along i pi/2 and (i + 1) pi/2
    for i, c in enumerate(corners):
        end_a.append(len(vertices))
        vertices.append(ray_end(c, i))
        end_b.append(len(vertices))
        vertices.append(ray_end(c, i + 1))
    sheet_corner = []
    for p in ([half, half], [-half, half], [-half, -half], [half, -half]):
        sheet_corner.append(len(vertices))
        vertices.append(np.array(p))
    faces = [(0, 1, 2, 3)]
    for i in range(4):
        faces.append((i, end_a[i], sheet_corner[i], end_b[i]))  # corner region
        j = (i + 1) % 4
        faces.append((i, end_b[i], end_a[j], j))  # pleat strip along side c_i c_j
    creases = {}
    for i in range(4):
        creases[_key(i, (i + 1) % 4)] = (_letter(sigma * mag, sigma), sigma * mag)
        creases[_key(i, end_a[i])] = (_letter(-sigma * mag, -sigma), -sigma * mag)
        creases[_key(i, end_b[i])] = (_letter(sigma * mag, sigma), sigma * mag)
    vertices = np.array(vertices)
    if a < 0:
        vertices[:, 0] *= -1
    return _assemble(vertices, faces, creases, name="square_twist")
