"""Solvers of the folding problem, chosen by name in :func:`origami_jax.fold`."""

from origami_jax.solvers.base import Problem, Solver, Status
from origami_jax.solvers.dynamics import Dynamics, DynamicsState, origami_simulator
from origami_jax.solvers.lbfgs import Lbfgs, LbfgsState
from origami_jax.solvers.newton import Newton, NewtonState

SOLVERS: dict[str, Solver] = {"lbfgs": Lbfgs(), "dynamics": Dynamics(), "newton": Newton()}


def get_solver(name: str | Solver) -> Solver:
    """The solver registered under ``name`` (a solver object passes through)."""
    if not isinstance(name, str):
        return name
    try:
        return SOLVERS[name]
    except KeyError:
        raise ValueError(
            f"unknown solver {name!r} (available: {', '.join(sorted(SOLVERS))})"
        ) from None


__all__ = [
    "SOLVERS",
    "get_solver",
    "Problem",
    "Solver",
    "Status",
    "Lbfgs",
    "LbfgsState",
    "Dynamics",
    "DynamicsState",
    "origami_simulator",
    "Newton",
    "NewtonState",
]
