"""Solvers of the folding problem, chosen by name in :func:`origami_jax.fold`."""

from origami_jax.solvers.base import Problem, Solver, SolverState, Status
from origami_jax.solvers.dynamics import Dynamics, DynamicsState, origami_simulator
from origami_jax.solvers.lbfgs import Lbfgs, LbfgsState
from origami_jax.solvers.newton import Newton, NewtonState

SOLVERS: dict[str, Solver] = {"lbfgs": Lbfgs(), "dynamics": Dynamics(), "newton": Newton()}


def get_solver(name: str | Solver) -> Solver:
    """The solver registered under ``name`` (a :class:`Solver` object passes through)."""
    if not isinstance(name, str):
        if not isinstance(name, Solver):
            raise TypeError(
                f"solver: a name ({', '.join(sorted(SOLVERS))}) or an origami_jax.solvers.Solver, "
                f"got {type(name).__name__} (a solver subclasses Solver: see its docstring)"
            )
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
    "SolverState",
    "Status",
    "Lbfgs",
    "LbfgsState",
    "Dynamics",
    "DynamicsState",
    "origami_simulator",
    "Newton",
    "NewtonState",
]
