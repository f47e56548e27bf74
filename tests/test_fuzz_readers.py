"""Fuzzing the FOLD and SVG readers: any input gives a pattern or a PatternError, nothing else.

2,700 generated cases in all (hypothesis, derandomized so CI runs the same cases each time),
300 of them loose segments drawn a little off each other, for the noding.
"""

from __future__ import annotations

import copy
import math
import os
import tempfile
import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from origami_jax import CreasePattern, PatternError, PatternWarning, io, patterns
from origami_jax.io import from_fold_dict, pattern_from_segments, to_fold_dict

# FUZZ_RANDOM=1 draws new cases each run (for hunting); CI runs the fixed ones
SETTINGS = dict(
    deadline=None,
    derandomize="FUZZ_RANDOM" not in os.environ,
    suppress_health_check=[HealthCheck.too_slow],
)
FOLDER = Path(tempfile.mkdtemp(prefix="origami_jax_fuzz_"))


def outcome(read) -> CreasePattern | None:
    """Run a reader: a valid pattern, or None after a PatternError; anything else fails."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning but a PatternWarning is a bug
        warnings.simplefilter("ignore", PatternWarning)
        try:
            cp = read()
        except PatternError as exc:
            assert str(exc)  # a message
            return None
    assert isinstance(cp, CreasePattern)
    assert np.isfinite(cp.vertices).all()
    assert cp.num_faces > 0
    return cp


# ---------------------------------------------------------------------------------------------
# FOLD

numbers = st.one_of(
    st.integers(-5, 12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.5, -0.0, 1e308, -1e-320, 2**63]),
)
json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), numbers, st.text(max_size=4)),
    lambda inner: st.one_of(
        st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)
KEYS = [
    "vertices_coords",
    "edges_vertices",
    "edges_assignment",
    "edges_foldAngle",
    "faces_vertices",
    "file_frames",
    "frame_classes",
    "file_spec",
]
BASES = [
    to_fold_dict(patterns.miura_ori(2, 2)),
    to_fold_dict(patterns.single_crease()),
    to_fold_dict(patterns.seed_waterbomb()),
]


@st.composite
def mutated_fold(draw):
    data = copy.deepcopy(draw(st.sampled_from(BASES)))
    for _ in range(draw(st.integers(1, 3))):
        key = draw(st.sampled_from(KEYS))
        action = draw(st.sampled_from(["delete", "replace", "element", "inner"]))
        value = data.get(key)
        if action == "delete":
            data.pop(key, None)
        elif action == "replace" or not isinstance(value, list) or not value:
            data[key] = draw(json_values)
        elif action == "element":
            value[draw(st.integers(0, len(value) - 1))] = draw(json_values)
        else:
            row = value[draw(st.integers(0, len(value) - 1))]
            if isinstance(row, list) and row:
                row[draw(st.integers(0, len(row) - 1))] = draw(json_values)
    return data


@settings(max_examples=1000, **SETTINGS)
@given(mutated_fold())
def test_fold_reader_on_mutated_files(data):
    outcome(lambda: from_fold_dict(data))


@settings(max_examples=200, **SETTINGS)
@given(json_values)
def test_fold_reader_on_random_json(data):
    outcome(lambda: from_fold_dict(data))


@settings(max_examples=200, **SETTINGS)
@given(st.binary(max_size=200))
def test_fold_file_of_random_bytes(blob):
    load_written("fuzz.fold", blob)


def load_written(name: str, content: bytes | str) -> CreasePattern | None:
    """Write ``content`` to a file called ``name`` and read it with :func:`io.load`."""
    path = FOLDER / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return outcome(lambda: io.load(path))


# ---------------------------------------------------------------------------------------------
# SVG

clean_coordinate = st.one_of(
    st.integers(-5, 105).map(str),
    st.floats(-1e3, 1e3, allow_nan=False).map(repr),
    st.sampled_from(["0", "100", "50", "1e-320", "5px", "50%", "1e300"]),
)
coordinate = st.one_of(
    clean_coordinate, st.sampled_from(["nan", "inf", "1e400", "-", "", "abc", "1.2.3", "5 5"])
)
colour = st.sampled_from(
    [
        "black",
        "red",
        "#00f",
        "#ff0000",
        "green",
        "yellow",
        "magenta",
        "cyan",
        "none",
        "#zzz",
        "rgb(0,0,255)",
        "rgb(300,-1,0)",
        "url(#x)",
        "",
    ]
)
TRANSFORMS = st.sampled_from(["scale(0)", "rotate(30)", "matrix(1 0 0", "translate(5)", "x"])
opacity = st.sampled_from(["1", "0.5", "0", "-1", "2", "x", "50%", "nan", ""])


@st.composite
def svg_element(draw, coordinate=coordinate):
    tag = draw(st.sampled_from(["line", "rect", "polyline", "polygon", "path", "circle", "g"]))
    c = [draw(coordinate) for _ in range(6)]
    attrs = {
        "line": f'x1="{c[0]}" y1="{c[1]}" x2="{c[2]}" y2="{c[3]}"',
        "rect": f'x="{c[0]}" y="{c[1]}" width="{c[2]}" height="{c[3]}"',
        "polyline": f'points="{c[0]},{c[1]} {c[2]},{c[3]} {c[4]},{c[5]}"',
        "polygon": f'points="{c[0]},{c[1]} {c[2]},{c[3]} {c[4]},{c[5]}"',
        "path": f'd="M{c[0]} {c[1]} L{c[2]} {c[3]} Q{c[4]} {c[5]} {c[0]} {c[3]} Z"',
        "circle": f'cx="{c[0]}" cy="{c[1]}" r="{c[2]}"',
        "g": f'transform="{draw(TRANSFORMS)}"',
    }[tag]
    style = f'stroke="{draw(colour)}" stroke-opacity="{draw(opacity)}"'
    if tag == "g":
        return f"<g {attrs} {style}><line x1='0' y1='0' x2='{c[2]}' y2='{c[3]}'/></g>"
    return f"<{tag} {attrs} {style}/>"


SQUARE = '<rect x="0" y="0" width="100" height="100" stroke="black" fill="none"/>'


@settings(max_examples=600, **SETTINGS)
@given(st.lists(svg_element(clean_coordinate), max_size=8), st.booleans())
def test_svg_reader_on_generated_drawings(elements, with_square):
    check_drawing(elements, with_square)


@settings(max_examples=200, **SETTINGS)
@given(st.lists(svg_element(), max_size=4), st.booleans())
def test_svg_reader_on_drawings_with_bad_numbers(elements, with_square):
    check_drawing(elements, with_square)


def check_drawing(elements, with_square):
    body = (SQUARE if with_square else "") + "".join(elements)
    cp = load_written(
        "fuzz.svg", f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100">{body}</svg>'
    )
    if cp is not None:
        assert all(math.isfinite(a) for a in cp.fold_angles)


@settings(max_examples=200, **SETTINGS)
@given(st.text(max_size=300))
def test_svg_file_of_random_text(text):
    load_written("fuzz.svg", text)


# ---------------------------------------------------------------------------------------------
# noding: lines drawn a little off each other (a grid, jittered at the tolerance's scale)


@st.composite
def near_segments(draw):
    n = draw(st.integers(1, 16))
    ends = draw(st.lists(st.tuples(st.integers(0, 3), st.integers(0, 3)), min_size=2 * n,
                         max_size=2 * n))  # fmt: skip
    scale = draw(st.sampled_from([0.0, 1e-7, 1e-6, 3e-6, 1e-5]))
    jitter = draw(st.lists(st.floats(-1, 1), min_size=4 * n, max_size=4 * n))
    pts = np.array(ends, float).reshape(n, 2, 2) + scale * np.array(jitter).reshape(n, 2, 2)
    letters = draw(st.lists(st.sampled_from("BMVFUC"), min_size=n, max_size=n))
    ranked = draw(st.booleans())
    return pts, letters, ranked


@settings(max_examples=300, **SETTINGS)
@given(near_segments())
def test_noding_near_coincident_lines_gives_a_pattern_or_a_clear_error(case):
    """Snapping never fails as noding (every piece comes from a segment, the rounds settle)."""
    pts, letters, ranked = case
    angles = [{"M": -1.0, "V": 1.0}.get(a, 0.0) for a in letters]
    names = [f"s{k}" for k in range(len(letters))]
    precedence = list(range(len(letters))) if ranked else None

    def read():
        try:
            return pattern_from_segments(
                pts[:, 0], pts[:, 1], letters, angles, names, precedence=precedence
            )
        except PatternError as exc:
            assert "noding" not in str(exc) and "settle" not in str(exc), str(exc)
            raise

    outcome(read)
