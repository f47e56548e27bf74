"""Reading and writing FOLD files and exporting meshes (origami_jax.io); no JAX needed."""

from __future__ import annotations

import copy
import json
import math
import os
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import meshio
import numpy as np
import pytest

from origami_jax import CreasePattern, PatternError, PatternWarning
from origami_jax.io import fold as fold_module
from origami_jax.io import (
    from_fold_dict,
    load,
    load_fold,
    save,
    save_fold,
    save_mesh,
    to_fold_dict,
)
from origami_jax.io import mesh as mesh_module

SHARED = Path(__file__).resolve().parents[2] / "shared"


# ---------------------------------------------------------------------------------------------
# small patterns and a stand-in result


def diagonal_valley() -> CreasePattern:
    """A unit square folded along the diagonal 0-2 (valley, default +pi)."""
    return CreasePattern(
        vertices=[[0, 0], [1, 0], [1, 1], [0, 1]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]],
        faces=[[0, 1, 2], [0, 2, 3]],
        assignments="BBBBV",
        name="diagonal",
    )


def two_quads() -> CreasePattern:
    """A 2 x 1 rectangle of two quads with a mountain in the middle at -90 degrees."""
    return CreasePattern(
        vertices=[[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 1]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 0], [1, 4]],
        faces=[[0, 1, 4, 5], [1, 2, 3, 4]],
        assignments="BBBBBBM",
        fold_angles=[0, 0, 0, 0, 0, 0, -np.pi / 2],
        name="two quads",
    )


def explicit_angles() -> CreasePattern:
    """A square with a centre vertex: valley, mountain, unassigned, flat creases."""
    return CreasePattern(
        vertices=[[0, 0], [2, 0], [2, 2], [0, 2], [0.9, 1.1]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 4], [1, 4], [2, 4], [3, 4]],
        faces=[[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]],
        assignments=["B", "B", "B", "B", "V", "M", "U", "F"],
        fold_angles=[0, 0, 0, 0, 0.3, -2.5, 0.1234567890123, 0],
    )


def cut_pattern() -> CreasePattern:
    """A cut from corner 0 to an inner vertex: mesh vertex 0 is split; a quad is triangulated."""
    return CreasePattern(
        vertices=[[0, 0], [1, 0], [1, 1], [0, 1], [0.4, 0.4]],
        edges=[[0, 1], [1, 2], [2, 3], [3, 0], [0, 4], [1, 4], [3, 4]],
        faces=[[0, 1, 4], [1, 2, 3, 4], [3, 0, 4]],
        assignments="BBBBCVM",
    )


PATTERNS = [diagonal_valley, two_quads, explicit_angles, cut_pattern]


@dataclass
class FakeResult:
    pattern: CreasePattern
    positions: np.ndarray
    fold_angles: np.ndarray


def folded(pattern: CreasePattern, seed: int = 0) -> FakeResult:
    """A made-up folded state: the flat mesh, lifted and jittered, with some fold angles."""
    rng = np.random.default_rng(seed)
    mesh = pattern.mesh
    x = mesh.vertices + 0.1 * rng.standard_normal(mesh.vertices.shape)
    return FakeResult(pattern, x, rng.uniform(-3, 3, mesh.num_edges))


def canonical_faces(faces) -> list[tuple[int, ...]]:
    """Faces up to rotation and orientation."""
    out = []
    for f in faces:
        f = [int(v) for v in f]
        best = None
        for g in (f, f[::-1]):
            i = g.index(min(g))
            h = tuple(g[i:] + g[:i])
            best = h if best is None else min(best, h)
        out.append(best)
    return sorted(out)


def assert_same_pattern(a: CreasePattern, b: CreasePattern) -> None:
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.edges, b.edges)
    np.testing.assert_array_equal(a.assignments, b.assignments)
    np.testing.assert_allclose(a.fold_angles, b.fold_angles, rtol=0, atol=1e-12)
    assert canonical_faces(a.faces) == canonical_faces(b.faces)


# ---------------------------------------------------------------------------------------------
# reading and writing FOLD


@pytest.mark.parametrize("make", PATTERNS)
def test_dict_round_trip(make):
    cp = make()
    data = to_fold_dict(cp)
    assert data["file_spec"] == 1.2
    assert data["file_creator"] == "origami_jax"
    assert data["file_classes"] == ["singleModel"]
    assert data["frame_classes"] == ["creasePattern"]
    assert data["frame_attributes"][0] == "2D"
    assert all(len(c) == 2 for c in data["vertices_coords"])
    assert "file_frames" not in data
    json.dumps(data, allow_nan=False)  # plain JSON types only
    back = from_fold_dict(data)
    assert_same_pattern(cp, back)
    assert back.name == cp.name
    # and through JSON text
    assert_same_pattern(cp, from_fold_dict(json.loads(json.dumps(data))))


@pytest.mark.parametrize("make", PATTERNS)
@pytest.mark.parametrize("suffix", [".fold", ".json"])
def test_file_round_trip(tmp_path, make, suffix):
    cp = make()
    path = tmp_path / f"p{suffix}"
    save(path, cp)
    assert_same_pattern(cp, load(path))
    assert_same_pattern(cp, load_fold(path))
    assert sorted(os.listdir(tmp_path)) == [path.name]  # no temporary file left


def test_degrees_in_file_radians_in_pattern():
    data = to_fold_dict(explicit_angles())
    assert data["edges_foldAngle"][5] == pytest.approx(-2.5 * 180 / math.pi, abs=1e-12)
    data["edges_foldAngle"] = [0, 0, 0, 0, 90, -45, 30, 0]
    cp = from_fold_dict(data)
    np.testing.assert_allclose(
        cp.fold_angles, np.radians([0, 0, 0, 0, 90, -45, 30, 0]), rtol=0, atol=1e-15
    )


def test_missing_fold_angles_give_plus_minus_pi():
    data = to_fold_dict(explicit_angles())
    del data["edges_foldAngle"]
    cp = from_fold_dict(data)
    np.testing.assert_array_equal(cp.fold_angles, [0, 0, 0, 0, np.pi, -np.pi, 0, 0])


def test_null_fold_angle_takes_the_assignment_default():
    data = to_fold_dict(explicit_angles())
    data["edges_foldAngle"] = [0, None, 0, 0, None, None, 45, None]
    cp = from_fold_dict(data)
    np.testing.assert_allclose(cp.fold_angles, [0, 0, 0, 0, np.pi, -np.pi, np.pi / 4, 0])


def test_old_spelling_edges_fold_angles():
    data = to_fold_dict(diagonal_valley())
    data["edges_foldAngles"] = data.pop("edges_foldAngle")
    data["edges_foldAngles"][4] = 90
    assert from_fold_dict(data).fold_angles[4] == pytest.approx(np.pi / 2)


def test_missing_assignments_default_to_border_and_unassigned():
    data = to_fold_dict(diagonal_valley())
    del data["edges_assignment"], data["edges_foldAngle"]
    cp = from_fold_dict(data)
    assert "".join(cp.assignments) == "BBBBU"
    np.testing.assert_array_equal(cp.fold_angles, 0)


def test_missing_edges_are_computed_from_faces():
    data = to_fold_dict(two_quads())
    for key in ("edges_vertices", "edges_assignment", "edges_foldAngle"):
        del data[key]
    cp = from_fold_dict(data)
    assert cp.num_edges == 7
    assert sorted(cp.assignments) == ["B"] * 6 + ["U"]


@pytest.mark.parametrize("make", PATTERNS)
def test_missing_faces_are_computed_from_the_edges(make):
    cp = make()
    data = to_fold_dict(cp)
    del data["faces_vertices"]
    got = from_fold_dict(data)
    # same vertices (numbers kept), same edges with the same letters and angles, same faces
    np.testing.assert_array_equal(got.vertices, cp.vertices)
    key = {tuple(sorted(e)): k for k, e in enumerate(cp.edges.tolist())}
    order = [key[tuple(sorted(e))] for e in got.edges.tolist()]
    assert sorted(order) == list(range(cp.num_edges))
    np.testing.assert_array_equal(got.assignments, cp.assignments[order])
    np.testing.assert_allclose(got.fold_angles, cp.fold_angles[order], atol=1e-12)
    assert canonical_faces(got.faces) == canonical_faces(cp.faces)


def test_three_dimensional_coordinates_are_a_prefolded_start():
    cp = diagonal_valley()
    data = to_fold_dict(cp)
    data["vertices_coords"] = [[x, y, 0.0] for x, y in data["vertices_coords"]]
    assert from_fold_dict(data).start is None  # z = 0 is a crease pattern
    data["vertices_coords"][2][2] = 0.25
    got = from_fold_dict(data)
    np.testing.assert_array_equal(got.start, np.array(data["vertices_coords"]))
    # unfolded: every edge keeps its folded length, the faces are counterclockwise
    folded = np.linalg.norm(np.subtract(*got.start[got.edges.T]), axis=1)
    flat = np.linalg.norm(np.subtract(*got.vertices[got.edges.T]), axis=1)
    np.testing.assert_allclose(flat, folded, rtol=1e-12)
    assert np.all(got.vertices[:, 2] == 0)


def test_lowercase_assignments_and_integral_floats_are_accepted():
    data = to_fold_dict(diagonal_valley())
    data["edges_assignment"] = [a.lower() for a in data["edges_assignment"]]
    data["edges_vertices"] = [[float(a), float(b)] for a, b in data["edges_vertices"]]
    assert "".join(from_fold_dict(data).assignments) == "BBBBV"


def test_name_from_title_or_file_name(tmp_path):
    data = to_fold_dict(diagonal_valley())
    del data["frame_title"]
    path = tmp_path / "my-square.fold"
    path.write_text(json.dumps(data))
    assert load(path).name == "my-square"
    data["file_title"] = "titled"
    path.write_text(json.dumps(data))
    assert load(path).name == "titled"


# ---------------------------------------------------------------------------------------------
# the folded-state frame


def test_result_frame_inherits_when_no_vertex_is_split(tmp_path):
    cp = two_quads()
    assert cp.mesh.num_vertices == cp.num_vertices
    res = folded(cp)
    data = to_fold_dict(cp, res)
    (frame,) = data["file_frames"]
    assert frame["frame_classes"] == ["foldedForm"]
    assert frame["frame_attributes"] == ["3D"]
    assert frame["frame_parent"] == 0 and frame["frame_inherit"] is True
    assert set(frame) == {
        "frame_classes",
        "frame_attributes",
        "frame_parent",
        "frame_inherit",
        "vertices_coords",
        "edges_foldAngle",
    }
    np.testing.assert_array_equal(np.array(frame["vertices_coords"]), res.positions)
    expected = np.where(cp.mesh.role == "border", 0.0, res.fold_angles)[: cp.num_edges]
    np.testing.assert_allclose(np.radians(frame["edges_foldAngle"]), expected, atol=1e-12)

    # the file: the crease pattern reads back, the folded coordinates round-trip exactly
    path = tmp_path / "folded.fold"
    save_fold(path, res)
    raw = json.loads(path.read_text())
    np.testing.assert_array_equal(np.array(raw["file_frames"][0]["vertices_coords"]), res.positions)
    assert_same_pattern(cp, load(path))
    # frame 1 is a 3-D folded form whose quadrilateral faces bend: it does not unfold
    with pytest.raises(PatternError, match=r"frame 1 \(file_frames\[0\]\).*not planar"):
        load_fold(path, frame=1)


def test_result_frame_has_its_own_topology_when_cuts_split_vertices(tmp_path):
    cp = cut_pattern()
    mesh = cp.mesh
    assert mesh.num_vertices > cp.num_vertices
    res = folded(cp, seed=3)
    path = tmp_path / "cut.fold"
    save(path, res)
    raw = json.loads(path.read_text())
    (frame,) = raw["file_frames"]
    assert frame["frame_classes"] == ["foldedForm"]
    assert frame["frame_attributes"][0] == "3D"
    assert frame["frame_inherit"] is False
    np.testing.assert_array_equal(np.array(frame["vertices_coords"]), res.positions)
    np.testing.assert_array_equal(np.array(frame["edges_vertices"]), mesh.edges)
    np.testing.assert_array_equal(np.array(frame["faces_vertices"]), mesh.triangles)
    letters = frame["edges_assignment"]
    assert len(letters) == mesh.num_edges
    for k, src in enumerate(mesh.source_edge):
        if src < 0:
            assert letters[k] == "J"
        elif cp.assignments[src] == "C":
            assert letters[k] == "B"
        else:
            assert letters[k] == cp.assignments[src]
    angles = np.radians(frame["edges_foldAngle"])
    np.testing.assert_allclose(angles[mesh.role == "border"], 0.0)
    inner = mesh.role != "border"
    np.testing.assert_allclose(angles[inner], res.fold_angles[inner], atol=1e-12)
    assert_same_pattern(cp, load(path))


def test_result_with_wrong_shapes_or_nan_is_refused(tmp_path):
    cp = diagonal_valley()
    res = folded(cp)
    with pytest.raises(ValueError, match=r"result.positions: expected shape \(4, 3\)"):
        to_fold_dict(cp, FakeResult(cp, res.positions[:3], res.fold_angles))
    with pytest.raises(ValueError, match=r"result.fold_angles: expected shape \(5,\)"):
        save_fold(tmp_path / "x.fold", FakeResult(cp, res.positions, res.fold_angles[:2]))
    bad = res.positions.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"result.positions\[2\]"):
        save_fold(tmp_path / "x.fold", FakeResult(cp, bad, res.fold_angles))
    with pytest.raises(TypeError):
        save_fold(tmp_path / "x.fold", "not a pattern")
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# frames


def folded_top_with_cp_frame(inherit: bool) -> dict:
    """Top level: a 3-D folded form; file_frames[1]: the crease pattern."""
    cp = diagonal_valley()
    data = to_fold_dict(cp)
    flat = data["vertices_coords"]
    data["frame_classes"] = ["foldedForm"]
    data["frame_attributes"] = ["3D"]
    data["vertices_coords"] = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0.5, 0.5, 0.7]]
    cp_frame = {"frame_classes": ["creasePattern"], "vertices_coords": flat}
    if inherit:
        cp_frame.update(frame_parent=0, frame_inherit=True)
    else:
        for key in ("edges_vertices", "edges_assignment", "edges_foldAngle", "faces_vertices"):
            cp_frame[key] = data[key]
    other = {"frame_classes": ["foldedForm"], "frame_parent": 0, "frame_inherit": True}
    data["file_frames"] = [other, cp_frame]
    return data


@pytest.mark.parametrize("inherit", [True, False])
def test_crease_pattern_frame_is_chosen_over_folded_top_level(inherit):
    data = folded_top_with_cp_frame(inherit)
    assert_same_pattern(diagonal_valley(), from_fold_dict(data))
    assert_same_pattern(diagonal_valley(), from_fold_dict(data, frame=2))
    folded = from_fold_dict(data, frame=0)  # the folded form itself, unfolded
    np.testing.assert_array_equal(folded.start, np.array(data["vertices_coords"], float))
    assert folded.num_faces == 2


def test_frame_selection_errors():
    data = folded_top_with_cp_frame(inherit=True)
    for frame in (3, -1, "1", 1.5, True):
        with pytest.raises(PatternError, match="no such frame"):
            from_fold_dict(data, frame=frame)
    data["file_frames"][1]["frame_parent"] = 2
    with pytest.raises(PatternError, match="cycle"):
        from_fold_dict(data)


def test_inherited_keys_are_overridden_by_the_child():
    data = to_fold_dict(diagonal_valley())
    data["file_frames"] = [
        {"frame_parent": 0, "frame_inherit": True, "edges_foldAngle": [0, 0, 0, 0, 45]},
        {"frame_parent": 1, "frame_inherit": True, "frame_title": "grandchild"},
    ]
    assert from_fold_dict(data, frame=1).fold_angles[4] == pytest.approx(np.pi / 4)
    child = from_fold_dict(data, frame=2)
    assert child.fold_angles[4] == pytest.approx(np.pi / 4)
    assert child.name == "grandchild"
    assert from_fold_dict(data).fold_angles[4] == pytest.approx(np.pi)


def test_flat_folded_form_unfolds_to_the_square():
    data = to_fold_dict(diagonal_valley())
    data["frame_classes"] = ["foldedForm"]
    data["vertices_coords"][3] = [1.0, 0.0]  # flat-folded along the diagonal: face 1 flipped
    got = from_fold_dict(data)
    np.testing.assert_allclose(got.start[3], [1.0, 0.0, 0.0])
    side = np.linalg.norm(np.subtract(*got.vertices[got.edges.T]), axis=1)
    np.testing.assert_allclose(side, [1, 1, 1, 1, np.sqrt(2)], rtol=1e-12)


def test_folded_form_that_does_not_unfold_is_a_clear_error():
    # a closed pyramid of four triangles on a square: the apex vertex closes up
    data = {
        "file_spec": 1.2,
        "vertices_coords": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 0.5]],
        "faces_vertices": [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]],
    }
    with pytest.raises(PatternError, match=r"unfolding puts vertex \d at two places"):
        from_fold_dict(data)
    data["faces_vertices"] = [[0, 1, 2, 4]]
    with pytest.raises(PatternError, match=r"faces_vertices\[0\]: is not planar"):
        from_fold_dict(data)


# ---------------------------------------------------------------------------------------------
# the public example files


def fold_spec_files() -> list[Path]:
    folder = SHARED / "patterns" / "fold-spec"
    return sorted(folder.glob("*.fold")) if folder.is_dir() else []


@pytest.mark.parametrize(
    "path", fold_spec_files() or [None], ids=lambda p: getattr(p, "name", "none")
)
def test_fold_spec_examples_load_or_fail_clearly(path):
    if path is None:
        pytest.skip(f"{SHARED / 'patterns' / 'fold-spec'} is absent")
    try:
        cp = load(path)
    except PatternError as exc:
        message = str(exc)
        assert message.startswith(str(path))
        assert len(message) > len(str(path)) + 20
        return
    assert cp.num_faces > 0
    assert_same_pattern(cp, from_fold_dict(to_fold_dict(cp)))


def test_fold_spec_diagonal_crease_pattern():
    path = SHARED / "patterns" / "fold-spec" / "diagonal-cp.fold"
    if not path.exists():
        pytest.skip(f"{path} is absent")
    cp = load(path)
    assert "".join(cp.assignments) == "BBBBV"
    assert cp.fold_angles[4] == pytest.approx(np.pi)
    folded = load(path.with_name("diagonal-folded.fold"))  # unfolds to the same square
    side = np.linalg.norm(np.subtract(*folded.vertices[folded.edges.T]), axis=1)
    np.testing.assert_allclose(side, np.linalg.norm(np.subtract(*cp.vertices[cp.edges.T]), axis=1))


# ---------------------------------------------------------------------------------------------
# malformed input


def base() -> dict:
    return to_fold_dict(diagonal_valley())


def _set(path, value):
    """A modifier setting data[path...] = value (a path of keys and indices)."""

    def modify(d):
        target = d
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
        return d

    return modify


def _del(key):
    def modify(d):
        del d[key]
        return d

    return modify


MALFORMED = [
    # (modifier of a valid dict, or a replacement, and text the message must contain)
    (lambda d: [], "expected a JSON object"),
    (lambda d: "text", "expected a JSON object"),
    (_del("vertices_coords"), "vertices_coords missing"),
    (_set(["vertices_coords"], "abc"), "vertices_coords: expected an array"),
    (_set(["vertices_coords"], []), "vertices_coords: is empty"),
    (_set(["vertices_coords", 2], 5), "vertices_coords[2]: expected an array of 2 or 3 numbers"),
    (_set(["vertices_coords", 2], [1]), "vertices_coords[2]: expected 2 or 3 coordinates"),
    (_set(["vertices_coords", 2], [1, 1, 0, 0]), "vertices_coords[2]: expected 2 or 3"),
    (_set(["vertices_coords", 2], [1, "y"]), "vertices_coords[2][1]: expected a number"),
    (_set(["vertices_coords", 2], [1, True]), "vertices_coords[2][1]: expected a number"),
    (_set(["vertices_coords", 2], [1, None]), "vertices_coords[2][1]: expected a number"),
    (_set(["vertices_coords", 2], [1, float("nan")]), "vertices_coords[2][1]: expected a finite"),
    (_set(["vertices_coords", 2], [10**400, 1]), "vertices_coords[2][0]: expected a finite"),
    (_set(["vertices_coords", 2], [1, 0]), "edge 1 (vertices 1, 2): has zero length"),
    (
        _set(["vertices_coords", 2], [1e20, 1]),
        "edge 0 (vertices 0, 1): is 1 long, under 1e-12 of the longest edge (1e+20): vertex 2 "
        "at (1e+20, 1, 0) lies that far from the others; is its coordinate a mistake?",
    ),
    (_set(["edges_vertices"], {"a": 1}), "edges_vertices: expected an array"),
    (_set(["edges_vertices", 4], [0]), "edges_vertices[4]: expected 2 vertex indices"),
    (_set(["edges_vertices", 4], 0), "edges_vertices[4]: expected an array of vertex indices"),
    (_set(["edges_vertices", 4], [0, 2.5]), "edges_vertices[4][1]: expected a vertex index"),
    (_set(["edges_vertices", 4], [0, "2"]), "edges_vertices[4][1]: expected a vertex index"),
    (_set(["edges_vertices", 4], [False, 2]), "edges_vertices[4][0]: expected a vertex index"),
    (_set(["edges_vertices", 4], [0, 7]), "edges_vertices[4]: vertex index 7 is out of range"),
    (_set(["edges_vertices", 4], [0, -1]), "edges_vertices[4]: vertex index -1 is out of range"),
    (_set(["edges_vertices", 4], [0, 10**30]), "edges_vertices[4]: vertex index 1000"),
    (_set(["edges_vertices", 4], [0, 0]), "edge 4 (vertices 0, 0): joins a vertex to itself"),
    (_set(["edges_vertices", 4], [1, 0]), "edges_vertices[0] and edges_vertices[4]: the same"),
    (_set(["edges_vertices"], []), "edges_vertices: is empty"),
    (_set(["edges_assignment"], "BBBBV"), "edges_assignment: expected an array"),
    (_set(["edges_assignment", 4], "X"), "edges_assignment[4]: expected one of the letters"),
    (_set(["edges_assignment", 4], 1), "edges_assignment[4]: expected one of the letters"),
    (_set(["edges_assignment", 4], "VV"), "edges_assignment[4]"),
    (_set(["edges_assignment"], ["B"] * 4), "edges_assignment: has 4 entries"),
    (
        lambda d: _set(["edges_foldAngle", 4], 0)(_set(["edges_assignment", 4], "B")(d)),
        "edge 4 (vertices 0, 2): is a border (B)",
    ),
    (_set(["edges_assignment", 4], "B"), "edge 4: assignment B takes no fold angle"),
    (_set(["edges_assignment", 0], "M"), "edge 0 (vertices 0, 1): is assigned M but lies on"),
    (_set(["edges_foldAngle"], 180), "edges_foldAngle: expected an array"),
    (_set(["edges_foldAngle", 4], "90"), "edges_foldAngle[4]: expected a number"),
    (_set(["edges_foldAngle", 4], 270), "edges_foldAngle[4]: 270 degrees is outside"),
    (_set(["edges_foldAngle", 4], -90), "edge 4: assignment V but fold angle"),
    (_set(["edges_foldAngle", 0], 10), "edge 0: assignment B takes no fold angle"),
    (_set(["edges_foldAngle"], [0, 0, 0]), "edges_foldAngle: has 3 entries"),
    (_del("edges_vertices"), "edges_vertices missing"),
    (
        lambda d: _del("faces_vertices")(
            _del("edges_vertices")(_del("edges_assignment")(_del("edges_foldAngle")(d)))
        ),
        "the frame has neither faces_vertices nor edges_vertices",
    ),
    (_set(["faces_vertices"], []), "faces_vertices: is empty"),
    (_set(["faces_vertices"], 3), "faces_vertices: expected an array"),
    (_set(["faces_vertices", 1], 3), "faces_vertices[1]: expected an array of vertex indices"),
    (_set(["faces_vertices", 1], [0, 2]), "faces_vertices[1]: a face needs at least 3"),
    (_set(["faces_vertices", 1], [0, 2, 9]), "faces_vertices[1]: vertex index 9 is out of range"),
    (_set(["faces_vertices", 1], [0, 2, None]), "faces_vertices[1][2]: expected a vertex index"),
    (_set(["faces_vertices", 1], [0, 2, 2]), "face 1: repeats a vertex"),
    (_set(["faces_vertices"], [[0, 1, 2]]), "edge 2 (vertices 2, 3): belongs to no face"),
    (_set(["faces_vertices", 0], [0, 1, 3]), "face 0: side (1, 3) is not an edge"),
    (_set(["frame_classes"], "foldedForm"), "frame_classes: expected an array"),
    (_set(["frame_classes"], [1]), "frame_classes[0]: expected a string"),
    (_set(["file_frames"], 3), "file_frames: expected an array"),
    (_set(["file_frames"], [5]), "file_frames[0]: expected an object"),
]


@pytest.mark.parametrize(("modify", "expected"), MALFORMED, ids=[m[1] for m in MALFORMED])
def test_malformed_dicts_raise_pattern_error_naming_the_element(modify, expected):
    data = modify(copy.deepcopy(base()))
    with pytest.raises(PatternError) as info:
        from_fold_dict(data)
    assert expected in str(info.value)


MALFORMED_FRAMES = [
    ([{"frame_inherit": "yes"}], "file_frames[0].frame_inherit: expected true or false"),
    ([{"frame_inherit": True, "frame_parent": 7}], "file_frames[0].frame_parent: expected"),
    ([{"frame_inherit": True, "frame_parent": "0"}], "file_frames[0].frame_parent: expected"),
    ([{"frame_inherit": True, "frame_parent": 1}], "frame_parent makes a cycle"),
    (
        [{"frame_inherit": True, "edges_foldAngle": ["x", 0, 0, 0, 0]}],
        "frame 1 (file_frames[0]): edges_foldAngle[0]: expected a number",
    ),
    ([{"vertices_coords": [[0, 0]]}], "frame 1 (file_frames[0]): the frame has neither"),
]


def test_overlapping_edges_with_different_assignments_are_an_error_without_faces():
    """FOLD coordinates are exact: edges that overlap with different letters contradict each
    other (the SVG reader, whose drawings are not exact, applies Origami Simulator's rule)."""
    data = {
        "file_spec": 1.2,
        "vertices_coords": [[0, 0], [2, 0], [2, 2], [0, 2], [1, 1]],
        "edges_vertices": [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2], [0, 4]],
        "edges_assignment": ["B", "B", "B", "B", "V", "M"],
    }
    with pytest.raises(PatternError) as info:
        from_fold_dict(data)
    assert "edges_vertices[4] and edges_vertices[5]: overlap with different assignments" in str(
        info.value
    )


def test_far_vertex_without_faces_is_named():
    data = {
        "file_spec": 1.2,
        "vertices_coords": [[0, 0], [1, 0], [1, 1], [0, 1], [1e20, 0]],
        "edges_vertices": [[0, 1], [1, 2], [2, 3], [3, 0], [1, 4], [4, 2]],
        "edges_assignment": ["B", "M", "B", "B", "B", "B"],
    }
    with pytest.raises(PatternError) as info:
        from_fold_dict(data)
    assert str(info.value).startswith(
        "edges_vertices[5]: its point (1e+20, 0) spreads the lines over 1e+20, so 4 of the 6 "
        "lines are shorter than the merge tolerance"
    )


def test_slit_loads_as_a_free_hinge_with_a_warning():
    """A cut with both ends inside the paper and no other cut at them cannot open: loaded as
    Origami Simulator loads it, a free hinge (U, angle 0), with a warning naming the edge."""
    data = {
        "file_spec": 1.2,
        "vertices_coords": [[0, 0], [1, 0], [1, 1], [0, 1], [0, 0.5], [0.3, 0.5], [0.7, 0.5]]
        + [[1, 0.5]],
        "edges_vertices": [[0, 1], [1, 7], [7, 2], [2, 3], [3, 4], [4, 0], [4, 5], [5, 6]]
        + [[6, 7]],
        "edges_assignment": ["B"] * 6 + ["M", "C", "M"],
        "edges_foldAngle": [0] * 6 + [-90, 0, -90],
        "faces_vertices": [[0, 1, 7, 6, 5, 4], [4, 5, 6, 7, 2, 3]],
    }
    with pytest.warns(PatternWarning) as record:
        cp = from_fold_dict(data)
    assert cp.assignments[7] == "U" and cp.fold_angles[7] == 0.0
    assert "".join(cp.assignments) == "BBBBBBMUM"
    messages = [str(w.message) for w in record]
    assert messages == [
        "edges_vertices[7]: is a cut whose ends are both inside the paper and meet no other "
        "cut (a slit), which cannot open; loaded as a free hinge (U, angle 0), as Origami "
        "Simulator does"
    ]
    # with the cut reaching the paper's edge it opens: it stays a cut, and nothing is said
    data["edges_assignment"][6] = "C"
    data["edges_foldAngle"][6] = 0
    with warnings.catch_warnings():
        warnings.simplefilter("error", PatternWarning)
        cp = from_fold_dict(data)
    assert "".join(cp.assignments) == "BBBBBBCCM"


@pytest.mark.parametrize(
    ("frames", "expected"), MALFORMED_FRAMES, ids=[m[1] for m in MALFORMED_FRAMES]
)
def test_malformed_frames_raise_pattern_error(frames, expected):
    data = base()
    data["file_frames"] = frames
    with pytest.raises(PatternError) as info:
        from_fold_dict(data, frame=1)
    assert expected in str(info.value)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("{", "invalid JSON at line 1"),
        ('{"vertices_coords": [[0, 0], [1, 0]]\n  "x": 1}', "invalid JSON at line 2"),
        ("", "invalid JSON"),
        ("[1, 2, 3]", "expected a JSON object"),
        ("NaN", "expected a JSON object"),
        ("[" * 100000 + "]" * 100000, "invalid JSON"),
    ],
)
def test_invalid_json_files(tmp_path, text, expected):
    path = tmp_path / "bad.fold"
    path.write_text(text)
    with pytest.raises(PatternError) as info:
        load(path)
    assert str(info.value).startswith(str(path))
    assert expected in str(info.value)


def test_binary_file_is_a_pattern_error(tmp_path):
    path = tmp_path / "bad.fold"
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(PatternError, match="bad.fold"):
        load(path)


def test_missing_file_and_folder_name_the_path(tmp_path):
    missing = tmp_path / "nope.fold"
    with pytest.raises(PatternError) as info:
        load(missing)
    assert str(missing) in str(info.value)
    assert "No such file" in str(info.value)
    folder = tmp_path / "dir.fold"
    folder.mkdir()
    with pytest.raises(PatternError, match="dir.fold"):
        load_fold(folder)


def test_unsupported_suffixes(tmp_path):
    with pytest.raises(PatternError, match=r"unsupported input format '\.dxf' \(supported: \.fold"):
        load(tmp_path / "x.dxf")
    with pytest.raises(PatternError, match=r"unsupported input format \(no suffix\)"):
        load(tmp_path / "x")
    for bad in ("x.xyz", "x"):
        with pytest.raises(
            ValueError, match=r"supported: \.fold, \.json, \.svg, \.obj, \.ply"
        ) as info:
            save(tmp_path / bad, diagonal_valley())
        assert type(info.value) is ValueError
    with pytest.raises(ValueError, match=r"supported: \.obj, \.ply, \.stl, \.vtu") as info:
        save_mesh(tmp_path / "x.off", diagonal_valley())
    assert type(info.value) is ValueError
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------------------------
# mesh export


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl", ".vtu"])
@pytest.mark.parametrize("folded_state", [False, True])
def test_mesh_export_reads_back(tmp_path, suffix, folded_state):
    cp = two_quads()
    obj = folded(cp) if folded_state else cp
    path = tmp_path / f"mesh{suffix}"
    save(path, obj)
    assert path.stat().st_size > 0
    m = meshio.read(path)
    triangles = np.concatenate([c.data for c in m.cells if c.type == "triangle"])
    assert triangles.shape == cp.mesh.triangles.shape
    assert len(m.points) == cp.mesh.num_vertices
    expected = obj.positions if folded_state else cp.mesh.vertices
    if suffix != ".stl":  # STL has no shared points: the reader makes its own numbering
        np.testing.assert_allclose(np.asarray(m.points)[:, :3], expected, atol=1e-6)
        np.testing.assert_array_equal(triangles, cp.mesh.triangles)
    else:
        got = np.sort(np.round(np.asarray(m.points)[triangles], 5).reshape(-1, 9), axis=0)
        want = np.sort(np.round(expected[cp.mesh.triangles], 5).reshape(-1, 9), axis=0)
        np.testing.assert_allclose(got, want, atol=1e-5)
    assert sorted(os.listdir(tmp_path)) == [path.name]


def test_vtu_carries_strain_and_fold_angles(tmp_path):
    cp = cut_pattern()
    mesh = cp.mesh
    res = folded(cp, seed=1)
    res = replace(res, positions=2.0 * mesh.vertices)  # every edge stretched 100 %
    path = tmp_path / "out.vtu"
    save_mesh(path, res)
    m = meshio.read(path)
    assert [c.type for c in m.cells] == ["triangle", "line"]
    np.testing.assert_array_equal(m.cells[0].data, mesh.triangles)
    np.testing.assert_array_equal(m.cells[1].data, mesh.edges)
    for name in ("strain", "fold_angle", "target_fold_angle", "assignment"):
        assert name in m.cell_data and len(m.cell_data[name]) == 2
    strain_t, strain_e = m.cell_data["strain"]
    np.testing.assert_allclose(strain_t, 1.0, atol=1e-12)
    np.testing.assert_allclose(strain_e, 1.0, atol=1e-12)
    angle_t, angle_e = m.cell_data["fold_angle"]
    assert np.isnan(angle_t).all()
    expected = np.where(mesh.role == "border", 0.0, res.fold_angles)
    np.testing.assert_allclose(angle_e, expected, atol=1e-12)
    np.testing.assert_allclose(m.cell_data["target_fold_angle"][1], mesh.target)
    codes = m.cell_data["assignment"][1]
    np.testing.assert_array_equal(m.cell_data["assignment"][0], -1)
    letters = ["BMVFUCJ"[int(c)] for c in codes]
    for k, src in enumerate(mesh.source_edge):
        assert letters[k] == ("F" if src < 0 else cp.assignments[src])


def test_vtu_strain_of_a_sheared_triangle(tmp_path):
    cp = diagonal_valley()
    x = cp.mesh.vertices.copy()
    x[1] = [1.5, 0.0, 0.0]  # stretches edges 0-1 (x1.5) and 1-2 (sqrt(1.25)/1)
    res = FakeResult(cp, x, np.zeros(cp.mesh.num_edges))
    path = tmp_path / "s.vtu"
    save_mesh(path, res)
    m = meshio.read(path)
    strain_t = m.cell_data["strain"][0]
    t = [i for i, tri in enumerate(cp.mesh.triangles) if 1 in tri][0]
    assert strain_t[t] == pytest.approx((0.5 + (math.sqrt(1.25) - 1)) / 3)
    assert strain_t[1 - t] == pytest.approx(0.0)


def test_flat_pattern_vtu_has_zero_strain_and_angles(tmp_path):
    cp = explicit_angles()
    path = tmp_path / "flat.vtu"
    save(path, cp)
    m = meshio.read(path)
    np.testing.assert_allclose(m.cell_data["strain"][0], 0.0, atol=1e-15)
    np.testing.assert_allclose(m.cell_data["fold_angle"][1], 0.0)
    np.testing.assert_allclose(m.cell_data["target_fold_angle"][1], cp.mesh.target)


# ---------------------------------------------------------------------------------------------
# atomic writes


def test_failing_fold_write_leaves_nothing(tmp_path, monkeypatch):
    path = tmp_path / "p.fold"

    def boom(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(fold_module.os, "replace", boom)
    with pytest.raises(OSError, match="disk full"):
        save_fold(path, diagonal_valley())
    assert os.listdir(tmp_path) == []


def test_failing_mesh_write_leaves_nothing_and_keeps_old_file(tmp_path, monkeypatch):
    path = tmp_path / "m.vtu"
    save_mesh(path, two_quads())
    before = path.read_bytes()

    def half_write(filename, mesh, file_format=None, **kwargs):
        # a temporary file beside the target, with the target's suffix
        assert Path(filename).parent == tmp_path
        assert Path(filename).suffix == "." + file_format
        Path(filename).write_text("<half a file")
        raise RuntimeError("writer crashed")

    monkeypatch.setattr(mesh_module.meshio, "write", half_write)
    with pytest.raises(RuntimeError, match="writer crashed"):
        save_mesh(path, folded(two_quads()))
    assert os.listdir(tmp_path) == ["m.vtu"]
    assert path.read_bytes() == before
    with pytest.raises(RuntimeError):
        save_mesh(tmp_path / "new.obj", two_quads())
    assert os.listdir(tmp_path) == ["m.vtu"]


def test_failing_result_save_leaves_no_file(tmp_path):
    cp = diagonal_valley()
    bad = FakeResult(cp, np.zeros((2, 3)), np.zeros(5))
    for name in ("r.fold", "r.obj", "r.vtu"):
        with pytest.raises(ValueError):
            save(tmp_path / name, bad)
    assert os.listdir(tmp_path) == []


def test_saved_file_has_ordinary_permissions(tmp_path):
    path = tmp_path / "p.fold"
    save(path, diagonal_valley())
    mask = os.umask(0)
    os.umask(mask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask


def test_save_into_missing_folder_raises(tmp_path):
    with pytest.raises(FileNotFoundError):
        save(tmp_path / "no" / "p.fold", diagonal_valley())
