"""SVG input (Origami Simulator's conventions) and the planar arrangement of loose lines."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from origami_jax import CreasePattern, PatternError, PatternWarning, io, patterns
from origami_jax.io.svg import path_data_error, stroke_assignment, to_svg
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
DATA = Path(__file__).resolve().parent / "data"


def load_with_warnings(path) -> tuple[CreasePattern, str]:
    """The pattern and every PatternWarning's message, joined by " | "."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always", PatternWarning)
        cp = io.load(path)
    return cp, " | ".join(str(w.message) for w in record if w.category is PatternWarning)


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
# what Origami Simulator opens: junctions drawn a little off, overlaps, slits, colours


def test_regression_junction_drawn_a_little_off_loads_as_the_exact_junction():
    """Four creases meeting at (50, 50), two drawn to (50, 49.98): 1.4 merge tolerances off.
    It was refused ("overlap with different assignments"): the short piece between the two
    vertices was credited to every line near it. It is the exact junction's pattern."""
    off = load_quiet(DATA / "synthetic_junction.svg")
    exact = load_quiet(DATA / "synthetic_junction_exact.svg")
    assert (off.num_vertices, off.num_edges, off.num_faces) == (5, 8, 4)
    assert (exact.num_vertices, exact.num_edges, exact.num_faces) == (5, 8, 4)
    assert edge_table(off, decimals=3) == edge_table(exact, decimals=3)
    assert sorted(off.assignments) == list("BBBBMMMV")


@pytest.mark.parametrize("gap", [0.0, 0.005, 0.014, 0.02, 0.028])
def test_junction_up_to_two_tolerances_off_is_one_vertex(tmp_path, gap):
    """Snapping moves a vertex by up to the tolerance (0.0141 here), so two vertices of one
    point can be up to twice that apart: they are one vertex, with no short edge."""
    y = 50 - gap
    body = (
        SQUARE
        + '<line x1="0" y1="0" x2="50" y2="50" stroke="red"/>'
        + '<line x1="50" y1="50" x2="100" y2="100" stroke="blue"/>'
        + f'<line x1="0" y1="100" x2="50" y2="{y}" stroke="red"/>'
        + f'<line x1="100" y1="0" x2="50" y2="{y}" stroke="red"/>'
    )
    cp = load_quiet(write(tmp_path, body))
    assert (cp.num_vertices, cp.num_edges, cp.num_faces) == (5, 8, 4)


@pytest.mark.parametrize("seed", range(20))
def test_creases_meeting_at_a_point_drawn_slightly_apart_never_overlap(tmp_path, seed):
    """Eight creases, mountain and valley by turns, each drawn to a point within one tolerance
    (0.0141) of the centre, as in Origami Simulator's files: one vertex, eight creases, and
    nothing reported. Before, most such junctions were refused as overlaps."""
    rng = np.random.default_rng(seed)
    ends = [(0, 0), (50, 0), (100, 0), (100, 50), (100, 100), (50, 100), (0, 100), (0, 50)]
    body = SQUARE
    for k, (x, y) in enumerate(ends):
        cx, cy = (50 + rng.uniform(-0.01, 0.01, size=2)).tolist()
        colour = "red" if k % 2 else "blue"
        body += f'<line x1="{x}" y1="{y}" x2="{cx!r}" y2="{cy!r}" stroke="{colour}"/>'
    cp = load_quiet(write(tmp_path, body))
    assert cp.num_vertices == 9
    assert (int((cp.assignments == "M").sum()), int((cp.assignments == "V").sum())) == (4, 4)


def test_overlapping_lines_follow_origami_simulators_rule_with_a_warning(tmp_path):
    """Origami Simulator keeps the later of coinciding edges in the order B, M, V, F, U, C
    (then path, line, rect, polygon, polyline, then the file's order): a valley drawn before
    a mountain on the same line still wins, over the part where they overlap."""
    body = (
        SQUARE
        + '<line x1="25" y1="25" x2="75" y2="75" stroke="blue"/>'
        + '<line x1="0" y1="0" x2="100" y2="100" stroke="red"/>'
    )
    cp, text = load_with_warnings(write(tmp_path, body))
    table = edge_table(cp)
    creases = {k: v for k, v in table.items() if v[0] != "B"}
    assert sorted(v[0] for v in creases.values()) == ["M", "M", "V"]
    middle = frozenset([(0.25, 0.75), (0.75, 0.25)])  # normalised, y up
    assert creases[middle] == ("V", round(math.pi, 9))
    assert (
        "<line> 2 (M -180 deg) and <line> 1 (V 180 deg): overlap with different assignments "
        "at the piece from (25, -25) to (75, -75); <line> 1's V is kept (Origami Simulator's "
        "rule: the later in the order B, M, V, F, U, C is kept" in text
    )


@pytest.mark.parametrize(
    ("first", "second", "kept"),
    [
        # same letter, different angles: the later element in the file
        ('<line x1="0" y1="0" x2="100" y2="100" stroke="red" stroke-opacity="0.5"/>',
         '<line x1="0" y1="0" x2="100" y2="100" stroke="red"/>', ("M", -math.pi)),
        # a line beats a path whatever the file's order (Origami Simulator reads paths first)
        ('<line x1="0" y1="0" x2="100" y2="100" stroke="red"/>',
         '<path d="M0 0 L100 100" stroke="red" stroke-opacity="0.5"/>', ("M", -math.pi)),
        # a cut beats a facet crease
        ('<line x1="0" y1="0" x2="100" y2="100" stroke="lime"/>',
         '<line x1="0" y1="0" x2="100" y2="100" stroke="yellow"/>', ("C", 0.0)),
    ],
)  # fmt: skip
def test_overlap_rule_order(tmp_path, first, second, kept):
    cp, text = load_with_warnings(write(tmp_path, SQUARE + first + second))
    diagonal = [v for v in edge_table(cp).values() if v[0] != "B"]
    assert diagonal == [(kept[0], round(kept[1], 9))]
    assert "overlap with different assignments" in text


def test_border_line_over_an_interior_crease_keeps_the_crease(tmp_path):
    """Origami Simulator keeps the crease (B comes first in its order); the old rule made the
    border win, and a border with paper on both sides became a cut."""
    body = (
        SQUARE
        + '<line x1="0" y1="0" x2="100" y2="100" stroke="red"/>'
        + '<line x1="0" y1="0" x2="100" y2="100" stroke="black"/>'
    )
    cp, text = load_with_warnings(write(tmp_path, body))
    assert "".join(sorted(cp.assignments)) == "BBBBM"
    assert "<line> 2 (B 0 deg) and <line> 1 (M -180 deg): overlap" in text


def test_a_slit_loads_as_a_free_hinge_with_a_warning(tmp_path):
    """A cut whose two ends are inside the paper, meeting no other cut, cannot open: Origami
    Simulator doubles it into two border bars on the same two vertices, which keeps both sides
    joined at both ends with no torsion spring, a free hinge."""
    body = (
        SQUARE
        + '<line x1="0" y1="50" x2="30" y2="50" stroke="red"/>'
        + '<line x1="30" y1="50" x2="70" y2="50" stroke="lime"/>'
        + '<line x1="70" y1="50" x2="100" y2="50" stroke="red"/>'
    )
    cp, text = load_with_warnings(write(tmp_path, body))
    assert cp.num_faces == 2
    slit = {k: v for k, v in edge_table(cp).items() if v[0] not in "BM"}
    assert slit == {frozenset([(0.3, 0.5), (0.7, 0.5)]): ("U", 0.0)}
    assert (
        "<line> 2: the piece from (30, -50) to (70, -50): is a cut whose ends are both inside "
        "the paper and meet no other cut (a slit), which cannot open; loaded as a free hinge "
        "(U, angle 0), as Origami Simulator does" in text
    )
    # a cut that reaches the paper's edge opens: it stays a cut, and nothing is said
    body = (
        SQUARE
        + '<line x1="0" y1="50" x2="70" y2="50" stroke="lime"/>'
        + '<line x1="70" y1="50" x2="100" y2="50" stroke="red"/>'
    )
    cp, text = load_with_warnings(write(tmp_path, body, name="q.svg"))
    assert "C" in cp.assignments and "U" not in cp.assignments
    assert text == ""


@pytest.mark.parametrize(
    ("stroke", "problem"),
    [
        ('stroke="url(#missing)"', "stroke 'url(#missing)' is a paint server"),
        ('stroke="#zzzzzz"', "stroke '#zzzzzz' is not a colour"),
        ('style="stroke: #12345"', "stroke '#12345' is not a colour"),
        ('stroke="currentColor"', "stroke currentColor, but no color is set on it or around it"),
        ('stroke="inherit"', "stroke 'inherit' is not read"),
    ],
)
def test_a_stroke_that_is_no_colour_is_skipped_with_a_warning(tmp_path, stroke, problem):
    """svgelements reads these as black: a crease across the paper became a cut."""
    body = SQUARE + f'<line x1="0" y1="0" x2="100" y2="100" {stroke}/>'
    cp, text = load_with_warnings(write(tmp_path, body))
    assert cp.num_faces == 1 and "".join(cp.assignments) == "BBBB"
    assert f"<line> 1: {problem}" in text and "skipped" in text


def test_current_color_takes_the_color_around_it(tmp_path):
    body = SQUARE + (
        '<g color="blue"><line x1="0" y1="0" x2="100" y2="100" stroke="currentColor"/></g>'
    )
    cp = load_quiet(write(tmp_path, body))
    assert "".join(sorted(cp.assignments)) == "BBBBV"


# ---------------------------------------------------------------------------------------------
# bad input


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ("", "no stroked line in a pattern colour"),
        ('<line x1="0" y1="0" x2="10" y2="0" stroke="cyan"/>', "no stroked line"),
        ('<line x1="0" y1="0" x2="10" y2="0" stroke="red"/>', "enclose no face"),
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
        # malformed path data: svgelements dropped the rest of the path without a word
        (
            SQUARE + '<path id="p" d="M 0 0 L" stroke="red"/>',
            "<path> number 0 of its kind (id 'p'): d='M 0 0 L' is malformed path data: "
            "'L' at character 6 has no numbers after it",
        ),
        (
            SQUARE + '<path d="M 0 0 L 100 100 50" stroke="red"/>',
            "<path> number 0 of its kind: d='M 0 0 L 100 100 50' is malformed path data: 'L' "
            "at character 6 has 3 numbers after it, not a multiple of 2",
        ),
        (
            SQUARE + '<path d="M 0 0 L 1e 100" stroke="red"/>',
            "'1e' at character 8 is not a number",
        ),
        (
            SQUARE + '<polyline points="0,0 100,100 50" stroke="red"/>',
            "<polyline> number 0 of its kind: points='0,0 100,100 50' has 5 numbers, an odd",
        ),
        # a far point: the drawing's size (and tolerance) follow it, the other lines vanish
        (
            SQUARE + '<line x1="0" y1="0" x2="100" y2="100" stroke="red"/>'
            '<line x1="0" y1="0" x2="1e20" y2="100" stroke="red"/>',
            "<line> 2: its point (1e+20, -100) spreads the lines over 1e+20, so 5 of the 6 "
            "lines are shorter than the merge tolerance",
        ),
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


def test_a_root_element_other_than_svg_is_refused(tmp_path):
    path = tmp_path / "page.svg"
    path.write_text(
        '<html><body><svg xmlns="http://www.w3.org/2000/svg">'
        '<line x1="0" y1="0" x2="1" y2="1" stroke="red"/></svg></body></html>'
    )
    with pytest.raises(PatternError) as info:
        io.load(path)
    assert str(info.value) == f"{path}: the root element is <html>, not <svg>: not an SVG file"


@pytest.mark.parametrize(
    ("d", "problem"),
    [
        ("M 0 0 L 10 0", None),
        ("m0 0 10 10z", None),  # implicit lineto after a relative move
        ("M1.5.5L2-3", None),  # numbers run together
        ("M0 0 a5 5 0 10 1 1z", None),  # arc flags run together
        ("M0,0 L1,1, L2,2", None),  # a comma before a command, as renderers accept
        ("", None),
        ("L0 0", "it starts with 'L' at character 0, not with a move (M or m)"),
        ("M0 0 a5 5 0 2 0 1 1", "'2 0 1 1' at character 12 is not an arc flag (0 or 1)"),
        ("M0 0 Z 5 5", "'5 5' at character 7 is not a path command"),
        ("M0 0 C1 1 2 2", "'C' at character 5 has 4 numbers after it, not a multiple of 6"),
        ("M0 0 L 1e+ 2", "'1e+' at character 7 is not a number"),
    ],
)
def test_path_data_is_checked_as_the_svg_grammar_says(d, problem):
    assert path_data_error(d) == problem


def test_missing_svg_names_the_path(tmp_path):
    with pytest.raises(PatternError, match="nope.svg"):
        io.load(tmp_path / "nope.svg")
