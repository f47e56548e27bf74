"""What is particular to L-BFGS: the step limits in its optax chain, a start already at rest,
its memory, and its options checked where it is made."""

import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import fold, patterns
from origami_jax.solvers import Lbfgs, Status
from origami_jax.solvers.lbfgs import limit_by, limit_displacement


def test_no_vertex_moves_farther_than_the_step_limit():
    u = jnp.array([[3.0, 4.0, 0.0], [0.0, 1.0, 0.0]])  # the largest vertex move: 5
    limit = limit_displacement(2.0)
    out, _ = limit.update(u, limit.init(u))
    np.testing.assert_allclose(out, 0.4 * u, rtol=1e-15)
    within, _ = limit_displacement(10.0).update(u, None)
    np.testing.assert_array_equal(within, u)
    still, _ = limit.update(jnp.zeros_like(u), None)
    np.testing.assert_array_equal(still, 0.0)  # no division by a zero step


def test_a_step_is_scaled_by_the_fraction_it_is_allowed():
    u = jnp.array([[1.0, -2.0, 2.0]])
    out, _ = limit_by(lambda du: 1.0 / (1.0 + jnp.max(jnp.abs(du)))).update(u, None)
    np.testing.assert_allclose(out, u / 3.0, rtol=1e-15)


def test_a_start_at_rest_takes_no_step():
    # a flat sheet with its creases' goals at 0: every term is exactly zero, and so is the
    # gradient
    cp = patterns.single_crease(fold_angle=1.0)
    result = fold(cp, percent=0.0, solver="lbfgs")
    assert result.status == Status.CONVERGED and result.iterations == 1
    np.testing.assert_array_equal(result.positions, cp.mesh.vertices)


def test_a_shorter_memory_reaches_the_same_shape():
    cp = patterns.miura_ori(3, 3, sector_angle=np.radians(60), fold_angle=np.pi / 2)
    short, default = fold(cp, solver=Lbfgs(memory_size=3)), fold(cp, solver="lbfgs")
    assert short.converged and default.converged
    np.testing.assert_allclose(short.positions, default.positions, atol=1e-9 * cp.diameter)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"memory_size": 0}, "memory_size must be >= 1"),
        ({"memory_size": 2.0}, "memory_size must be an integer"),
        ({"max_linesearch_steps": -1}, "max_linesearch_steps must be >= 1"),
        ({"patience": True}, "patience must be an integer"),
    ],
)
def test_options_out_of_range_are_refused_by_name(options, message):
    with pytest.raises(ValueError, match=message):
        Lbfgs(**options)
