"""Normals of points that have none: :func:`estimate_normals`."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _core
from ._progress import reporter

__all__ = ["estimate_normals"]


def estimate_normals(
    points: npt.ArrayLike,
    *,
    neighbours: int = 20,
    viewpoints: npt.ArrayLike | None = None,
    progress: Any = False,
) -> npt.NDArray[np.float64]:
    """Unit normals of a point cloud, consistently oriented and pointing outward.

    Each point's normal is the plane of its ``neighbours`` nearest points; neighbours whose
    planes agree are joined into patches, oriented consistently within, without crossing from
    one side of a thin part to the other; patches are oriented against each other by votes
    along their boundaries; and each resulting body is turned outward: toward its
    ``viewpoints`` when given, else out of the volume it encloses (the sign of its winding
    number), else, for open data such as a terrain, up (+z). See ``docs/normals.md``.

    Parameters
    ----------
    points : (N, 3) float64
        The points, at least ``neighbours`` of them, not all on one line or plane.
    neighbours : int
        Neighbours of each local plane, the point itself included (at least 3). More smooth
        noise; fewer keep thin parts apart.
    viewpoints : (3,) or (N, 3) float64, optional
        Where the sensor was: one position for all points, or one per point (for several
        scans, ``cameras[scan_index]``). Each body then faces its viewpoints.
    progress : bool or callable
        True shows progress (points done by the local step); a callable gets the count.

    Returns
    -------
    normals : (N, 3) float64
        Unit normals, in the order of ``points``.

    Raises
    ------
    ValueError
        Naming the argument: points not finite, fewer than ``neighbours``, all on one line or
        plane; ``neighbours`` below 3; ``viewpoints`` not finite or of the wrong shape.

    Warns
    -----
    UserWarning
        When the points fall into several large pieces that no neighbour joins (e.g. separate
        objects): each is oriented on its own.

    Examples
    --------
    >>> import numpy as np, implicitmesh as im
    >>> v, f = im.shapes.load_model("knot")
    >>> s = im.scanner.scan(v, f, 20_000, seed=1)
    >>> n = im.estimate_normals(s.points)
    >>> bool(np.all(np.abs(np.linalg.norm(n, axis=1) - 1) < 1e-12))
    True
    """
    if viewpoints is not None:
        viewpoints = np.asarray(viewpoints, dtype=np.float64)
        if viewpoints.shape != (3,) and (viewpoints.ndim != 2 or viewpoints.shape[1] != 3):
            raise ValueError(f"viewpoints: expected shape (3,) or (N, 3), got {viewpoints.shape}")
    callback, end = reporter(progress, "normals", None, "points")
    try:
        normals, info = _core.estimate_normals(points, neighbours, viewpoints, callback)
    finally:
        end()
    if info["large_bodies"] > 1:
        warnings.warn(
            f"points: the cloud falls into {info['large_bodies']} pieces of {info['significant']:,} or more points "
            "that no neighbours join; each was oriented outward on its own",
            UserWarning,
            stacklevel=2,
        )
    return normals
