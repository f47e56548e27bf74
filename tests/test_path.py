"""Folding along the physical path: continuation in fold percent, its frames, their export,
and the stiff and extreme cases a flat-foldable or rigid-foldable pattern must reach."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import CreasePattern, fold, io, patterns
from origami_jax.barrier import HINGE_GAP
from origami_jax.energy import Barriers, energy, make_params, make_structure
from origami_jax.fold import PATH_HINGE_GAP, PATH_MAX_STEP, is_unfolded
from origami_jax.kinematics import rigid_fold
from origami_jax.solvers import Status


def test_a_full_fold_follows_the_path_from_flat():
    cp = patterns.degree4_vertex(2.0, 0.7, np.pi)
    result = fold(cp)
    assert result.path == "continuation" and result.barriers == Barriers()
    assert result.converged, result.reason
    assert result.fold_angle_error_max <= 1e-8 and len(result.through_pi) == 0
    # the frames: flat first, fold percents rising to the full fold, the last one the result
    percents = [f.percent for f in result.frames]
    assert percents[0] == 0.0 and percents[-1] == pytest.approx(1.0)
    assert np.all(np.diff(percents) >= 0)
    np.testing.assert_array_equal(result.frames[-1].positions, result.positions)
    np.testing.assert_allclose(result.frames[0].positions, cp.mesh.vertices)
    for frame in result.frames:  # on the way the gap is wider; at the end, the scene's
        assert frame.positions.shape == result.positions.shape
        assert np.max(np.abs(frame.fold_angles)) <= np.pi + PATH_HINGE_GAP
    assert np.max(np.abs(result.frames[-1].fold_angles)) <= np.pi + HINGE_GAP
    # the history starts where a direct solve's does: flat, fully driven
    direct = fold(cp, path="direct")
    assert result.history["energy"][0] == pytest.approx(direct.history["energy"][0], rel=1e-12)
    assert direct.frames == [] and direct.path == "direct"
    assert result.history["grad_norm_rel"][-1] == pytest.approx(result.grad_norm_rel, rel=1e-9)


def test_rigid_foldable_scenes_fold_directly_without_barriers():
    cp = patterns.miura_ori(3, 3, fold_angle=1.5)
    result = fold(cp, reference_positions=rigid_fold(cp))
    assert result.path == "direct" and result.barriers == Barriers(0.0, 0.0)
    assert result.shape_error <= 1e-8
    with pytest.raises(ValueError, match="path must be"):
        fold(cp, path="sideways")


def test_path_frames_are_written_as_fold_frames(tmp_path):
    cp = patterns.single_crease(fold_angle=np.pi)
    result = fold(cp)
    assert len(result.frames) >= 3
    out = tmp_path / "path.fold"
    io.save(out, result)
    data = json.loads(out.read_text())
    frames = data["file_frames"]
    assert len(frames) == 1 + len(result.frames)
    k = cp.mesh.edges_with_role("driven")[0]
    for frame, state in zip(frames[1:], result.frames, strict=True):
        assert frame["frame_title"].endswith(f"fold percent {100 * state.percent:.6g}")
        assert frame["edges_foldAngle"][k] == pytest.approx(np.degrees(state.fold_angles[k]))
    assert frames[-1]["edges_foldAngle"][k] == pytest.approx(180.0, abs=1e-6)


def test_a_start_in_a_tilted_plane_counts_as_flat():
    cp = patterns.single_crease(fold_angle=np.pi)
    x = cp.mesh.vertices
    turned = x @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # the sheet in the x-z plane
    half = rigid_fold(cp, 0.5 * cp.mesh.target)
    assert is_unfolded(turned, cp.mesh) and not is_unfolded(half, cp.mesh)
    # folded flat: planar, but not the unfolded sheet
    assert not is_unfolded(rigid_fold(cp, cp.mesh.target), cp.mesh)
    assert fold(cp, start=turned).path == "continuation"
    assert fold(cp, start=half).path == "direct"


def square_base(shift: float = 0.0) -> CreasePattern:
    """The square (preliminary) base of a 2 x 2 sheet, folded flat: both midlines mountains and
    one diagonal a valley, all to +-pi (a flat-foldable degree-6 vertex, as Origami Simulator's
    squareBase.svg). ``shift`` moves the centre along x: off Kawasaki's condition, the flat
    fold then needs strained bars."""
    vertices = [[0, 0], [1, 0], [2, 0], [2, 1], [2, 2], [1, 2], [0, 2], [0, 1], [1 + shift, 1]]
    edges = [[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 7], [7, 0]]
    edges += [[1, 8], [8, 5], [3, 8], [8, 7], [0, 8], [8, 4]]
    faces = [[0, 1, 8], [1, 2, 3, 8], [3, 4, 8], [4, 5, 8], [5, 6, 7, 8], [7, 0, 8]]
    angles = [0.0] * 8 + [-np.pi] * 4 + [np.pi] * 2
    return CreasePattern(vertices, edges, faces, "B" * 8 + "MMMMVV", angles, "square base")


FLAT_FOLDABLE = {
    "miura 3 x 3 (rigid)": patterns.miura_ori(3, 3, fold_angle=2.0),
    "degree-4 vertex, flat": patterns.degree4_vertex(2.0, 0.7, np.pi),
    "square twist, flat": patterns.square_twist(fold_angle=np.pi),
    "square base, flat": square_base(),
}


@pytest.mark.parametrize("name", list(FLAT_FOLDABLE))
def test_stiff_and_extreme_cases_reach_the_zero_energy_state(name):
    """A pattern with a zero-energy folded state reaches it, with no crease past pi, at every
    axial : crease ratio from 1e2 to 1e8 (facets 20x the crease) and at sheet sizes 1e-6 and
    1e6."""
    cp = FLAT_FOLDABLE[name]
    for ratio in (1e2, 1e4, 1e6, 1e8):
        stiffness = {"axial": 1.0, "facet": 20.0 / ratio, "crease": 1.0 / ratio}
        result = fold(cp, stiffness=stiffness)
        assert result.converged, (ratio, result.reason)
        assert result.fold_angle_error_max <= 1e-6, ratio
        assert len(result.through_pi) == 0 and len(result.collapsed) == 0
    for scale in (1e-6, 1e6):
        scaled = CreasePattern(
            cp.vertices * scale, cp.edges, cp.faces, cp.assignments, cp.fold_angles, cp.name
        )
        result = fold(scaled)
        assert result.converged, (scale, result.reason)
        assert result.fold_angle_error_max <= 1e-6 and len(result.through_pi) == 0
        assert len(result.collapsed) == 0


def test_targets_that_strain_the_bars_give_way_when_stiff():
    """A square base drawn off flat-foldability (its centre 0.01 off) reaches its flat targets
    only by straining its bars: no zero-energy state. At the defaults the creases hold that
    prestressed fold; at axial : crease 1e8 the strained bars buckle it, and the solve ends
    converged in an equilibrium of far lower energy than the targets' (benchmarks/extreme.py
    reports such shared files apart)."""
    cp = square_base(shift=0.01)
    base = fold(cp)
    assert base.converged and base.fold_angle_error_max <= 1e-6
    assert base.strain_max > 1e-3
    stiffness = {"axial": 1.0, "facet": 20.0 / 1e8, "crease": 1.0 / 1e8}
    params = make_params(cp, 1.0, stiffness, jnp.float64)
    at_targets = float(energy(jnp.asarray(base.positions), make_structure(cp.mesh), params))
    result = fold(cp, stiffness=stiffness)
    assert result.converged, result.reason
    assert result.energy < 1e-3 * at_targets
    assert result.fold_angle_error_max > 0.1
    assert len(result.through_pi) == 0 and len(result.collapsed) == 0


def test_path_end_raises_the_stiffness_after_the_fold():
    # the path's second half, at full percent, only stiffens the bars and facets back to
    # the user's: the last frame and the result agree with a direct solve from there
    cp = patterns.degree4_vertex(2.0, 0.7, np.pi)
    result = fold(cp)
    again = fold(cp, start=result.positions, path="direct")
    assert again.converged and again.iterations <= 2
    np.testing.assert_allclose(again.positions, result.positions, atol=1e-9 * cp.diameter)


def test_path_frames_rise_by_the_adaptive_steps():
    result = fold(patterns.degree4_vertex(2.0, 0.7, np.pi))
    percents = np.array([f.percent for f in result.frames])
    assert np.all(np.diff(percents) > 0) and percents[-1] == pytest.approx(1.0)
    assert np.max(np.diff(percents)) <= PATH_MAX_STEP + 1e-12


def test_a_path_cut_short_is_not_converged():
    cp = patterns.degree4_vertex(2.0, 0.7, np.pi)
    for limit in (3, 8, 24):
        result = fold(cp, max_iter=limit)
        assert not result.converged and result.status == Status.MAX_ITER, limit
        assert result.iterations <= limit
    assert not fold(cp, max_time=0.0).converged


def test_first_order_solvers_follow_the_path_on_the_same_scale():
    """L-BFGS asked to follow the path: its tolerance is relative to the same start gradient
    as a direct solve's (its grad_norm_rel of the same size), and it reaches the target."""
    cp = patterns.single_crease(fold_angle=np.pi)
    path = fold(cp, solver="lbfgs", path="continuation")
    direct = fold(cp, solver="lbfgs", path="direct")
    assert path.converged and direct.converged
    assert path.grad_norm_rel <= 1e-10 and path.grad_norm_rel > 1e-14
    assert path.fold_angle_error_max <= 1e-6


def test_a_folded_form_is_its_own_target_and_mirrored_if_folded_against_its_letters():
    """A FOLD folded form without fold angles: its creases' targets are their angles in it;
    a form whose creases fold against their letters is read as its mirror image."""
    from origami_jax.io import from_fold_dict
    from origami_jax.kinematics import fold_angles_np

    half = np.sqrt(0.5)
    coords = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0.5, 0.5, half]]
    frame = {
        "file_spec": 1.2,
        "frame_classes": ["foldedForm"],
        "vertices_coords": coords,
        "edges_vertices": [[0, 1], [1, 2], [2, 0], [2, 3], [3, 0]],
        "faces_vertices": [[0, 1, 2], [0, 2, 3]],
    }
    for letter in "VM":
        cp = from_fold_dict({**frame, "edges_assignment": ["B", "B", letter, "B", "B"]})
        k = 2
        assert abs(cp.fold_angles[k]) == pytest.approx(np.pi / 2, abs=1e-12)
        assert np.sign(cp.fold_angles[k]) == (1 if letter == "V" else -1)
        start = np.asarray(cp.start)[cp.mesh.source_vertex]
        measured = fold_angles_np(start, cp.mesh.hinges[[k]])[0]
        assert measured == pytest.approx(cp.fold_angles[k], abs=1e-12)  # mirrored if need be
        result = fold(cp)
        assert result.converged and result.iterations <= 2


def test_a_direct_solve_through_pi_is_followed_again_from_flat():
    # creases driven to 0.89 pi: no barriers by default, and the direct solve from flat ends
    # with creases through themselves; "auto" then follows the fold from flat, with barriers
    cp = patterns.waterbomb(2, 2)
    direct = fold(cp, percent=1.78, path="direct")
    assert direct.converged and len(direct.through_pi) > 0 and direct.barriers == Barriers(0, 0)
    result = fold(cp, percent=1.78)
    assert result.path == "continuation" and result.barriers == Barriers()
    assert result.converged, result.reason
    assert len(result.through_pi) == 0 and len(result.collapsed) == 0
    assert len(result.intersections) == 0 < len(direct.intersections)
    # the direct try's work is counted: its iterations and time come first in the history
    assert result.iterations > direct.iterations
    assert result.history["iteration"][-1] == result.iterations
    assert np.all(np.diff(result.history["wall_time"]) >= 0)
    # the user's choice of barriers stands in the second try
    assert fold(cp, percent=1.78, barriers=False).barriers == Barriers(0, 0)


def test_a_shared_tessellation_reaches_its_targets_when_stiff(shared_patterns):
    # Origami Simulator's waterbomb tessellation (its targets reachable: the defaults fold it
    # to 1e-11 rad, with bars strained up to 5e-6: a prestressed state, which these ratios do
    # not buckle) at axial : crease 1e6 and 1e8: its bars' rounding, from coordinates ten
    # times their length, is above tol there, and the solve ends at that floor, converged
    cp = io.load(shared_patterns / "origami-simulator" / "Tessellations" / "waterbomb.svg")
    for ratio in (1e6, 1e8):
        stiffness = {"axial": 1.0, "facet": 20.0 / ratio, "crease": 1.0 / ratio}
        result = fold(cp, stiffness=stiffness)
        assert result.converged, (ratio, result.reason)
        assert result.fold_angle_error_max <= 1e-6, ratio
        assert len(result.through_pi) == 0 and len(result.collapsed) == 0
