"""SVG input (Origami Simulator's conventions) and the planar arrangement of loose lines."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from origami_jax import CreasePattern, PatternError, PatternWarning, io, patterns
from origami_jax.io.svg import stroke_assignment, to_svg
from origami_jax.pattern import signed_area


def write(tmp_path, body: str, name: str = "p.svg", view: str = "0 0 100 100") -> str:
    path = tmp_path / name
    path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{view}">{body}</svg>')
    return path


def load_quiet(path) -> CreasePattern:
    with warnings.catch_warnings():
        warnings.simplefilter("error", PatternWarning)
        return io.load(path)


def normalised(cp: CreasePattern) -> np.ndarray:
    xy = cp.vertices[:, :2]
    return (xy - xy.min(0)) / (xy.max(0) - xy.min(0)).max()


def edge_table(cp: CreasePattern, decimals: int = 9) -> dict:
    """{frozenset of rounded end points: (letter, angle)} for every edge."""
    xy = np.round(normalised(cp), decimals) + 0.0
    return {
        frozenset(map(tuple, xy[[a, b]].tolist())): (str(letter), round(float(rho), 9))
        for (a, b), letter, rho in zip(
            cp.edges.tolist(), cp.assignments, cp.fold_angles, strict=True
        )
    }


SQUARE = '<rect x="0" y="0" width="100" height="100" stroke="black" fill="none"/>'


# ---------------------------------------------------------------------------------------------
# round trip through our own writer


@pytest.mark.parametrize(
    "make",
    [
        lambda: patterns.miura_ori(3, 3, sector_angle=1.1, fold_angle=1.3),
        patterns.seed_waterbomb,
        lambda: patterns.kresling(n=6, stories=1),
    ],
    ids=["miura", "seed", "kresling"],
)
def test_svg_round_trip_keeps_edges_letters_and_angles(tmp_path, make):
    cp = make()
    path = tmp_path / "p.svg"
    io.save(path, cp)
    got = load_quiet(path)
    assert got.num_vertices == cp.num_vertices
    assert got.num_faces == cp.num_faces
    assert edge_table(got) == edge_table(cp)


def test_svg_y_axis_points_down():
    cp = CreasePattern(
        vertices=[[0, 0], [2, 0], [2, 1], [0, 1]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]],
        faces=[[0, 1, 2], [0, 2, 3]],
        assignments="BBBBV",
    )
    text = to_svg(cp, width=200)
    assert 'x1="0.0" y1="100.0" x2="200.0" y2="100.0"' in text  # the bottom edge, y = 0


# ---------------------------------------------------------------------------------------------
# what the reader understands


def test_colours_by_hue_named_and_hex():
    assert stroke_assignment((0, 0, 0)) == "B"
    assert stroke_assignment((0.2, 0.2, 0.2)) == "B"
    assert stroke_assignment((1, 0, 0)) == "M"
    assert stroke_assignment((0, 0, 1)) == "V"
    assert stroke_assignment((1, 1, 0)) == "F"
    assert stroke_assignment((0, 128 / 255, 0)) == "C"  # CSS "green"
    assert stroke_assignment((1, 0, 1)) == "U"
    assert stroke_assignment((0, 1, 1)) is None  # cyan
    assert stroke_assignment((0.8, 0.8, 0.8)) is None  # light grey


def test_shapes_styles_transforms_and_opacity(tmp_path):
    body = (
        "<style>.mtn { stroke: #F00; stroke-opacity: 0.5 }</style>"
        '<path d="M0 0 H100 V100 H0 Z" style="stroke:black;fill:none"/>'
        '<g transform="translate(50 0)"><line class="mtn" x1="0" y1="0" x2="0" y2="100"/></g>'
        '<polyline points="0,50 50,50" stroke="blue" opacity="0.25"/>'
        '<line x1="50" y1="50" x2="100" y2="50" stroke="blue" stroke-opacity="25%"/>'
    )
    cp = load_quiet(write(tmp_path, body))
    assert cp.num_faces == 4
    table = edge_table(cp)
    assert sum(v == ("M", round(-math.pi / 2, 9)) for v in table.values()) == 2
    assert sum(v == ("V", round(math.pi / 4, 9)) for v in table.values()) == 2
    assert sum(v[0] == "B" for v in table.values()) == 8


def test_crossing_lines_are_split_and_polygons_are_read(tmp_path):
    body = (
        '<polygon points="0,0 100,0 100,100 0,100" stroke="black" fill="none"/>'
        '<line x1="0" y1="0" x2="100" y2="100" stroke="red"/>'
        '<line x1="100" y1="0" x2="0" y2="100" stroke="blue"/>'
    )
    cp = load_quiet(write(tmp_path, body))
    assert (cp.num_vertices, cp.num_edges, cp.num_faces) == (5, 8, 4)
    centre = np.flatnonzero(np.all(np.isclose(cp.vertices[:, :2], [50, -50]), axis=1))
    assert len(centre) == 1


def test_curves_become_pieces(tmp_path):
    body = SQUARE + '<path d="M50 0 C 20 30 80 70 50 100" stroke="red" fill="none"/>'
    cp = load_quiet(write(tmp_path, body))
    creases = np.flatnonzero(cp.assignments == "M")
    assert 4 <= len(creases) <= 200
    assert cp.num_faces == 2
    # the pieces follow the curve: their end points lie on it (x(t) within [35, 65])
    assert np.all(np.abs(cp.vertices[cp.edges[creases].ravel(), 0] - 50) < 15)


def test_hole_and_separate_pieces(tmp_path):
    body = (
        '<rect x="0" y="0" width="30" height="30" stroke="black" fill="none"/>'
        '<rect x="10" y="10" width="10" height="10" stroke="black" fill="none"/>'
        '<rect x="50" y="0" width="30" height="30" stroke="black" fill="none"/>'
        '<line x1="50" y1="0" x2="80" y2="30" stroke="blue"/>'
    )
    cp = load_quiet(write(tmp_path, body))
    area = sum(abs(signed_area(cp.vertices[list(f), :2])) for f in cp.faces)
    assert all(len(f) == 3 for f in cp.faces)
    assert area == pytest.approx(30 * 30 - 10 * 10 + 30 * 30)
    assert "J" in cp.assignments  # the face with the hole was triangulated
    assert int((cp.assignments == "B").sum()) == 12  # 4 outer + 4 around the hole + 4


def test_close_end_points_merge_and_free_ends_join_a_line(tmp_path):
    body = (
        SQUARE
        + '<line x1="0" y1="50" x2="50.004" y2="50" stroke="red"/>'  # 4e-5 of the diagonal
        + '<line x1="50" y1="50.002" x2="100" y2="50" stroke="red"/>'
        + '<line x1="30" y1="50.05" x2="30" y2="100" stroke="blue"/>'  # short of the M
    )
    cp = load_quiet(write(tmp_path, body))
    assert cp.num_faces == 3
    assert int((cp.assignments == "V").sum()) == 1


def test_dropped_and_changed_lines_warn(tmp_path):
    body = (
        SQUARE
        + '<line x1="100" y1="0" x2="100" y2="100" stroke="red"/>'  # on the edge: made B
        + '<line x1="10" y1="10" x2="20" y2="20" stroke="blue"/>'  # dangling: dropped
        + '<line x1="0" y1="0" x2="100" y2="100" stroke="cyan"/>'  # unknown colour: skipped
        + '<line x1="0" y1="0" x2="100" y2="100"/>'  # no stroke: ignored silently
    )
    with pytest.warns(PatternWarning) as record:
        cp = io.load(write(tmp_path, body))
    text = " | ".join(str(w.message) for w in record)
    assert "<line> 1: runs along the border line <rect> 0; taken as border" in text
    assert "<line> 2" in text and "dropped" in text
    assert "<line> 3" in text and "not one of the pattern colours" in text
    assert "<line> 4" not in text
    assert cp.num_faces == 1


# ---------------------------------------------------------------------------------------------
# bad input


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ("", "no stroked line in a pattern colour"),
        ('<line x1="0" y1="0" x2="10" y2="0" stroke="cyan"/>', "no stroked line"),
        ('<line x1="0" y1="0" x2="10" y2="0" stroke="red"/>', "enclose no face"),
        (
            SQUARE + '<line x1="0" y1="0" x2="100" y2="100" stroke="red"/>'
            '<line x1="0" y1="0" x2="100" y2="100" stroke="blue"/>',
            "overlap with different assignments",
        ),
        (
            SQUARE + '<line x1="0" y1="0" x2="100" y2="100" stroke="red" stroke-opacity="x"/>',
            "<line> 1: stroke-opacity 'x' is not a number",
        ),
        (
            SQUARE + '<line id="a" x1="0" y1="0" x2="1OO" y2="100" stroke="red"/>',
            "<line> number 0 of its kind (id 'a'): x2='1OO' is not a length",
        ),
        (SQUARE + '<polygon points="0,0 5,x 9,0" stroke="red"/>', "points='0,0 5,x 9,0'"),
        (SQUARE + '<path d="M0 0 L5 5 W" stroke="red"/>', "d='M0 0 L5 5 W' is not path data"),
    ],
)
def test_bad_drawings_raise_pattern_error_naming_the_element(tmp_path, body, expected):
    path = write(tmp_path, body)
    with pytest.raises(PatternError) as info, warnings.catch_warnings():
        warnings.simplefilter("ignore", PatternWarning)
        io.load(path)
    assert str(info.value).startswith(str(path))
    assert expected in str(info.value)


@pytest.mark.parametrize("text", ["<svg", "not xml at all", "", "<svg><line</svg>"])
def test_malformed_files_raise_pattern_error(tmp_path, text):
    path = tmp_path / "bad.svg"
    path.write_text(text)
    with pytest.raises(PatternError, match="bad.svg"), warnings.catch_warnings():
        warnings.simplefilter("ignore", PatternWarning)
        io.load(path)


def test_missing_svg_names_the_path(tmp_path):
    with pytest.raises(PatternError, match="nope.svg"):
        io.load(tmp_path / "nope.svg")
