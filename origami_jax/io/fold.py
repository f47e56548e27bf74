"""Reading and writing FOLD 1.2 files (``.fold``, JSON).

Reading (:func:`from_fold_dict`, :func:`load_fold`)
----------------------------------------------------

The keys read are ``vertices_coords``, ``edges_vertices``, ``edges_assignment``,
``edges_foldAngle`` (degrees in FOLD, radians in :class:`~origami_jax.CreasePattern`; the pre-1.1
spelling ``edges_foldAngles`` is accepted too) and ``faces_vertices``; everything else is ignored.

* A missing ``edges_foldAngle`` gives the pattern's defaults, -180 degrees for ``M``, +180 for
  ``V``, 0 otherwise; a ``null`` entry gives that default for its edge.
* A missing ``edges_assignment`` is left to the pattern: ``B`` on edges with one face, ``U``
  elsewhere.
* A missing ``edges_vertices`` (with no ``edges_assignment`` or ``edges_foldAngle``) is computed
  from the sides of the faces.
* A missing ``faces_vertices`` (in a flat frame) is computed from the edges: the faces of their
  planar arrangement (:func:`~origami_jax.io.planar.pattern_from_segments`: crossing edges are
  split, end points within 1e-9 of the diagonal merge, holes are regions bounded by ``B``
  edges only inside another face; a border edge along a crease wins, with a warning, and other
  edges that overlap with different assignments are an error naming both). The vertices keep
  their order, new crossing points last.
* Edges given twice are merged (a :class:`~origami_jax.PatternWarning`); twice with different
  assignments or fold angles is an error naming both.
* ``J`` (join) edges are facet creases; ``C`` (cut) edges split the paper. A cut whose two ends
  are inside the paper and meet no other cut (a slit) cannot open: it is loaded as Origami
  Simulator loads it, as a free hinge (``U``, angle 0), with a warning.
* Coordinates are ``[x, y]`` or ``[x, y, z]``. A frame that is 3-D, or flat with faces turned
  clockwise (flipped over), is a **folded form**: it is unfolded onto the plane face by face
  (breadth first over shared edges, separate pieces side by side) to give the crease pattern,
  and its own positions become the pattern's ``start``, from which :func:`~origami_jax.fold`
  starts. Without ``edges_foldAngle``, its ``M`` and ``V`` creases' targets are the angles they
  have in it (so the folded form is its own equilibrium; mirrored, if most of its creases fold
  against their letters), not the default +-180 degrees. A folded form that does not unfold to
  a flat sheet (a non-planar face, or a vertex that two faces put at different places, as in a
  closed box) is an error naming them.
* A missing ``file_spec``, or one that is not a number from 1 to 1.2, gives a warning.

Frames: frame 0 is the top level, frame ``k >= 1`` is ``file_frames[k - 1]``. A frame with
``frame_inherit: true`` takes the keys it does not set from its ``frame_parent`` (frame 0 when the
parent is not given), recursively. Without an explicit ``frame``, the top level is read, unless
its ``frame_classes`` say ``foldedForm`` (and not ``creasePattern``) and some frame of
``file_frames`` has the class ``creasePattern``: then the first such frame is read.

Every malformed input raises :class:`~origami_jax.PatternError` naming the key and element, for
example ``"edges_vertices[3]: vertex index 9 is out of range (the frame has 9 vertices)"``; errors
found in a frame other than the top level start with ``"frame k (file_frames[k-1]): "`` and those
of :func:`load_fold` with the file's path.

Writing (:func:`to_fold_dict`, :func:`save_fold`)
--------------------------------------------------

The top level is the crease pattern: ``file_spec`` 1.2, ``file_creator`` ``"origami_jax"``,
``file_classes`` ``["singleModel"]``, ``frame_title`` (the pattern's name), ``frame_classes``
``["creasePattern"]``, ``frame_attributes`` ``["2D"]`` (plus ``"cuts"`` / ``"joins"`` when the
pattern has ``C`` / ``J`` edges, as the spec recommends), 2-D ``vertices_coords``,
``edges_vertices``, ``edges_assignment``, ``edges_foldAngle`` (degrees, always written) and the
counterclockwise ``faces_vertices``.

With a simulation result (any object with ``pattern``, ``positions`` (V_mesh, 3) and
``fold_angles`` (E_mesh,) radians, in the order of ``pattern.mesh``), ``file_frames`` holds one
frame of class ``foldedForm``, attributes ``["3D"]``, and after it one more per state of the
result's ``frames`` (the path a fold followed from flat: the simulated fold angles frame by
frame, an animation), each titled with its fold percent:

* when the mesh has as many vertices as the pattern (no vertex was split by a cut), the frame has
  ``frame_parent: 0``, ``frame_inherit: true`` and only ``vertices_coords`` (3-D) and
  ``edges_foldAngle`` (simulated, degrees, of mesh edges ``0 .. E-1``, which are the pattern's
  edges);
* otherwise it has ``frame_parent: 0``, ``frame_inherit: false`` and the mesh's own topology:
  ``vertices_coords`` (3-D, mesh vertices), ``edges_vertices`` (mesh edges), ``edges_assignment``
  (the source pattern edge's letter; ``B`` for both sides of a cut, which are border edges of the
  split mesh; ``J`` for triangulation edges, the spec's letter for edges added for simulation,
  and then ``"joins"`` is added to ``frame_attributes``), ``edges_foldAngle`` (simulated,
  degrees) and ``faces_vertices`` (the mesh triangles).

Simulated fold angles of border edges (mesh role ``"border"``) are written as 0. Simulated angles
are written as they are, so a mountain that is not folded yet may carry a small positive angle.

Files are written atomically: the text goes to a temporary file in the same folder, which then
replaces the target (:func:`os.replace`); on any error the temporary file is removed and an
existing target is left untouched.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import json
import math
import numbers
import os
import secrets
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from origami_jax.io.planar import pattern_from_segments, slit_edges
from origami_jax.kinematics import fold_angles_np
from origami_jax.pattern import (
    ASSIGNMENTS,
    MAX_COORDINATE,
    CreasePattern,
    PatternError,
    PatternWarning,
    signed_area,
)

__all__ = ["from_fold_dict", "load_fold", "to_fold_dict", "save_fold"]

FILE_SPEC = 1.2
FILE_CREATOR = "origami_jax"

# the frame keys read; inheritance (frame_inherit) covers every key except these
_NOT_INHERITED = ("frame_parent", "frame_inherit")
_DEFAULT_DEGREES = {"M": -180.0, "V": 180.0}
# FOLD coordinates are exact: only end points within 1e-9 of the diagonal merge
FOLD_TOLERANCE = 1e-9


# ---------------------------------------------------------------------------------------------
# small type checks (JSON values: int, float, str, list, dict, bool, None)


def _is_number(x: Any) -> bool:
    return isinstance(x, (numbers.Real, np.integer, np.floating)) and not isinstance(
        x, (bool, np.bool_)
    )


def _is_index(x: Any) -> bool:
    if isinstance(x, (bool, np.bool_)):
        return False
    if isinstance(x, (numbers.Integral, np.integer)):
        return True
    return isinstance(x, (float, np.floating)) and math.isfinite(x) and float(x).is_integer()


def _type_name(x: Any) -> str:
    if x is None:
        return "null"
    if isinstance(x, (bool, np.bool_)):
        return "a boolean"
    if isinstance(x, str):
        return f"the string {x!r}" if len(x) <= 20 else "a string"
    if isinstance(x, dict):
        return "an object"
    if isinstance(x, (list, tuple, np.ndarray)):
        return "an array"
    if _is_number(x):
        return f"the number {x!r}"
    return type(x).__name__


def _array(value: Any, key: str) -> list:
    """A JSON array (list, tuple or numpy array) as a list, or a PatternError naming ``key``."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return list(value)
    raise PatternError(f"{key}: expected an array, got {_type_name(value)}")


def _float(x: Any, what: str) -> float:
    if not _is_number(x):
        raise PatternError(f"{what}: expected a number, got {_type_name(x)}")
    try:
        f = float(x)
    except OverflowError:
        f = math.inf
    if not math.isfinite(f):
        raise PatternError(f"{what}: expected a finite number, got {x!r}")
    return f


# ---------------------------------------------------------------------------------------------
# frames


def _frames(data: dict) -> list[dict]:
    if "file_frames" not in data:
        return []
    frames = _array(data["file_frames"], "file_frames")
    for i, fr in enumerate(frames):
        if not isinstance(fr, dict):
            raise PatternError(
                f"file_frames[{i}]: expected an object (a frame), got {_type_name(fr)}"
            )
    return frames


def _frame_name(k: int) -> str:
    return "the top level (frame 0)" if k == 0 else f"frame {k} (file_frames[{k - 1}])"


def _classes(frame: dict, k: int) -> list[str]:
    if "frame_classes" not in frame:
        return []
    where = "" if k == 0 else f"file_frames[{k - 1}]: "
    classes = _array(frame["frame_classes"], f"{where}frame_classes")
    for i, c in enumerate(classes):
        if not isinstance(c, str):
            raise PatternError(f"{where}frame_classes[{i}]: expected a string, got {_type_name(c)}")
    return classes


def _choose_frame(data: dict, frames: list[dict]) -> int:
    top = _classes(data, 0)
    if "foldedForm" in top and "creasePattern" not in top:
        for i, fr in enumerate(frames):
            if "creasePattern" in _classes(fr, i + 1):
                return i + 1
    return 0


def _resolve(data: dict, frames: list[dict], k: int) -> dict:
    """Frame ``k``'s keys, with inheritance resolved (file_... keys of the top level dropped)."""
    chain: list[int] = []
    while True:
        if k in chain:
            cycle = " -> ".join(str(c) for c in [*chain, k])
            raise PatternError(f"file_frames: frame_parent makes a cycle (frames {cycle})")
        chain.append(k)
        if k == 0:
            break
        fr = frames[k - 1]
        inherit = fr.get("frame_inherit", False)
        if not isinstance(inherit, (bool, np.bool_)):
            raise PatternError(
                f"file_frames[{k - 1}].frame_inherit: expected true or false, "
                f"got {_type_name(inherit)}"
            )
        if not inherit:
            break
        parent = fr.get("frame_parent", 0)
        if not _is_index(parent) or not 0 <= int(parent) <= len(frames):
            raise PatternError(
                f"file_frames[{k - 1}].frame_parent: expected a frame number 0..{len(frames)}, "
                f"got {_type_name(parent)}"
            )
        k = int(parent)
    out: dict = {}
    for j in reversed(chain):  # ancestors first, the frame itself last
        src = data if j == 0 else frames[j - 1]
        for key, value in src.items():
            if j == 0 and key.startswith("file_"):
                continue
            if key in _NOT_INHERITED:
                continue
            out[key] = value
    return out


# ---------------------------------------------------------------------------------------------
# reading


def _check_file_spec(spec: Any) -> None:
    if spec is None:
        message = "file_spec missing; read as FOLD 1.2"
    elif not _is_number(spec) or not 1.0 <= float(spec) <= FILE_SPEC:
        message = f"file_spec {spec!r} is not a FOLD version 1 to 1.2; read as FOLD 1.2"
    else:
        return
    warnings.warn(message, PatternWarning, stacklevel=4)


def from_fold_dict(data: dict, frame: int | None = None) -> CreasePattern:
    """The crease pattern of a FOLD dictionary (a parsed ``.fold`` file).

    Args:
      data: the FOLD top-level object.
      frame: the frame to read, 0 for the top level, ``k`` for ``file_frames[k - 1]``; by
        default the crease-pattern frame (see the module docstring).

    Raises:
      PatternError: naming the key and element at fault.
    """
    if not isinstance(data, dict):
        raise PatternError(
            f"FOLD data: expected a JSON object at the top level, got {_type_name(data)}"
        )
    _check_file_spec(data.get("file_spec"))
    frames = _frames(data)
    if frame is None:
        k = _choose_frame(data, frames)
    else:
        if not _is_index(frame) or not 0 <= int(frame) <= len(frames):
            raise PatternError(
                f"frame {frame!r}: no such frame (the file has frames 0..{len(frames)}: "
                f"0 is the top level, k is file_frames[k-1])"
            )
        k = int(frame)
    fr = _resolve(data, frames, k)
    prefix = "" if k == 0 else f"{_frame_name(k)}: "
    try:
        _classes(fr, 0)  # checked, though any frame is read the same way
        name = fr.get("frame_title", data.get("file_title", "pattern"))
        if not isinstance(name, str) or not name:
            name = "pattern"
        return _read_frame(fr, name)
    except PatternError as exc:
        raise PatternError(f"{prefix}{exc}") from None


def _read_frame(fr: dict, name: str) -> CreasePattern:
    vertices = _read_vertices(fr)
    nv = len(vertices)
    faces = None
    if "faces_vertices" in fr:
        faces = _read_index_lists(fr["faces_vertices"], "faces_vertices", nv, exact=None)
    angle_key = "edges_foldAngle" if "edges_foldAngle" in fr else "edges_foldAngles"
    if "edges_vertices" in fr:
        edges = _read_index_lists(fr["edges_vertices"], "edges_vertices", nv, exact=2)
    elif "edges_assignment" in fr or angle_key in fr:
        raise PatternError(
            "edges_vertices missing: the frame has edges_assignment or edges_foldAngle "
            "but no edges_vertices to attach them to"
        )
    elif faces is not None:
        edges = _edges_of_faces(faces)
    else:
        raise PatternError("the frame has neither faces_vertices nor edges_vertices")
    ne = len(edges)
    assignments = _read_assignments(fr, ne)
    fold_angles = _read_fold_angles(fr, angle_key, ne, assignments)
    if faces is not None and assignments is not None and "C" in assignments:
        _open_slits(edges, faces, assignments, fold_angles)
    edges, assignments, fold_angles = _merge_duplicates(edges, assignments, fold_angles)

    flat = not np.any(np.abs(vertices[:, 2]) > 1e-12 * _scale(vertices))
    if faces is None:
        if not flat:
            raise PatternError(
                "faces_vertices missing and vertices_coords are 3-D: a folded form needs its "
                "faces to be unfolded"
            )
        return _pattern_from_edges(vertices, edges, assignments, fold_angles, name)
    start = None
    span2 = _scale(vertices) ** 2
    if not flat or any(signed_area(vertices[face, :2]) < -1e-9 * span2 for face in faces):
        # a folded form (3-D, or flat with faces flipped over): unfolded to the crease
        # pattern, its positions kept as the start
        start = vertices
        vertices = _develop(vertices, faces)
    pattern = CreasePattern(
        vertices=vertices,
        edges=np.array(edges, dtype=np.int64).reshape(-1, 2),
        faces=tuple(tuple(f) for f in faces),
        assignments=assignments,
        fold_angles=fold_angles,
        name=name,
        start=start,
    )
    if start is not None and fold_angles is None:
        # a folded form that gives no fold angles is its own target: its creases are driven to
        # the angles they have in it (not to the assignments' default +-180 degrees)
        angles, mirrored = _folded_angles(pattern)
        if mirrored:  # unfolded onto the plane face down: its mirror image is the one meant
            pattern = dataclasses.replace(pattern, start=start * np.array([1.0, 1.0, -1.0]))
        pattern = pattern.with_fold_angles(angles)
    return pattern


def _folded_angles(pattern: CreasePattern) -> tuple[np.ndarray, bool]:
    """(E,) the fold angles (radians) of a pattern's ``M`` and ``V`` edges in its ``start``: the
    size of the atan2 dihedral of the triangles beside each edge, negative for ``M``; its other
    edges' own targets elsewhere. And whether the start is the mirror image of the form the
    assignments describe (most creases folded against their letter)."""
    mesh = pattern.mesh
    x = np.asarray(pattern.start, np.float64)[mesh.source_vertex]
    out = np.array(pattern.fold_angles, np.float64)
    creases = [
        k
        for k in range(pattern.num_edges)
        if pattern.assignments[k] in "MV" and not np.any(mesh.hinges[k] < 0)
    ]
    measured = dict(zip(creases, fold_angles_np(x, mesh.hinges[creases]), strict=True))
    # folded flat (+-180 degrees) a crease has no side: the others tell which way up it is
    sided = [k for k in creases if 1e-9 < abs(measured[k]) < math.pi - 1e-9]
    agree = sum((measured[k] > 0) == (pattern.assignments[k] == "V") for k in sided)
    mirrored = 2 * agree < len(sided)
    for k in creases:
        size = abs(measured[k])
        out[k] = size if pattern.assignments[k] == "V" else -size
    return out, mirrored


def _read_assignments(fr: dict, ne: int) -> list[str] | None:
    if "edges_assignment" not in fr:
        return None
    letters = _array(fr["edges_assignment"], "edges_assignment")
    if len(letters) != ne:
        raise PatternError(
            f"edges_assignment: has {len(letters)} entries, but edges_vertices has {ne} edges"
        )
    out = []
    for i, a in enumerate(letters):
        if not isinstance(a, str) or a.upper() not in tuple(ASSIGNMENTS):
            raise PatternError(
                f"edges_assignment[{i}]: expected one of the letters "
                f"{', '.join(ASSIGNMENTS)}, got {_type_name(a)}"
            )
        out.append(a.upper())
    return out


def _read_fold_angles(fr: dict, key: str, ne: int, assignments) -> np.ndarray | None:
    if key not in fr:
        return None
    degrees = _array(fr[key], key)
    if len(degrees) != ne:
        raise PatternError(f"{key}: has {len(degrees)} entries, but edges_vertices has {ne} edges")
    rad = np.empty(ne)
    for i, d in enumerate(degrees):
        if d is None:
            default = _DEFAULT_DEGREES.get(assignments[i], 0.0) if assignments else 0.0
            rad[i] = math.radians(default)
            continue
        deg = _float(d, f"{key}[{i}]")
        if abs(deg) > 180.0 * (1 + 1e-12):
            raise PatternError(f"{key}[{i}]: {deg:g} degrees is outside [-180, 180]")
        rad[i] = math.radians(deg)
    return rad


def _open_slits(edges, faces, assignments: list[str], fold_angles) -> None:
    """Make each cut that cannot open (both ends inside the paper, neither on another cut: a
    slit) a free hinge, in place, with a warning, as Origami Simulator loads it."""
    sides = collections.Counter(
        (min(f[i - 1], f[i]), max(f[i - 1], f[i])) for f in faces for i in range(len(f))
    )
    # an edge with one face is on the paper's edge, whatever its letter
    letters = [
        "B" if sides[(min(a, b), max(a, b))] == 1 else x
        for (a, b), x in zip(edges, assignments, strict=True)
    ]
    for k in slit_edges(edges, letters):
        warnings.warn(
            f"edges_vertices[{k}]: is a cut whose ends are both inside the paper and meet no "
            "other cut (a slit), which cannot open; loaded as a free hinge (U, angle 0), as "
            "Origami Simulator does",
            PatternWarning,
            stacklevel=6,
        )
        assignments[k] = "U"
        if fold_angles is not None:
            fold_angles[k] = 0.0


def _merge_duplicates(edges, assignments, fold_angles):
    """Drop repeated edges that agree (with a warning); repeated edges that disagree are an
    error naming both."""
    first: dict[tuple[int, int], int] = {}
    keep = []
    for i, (a, b) in enumerate(edges):
        key = (min(a, b), max(a, b))
        j = first.setdefault(key, i)
        if j == i:
            keep.append(i)
            continue
        what = f"edges_vertices[{j}] and edges_vertices[{i}]: the same edge (vertices {a}, {b})"
        if assignments is not None and assignments[i] != assignments[j]:
            raise PatternError(
                f"{what} with different assignments ({assignments[j]} and {assignments[i]})"
            )
        if fold_angles is not None and fold_angles[i] != fold_angles[j]:
            raise PatternError(
                f"{what} with different fold angles ({math.degrees(fold_angles[j]):g} and "
                f"{math.degrees(fold_angles[i]):g} degrees)"
            )
        warnings.warn(f"{what} twice; the repeat is dropped", PatternWarning, stacklevel=6)
    if len(keep) == len(edges):
        return edges, assignments, fold_angles
    return (
        [edges[i] for i in keep],
        None if assignments is None else [assignments[i] for i in keep],
        None if fold_angles is None else fold_angles[keep],
    )


def _pattern_from_edges(vertices, edges, assignments, fold_angles, name) -> CreasePattern:
    """Faces of a flat frame without faces_vertices: the planar arrangement of its edges."""
    e = np.asarray(edges, dtype=np.int64)
    letters = assignments if assignments is not None else ["U"] * len(e)
    if fold_angles is None:
        fold_angles = [math.radians(_DEFAULT_DEGREES.get(a, 0.0)) for a in letters]
    return pattern_from_segments(
        vertices[e[:, 0], :2],
        vertices[e[:, 1], :2],
        letters,
        fold_angles,
        [f"edges_vertices[{i}]" for i in range(len(e))],
        tolerance=FOLD_TOLERANCE,
        name=name,
        vertex_order=vertices[:, :2],
    )


def _develop(vertices: np.ndarray, faces: list[list[int]]) -> np.ndarray:
    """Flat positions of a folded form: each face unfolded onto the plane next to its
    neighbour, breadth first over shared edges, one piece after another along x.

    Raises:
      PatternError: a face that is not planar, or a vertex that two faces put in different
        places (the folded form does not unfold to a flat sheet, e.g. a closed box).
    """
    scale = max(float(np.ptp(vertices, axis=0).max()), 1e-300)
    tol = 1e-4 * scale  # folded forms in files are often rounded to a few digits
    local = [_face_frame(vertices, face, f, tol) for f, face in enumerate(faces)]
    by_edge: dict[tuple[int, int], list[int]] = {}
    for f, face in enumerate(faces):
        for a, b in zip(face, face[1:] + face[:1], strict=True):
            by_edge.setdefault((min(a, b), max(a, b)), []).append(f)
    flat = np.full((len(vertices), 2), np.nan)
    placed_face = np.zeros(len(faces), dtype=bool)
    x_offset = 0.0
    for root in range(len(faces)):
        if placed_face[root]:
            continue
        piece = [root]
        pts = local[root]
        shift = np.array([x_offset - pts[:, 0].min(), -pts[:, 1].min()])
        _place(flat, faces[root], pts + shift, root, tol)
        placed_face[root] = True
        queue = collections.deque([root])
        while queue:
            f = queue.popleft()
            face = faces[f]
            for a, b in zip(face, face[1:] + face[:1], strict=True):
                for g in by_edge[(min(a, b), max(a, b))]:
                    if placed_face[g]:
                        continue
                    _place(flat, faces[g], _fit(local[g], faces[g], a, b, flat), g, tol)
                    placed_face[g] = True
                    piece.append(g)
                    queue.append(g)
        used = sorted({v for f in piece for v in faces[f]})
        x_offset = float(flat[used, 0].max()) + 0.1 * scale
    return flat


def _face_frame(vertices: np.ndarray, face: list[int], f: int, tol: float) -> np.ndarray:
    """The face's vertices in its own plane (2-D, counterclockwise about its normal)."""
    p = vertices[face]
    normal = np.zeros(3)
    for i in range(len(face)):  # Newell's method: the normal of a polygon, orientation kept
        normal += np.cross(p[i], p[(i + 1) % len(face)])
    size = np.linalg.norm(normal)
    if size <= 1e-300:
        raise PatternError(f"faces_vertices[{f}]: has zero area")
    normal /= size
    off = np.abs((p - p.mean(0)) @ normal)
    if off.max() > tol:
        i = int(off.argmax())
        raise PatternError(
            f"faces_vertices[{f}]: is not planar (vertex {face[i]} is {off[i]:.3g} off its plane)"
        )
    x = p[1] - p[0]
    x /= np.linalg.norm(x)
    y = np.cross(normal, x)
    return np.stack([(p - p[0]) @ x, (p - p[0]) @ y], axis=1)


def _fit(pts: np.ndarray, face: list[int], a: int, b: int, flat: np.ndarray) -> np.ndarray:
    """The face's local points moved rigidly so its vertices a and b land where they are."""
    ia, ib = face.index(a), face.index(b)
    u, w = pts[ib] - pts[ia], flat[b] - flat[a]
    angle = math.atan2(w[1], w[0]) - math.atan2(u[1], u[0])
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return (pts - pts[ia]) @ rot.T + flat[a]


def _place(flat: np.ndarray, face: list[int], pts: np.ndarray, f: int, tol: float) -> None:
    for v, q in zip(face, pts, strict=True):
        if np.isnan(flat[v, 0]):
            flat[v] = q
        elif np.linalg.norm(flat[v] - q) > tol:
            raise PatternError(
                f"faces_vertices[{f}]: unfolding puts vertex {v} at two places "
                f"({flat[v, 0]:.6g}, {flat[v, 1]:.6g}) and ({q[0]:.6g}, {q[1]:.6g}): "
                "the folded form does not unfold to a flat sheet"
            )


def _read_vertices(fr: dict) -> np.ndarray:
    if "vertices_coords" not in fr:
        raise PatternError("vertices_coords missing: the frame has no vertex coordinates")
    coords = _array(fr["vertices_coords"], "vertices_coords")
    if not coords:
        raise PatternError("vertices_coords: is empty")
    out = np.zeros((len(coords), 3))
    for i, c in enumerate(coords):
        what = f"vertices_coords[{i}]"
        if not isinstance(c, (list, tuple, np.ndarray)):
            raise PatternError(f"{what}: expected an array of 2 or 3 numbers, got {_type_name(c)}")
        c = list(c)
        if len(c) not in (2, 3):
            raise PatternError(f"{what}: expected 2 or 3 coordinates, got {len(c)}")
        for j, x in enumerate(c):
            out[i, j] = _float(x, f"{what}[{j}]")
            if abs(out[i, j]) > MAX_COORDINATE:
                raise PatternError(f"{what}[{j}]: {out[i, j]:g} is beyond {MAX_COORDINATE:g}")
    return out


def _read_index_lists(value: Any, key: str, nv: int, exact: int | None) -> list[list[int]]:
    rows = _array(value, key)
    out = []
    for i, row in enumerate(rows):
        what = f"{key}[{i}]"
        if not isinstance(row, (list, tuple, np.ndarray)):
            raise PatternError(
                f"{what}: expected an array of vertex indices, got {_type_name(row)}"
            )
        row = list(row)
        if exact is not None and len(row) != exact:
            raise PatternError(f"{what}: expected {exact} vertex indices, got {len(row)}")
        if exact is None and len(row) < 3:
            raise PatternError(f"{what}: a face needs at least 3 vertices, got {len(row)}")
        idx = []
        for j, v in enumerate(row):
            if not _is_index(v):
                raise PatternError(f"{what}[{j}]: expected a vertex index, got {_type_name(v)}")
            v = int(v)
            if not 0 <= v < nv:
                raise PatternError(
                    f"{what}: vertex index {v} is out of range (the frame has {nv} vertices)"
                )
            idx.append(v)
        out.append(idx)
    if not out:
        raise PatternError(f"{key}: is empty")
    return out


def _edges_of_faces(faces: list[list[int]]) -> list[list[int]]:
    seen: set[tuple[int, int]] = set()
    edges = []
    for f in faces:
        for a, b in zip(f, f[1:] + f[:1], strict=True):
            key = (min(a, b), max(a, b))
            if key not in seen:
                seen.add(key)
                edges.append([a, b])
    return edges


def _scale(vertices: np.ndarray) -> float:
    return max(float(np.abs(vertices[:, :2]).max()), 1e-300)


def load_fold(path: str | os.PathLike, frame: int | None = None) -> CreasePattern:
    """The crease pattern of a ``.fold`` file (see :func:`from_fold_dict`).

    The pattern's name is the frame's ``frame_title``, else ``file_title``, else the file name
    without its suffix.

    Raises:
      PatternError: the file cannot be read, is not valid JSON, or is not a valid pattern; the
        message starts with the path.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a BOM is tolerated
    except (OSError, UnicodeDecodeError) as exc:
        raise PatternError(f"{path}: cannot read the FOLD file ({exc})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PatternError(
            f"{path}: invalid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}"
        ) from None
    except RecursionError:
        raise PatternError(f"{path}: invalid JSON (nested too deeply)") from None
    try:
        if isinstance(data, dict) and "file_title" not in data:
            data = {**data, "file_title": path.stem}
        return from_fold_dict(data, frame=frame)
    except PatternError as exc:
        raise PatternError(f"{path}: {exc}") from None


# ---------------------------------------------------------------------------------------------
# writing


def pattern_and_state(obj: Any) -> tuple[CreasePattern, np.ndarray | None, np.ndarray | None]:
    """(pattern, positions, fold_angles) of a CreasePattern (None, None) or of a result."""
    if isinstance(obj, CreasePattern):
        return obj, None, None
    if all(hasattr(obj, a) for a in ("pattern", "positions", "fold_angles")):
        pattern = obj.pattern
        if not isinstance(pattern, CreasePattern):
            raise TypeError(
                f"result.pattern: expected a CreasePattern, got {type(pattern).__name__}"
            )
        return (pattern, *_result_arrays(pattern, obj.positions, obj.fold_angles))
    raise TypeError(
        "expected a CreasePattern or a result with attributes pattern, positions and "
        f"fold_angles, got {type(obj).__name__}"
    )


def _result_arrays(pattern: CreasePattern, positions: Any, fold_angles: Any):
    """A result's positions and fold angles as float arrays, their shapes checked."""
    mesh = pattern.mesh
    try:
        x = np.asarray(positions, dtype=np.float64)
        rho = np.asarray(fold_angles, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"result: positions and fold_angles must be numeric arrays ({exc})"
        ) from None
    if x.shape != (mesh.num_vertices, 3):
        raise ValueError(
            f"result.positions: expected shape ({mesh.num_vertices}, 3) (one row per mesh "
            f"vertex), got {x.shape}"
        )
    if rho.shape != (mesh.num_edges,):
        raise ValueError(
            f"result.fold_angles: expected shape ({mesh.num_edges},) (one per mesh edge), "
            f"got {rho.shape}"
        )
    return x, rho


def _check_finite(array: np.ndarray, what: str) -> None:
    bad = ~np.isfinite(array)
    if bad.any():
        i = int(np.flatnonzero(bad.reshape(len(array), -1).any(axis=1))[0])
        raise ValueError(f"{what}[{i}]: non-finite value {array[i].tolist()} cannot be written")


def _degrees(radians: np.ndarray) -> list[float]:
    return [float(x) for x in np.degrees(radians)]


def to_fold_dict(pattern: CreasePattern, result: Any = None) -> dict:
    """The FOLD 1.2 dictionary of a pattern, with the folded state of ``result`` if given.

    Args:
      pattern: the crease pattern (the top-level frame).
      result: ``None`` or an object with ``positions`` ((V_mesh, 3), mesh vertex order) and
        ``fold_angles`` ((E_mesh,) radians); written as ``file_frames[0]``, a ``foldedForm``
        frame (see the module docstring); its ``frames`` (a fold's path from flat, each with
        ``percent``, ``positions`` and ``fold_angles``), if any, follow as further frames,
        titled ``"path k: fold percent p"``. Its ``pattern`` attribute, if any, is not used.

    Raises:
      ValueError: the result's arrays have the wrong shape or non-finite values.
    """
    if not isinstance(pattern, CreasePattern):
        raise TypeError(f"pattern: expected a CreasePattern, got {type(pattern).__name__}")
    attributes = ["2D"]
    if (pattern.assignments == "C").any():
        attributes.append("cuts")
    if (pattern.assignments == "J").any():
        attributes.append("joins")
    out: dict = {
        "file_spec": FILE_SPEC,
        "file_creator": FILE_CREATOR,
        "file_classes": ["singleModel"],
        "frame_title": pattern.name,
        "frame_classes": ["creasePattern"],
        "frame_attributes": attributes,
        "vertices_coords": [[float(x), float(y)] for x, y in pattern.vertices[:, :2]],
        "edges_vertices": [[int(a), int(b)] for a, b in pattern.edges],
        "edges_assignment": [str(a) for a in pattern.assignments],
        "edges_foldAngle": _degrees(pattern.fold_angles),
        "faces_vertices": [[int(v) for v in f] for f in pattern.faces],
    }
    if result is not None:
        positions, angles = _result_arrays(pattern, result.positions, result.fold_angles)
        out["file_frames"] = [_folded_frame(pattern, positions, angles)]
        for k, frame in enumerate(getattr(result, "frames", None) or ()):
            positions, angles = _result_arrays(pattern, frame.positions, frame.fold_angles)
            state = _folded_frame(pattern, positions, angles)
            state["frame_title"] = f"path {k}: fold percent {100 * frame.percent:.6g}"
            out["file_frames"].append(state)
    return out


def _folded_frame(pattern: CreasePattern, positions: np.ndarray, angles: np.ndarray) -> dict:
    mesh = pattern.mesh
    _check_finite(positions, "result.positions")
    _check_finite(angles, "result.fold_angles")
    angles = np.where(mesh.role == "border", 0.0, angles)
    coords = [[float(x), float(y), float(z)] for x, y, z in positions]
    if mesh.num_vertices == pattern.num_vertices:
        return {
            "frame_classes": ["foldedForm"],
            "frame_attributes": ["3D"],
            "frame_parent": 0,
            "frame_inherit": True,
            "vertices_coords": coords,
            "edges_foldAngle": _degrees(angles[: pattern.num_edges]),
        }
    letters = []
    for src, role in zip(mesh.source_edge, mesh.role, strict=True):
        if src < 0:
            letters.append("J")
        elif role == "border":
            letters.append("B")
        else:
            letters.append(str(pattern.assignments[src]))
    attributes = ["3D"]
    if "J" in letters:
        attributes.append("joins")
    return {
        "frame_classes": ["foldedForm"],
        "frame_attributes": attributes,
        "frame_parent": 0,
        "frame_inherit": False,
        "vertices_coords": coords,
        "edges_vertices": [[int(a), int(b)] for a, b in mesh.edges],
        "edges_assignment": letters,
        "edges_foldAngle": _degrees(angles),
        "faces_vertices": [[int(v) for v in t] for t in mesh.triangles],
    }


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """A temporary path beside ``path`` that replaces ``path`` when the block succeeds.

    The temporary file has the same suffix as ``path`` (or ``suffix``), so writers that choose
    the format by suffix see the right one. On any error it is removed and ``path`` is left as it
    was. The new file gets the usual permissions (``0o666`` less the umask).
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise FileNotFoundError(f"{path}: the folder {folder} does not exist")
    tmp_path = _new_file(folder, f".{path.name}.", path.suffix if suffix is None else suffix)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


def _new_file(folder: Path, prefix: str, suffix: str) -> Path:
    """A new empty file of a name no other has, created with mode ``0o666`` so that the system
    takes the umask off (``tempfile.mkstemp`` makes ``0o600``, and reading the umask means
    setting it, for every thread of the process)."""
    for _ in range(1000):
        candidate = folder / f"{prefix}{secrets.token_hex(6)}{suffix}"
        try:
            os.close(os.open(candidate, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
        except FileExistsError:
            continue
        return candidate
    raise FileExistsError(f"{folder}: no free temporary name")  # pragma: no cover


def save_fold(path: str | os.PathLike, pattern_or_result: Any) -> None:
    """Write a crease pattern, or a simulation result, to a ``.fold`` file, atomically.

    A result (detected by its ``pattern``, ``positions`` and ``fold_angles`` attributes) is
    written as its pattern plus a ``foldedForm`` frame (see :func:`to_fold_dict`).

    Raises:
      TypeError: not a CreasePattern nor a result.
      ValueError: the result's arrays have the wrong shape or non-finite values.
      OSError: the file cannot be written (nothing is left behind).
    """
    pattern, positions, angles = pattern_and_state(pattern_or_result)
    data = to_fold_dict(pattern, None if positions is None else pattern_or_result)
    text = json.dumps(data, indent=1, allow_nan=False) + "\n"
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
