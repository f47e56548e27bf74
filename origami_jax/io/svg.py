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
no stroke, and strokes of another colour (white, grey, cyan, ...), are skipped with a
:class:`~origami_jax.PatternWarning`. The drawing's ``y`` axis points down; the pattern's is
``-y``, so the pattern seen from ``+z`` looks like the drawing on screen. Units are the
drawing's user units. The segments then go to :func:`~origami_jax.io.planar.pattern_from_segments`
(merging, splitting at crossings, faces, holes, triangulation of faces with holes).
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

__all__ = ["load_svg", "save_svg", "to_svg", "stroke_assignment"]

CURVE_PIECES_PER_DIAGONAL = 100
# drawings are imprecise: end points within 1e-4 of the diagonal merge (0.1 px on 1000 px)
SVG_TOLERANCE = 1e-4
# hue in degrees -> FOLD letter (Origami Simulator's colours)
_HUES = {0.0: "M", 60.0: "F", 120.0: "C", 240.0: "V", 300.0: "U", 360.0: "M"}


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


def _element_name(el, k: int) -> str:
    tag = type(el).__name__.lower().replace("simpleline", "line")
    ident = getattr(el, "id", None)
    return f"<{tag}> {k}" + (f" (id {ident!r})" if ident else "")


def load_svg(path: str | os.PathLike, *, tolerance: float = SVG_TOLERANCE) -> CreasePattern:
    """The crease pattern drawn in an SVG file (see the module docstring for the conventions).

    Args:
      path: the ``.svg`` file.
      tolerance: end points closer than this fraction of the drawing's diagonal merge; a line
        end touching nothing joins a line within ``GAP_FACTOR`` (10) times that.

    Raises:
      PatternError: the file is missing or not SVG, a value cannot be read, or the drawing does
        not make a pattern; the message starts with the path.
    """
    import svgelements  # imported here: only SVG input needs it

    path = FilePath(path)
    _check_numbers(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # svgelements warns on unknown elements
            svg = svgelements.SVG.parse(str(path), reify=True)
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


def _check_numbers(path: FilePath) -> None:
    """Refuse geometry that is not a number: svgelements would read it as 0 without a word."""
    try:
        root = ElementTree.parse(path).getroot()
    except FileNotFoundError:
        raise PatternError(f"{path}: no such file") from None
    except (OSError, ElementTree.ParseError, UnicodeDecodeError) as exc:
        raise PatternError(f"{path}: cannot be read as SVG ({exc})") from None
    counts: dict[str, int] = {}
    for el in root.iter():
        tag = el.tag.rsplit("}", 1)[-1]
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
        if points is not None and not all(
            _NUMBER_RE.fullmatch(t) for t in re.split(r"[\s,]+", points.strip()) if t
        ):
            raise PatternError(f"{what}: points={el.get('points')!r} are not numbers")
        if el.get("d") is not None and not _PATH_DATA.fullmatch(el.get("d")):
            raise PatternError(f"{what}: d={el.get('d')[:40]!r} is not path data")


def _pattern(svg, svgelements, name: str, tolerance: float) -> CreasePattern:
    drawn = []  # (sample points of each segment, letter, angle, element name)
    shapes = (el for el in svg.elements() if isinstance(el, svgelements.Shape))
    for k, el in enumerate(shapes):
        what = _element_name(el, k)
        stroke = el.stroke
        if stroke is None or stroke.value is None:
            continue
        letter = stroke_assignment((stroke.red / 255, stroke.green / 255, stroke.blue / 255))
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
        drawn.append((_segments(svgelements.Path(el), what), letter, angle, what))
    samples = [pts for segments, _, _, _ in drawn for pts in segments]
    if not samples:
        raise PatternError("no stroked line in a pattern colour")
    points = np.concatenate(samples)
    diagonal = float(np.linalg.norm(points.max(0) - points.min(0)))
    starts, ends, letters, angles, names = [], [], [], [], []
    for segments, letter, angle, what in drawn:
        for pts in segments:
            pts = _flatten(pts, diagonal)
            starts.append(pts[:-1])
            ends.append(pts[1:])
            n = len(pts) - 1
            letters += [letter] * n
            angles += [angle] * n
            names += [what] * n
    flip = np.array([1.0, -1.0])  # SVG's y points down
    return pattern_from_segments(
        np.concatenate(starts) * flip,
        np.concatenate(ends) * flip,
        letters,
        angles,
        names,
        tolerance=tolerance,
        name=name,
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
