"""Figures, HTML, animations and the render command (origami_jax.viz, ``origami-jax render``).

One small pattern (Miura-ori 2 x 2, 8 triangles) folded once with L-BFGS; every fold here reuses
that compiled solver (same shapes), so the file stays fast.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection  # noqa: E402

from origami_jax import fold, io, patterns, viz  # noqa: E402
from origami_jax.cli import main  # noqa: E402
from origami_jax.metrics import shape_error  # noqa: E402
from origami_jax.viz import figures, hidden, views  # noqa: E402

SOLVER = "lbfgs"  # compiles fastest; every fold in this file shares its compiled code


@pytest.fixture(scope="module")
def result():
    r = fold(patterns.miura_ori(2, 2), solver=SOLVER)
    assert r.converged, r.reason
    return r


@pytest.fixture(scope="module")
def flat_folded():
    """A sheet folded flat in half (its folded state is a plane)."""
    r = fold(patterns.single_crease(fold_angle=np.pi))
    assert r.converged, r.reason
    return r


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _picture(ax):
    """The display box of what ``ax`` draws of the sheet (faces and creases, as projected)."""
    from matplotlib.transforms import Bbox

    ax.figure.canvas.draw()  # 3-D collections have their 2-D paths once projected
    paths = [p.vertices for c in ax.collections for p in c.get_paths()]
    points = ax.transData.transform(np.concatenate(paths))
    return Bbox([points.min(axis=0), points.max(axis=0)])


def _lines(ax) -> dict[str, Line3DCollection]:
    return {c.get_label(): c for c in ax.collections if isinstance(c, Line3DCollection)}


# -- data ----------------------------------------------------------------------------------------


def test_edge_assignments_mark_triangulation_edges_as_facets(result):
    cp = result.pattern
    letters = viz.edge_assignments(cp)
    assert len(letters) == cp.mesh.num_edges == 16
    assert list(letters[: cp.num_edges]) == list(cp.assignments)
    assert set(letters[cp.num_edges :]) == {"F"}


def test_face_values_strain_and_error(result):
    cp = result.pattern
    flat = cp.mesh.vertices
    assert np.allclose(viz.face_values(flat, "strain", cp), 0.0)
    # flat: every face touches a crease with target +-pi/2, error pi/2 at full percent
    err = viz.face_values(flat, "fold_angle_error", cp)
    assert err.shape == (len(cp.mesh.triangles),)
    assert np.allclose(err, np.pi / 2)
    # the folded result: the same from its fold angles and from positions alone
    from_result = viz.face_values(result, "fold_angle_error")
    from_positions = viz.face_values(result.positions, "fold_angle_error", cp)
    assert np.allclose(from_result, from_positions, atol=1e-9)
    assert from_result.max() < 1e-6
    with pytest.raises(ValueError, match="color"):
        viz.face_values(result, "nope")


def test_occluded_parts_of_creases_are_cut_away():
    segment = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]])
    # a triangle above the middle of the segment, seen from straight above
    above = np.array([[[0.4, -1.0, 1.0], [0.6, -1.0, 1.0], [0.5, 2.0, 1.0]]])
    pieces = hidden.visible_pieces(segment, above, np.array([0.0, 0.0, 1.0]))
    assert pieces.shape == (2, 2, 3)
    assert pieces[0, 0, 0] == 0.0 and pieces[1, 1, 0] == 1.0
    assert 0.3 < pieces[0, 1, 0] <= 0.45 and 0.55 <= pieces[1, 0, 0] < 0.7
    # seen from below, nothing hides it
    kept = hidden.visible_pieces(segment, above, np.array([0.0, 0.0, -1.0]))
    assert np.array_equal(kept, segment)


# -- matplotlib ----------------------------------------------------------------------------------


def test_plot_fold_faces_creases_and_framing(result):
    fig = viz.plot_fold(result, hide_occluded=False)
    fig.canvas.draw()  # 3-D collections have their 2-D paths once projected
    ax = fig.axes[0]
    faces = [c for c in ax.collections if isinstance(c, Poly3DCollection)]
    assert len(faces) == 1
    assert len(faces[0].get_paths()) == len(result.pattern.mesh.triangles) == 8
    lines = _lines(ax)
    # 2 x 2 Miura: 8 border edges, 1 mountain, 3 valleys; facets hidden by default
    expected = {"border": (8, "#000000"), "mountain": (1, "#ff0000"), "valley": (3, "#0000ff")}
    assert set(lines) == set(expected)
    for name, (count, colour) in expected.items():
        assert len(lines[name].get_segments()) == count
        assert to_hex(lines[name].get_color()[0]) == colour
    assert len(fig.axes) == 1  # no colour bar without a colour
    # limits hold every vertex, with equal scales on the three axes
    x = result.positions
    limits = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])
    assert (limits[:, 0] <= x.min(0)).all() and (x.max(0) <= limits[:, 1]).all()
    scale = (limits[:, 1] - limits[:, 0]) / np.asarray(ax.get_box_aspect())
    assert np.allclose(scale, scale[0], rtol=1e-6)


def test_plot_fold_leaves_out_a_crease_kind_hidden_everywhere(result, monkeypatch):
    # a flat-folded base seen from above hides every crease of some kinds under its top layer;
    # such a kind is left out of the picture (matplotlib refuses an empty 3-D line collection)
    hidden_kinds = {"mountain"}
    pieces = figures.visible_pieces
    kinds = {}

    def visible(segments, triangles, view):
        out = pieces(segments, triangles, view)
        return out[:0] if kinds.get(id(segments)) in hidden_kinds else out

    crease_segments = figures.crease_segments

    def named(pattern, x, show_facets):
        found = crease_segments(pattern, x, show_facets)
        kinds.update({id(v): viz.ASSIGNMENT_NAMES[k] for k, v in found.items()})
        return found

    # the names plot_fold's drawing looks up, in its module
    monkeypatch.setattr(figures, "visible_pieces", visible)
    monkeypatch.setattr(figures, "crease_segments", named)
    fig = viz.plot_fold(result)
    fig.canvas.draw()
    assert set(_lines(fig.axes[0])) == {"border", "valley"}
    plt.close(fig)


def test_plot_fold_facets_and_colour_bar(result):
    fig = viz.plot_fold(result, color="strain", show_facets=True, hide_occluded=False)
    fig.canvas.draw()
    lines = _lines(fig.axes[0])
    assert len(lines["facet"].get_segments()) == 4  # the quads' diagonals
    assert to_hex(lines["facet"].get_color()[0]) == "#ffff00"
    assert len(fig.axes) == 2 and "strain" in fig.axes[1].get_ylabel()
    fig = viz.plot_fold(result.positions, result.pattern, color="fold_angle_error")
    assert "fold-angle" in fig.axes[1].get_ylabel()
    assert len(viz.plot_fold(result, show_creases=False).axes[0].collections) == 1


@pytest.mark.parametrize("color", [None, "strain"])
def test_plot_fold_frames_the_sheet_beside_its_colour_bar(result, color):
    """The sheet's picture is centred in its axes and fills them up to a margin: nothing cut
    off at the figure's edges, nothing under the colour bar, which has an axes of its own."""
    fig = viz.plot_fold(result, color=color)
    ax = fig.axes[0]
    picture, box = _picture(ax), ax.bbox
    assert box.x0 < picture.x0 and picture.x1 < box.x1
    assert box.y0 < picture.y0 and picture.y1 < box.y1
    assert fig.bbox.contains(*picture.p0) and fig.bbox.contains(*picture.p1)
    fill = max(picture.width / box.width, picture.height / box.height)
    assert 0.85 < fill < 0.95
    assert np.allclose(
        [picture.x0 - box.x0, picture.y0 - box.y0],
        [box.x1 - picture.x1, box.y1 - picture.y1],
        atol=2.0,
    )
    if color is not None:
        bar = fig.axes[1].get_tightbbox(fig.canvas.get_renderer())  # ticks and label too
        assert not picture.overlaps(bar) and not box.overlaps(fig.axes[1].bbox)
        assert fig.bbox.x1 >= bar.x1  # its label inside the figure


def _normal(points) -> np.ndarray:
    """The unit normal of the best-fit plane of ``points`` (N, 3)."""
    return np.linalg.svd(points - points.mean(axis=0))[2][2]


def test_a_flat_folded_sheet_is_not_seen_edge_on(flat_folded):
    """A sheet folded flat in half, turned so that matplotlib's default camera would see it
    edge-on (a line): it is drawn seen along its normal, as wide as it is."""
    x = np.asarray(flat_folded.positions)
    x = x - x.mean(axis=0)
    own = np.linalg.svd(x)[2]  # the sheet's axes, its normal last
    assert np.ptp(x @ own[2]) < 1e-6  # flat
    camera = views.view_vector(*viz.DEFAULT_VIEW)
    normal = np.cross(camera, [0.0, 0.0, 1.0])
    normal /= np.linalg.norm(normal)
    turn = np.stack([camera, np.cross(normal, camera), normal], axis=1)  # the normal to normal
    edge_on = x @ own.T @ turn.T
    assert abs(_normal(edge_on) @ camera) < 1e-6  # the plane holds the default camera's ray
    for points, pattern in [(flat_folded, None), (edge_on, flat_folded.pattern)]:
        fig = viz.plot_fold(points, pattern)
        ax = fig.axes[0]
        seen_from = views.view_vector(ax.elev, ax.azim)
        assert abs(seen_from @ _normal(np.asarray(getattr(points, "positions", points)))) > 0.999
        picture = _picture(ax)  # edge-on, it would be a line
        assert min(picture.width, picture.height) > 0.4 * max(picture.width, picture.height)
    # a camera given is used as given
    ax = viz.plot_fold(edge_on, flat_folded.pattern, elev=30.0, azim=-60.0).axes[0]
    assert (ax.elev, ax.azim) == (30.0, -60.0)


def test_default_view(result):
    """From above for the unfolded sheet (x to the right, y up, as in the pattern's plot), the
    default camera for a sheet that is not flat."""
    assert viz.default_view(result.pattern.mesh.vertices) == (90.0, -90.0)
    assert viz.default_view(result.positions) == viz.DEFAULT_VIEW


def test_plot_fold_needs_pattern_for_positions(result):
    with pytest.raises(ValueError, match="pattern"):
        viz.plot_fold(result.positions)
    with pytest.raises(ValueError, match="rows"):
        viz.plot_fold(result.positions[:5], result.pattern)


def test_plot_pattern_line_counts_by_colour():
    cp = patterns.seed_waterbomb()  # B=20 M=32 V=16 F=5
    ax = viz.plot_pattern(cp).axes[0]
    counts = {}
    for c in ax.collections:
        colours = {to_hex(rgba, keep_alpha=False) for rgba in c.get_colors()}
        assert len(colours) == 1
        counts[colours.pop()] = len(c.get_segments())
    assert counts == {"#000000": 20, "#ff0000": 32, "#0000ff": 16, "#ffff00": 5}
    # opacity from the target: mountains at -pi/2 fainter than valleys at +pi
    alpha = {
        to_hex(c.get_colors()[0], keep_alpha=False): c.get_colors()[0][3] for c in ax.collections
    }
    assert alpha["#ff0000"] < alpha["#0000ff"] == 1.0


def test_plot_history_from_result_and_csv(result, tmp_path):
    ax = viz.plot_history(result).axes[0]
    assert len(ax.get_lines()) == 3
    assert ax.get_xscale() == ax.get_yscale() == "log"
    csv = tmp_path / "history.csv"
    rows = ["case,solver,iteration,wall_time,fold_angle_error_max,strain_max,energy,grad_norm_rel"]
    for case in ("a", "b"):
        for solver in ("newton", "lbfgs"):
            for k in range(4):
                rows.append(f"{case},{solver},{k},{0.1 * k},{10.0**-k},{1e-3 * k},1.0,{10.0**-k}")
    csv.write_text("\n".join(rows) + "\n")
    ax = viz.plot_history(csv, pattern="a", metrics=("fold_angle_error_max",)).axes[0]
    assert [line.get_label() for line in ax.get_lines()] == [
        "newton: fold_angle_error_max",
        "lbfgs: fold_angle_error_max",
    ]
    assert len(viz.plot_history(str(csv), pattern="b").axes[0].get_lines()) == 6
    with pytest.raises(ValueError, match="several patterns"):
        viz.plot_history(csv)


# -- plotly --------------------------------------------------------------------------------------


def test_plotly_fold_and_html(result, tmp_path):
    pytest.importorskip("plotly")
    fig = viz.plotly_fold(result, color="strain")
    mesh = [t for t in fig.data if t.type == "mesh3d"]
    assert len(mesh) == 1 and len(mesh[0].i) == len(result.pattern.mesh.triangles)
    assert len(mesh[0].intensity) == 8
    names = {t.name: t.line.color for t in fig.data if t.type == "scatter3d"}
    assert names == {"border": "#000000", "mountain": "#ff0000", "valley": "#0000ff"}
    assert fig.layout.scene.aspectmode == "data"
    out = viz.save_html(result, tmp_path / "fold.html")
    text = out.read_text(encoding="utf-8")
    assert len(text) > 100_000 and "plotly" in text  # plotly.js inlined: works offline
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left behind


# -- animation -----------------------------------------------------------------------------------


def test_animate_fold_gif_frames(result, tmp_path):
    from PIL import Image

    path = tmp_path / "fold.gif"
    frames = viz.animate_fold(
        result.pattern, path, frames=4, fps=5, solver=SOLVER, dpi=40, figsize=(3, 2.5)
    )
    assert len(frames) == 4 and np.allclose(frames[0], result.pattern.mesh.vertices)
    # by continuation: the same folded shape (placed elsewhere in space)
    assert shape_error(frames[-1], result.positions, result.pattern.diameter) < 1e-6
    with Image.open(path) as im:
        assert im.n_frames == 4
    # precomputed frames (e.g. a trajectory), coloured
    path2 = tmp_path / "given.gif"
    viz.animate_fold(result.pattern, path2, frames=frames[1:], color="strain", dpi=40)
    with Image.open(path2) as im:
        assert im.n_frames == 3
    with pytest.raises(ValueError, match=".avi"):
        viz.animate_fold(result.pattern, tmp_path / "x.avi", frames=frames)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fold.gif", "given.gif"]


def test_animate_a_fold_path(tmp_path):
    """The states a fold followed from flat (``result.frames``) animate as they are."""
    from PIL import Image

    cp = patterns.single_crease(fold_angle=np.pi)
    folded = fold(cp)
    assert folded.path == "continuation" and len(folded.frames) >= 3
    path = tmp_path / "path.gif"
    shown = viz.animate_fold(cp, path, frames=folded.frames, dpi=40, figsize=(3, 2.5))
    with Image.open(path) as im:
        assert im.n_frames == len(folded.frames)
    np.testing.assert_array_equal(shown[-1], folded.positions)


def test_mp4_with_imageio_ffmpeg(result, tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    path = tmp_path / "fold.mp4"
    frames = [result.pattern.mesh.vertices, result.positions]
    viz.animate_fold(result.pattern, path, frames=frames, dpi=41)  # odd size: padded to even
    assert path.read_bytes()[4:8] == b"ftyp"  # an MP4 container


def test_mp4_without_ffmpeg_is_a_clear_error(result, tmp_path, monkeypatch):
    from matplotlib import animation

    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)
    with pytest.raises(RuntimeError, match="imageio-ffmpeg"):
        viz.animate_fold(result.pattern, tmp_path / "x.mp4", frames=[result.positions])
    assert not list(tmp_path.iterdir())


# -- optional dependencies -----------------------------------------------------------------------


def test_require_and_movie_settings_check_before_any_work(tmp_path):
    # what ``origami-jax render`` calls before it folds
    assert viz.require("matplotlib") is matplotlib
    with pytest.raises(ValueError, match="'matplotlib' or 'plotly'"):
        viz.require("pillow")
    assert viz.movie_settings(str(tmp_path / "fold.gif")) == {}
    with pytest.raises(ValueError, match="unsupported animation format"):
        viz.movie_settings(tmp_path / "fold.avi")
    assert not list(tmp_path.iterdir())


def test_import_does_not_load_plotting_libraries():
    code = (
        "import sys, origami_jax, origami_jax.viz; "
        "print([m for m in ('matplotlib', 'plotly') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_missing_extra_names_it(result, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    with pytest.raises(ImportError, match=r"origami-jax\[viz\]"):
        viz.plot_fold(result)
    monkeypatch.setitem(sys.modules, "plotly", None)
    monkeypatch.setitem(sys.modules, "plotly.graph_objects", None)
    with pytest.raises(ImportError, match=r"origami-jax\[viz\]"):
        viz.plotly_fold(result)


# -- the render command --------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".png", ".html", ".gif"])
def test_render_writes_file(suffix, result, tmp_path, capsys):
    if suffix == ".html":
        pytest.importorskip("plotly")
    src = tmp_path / "miura.fold"
    io.save(src, result.pattern)
    out = tmp_path / f"fold{suffix}"
    argv = ["render", str(src), "--out", str(out), "--solver", SOLVER, "--dpi", "40"]
    argv += ["--frames", "3", "--color", "strain"] if suffix == ".gif" else []
    code = main(argv)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert out.stat().st_size > 0 and "written" in captured.out
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([src.name, out.name])
    if suffix == ".png":
        assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_render_solve_options(result, tmp_path, capsys):
    """``render`` takes ``fold``'s ``--float32``, ``--tol`` and ``--max-time``."""
    src = tmp_path / "miura.fold"
    io.save(src, result.pattern)
    out = tmp_path / "fold.png"
    argv = ["render", str(src), "--out", str(out), "--solver", SOLVER, "--dpi", "20"]
    assert main([*argv, "--float32", "--tol", "1e-3"]) == 0, capsys.readouterr().err
    table = capsys.readouterr().out
    assert f"{SOLVER} (float32)" in table and "tol 1.0e-03" in table
    assert main([*argv, "--max-time", "0"]) == 1
    assert "time limit reached" in capsys.readouterr().out


def test_render_bad_extension_is_an_error_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "fold.xyz"
    assert main(["render", "--example", "single_crease", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and ".xyz" in err
    assert not list(tmp_path.iterdir())
