"""Reading crease patterns drawn as SVG, with Origami Simulator's conventions.

Every stroked shape is read: ``<line>``, ``<polyline>``, ``<polygon>``, ``<rect>``, ``<path>``
(``Z`` closes it), ``<circle>`` and ``<ellipse>``, with the transforms of their groups, and
colours given as attributes, in ``style="..."`` or in ``<style>`` sheets (by svgelements).
Curves are replaced by straight pieces, about 100 per drawing diagonal of length (at least 4
per curve). The stroke colour gives the assignment, by hue:

=================  ==========  ===============================================
colour             letter      meaning
=================  ==========  ===============================================
black (dark)       ``B``       border
red                ``M``       mountain, target ``-opacity * 180`` degrees
blue               ``V``       valley, target ``+opacity * 180`` degrees
yellow             ``F``       facet (triangulation) crease, target flat
green              ``C``       cut
magenta            ``U``       undriven hinge (no torsion spring)
=================  ==========  ===============================================

The opacity is the stroke's: ``stroke-opacity`` times ``opacity`` (1 when absent). Shapes with
no stroke are passed over. Strokes of another colour (white, grey, cyan, ``transparent``, ...)
and strokes that are no colour at all (``url(#gradient)``, ``#zzzzzz``, ``currentColor`` with no
``color`` set, ``inherit``: svgelements reads these as black, a border) are skipped with a
:class:`~origami_jax.PatternWarning` naming the element. The drawing's ``y`` axis points down;
the pattern's is ``-y``, so the pattern seen from ``+z`` looks like the drawing on screen. Units
are the drawing's user units. The segments then go to
:func:`~origami_jax.io.planar.pattern_from_segments` (merging, splitting at crossings, faces,
holes, triangulation of faces with holes, slits loaded as free hinges).

Where lines of different assignments or angles overlap, the reader does what Origami
Simulator's import does: it lists the edges by kind (B, M, V, F, U, C), each kind by element
(path, line, rect, polygon, polyline), each in the file's order, and of edges that coincide keeps
the last. A :class:`~origami_jax.PatternWarning` names both lines and this rule.

Malformed input is a :class:`~origami_jax.PatternError` naming the element: a root element
other than ``<svg>``, a geometry attribute that is not a number, path data that breaks the SVG
grammar (renderers draw up to the fault; svgelements would drop the rest without a word), a
``points`` list of odd length.
"""

from __future__ import annotations

import colorsys
import math
import os
import re
import warnings
import xml.etree.ElementTree as ElementTree
from pathlib import Path as FilePath

import numpy as np

from origami_jax.io.fold import atomic_path
from origami_jax.io.planar import MAX_COORDINATE, pattern_from_segments
from origami_jax.pattern import CreasePattern, PatternError, PatternWarning

__all__ = ["load_svg", "save_svg", "to_svg", "stroke_assignment", "path_data_error"]

CURVE_PIECES_PER_DIAGONAL = 100
# drawings are imprecise: end points within 1e-4 of the diagonal merge (0.1 px on 1000 px)
SVG_TOLERANCE = 1e-4
# hue in degrees -> FOLD letter (Origami Simulator's colours)
_HUES = {0.0: "M", 60.0: "F", 120.0: "C", 240.0: "V", 300.0: "U", 360.0: "M"}
# Origami Simulator's import lists the edges by kind (B, M, V, F, U, C), each kind by element
# (path, line, rect, polygon, polyline; it reads no circle or ellipse), each in document order,
# then keeps the last of edges that coincide: overlaps go to the later in this order
_KIND_ORDER = "BMVFUC"
_ELEMENT_ORDER = ("path", "line", "rect", "polygon", "polyline", "circle", "ellipse")
OVERLAP_RULE = (
    "Origami Simulator's rule: the later in the order B, M, V, F, U, C is kept, then the later "
    "element in the order path, line, rect, polygon, polyline, then the later in the file"
)


def stroke_assignment(rgb: tuple[float, float, float]) -> str | None:
    """The FOLD letter of a stroke colour (r, g, b in [0, 1]), or None for an unknown colour.

    Dark colours (value < 0.25) are borders; saturated colours (saturation >= 0.5, value >=
    0.25) within 30 degrees of hue of red, yellow, green, blue or magenta are M, F, C, V, U.

    Example:
      >>> stroke_assignment((1.0, 0.0, 0.0)), stroke_assignment((0.0, 0.5, 0.0))
      ('M', 'C')
    """
    h, s, v = colorsys.rgb_to_hsv(*rgb)
    if v < 0.25:
        return "B"
    if s < 0.5:
        return None
    hue = 360.0 * h
    nearest = min(_HUES, key=lambda c: abs(c - hue))
    return _HUES[nearest] if abs(nearest - hue) <= 30.0 else None


# SVG.parse's currentColor outside any `color`: no colour, so that it can be told apart from black
_NO_CURRENT_COLOR = "currentColor with no color set"
_HEX_COLOUR = re.compile(r"#(?:[0-9a-fA-F]{3}|[0-9a-fA-F]{4}|[0-9a-fA-F]{6}|[0-9a-fA-F]{8})")


def _colour_problem(raw) -> str | None:
    """Why a stroke value (after styles and inheritance) is not a colour svgelements resolves,
    or None; svgelements reads every such value as black."""
    import svgelements

    black = svgelements.Color.rgb_to_int(0, 0, 0)  # what svgelements gives an unknown keyword
    text = str(raw).strip()
    if text == _NO_CURRENT_COLOR or text.lower() == "currentcolor":
        return "stroke currentColor, but no color is set on it or around it"
    if text.lower() == "none" or _HEX_COLOUR.fullmatch(text):
        return None
    for pattern in (
        svgelements.REGEX_COLOR_RGB,
        svgelements.REGEX_COLOR_RGB_PERCENT,
        svgelements.REGEX_COLOR_HSL,
    ):
        if pattern.fullmatch(text):
            return None
    name = text.replace(" ", "").lower()
    if name.isalpha() and (name == "black" or svgelements.Color.parse_color_lookup(name) != black):
        return None  # a colour keyword (every keyword but black is read as a colour not black)
    if text.lower() == "inherit":
        return "stroke 'inherit' is not read (give the colour itself)"
    if text.lower().startswith("url("):
        return f"stroke {text[:40]!r} is a paint server (gradient or pattern), not a colour"
    return f"stroke {text[:40]!r} is not a colour"


def _opacity(values: dict, what: str) -> float:
    out = 1.0
    for key in ("stroke-opacity", "opacity"):
        raw = values.get(key)
        if raw is None:
            continue
        text = str(raw).strip()
        try:
            x = float(text[:-1]) / 100 if text.endswith("%") else float(text)
        except ValueError:
            raise PatternError(f"{what}: {key} {text!r} is not a number") from None
        if not math.isfinite(x):
            raise PatternError(f"{what}: {key} {text!r} is not a finite number")
        out *= min(max(x, 0.0), 1.0)
    return out


def _tag(el) -> str:
    return type(el).__name__.lower().replace("simpleline", "line")


def _element_name(el, k: int) -> str:
    ident = getattr(el, "id", None)
    return f"<{_tag(el)}> {k}" + (f" (id {ident!r})" if ident else "")


def load_svg(path: str | os.PathLike, *, tolerance: float = SVG_TOLERANCE) -> CreasePattern:
    """The crease pattern drawn in an SVG file (see the module docstring for the conventions).

    Args:
      path: the ``.svg`` file.
      tolerance: end points closer than this fraction of the drawing's diagonal merge (and
        two vertices of one junction up to twice that); a line end touching nothing joins a
        line within ``GAP_FACTOR`` (10) times that (see :mod:`origami_jax.io.planar`).

    Raises:
      PatternError: the file is missing or not SVG, a value or path data cannot be read, or the
        drawing does not make a pattern; the message starts with the path.
    """
    import svgelements  # imported here: only SVG input needs it

    path = FilePath(path)
    _check_numbers(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # svgelements warns on unknown elements
            svg = svgelements.SVG.parse(str(path), reify=True, color=_NO_CURRENT_COLOR)
    except FileNotFoundError:
        raise PatternError(f"{path}: no such file") from None
    except (OSError, ElementTree.ParseError) as exc:
        raise PatternError(f"{path}: cannot be read as SVG ({exc})") from None
    except Exception as exc:  # svgelements raises assorted errors on malformed values
        raise PatternError(f"{path}: cannot be read as SVG ({type(exc).__name__}: {exc})") from None
    try:
        return _pattern(svg, svgelements, path.stem, tolerance)
    except PatternError as exc:
        raise PatternError(f"{path}: {exc}") from None


_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_LENGTH = re.compile(rf"\s*{_NUMBER}\s*(?:px|pt|pc|mm|cm|in|em|ex|%)?\s*")
_NUMBER_RE = re.compile(_NUMBER)
_PATH_DATA = re.compile(r"[MmLlHhVvCcSsQqTtAaZz0-9eE+\-.,\s]*")
_LENGTH_ATTRIBUTES = ("x", "y", "x1", "y1", "x2", "y2", "width", "height", "cx", "cy", "r")
_SHAPES = ("line", "rect", "polyline", "polygon", "path", "circle", "ellipse")
# numbers each path command takes (SVG 1.1, 8.3); arcs' 4th and 5th are flags, "0" or "1"
_PATH_ARGUMENTS = {"M": 2, "L": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "T": 2, "A": 7, "Z": 0}
_SEPARATOR = re.compile(r"[\s,]*")
_SPACE = re.compile(r"\s*")


def path_data_error(d: str) -> str | None:
    """What is wrong with SVG path data ``d`` (the first fault, with its position), or None.

    Renderers draw a path up to its first fault and drop the rest; svgelements drops what it
    cannot read without a word, so the reader refuses such a path instead.

    Example:
      >>> path_data_error("M 0 0 L 10 0"), path_data_error("M 0 0 L")
      (None, "'L' at character 6 has no numbers after it")
    """
    i = _SPACE.match(d, 0).end()
    if i == len(d):
        return None  # empty path data draws nothing (SVG 1.1, 8.3.9)
    if d[i] not in "Mm":
        return f"it starts with {d[i]!r} at character {i}, not with a move (M or m)"
    while True:
        i = _SPACE.match(d, i).end()
        if i == len(d):
            return None
        command = d[i]
        if command.upper() not in _PATH_ARGUMENTS:
            return f"{d[i : i + 8]!r} at character {i} is not a path command"
        start, i = i, i + 1
        count = _PATH_ARGUMENTS[command.upper()]
        if count == 0:
            continue
        numbers = 0
        while True:
            j = (_SPACE if numbers == 0 else _SEPARATOR).match(d, i).end()
            if j == len(d) or not (d[j].isdigit() or d[j] in "+-."):
                break
            if command.upper() == "A" and numbers % 7 in (3, 4):
                if d[j] not in "01":
                    return f"{d[j : j + 8]!r} at character {j} is not an arc flag (0 or 1)"
                i, numbers = j + 1, numbers + 1
                continue
            match = _NUMBER_RE.match(d, j)
            end = match.end() if match else j
            if match is None or (end < len(d) and d[end] in "eE"):
                token = re.match(r"[^\s,]*", d[j:]).group(0)[:12]
                return f"{token!r} at character {j} is not a number"
            i, numbers = end, numbers + 1
        i = _SEPARATOR.match(d, i).end()  # a comma before the next command: renderers accept it
        if numbers == 0:
            return f"{command!r} at character {start} has no numbers after it"
        if numbers % count:
            return (
                f"{command!r} at character {start} has {numbers} numbers after it, not a "
                f"multiple of {count}"
            )


def _check_numbers(path: FilePath) -> None:
    """Refuse geometry that is not a number: svgelements would read it as 0 without a word, or
    drop it; and a file whose root element is not ``<svg>``."""
    try:
        root = ElementTree.parse(path).getroot()
    except FileNotFoundError:
        raise PatternError(f"{path}: no such file") from None
    except (OSError, ElementTree.ParseError, UnicodeDecodeError) as exc:
        raise PatternError(f"{path}: cannot be read as SVG ({exc})") from None
    root_tag = root.tag.rsplit("}", 1)[-1]
    if root_tag != "svg":
        raise PatternError(f"{path}: the root element is <{root_tag}>, not <svg>: not an SVG file")
    counts: dict[str, int] = {}
    for el in root.iter():
        tag = el.tag.rsplit("}", 1)[-1] if isinstance(el.tag, str) else ""
        if tag not in _SHAPES:
            continue
        k = counts.get(tag, 0)
        counts[tag] = k + 1
        what = f"{path}: <{tag}> number {k} of its kind" + (
            f" (id {el.get('id')!r})" if el.get("id") else ""
        )
        for key in _LENGTH_ATTRIBUTES:
            value = el.get(key)
            if value is not None and not _LENGTH.fullmatch(value):
                raise PatternError(f"{what}: {key}={value!r} is not a length")
        points = el.get("points")
        if points is not None:
            tokens = [t for t in re.split(r"[\s,]+", points.strip()) if t]
            if not all(_NUMBER_RE.fullmatch(t) for t in tokens):
                raise PatternError(f"{what}: points={points!r} are not numbers")
            if len(tokens) % 2:
                raise PatternError(
                    f"{what}: points={points[:40]!r} has {len(tokens)} numbers, an odd count "
                    "(x and y of each point)"
                )
        d = el.get("d")
        if d is not None:
            if not _PATH_DATA.fullmatch(d):
                raise PatternError(f"{what}: d={d[:40]!r} is not path data")
            problem = path_data_error(d)
            if problem:
                raise PatternError(f"{what}: d={d[:40]!r} is malformed path data: {problem}")


def _pattern(svg, svgelements, name: str, tolerance: float) -> CreasePattern:
    drawn = []  # (sample points of each segment, letter, angle, element name, precedence)
    shapes = (el for el in svg.elements() if isinstance(el, svgelements.Shape))
    for k, el in enumerate(shapes):
        what = _element_name(el, k)
        stroke = el.stroke
        if stroke is None or stroke.value is None:
            continue
        problem = _colour_problem(el.values.get("stroke"))
        if problem:
            # svgelements reads a colour it cannot resolve as black, a border: skip it instead
            warnings.warn(f"{what}: {problem}; skipped", PatternWarning, stacklevel=3)
            continue
        letter = stroke_assignment((stroke.red / 255, stroke.green / 255, stroke.blue / 255))
        if stroke.alpha == 0:
            letter = None  # "transparent": drawn in no colour
        if letter is None:
            warnings.warn(
                f"{what}: stroke colour {stroke.hex} is not one of the pattern colours "
                "(black, red, blue, yellow, green, magenta); skipped",
                PatternWarning,
                stacklevel=3,
            )
            continue
        opacity = _opacity(el.values, what)
        angle = {"M": -math.pi * opacity, "V": math.pi * opacity}.get(letter, 0.0)
        # Origami Simulator's order as one number: kind, then element, then the file's order
        tag = _tag(el)
        element = _ELEMENT_ORDER.index(tag) if tag in _ELEMENT_ORDER else len(_ELEMENT_ORDER)
        rank = (_KIND_ORDER.index(letter) * (len(_ELEMENT_ORDER) + 1) + element) * (1 << 32) + k
        drawn.append((_segments(svgelements.Path(el), what), letter, angle, what, rank))
    samples = [pts for segments, *_ in drawn for pts in segments]
    if not samples:
        raise PatternError("no stroked line in a pattern colour")
    points = np.concatenate(samples)
    diagonal = float(np.linalg.norm(points.max(0) - points.min(0)))
    starts, ends, letters, angles, names, ranks = [], [], [], [], [], []
    for segments, letter, angle, what, rank in drawn:
        for pts in segments:
            pts = _flatten(pts, diagonal)
            starts.append(pts[:-1])
            ends.append(pts[1:])
            n = len(pts) - 1
            letters += [letter] * n
            angles += [angle] * n
            names += [what] * n
            ranks += [rank] * n
    flip = np.array([1.0, -1.0])  # SVG's y points down
    return pattern_from_segments(
        np.concatenate(starts) * flip,
        np.concatenate(ends) * flip,
        letters,
        angles,
        names,
        tolerance=tolerance,
        name=name,
        precedence=ranks,
        precedence_rule=OVERLAP_RULE,
    )


def _segments(path, what: str) -> list[np.ndarray]:
    """Each drawn segment of a path as sample points: 2 for a line, more for a curve."""
    import svgelements

    out = []
    for seg in path:
        if isinstance(seg, svgelements.Move) or seg.start is None or seg.end is None:
            continue
        if isinstance(seg, (svgelements.Line, svgelements.Close)):
            pts = np.array([[seg.start.x, seg.start.y], [seg.end.x, seg.end.y]], np.float64)
        else:  # a curve: sampled densely here, thinned in _flatten once the size is known
            pts = np.asarray(seg.npoint(np.linspace(0.0, 1.0, 257)), np.float64)
        if not (np.abs(pts) <= MAX_COORDINATE).all():
            raise PatternError(f"{what}: a coordinate is not finite or beyond {MAX_COORDINATE:g}")
        out.append(pts)
    return out


def _flatten(pts: np.ndarray, diagonal: float) -> np.ndarray:
    """A curve's samples thinned to about CURVE_PIECES_PER_DIAGONAL pieces per diagonal."""
    if len(pts) == 2 or diagonal == 0.0:
        return pts
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    n = int(np.clip(math.ceil(CURVE_PIECES_PER_DIAGONAL * length / diagonal), 4, len(pts) - 1))
    return pts[np.round(np.linspace(0, len(pts) - 1, n + 1)).astype(int)]


_COLOURS = {
    "B": "#000000",
    "M": "#ff0000",
    "V": "#0000ff",
    "F": "#ffff00",
    "J": "#ffff00",
    "C": "#00ff00",
    "U": "#ff00ff",
}


def to_svg(pattern: CreasePattern, *, width: float = 1000.0) -> str:
    """The crease pattern as SVG text with Origami Simulator's conventions (the inverse of
    :func:`load_svg`): one ``<line>`` per edge, coloured by assignment, stroke opacity
    ``|fold angle| / pi`` for creases; ``J`` edges are drawn as facet (yellow) lines. The
    drawing is scaled to ``width`` user units, ``y`` pointing down.
    """
    xy = pattern.vertices[:, :2]
    lo, hi = xy.min(0), xy.max(0)
    scale = width / max(float((hi - lo).max()), 1e-300)
    pts = (xy - lo) * scale
    pts[:, 1] = (hi[1] - lo[1]) * scale - pts[:, 1]  # y down
    w, h = ((hi - lo) * scale).tolist()
    pts = pts.tolist()
    lines = []
    for (a, b), letter, rho in zip(
        pattern.edges.tolist(), pattern.assignments, pattern.fold_angles, strict=True
    ):
        opacity = abs(float(rho)) / math.pi if letter in "MVU" else 1.0
        lines.append(
            f'<line x1="{pts[a][0]!r}" y1="{pts[a][1]!r}" x2="{pts[b][0]!r}" y2="{pts[b][1]!r}" '
            f'stroke="{_COLOURS[letter]}" stroke-opacity="{opacity!r}"/>'
        )
    body = "\n  ".join(lines)
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{w!r}" height="{h!r}" '
        f'viewBox="0 0 {w!r} {h!r}">\n  {body}\n</svg>\n'
    )


def save_svg(path: str | os.PathLike, pattern: CreasePattern, *, width: float = 1000.0) -> None:
    """Write :func:`to_svg` of a pattern (or of a result's pattern) to a file, atomically."""
    pattern = getattr(pattern, "pattern", pattern)
    with atomic_path(path) as tmp:
        tmp.write_text(to_svg(pattern, width=width), encoding="utf-8")
