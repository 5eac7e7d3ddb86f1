"""``polygonize``: from a field to a :class:`~implicitmesh.Mesh`."""

from __future__ import annotations

import enum
from typing import Any, Callable, Sequence, Union

import numpy as np

from . import _core
from .mesh import Mesh

__all__ = ["Ambiguity", "polygonize", "METHODS"]

#: Polygonizers available to :func:`polygonize`.
METHODS = ("dense",)


class Ambiguity(str, enum.Enum):
    """How a cube face with two diagonally opposite inside corners (and two outside) is split.

    Both choices give watertight meshes: the choice is made per face, so two cells sharing a face
    always agree (Triquet et al. §4.5).
    """

    #: The two inside corners are cut off separately: thin necks break apart.
    SEPARATE = "separate"
    #: The two inside corners are joined through the face: thin necks stay connected.
    JOIN = "join"


Field = Union["_core.VariationalSurface", Callable[[np.ndarray], np.ndarray]]


def polygonize(
    field: Field,
    *,
    bounds: Any = None,
    resolution: int | Sequence[int] = 64,
    method: str = "dense",
    ambiguity: Ambiguity | str = Ambiguity.SEPARATE,
    normals: bool = True,
    batch_size: int = 262144,
    memory_limit: int | None = None,
) -> Mesh:
    """Triangulates the zero set of a field (negative inside, positive outside).

    Parameters
    ----------
    field : VariationalSurface or callable
        A field of this package, or any Python callable taking an (N, 3) float64 array of points
        and returning N values. A callable is called in batches of up to ``batch_size`` points
        (never point by point), always from the calling thread.
    bounds : (2, 3) array_like, optional
        ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, the box to polygonize. Defaults to the
        field's ``bounds`` attribute (a :class:`VariationalSurface` has one); required for
        callables without it.
    resolution : int or (3,) ints
        Cells per axis (one int for all three axes). Default 64.
    method : {"dense"}
        ``"dense"``: plain marching cubes over every cell of the lattice (the reference).
    ambiguity : Ambiguity or {"separate", "join"}
        How ambiguous cube faces are split. Default ``SEPARATE``.
    normals : bool
        Compute vertex normals from the field's gradient (central differences for callables).
    batch_size : int
        Points per batched field call.
    memory_limit : int, optional
        Refuse lattices whose memory estimate exceeds this many bytes (default 8 GiB).

    Returns
    -------
    Mesh
        ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64 oriented outward, ``normals``
        (V, 3) float64, ``stats`` with exact evaluation counts and timings.

    Raises
    ------
    ValueError
        For bad bounds or resolution (not positive, absurdly large for ``memory_limit``), an
        unknown method or ambiguity, or a field returning NaN/inf or the wrong shape.
    TypeError
        When ``field`` is neither a field of this package nor callable.

    Notes
    -----
    The mesh is watertight wherever the surface stays inside ``bounds``; where it leaves the box
    the mesh is open along the box.
    """
    if bounds is None:
        bounds = getattr(field, "bounds", None)
        if bounds is None:
            raise ValueError(
                "bounds: required for a field without a `bounds` attribute, "
                "e.g. bounds=[[-1, -1, -1], [1, 1, 1]]"
            )
    if isinstance(ambiguity, Ambiguity):
        ambiguity = ambiguity.value
    if not isinstance(ambiguity, str):
        raise ValueError(f"ambiguity: expected Ambiguity.SEPARATE/JOIN or a string, got {ambiguity!r}")
    if not isinstance(method, str):
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    for name, value in (("batch_size", batch_size), ("memory_limit", memory_limit)):
        if value is None and name == "memory_limit":
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
            raise ValueError(f"{name}: must be a positive integer, got {value!r}")
    v, f, n, stats = _core.polygonize(
        field,
        bounds,
        resolution,
        method=method,
        ambiguity=ambiguity,
        normals=normals,
        batch_size=batch_size,
        memory_limit=memory_limit,
    )
    stats["triangles"] = len(f)
    stats["vertices"] = len(v)
    return Mesh(v, f, n, stats)
