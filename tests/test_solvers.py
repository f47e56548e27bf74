"""The same correctness tests for every solver: exact rigid shapes, the seed's scene, full folds
to +-pi, failures reported with a reason. What is particular to one solver is in its own file
(test_newton.py, test_lbfgs.py, test_dynamics.py; the host's sparse solves: test_hostsparse.py).

Patterns are few and small so that each solver compiles once per shape.
"""

import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.kinematics import rigid_fold
from origami_jax.solvers import SOLVERS, Status

SOLVER_NAMES = sorted(SOLVERS)


@pytest.fixture(scope="module")
def newton_seed():
    """The seed's scene folded at the defaults (Newton, along the path from flat)."""
    return fold(patterns.seed_waterbomb(), stiffness=patterns.SEED_WATERBOMB_STIFFNESS)


@pytest.mark.parametrize("solver", SOLVER_NAMES)
@pytest.mark.parametrize(
    "cp",
    [
        patterns.miura_ori(3, 3, sector_angle=np.radians(60), fold_angle=np.pi / 2),
        patterns.degree4_vertex(np.pi / 3, np.pi / 4, np.pi / 2, branch=1),
        patterns.degree4_vertex(np.pi / 2.5, np.pi / 5, 2.0, branch=2),
        patterns.degree4_vertex(2.5, 0.3, 3.1, branch=1),
    ],
    ids=lambda cp: cp.name,
)
def test_exact_rigid_shape(solver, cp):
    result = fold(cp, solver=solver, reference_positions=rigid_fold(cp))
    assert result.converged, result.reason
    assert result.solver == solver
    assert result.shape_error <= 1e-8
    assert result.fold_angle_error_max <= 1e-8
    assert result.strain_max <= 1e-8


@pytest.mark.parametrize("solver", SOLVER_NAMES)
def test_seed_scene_same_stationary_point(solver, newton_seed):
    # the direct solve of each (Newton follows the path from flat: the same point); every
    # crease ends short of pi, where the barriers are inactive
    result = fold(
        patterns.seed_waterbomb(),
        solver=solver,
        stiffness=patterns.SEED_WATERBOMB_STIFFNESS,
        path="direct",
    )
    assert np.max(np.abs(newton_seed.fold_angles)) < np.pi - 1e-3
    assert result.converged and result.grad_norm_rel <= 1e-9
    assert result.energy == pytest.approx(newton_seed.energy, rel=1e-6)
    # the stationary point docs/getting-started.md shows, far below 0.009519, where the
    # seed's simulator was stopped
    assert result.energy == pytest.approx(2.86669e-4, rel=1e-5)


@pytest.mark.parametrize("solver", SOLVER_NAMES)
def test_full_fold_reaches_pi_without_passing_through(solver):
    cp = patterns.single_crease(fold_angle=np.pi)
    k = cp.mesh.edges_with_role("driven")[0]
    result = fold(cp, solver=solver)
    assert result.converged, result.reason
    assert result.fold_angles[k] == pytest.approx(np.pi, abs=1e-8)
    mountain = fold(cp, solver=solver, percent=-1.0)
    assert mountain.fold_angles[k] == pytest.approx(-np.pi, abs=1e-8)
    assert len(result.through_pi) == 0 and len(mountain.through_pi) == 0


@pytest.mark.parametrize("solver", SOLVER_NAMES)
def test_iteration_limit_is_reported(solver):
    cp = patterns.miura_ori(3, 3, sector_angle=np.radians(60), fold_angle=np.pi / 2)
    result = fold(cp, solver=solver, max_iter=2)
    assert not result.converged and result.status == Status.MAX_ITER
    assert result.iterations == 2 and "iteration limit" in result.reason
    assert np.isfinite(result.positions).all()
