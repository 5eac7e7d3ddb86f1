"""Subdivision interpolating implicit surfaces (Jin, Sun & Peng 2003).

:func:`subdivide` refines a control mesh onto the variational surface that interpolates it (or
onto any other field of the package): every level splits each triangle into four at its edge
midpoints and moves the midpoints onto the surface by Newton steps along the gradient. :func:`butterfly` refines the same mesh with the
modified butterfly scheme (Zorin et al. 1996) into the same connectivity, and :func:`blend`
mixes the two, vertex by vertex (Jin §4).
"""

from __future__ import annotations

import numbers
import warnings
from typing import Any, Callable

import numpy as np

from . import _core
from ._core import BlobField, VariationalSurface
from ._progress import reporter
from .mesh import Mesh, count_edges

__all__ = ["subdivide", "butterfly", "blend"]


def _check_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name}: must be an integer, got {value!r}")
    return int(value)


def _check_levels(levels: Any) -> int:
    levels = _check_int("levels", levels)
    if not 0 <= levels <= 8:
        raise ValueError(f"levels: must be between 0 and 8, got {levels}")
    return levels


def _vertex_total(faces: Any, vertices: Any, levels: int) -> int | None:
    """Vertices of level ``levels`` (the count the progress reaches): level k + 1 adds one vertex
    per edge of level k, whose edges are twice its own plus three per face. None when the mesh is
    not an (F, 3) index array (the call then refuses it)."""
    try:
        f = np.asarray(faces)
        n = len(vertices)
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            return None
    except (TypeError, ValueError):
        return None
    e, t = count_edges(f) if len(f) else 0, len(f)
    for _ in range(levels):
        n, e, t = n + e, 2 * e + 3 * t, 4 * t
    return n


def subdivide(
    vertices: Any,
    faces: Any,
    *,
    levels: int = 2,
    field: VariationalSurface | BlobField | Callable[[np.ndarray], np.ndarray] | None = None,
    surface: VariationalSurface | BlobField | Callable[[np.ndarray], np.ndarray] | None = None,
    d: float | None = None,
    w: float | None = None,
    kernel: str | None = None,
    tolerance: float | None = None,
    max_steps: int | None = None,
    step: float | None = None,
    progress: Any = None,
) -> list[Mesh]:
    """Subdivides a control mesh onto an implicit surface (Jin et al. 2003).

    Each level splits every triangle into four at its edge midpoints (one new vertex per edge,
    shared by its faces) and projects the new vertices onto the zero set of the field by
    Newton's iteration r ← r − f ∇f / ‖∇f‖² (Jin et al. eq. 10), level after level. Vertices of a
    level keep their index and exact coordinates in every finer level; the new ones are appended.
    Where Newton fails (vanishing gradient, too many steps, wandering off), a sign change is
    searched along the gradient line through the midpoint and bisected.

    Parameters
    ----------
    vertices : (V, 3) float64
        Control mesh vertices, on the surface (they are kept as they are, not projected; level
        0's ``stats["max_abs_value"]`` tells how far off the surface they are).
    faces : (F, 3) int
        Triangles, counter-clockwise seen from outside; every edge shared by at most two faces,
        traversed in opposite directions. Open meshes are fine (their boundary is kept).
    levels : int
        Subdivision levels, 0 to 8 (default 2). Level k has F × 4^k triangles.
    field : VariationalSurface, BlobField or callable, optional
        The field to project on (negative inside). A callable takes (N, 3) float64 points and
        returns N values (e.g. :class:`implicitmesh.shapes.Sphere`); it is called in batches from
        the calling thread, and its gradient is taken by central differences (7 values per point
        and Newton step, all in one call). Default: ``VariationalSurface.from_mesh(vertices,
        faces, d=d, w=w, kernel=kernel)``, the surface that interpolates the control mesh.
    surface : optional
        Deprecated name of ``field`` (a ``DeprecationWarning``).
    d, w, kernel
        Passed to :meth:`VariationalSurface.from_mesh` when ``field`` is not given (kernel
        default ``"triharmonic"``); refused when it is.
    tolerance : float, optional
        Newton stops when its step is below ``tolerance`` × the local edge length (default 1e-9).
        Newton starts from the middle of the curved edge that the endpoint normals define (in
        the plane through the midpoint perpendicular to the edge), and a step is accepted
        without evaluating again when quadratic convergence predicts the next step below the
        tolerance with a margin of 10 (the step at least halved, and at most 1e-5 × the edge
        length): about 2 evaluations per new vertex on the shared meshes.
    max_steps : int, optional
        Most Newton steps per vertex and level before the fallback (default 30).
    step : float, optional
        Callables only: the central-difference step for gradients (default 1e-6 × the largest
        side of the control mesh's bounding box).
    progress : bool or callable, optional
        ``True``: show the vertices placed so far, of the vertex count of the finest level, while
        the call runs (a tqdm bar when tqdm is installed, else a line on standard error); a
        callable is called with that count (an int) about every 50 ms from the calling thread,
        and once at the end with the finest level's vertex count. A vertex counts once its
        position is final: the control vertices once their normals are evaluated, a new vertex
        once Newton (or the fallback) has placed it. With a callable as ``field`` the work runs
        on the calling thread, and the count is reported once, at the end. Default None (no
        report).

    Returns
    -------
    list of Mesh
        Levels 0 (the control mesh) to ``levels``: ``vertices`` (V_k, 3) float64, ``faces``
        (F_k, 3) int64, ``normals`` (V_k, 3) float64 unit gradients, and ``stats``: ``level``,
        ``projected`` (new vertices), ``iterations_mean`` / ``iterations_max`` (Newton
        evaluations per new vertex), ``fallbacks``, ``not_converged`` and
        ``not_converged_max_abs_value``, ``max_abs_value`` (largest ``|f|`` at the new vertices —
        for vertices accepted by prediction, the predicted ``|f|`` after the last step; at level 0,
        measured at the control vertices), ``evaluations`` (field values computed, 7 per point
        for a callable's value and gradient), ``batches``, ``seconds``.

    Raises
    ------
    ValueError
        For wrong shapes, out-of-range or repeated indices, non-manifold or inconsistently
        oriented faces, ``levels`` outside [0, 8] or too large for memory, a bad ``tolerance``,
        ``max_steps`` or ``step``, a ``field`` that is not a field, ``d``/``w``/``kernel``
        given with ``field``, ``field`` and ``surface`` both given, a callable returning the wrong shape or NaN, and everything
        :meth:`VariationalSurface.from_mesh` refuses, and a ``progress`` that is neither a bool
        nor callable. An exception raised by the callable (or by ``progress``) propagates as it
        is.
    KeyboardInterrupt
        On Ctrl-C (or Jupyter's interrupt) while the call runs: the work stops at its next batch.
    """
    levels = _check_levels(levels)
    if max_steps is not None:
        max_steps = _check_int("max_steps", max_steps)
    for name, value in (("tolerance", tolerance), ("step", step)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise ValueError(f"{name}: must be a number, got {value!r}")
    tolerance = None if tolerance is None else float(tolerance)
    step = None if step is None else float(step)
    name = "field"  # as the caller names it
    if surface is not None:
        warnings.warn("subdivide(surface=) is deprecated: use field=", DeprecationWarning, stacklevel=2)
        if field is not None:
            raise ValueError("surface: the deprecated name of field, given with field")
        field, name = surface, "surface"
    if field is None:
        if step is not None:
            raise ValueError("step: applies to a callable field only")
        field = VariationalSurface.from_mesh(vertices, faces, d=d, w=w, kernel="triharmonic" if kernel is None else kernel)
    else:
        for value_name, value in (("d", d), ("w", w), ("kernel", kernel)):
            if value is not None:
                raise ValueError(f"{value_name}: applies only when field is not given (it fits the default surface)")
        if not isinstance(field, (VariationalSurface, BlobField)) and not callable(field):
            raise ValueError(
                f"{name}: expected a VariationalSurface, a BlobField or a callable taking (N, 3) float64 "
                f"points and returning (N,) values, got {type(field).__name__}"
            )
        # ``step`` with a field of exact gradients: the core refuses it, naming ``step``.
    report, end = reporter(progress, "subdivide", _vertex_total(faces, vertices, levels) if progress is True else None, "vertices")
    try:
        out = _core.subdivide(field, vertices, faces, levels, tolerance=tolerance, max_steps=max_steps, step=step, progress=report)
    except ValueError as e:
        # The core names a callable's bad output "field"; with the deprecated name, `surface`.
        if name == "surface" and str(e).startswith("field:"):
            raise ValueError("surface:" + str(e)[len("field:") :]) from None
        raise
    finally:
        end()
    meshes = []
    for v, f, n, stats in out:
        stats["triangles"] = len(f)
        stats["vertices"] = len(v)
        stats["method"] = "subdivision"
        meshes.append(Mesh(v, f, n, stats))
    return meshes


def butterfly(vertices: Any, faces: Any, *, levels: int = 2, w: float = 0.0, progress: Any = None) -> list[Mesh]:
    """Modified butterfly subdivision (Zorin, Schröder & Sweldens 1996) of a triangle mesh.

    Interpolating: old vertices stay; each edge gets one new vertex from the 10-point stencil
    (weights 1/2 − w, 1/8 + 2w, −1/16 − w, w) between two interior vertices of valence 6, Zorin's
    stencil around an extraordinary end (averaged when both ends are extraordinary), and the
    four-point rule (−1/16, 9/16, 9/16, −1/16) on boundary edges. An interior edge with one end on
    the boundary uses the stencil of its interior end; one joining two boundary vertices uses
    the 10-point stencil with each missing vertex replaced by a ghost, the affine reflection
    x + y − o across the boundary edge (x, y) of the face (x, y, o), and the tension points by
    2a − b and 2b − a (affine, so planar meshes stay planar, and exact on regular lattices). The
    connectivity and vertex numbering equal those of :func:`subdivide`, so the results can be
    :func:`blend`-ed.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int
        As for :func:`subdivide`; every vertex's faces must form one fan.
    levels : int
        0 to 8 (default 2).
    w : float
        Tension (default 0: the classic butterfly; 1/16 is Dyn et al.'s choice).
    progress : bool or callable, optional
        As for :func:`subdivide`: ``True`` shows the vertices placed so far, a callable gets
        that count; it ends at the finest level's vertex count. Default None (no report).

    Returns
    -------
    list of Mesh
        Levels 0 to ``levels``, ``normals`` the area-weighted face normals.

    Raises
    ------
    ValueError
        For bad shapes or indices, non-manifold meshes, ``levels`` outside [0, 8], non-finite w,
        a ``progress`` that is neither a bool nor callable.
    KeyboardInterrupt
        On Ctrl-C (or Jupyter's interrupt) while the call runs: the work stops at its next level.
    """
    levels = _check_levels(levels)
    if isinstance(w, bool) or not isinstance(w, numbers.Real) or not np.isfinite(w):
        raise ValueError(f"w: must be a finite number, got {w!r}")
    report, end = reporter(progress, "butterfly", _vertex_total(faces, vertices, levels) if progress is True else None, "vertices")
    try:
        out = _core.butterfly(vertices, faces, levels, float(w), progress=report)
    finally:
        end()
    return [Mesh(v, f, n, {"level": k, "triangles": len(f), "vertices": len(v), "method": "butterfly"}) for k, (v, f, n) in enumerate(out)]


def blend(implicit: Mesh, butterfly: Mesh, lam: float) -> Mesh:
    """Blends a subdivided implicit surface with a butterfly surface: (1 − λ) a + λ b (Jin §4).

    Parameters
    ----------
    implicit : Mesh
        A level of :func:`subdivide`.
    butterfly : Mesh
        The same level of :func:`butterfly` on the same control mesh (same faces).
    lam : float
        λ in [0, 1]: 0 gives ``implicit``'s vertices exactly, 1 ``butterfly``'s.

    Returns
    -------
    Mesh
        ``vertices`` (V, 3) float64 blended, ``faces`` (F, 3) int64 shared, ``normals`` (V, 3)
        the blended unit normals (when both meshes have normals), ``stats`` with ``lam``.

    Raises
    ------
    ValueError
        When λ is outside [0, 1] or the meshes' vertex counts or faces differ.
    """
    if isinstance(lam, bool) or not isinstance(lam, numbers.Real) or not (0.0 <= float(lam) <= 1.0):
        raise ValueError(f"lam: must be a number in [0, 1], got {lam!r}")
    lam = float(lam)
    for name, m in (("implicit", implicit), ("butterfly", butterfly)):
        if not isinstance(m, Mesh):
            raise ValueError(f"{name}: expected a Mesh, got {type(m).__name__}")
    if implicit.vertices.shape != butterfly.vertices.shape:
        raise ValueError(
            f"butterfly: has {len(butterfly.vertices)} vertices, implicit has {len(implicit.vertices)}; "
            "use the same level and control mesh"
        )
    if not np.array_equal(implicit.faces, butterfly.faces):
        raise ValueError("butterfly: faces differ from implicit's; use the same level and control mesh")
    if lam == 0.0:
        v = implicit.vertices.copy()
    elif lam == 1.0:
        v = butterfly.vertices.copy()
    else:
        v = (1.0 - lam) * implicit.vertices + lam * butterfly.vertices
    n = np.zeros((0, 3))
    if len(implicit.normals) == len(v) and len(butterfly.normals) == len(v):
        n = (1.0 - lam) * implicit.normals + lam * butterfly.normals
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)
    return Mesh(v, implicit.faces.copy(), n, {"lam": lam, "triangles": len(implicit.faces), "vertices": len(v), "method": "blend"})
