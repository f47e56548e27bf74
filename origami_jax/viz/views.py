"""The camera: the default view of a sheet (along its normal when it is flat)."""

from __future__ import annotations

import numpy as np

__all__ = ["default_view"]


def view_vector(elev: float, azim: float) -> np.ndarray:
    """Unit vector from the scene towards the camera of a 3-D axes (degrees)."""
    e, a = np.radians(elev), np.radians(azim)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


# the default camera (matplotlib's) for a sheet that is not flat
DEFAULT_VIEW = (30.0, -60.0)
# a sheet whose RMS thickness off its best-fit plane is under this fraction of its smaller RMS
# size in that plane counts as flat: the default camera may see it edge-on, as a line
_FLAT = 0.02


def default_view(points: np.ndarray) -> tuple[float, float]:
    """The camera ``(elev, azim)`` (degrees) for a sheet at ``points`` (N, 3): along the normal
    of its best-fit plane when it is (nearly) flat (a flat-folded base, the unfolded sheet),
    from the side :data:`DEFAULT_VIEW` sees; else :data:`DEFAULT_VIEW`.

    Example:
      >>> import origami_jax as oj
      >>> default_view(oj.patterns.miura_ori(2, 2).mesh.vertices)   # flat: seen from above
      (90.0, -90.0)
    """
    x = np.asarray(points, np.float64)
    if x.shape[1] == 2:  # a flat pattern's 2-D coordinates
        return (90.0, -90.0)
    _, sv, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    if len(sv) < 3 or sv[2] > _FLAT * sv[1]:
        return DEFAULT_VIEW
    normal = vt[2] if vt[2] @ view_vector(*DEFAULT_VIEW) >= 0 else -vt[2]
    elev = float(np.degrees(np.arcsin(np.clip(normal[2], -1.0, 1.0))))
    if abs(normal[2]) > np.cos(np.radians(1.0)):  # from above: x to the right, y up, as in 2-D
        return (90.0 if normal[2] > 0 else -90.0, -90.0)
    return (elev, float(np.degrees(np.arctan2(normal[1], normal[0]))))


def camera(points: np.ndarray, elev: float | None, azim: float | None) -> tuple[float, float]:
    """The camera: as given; :func:`default_view` when neither angle is given."""
    if elev is None and azim is None:
        return default_view(points)
    return (DEFAULT_VIEW[0] if elev is None else elev, DEFAULT_VIEW[1] if azim is None else azim)
