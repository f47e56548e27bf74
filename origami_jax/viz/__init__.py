"""Pictures of crease patterns and folded states: matplotlib figures, plotly HTML, animations.

matplotlib, plotly and pillow are optional (``pip install "origami-jax[viz]"``): they are
imported inside the functions, so ``import origami_jax.viz`` works without them and a function
that needs a missing one raises :class:`ImportError` naming the extra.

Colours are Origami Simulator's, by FOLD assignment: mountain red ``#ff0000``, valley blue
``#0000ff``, facet yellow ``#ffff00`` (hidden in 3-D unless ``show_facets``), border black, cut
green ``#00ff00``, unassigned / join (an undriven hinge) magenta ``#ff00ff``. An unassigned
crease with a non-zero target folds like a mountain or valley and is drawn as one.

* :func:`plot_fold`: the folded sheet in 3-D (shaded faces, creases), optionally coloured per
  face by ``"strain"`` or ``"fold_angle_error"``;
* :func:`plot_pattern`: the crease pattern in 2-D;
* :func:`plotly_fold`, :func:`save_html`: an interactive 3-D view, as a self-contained HTML file;
* :func:`plot_history`: error against run time, from a result or a benchmark CSV;
* :func:`animate_fold`: the fold from flat to folded as a GIF or MP4.

Example:
  >>> import origami_jax as oj
  >>> from origami_jax import viz
  >>> result = oj.fold(oj.patterns.miura_ori(3, 3))                  # doctest: +SKIP
  >>> viz.plot_fold(result, color="strain").savefig("miura.png")    # doctest: +SKIP
  >>> viz.save_html(result, "miura.html")                           # doctest: +SKIP
  >>> viz.animate_fold(oj.patterns.miura_ori(3, 3), "miura.gif")    # doctest: +SKIP
"""

# COLOR_LABELS, PAPER, HISTORY_METRICS, DEFAULT_VIEW: public names of viz before it became a
# package, though outside __all__ (hence the noqa): still here
from origami_jax.viz.colors import (
    ASSIGNMENT_COLORS,
    ASSIGNMENT_NAMES,
    COLOR_LABELS,  # noqa: F401
    PAPER,  # noqa: F401
    edge_assignments,
    face_values,
)
from origami_jax.viz.extras import require
from origami_jax.viz.figures import plot_fold, plot_pattern
from origami_jax.viz.history import HISTORY_METRICS, plot_history  # noqa: F401
from origami_jax.viz.interactive import plotly_fold, save_html
from origami_jax.viz.movie import animate_fold, fold_frames, movie_settings
from origami_jax.viz.views import DEFAULT_VIEW, default_view  # noqa: F401

__all__ = [
    "ASSIGNMENT_COLORS",
    "ASSIGNMENT_NAMES",
    "edge_assignments",
    "face_values",
    "default_view",
    "plot_fold",
    "plot_pattern",
    "plotly_fold",
    "save_html",
    "plot_history",
    "fold_frames",
    "animate_fold",
    "require",
    "movie_settings",
]
