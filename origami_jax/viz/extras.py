"""The optional dependencies (the ``viz`` extra): imported by the functions that need them, so
``import origami_jax.viz`` works without them."""

from __future__ import annotations

from types import ModuleType

__all__ = ["require"]

EXTRA = 'pip install "origami-jax[viz]"'


def require(name: str) -> ModuleType:
    """Import "matplotlib" or "plotly" (its graph_objects); ImportError naming the extra if not."""
    if name == "matplotlib":
        try:
            import matplotlib
            import matplotlib.pyplot  # noqa: F401  (the figure manager, for plt.figure)
        except ImportError as exc:
            raise ImportError(f"this plot needs matplotlib: {EXTRA}") from exc
        return matplotlib
    if name == "plotly":
        try:
            import plotly.graph_objects as go
        except ImportError as exc:
            raise ImportError(f"this figure needs plotly: {EXTRA}") from exc
        return go
    raise ValueError(f"require: expected 'matplotlib' or 'plotly', got {name!r}")
