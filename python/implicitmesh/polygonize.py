"""``polygonize``: from a field to a :class:`~implicitmesh.Mesh`."""

from __future__ import annotations

import enum
from typing import Any, Callable, Sequence, Union

import numpy as np

from . import _core
from ._progress import reporter
from .mesh import Mesh
from .options import OctreeOptions, TrackingOptions, _method_keywords

__all__ = ["Ambiguity", "polygonize", "Tessellator", "METHODS", "OctreeOptions", "TrackingOptions"]

#: Polygonizers available to :func:`polygonize`.
METHODS = ("dense", "sparse", "octree", "tracking")


class Ambiguity(str, enum.Enum):
    """How a cube face with two diagonally opposite inside corners (and two outside) is split.

    Both choices give watertight meshes: the choice is made per face, so two cells sharing a face
    always agree (Triquet et al. §4.5).
    """

    #: The two inside corners are cut off separately: thin necks break apart.
    SEPARATE = "separate"
    #: The two inside corners are joined through the face: thin necks stay connected.
    JOIN = "join"


Field = Union["_core.VariationalSurface", "_core.BlobField", Callable[[np.ndarray], np.ndarray]]


def polygonize(
    field: Field,
    *,
    bounds: Any = None,
    resolution: int | Sequence[int] = 64,
    method: str = "dense",
    ambiguity: Ambiguity | str = Ambiguity.SEPARATE,
    normals: bool = True,
    project: bool = False,
    batch_size: int = 262144,
    memory_limit: int | None = None,
    start_level: int | None = None,
    safety: float | None = None,
    corner_test: bool | None = None,
    seeds: Any = None,
    options: OctreeOptions | TrackingOptions | None = None,
    trim: float | None = None,
    min_particles: int | None = None,
    progress: Any = False,
) -> Mesh:
    """Triangulates the zero set of a field (negative inside, positive outside).

    Parameters
    ----------
    field : VariationalSurface, BlobField or callable
        A field of this package, or any Python callable taking an (N, 3) float64 array of points
        and returning N values. A callable is called in batches of up to ``batch_size`` points
        (never point by point), always from the calling thread.
    bounds : (2, 3) array_like, optional
        ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, the box to polygonize. Defaults to the
        field's ``bounds`` attribute (a :class:`VariationalSurface` has one); required for
        callables without it.
    resolution : int or (3,) ints
        One int: cells along the longest side of ``bounds``, with cubic cells (the shorter sides
        get the whole number of cells that covers them and grow symmetrically to fit). Three
        ints: cells per axis exactly over ``bounds``. Default 64.
    method : {"dense", "sparse", "octree", "tracking"}
        ``"dense"``: plain marching cubes over every cell of the lattice (the reference).
        ``"sparse"`` (:class:`BlobField` only): the same marching cubes over blocks of 7³ cells,
        skipping every block where bounds on the primitives' terms show that the field has one
        sign; the mesh is the dense mesh (the same triangles, vertices and normals, bit for bit,
        in another order; where the gradient vanishes, the fallback normal is equal to rounding),
        every component is found, and the work follows the surface. The fastest method for
        blobs at 128³ and above.
        ``"octree"``: hierarchical sampling (Cuno et al.): a block of cells is skipped when
        ``|f(centre)| > safety × circumradius``, so only blocks near the surface are refined; the
        leaves get the same marching cubes. The test assumes ``|f| ≤ distance to the surface``,
        which fitted fields can break near thin parts; where it fails, the octree walks on from
        its crossed leaves into the blocks it dropped wrongly (and around signs it inferred
        wrongly), evaluating them, so the mesh is the dense mesh on every component it found
        (``stats["cells_repaired"]`` counts the cells so visited, 0 when the premise held). Only
        a component lying wholly inside dropped blocks can be missed; raise ``safety`` for
        fields far from a distance (e.g. ``3 × distance``). For a :class:`BlobField` the default
        ``safety`` is a bound on ``|∇f|``, which makes the octree exact but lets it reject
        little: use ``"sparse"`` for blobs.
        ``"tracking"``: surface tracking (Triquet et al.): from seed cells, visit only the cells
        the surface crosses; the mesh equals the dense mesh on every component that holds a seed.
        Seeds are found by walking along +x from ``seeds`` (default: the primitives' centres
        of a :class:`BlobField`, the data points of a :class:`VariationalSurface`; required for
        callables) to the first cell the surface crosses; a walk that meets the side of the box
        first starts again along -x, then ±y, ±z, and seeds outside the box start from the
        nearest cell. For a :class:`BlobField` every component is found, also those no walk
        reaches (a cavity inside a cluster of blobs; a surface made only by blobs each weaker
        than the threshold): when the walk ends, the blocks of 7³ cells that the bounds of
        ``"sparse"`` cannot rule out are evaluated and the walk goes on from their crossed cells
        it did not reach, so the mesh is the dense mesh. For other fields a component no walk
        reaches is not found.
    ambiguity : Ambiguity or {"separate", "join"}
        How ambiguous cube faces are split. Default ``SEPARATE``.
    normals : bool
        Compute vertex normals from the field's gradient (central differences for callables).
    project : bool
        Move each vertex onto the surface by one Newton step along the gradient,
        ``x - f(x) ∇f(x) / |∇f(x)|²`` (at most half a cell), after triangulating: marching cubes
        places vertices by linear interpolation along lattice edges, which errs where the field
        curves. Costs a value and a gradient per vertex; the faces are unchanged, the vertices
        leave the lattice edges, and normals (if asked) are taken at the moved vertices.
        It pays where the cells are coarse beside the data (a scan fitted with
        :class:`VariationalSurface` and meshed at 128–256 cells); on fine lattices it only
        costs. Default ``False``.
    batch_size : int
        Points per batched field call.
    memory_limit : int, optional
        Refuse lattices whose memory estimate exceeds this many bytes (default 8 GiB).
    start_level : int, optional
        Octree only: level of the first rejection test; 1 tests the root's eight octants (the
        paper's r = √3/2 when the root is [-1, 1]³), each further level halves r. Default: the
        first level whose blocks span at most 1/8 of the lattice's longest side (starting
        coarser rejected cells wrongly on the shared meshes at some resolutions).
    safety : float, optional
        Octree only: factor on the circumradius in the rejection test (default 1.0; for a
        :class:`BlobField`, a bound on ``|∇f|``, so that no block the surface crosses is
        rejected).
    corner_test : bool, optional
        Octree only: also decide with values already known, by the same pseudo-distance
        argument (no surface within ``|f(x)| / safety`` of ``x``): a block covered by the balls
        around its known corners is dropped without evaluating its centre, and leaf cells are
        settled by the signs of their corners (a corner inside the ball of a known value has its
        sign; marching cubes needs values only at the ends of crossed edges), so a leaf whose
        corners all get one sign needs no more evaluations. A third or more fewer evaluations
        on the shared meshes, the same mesh. Default True; False samples exactly as Cuno et al.
        §4.3.
    seeds : (K, 3) array_like, optional
        Tracking only: points inside or on each component of the surface to start from. (A
        :class:`BlobField`'s components are all found whatever the seeds; they only choose where
        the walk starts.)
    options : OctreeOptions or TrackingOptions, optional
        The settings of ``method`` in one object, instead of the keywords marked "Octree only"
        or "Tracking only" (not with them): :class:`OctreeOptions` for ``"octree"``,
        :class:`TrackingOptions` for ``"tracking"``.
    trim : float, optional
        :class:`VariationalSurface` only: drop the triangles with a vertex farther than ``trim``
        (in the data's units) from every data point (:meth:`VariationalSurface.distance_to_data`),
        and the vertices no triangle keeps: what is left is the surface where the data was, open
        where it was not (a scan of a room or a terrain). ``stats["trimmed"]`` counts the
        triangles dropped. Default ``None``: the whole, closed surface.
    min_particles : int, optional
        :class:`BlobField` only (a field of particles): drop the bodies of the mesh (connected
        components) holding fewer than ``min_particles`` of the field's centres, each centre
        counted for the body of its nearest vertex: stray droplets and spray.
        ``stats["fragments_dropped"]`` and ``stats["fragment_particles"]`` count the bodies
        dropped and their particles. Default ``None``: every body.
    progress : bool or callable
        ``True``: show the field evaluations done so far while the call runs (a tqdm bar when
        tqdm is installed, else a line on standard error); a callable is called with that count
        (an int) about every 50 ms from the calling thread. Default ``False``.

    Returns
    -------
    Mesh
        ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64 oriented outward, ``normals``
        (V, 3) float64, ``stats`` with exact evaluation counts and timings.

    Raises
    ------
    ValueError
        For bad bounds or resolution (not positive, absurdly large for ``memory_limit``), an
        unknown method or ambiguity, an option of another method, ``options`` of the wrong
        class or with the keywords it replaces, or a field returning NaN/inf or the wrong shape.
    TypeError
        When ``field`` is neither a field of this package nor callable.

    KeyboardInterrupt
        On Ctrl-C (or Jupyter's interrupt) while the call runs: the work stops at its next batch.

    Notes
    -----
    The mesh is watertight wherever the surface stays inside ``bounds``; where it leaves the box
    the mesh is open along the box.
    """
    bounds, ambiguity = _check_common(field, bounds, ambiguity, batch_size, memory_limit)
    if not isinstance(method, str):  # the core names an unknown method
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    per_method = _method_keywords(
        method, options, {"start_level": start_level, "safety": safety, "corner_test": corner_test, "seeds": seeds}
    )
    if not isinstance(project, (bool, np.bool_)):
        raise ValueError(f"project: must be True or False, got {project!r}")
    _check_trim(field, trim)
    _check_min_particles(field, min_particles)
    mesh = _mesh(
        _core.polygonize,
        f"polygonize ({method})",
        progress,
        field,
        bounds,
        resolution,
        method=method,
        ambiguity=ambiguity,
        normals=normals,
        project=project,
        batch_size=batch_size,
        memory_limit=memory_limit,
        **per_method,
    )
    return without_fragments(trimmed(mesh, field, trim), field, min_particles)


def _check_min_particles(field, min_particles) -> None:
    """A ValueError naming ``min_particles`` unless it is None, or a non-negative int for a
    :class:`BlobField`."""
    if min_particles is None:
        return
    if not isinstance(field, _core.BlobField):
        raise ValueError("min_particles: only for a BlobField (a field of particles)")
    if isinstance(min_particles, bool) or not isinstance(min_particles, (int, np.integer)) or min_particles < 0:
        raise ValueError(f"min_particles: must be a non-negative int, got {min_particles!r}")


def without_fragments(mesh: Mesh, field, min_particles: int | None) -> Mesh:
    """``mesh`` without its bodies holding fewer than ``min_particles`` of ``field``'s centres
    (``mesh`` itself for ``None``); see :func:`polygonize`."""
    if min_particles is None:
        return mesh
    keep, bodies, particles = _core.small_bodies(mesh.vertices, mesh.faces, field.centers, int(min_particles))
    out = mesh.trimmed(keep)
    out.stats.pop("trimmed", None)
    out.stats.update(fragments_dropped=bodies, fragment_particles=particles)
    return out


def _check_trim(field, trim) -> None:
    """A ValueError naming ``trim`` unless it is None, or a positive distance for a field
    fitted to data."""
    if trim is None:
        return
    if not hasattr(field, "distance_to_data"):
        raise ValueError("trim: only for a VariationalSurface (a field fitted to data)")
    if isinstance(trim, bool) or not isinstance(trim, (int, float, np.floating, np.integer)) or not (np.isfinite(trim) and trim > 0):
        raise ValueError(f"trim: must be a positive distance, got {trim!r}")


def trimmed(mesh: Mesh, field, trim: float | None) -> Mesh:
    """``mesh`` without the bodies a scan fit's data disowns (see
    :meth:`VariationalSurface.owned_vertices`; ``stats["bodies_dropped"]`` counts them) and
    without the triangles that have a vertex farther than ``trim`` from ``field``'s data (none
    for ``trim=None``); see :func:`polygonize`."""
    if getattr(field, "report", None) is not None and len(mesh.faces):
        owned, dropped = field.owned_vertices(mesh.vertices, mesh.faces)
        kept = mesh.trimmed(owned)
        kept.stats.pop("trimmed")
        kept.stats["bodies_dropped"] = dropped
        mesh = kept
    if trim is None:
        return mesh
    return mesh.trimmed(field.distance_to_data(mesh.vertices) <= trim)


def _mesh(polygonizer, what: str, progress, *args, **kwargs) -> Mesh:
    """Calls the core's ``polygonizer`` with a progress report titled ``what``; its result as a
    :class:`Mesh` whose stats also count the triangles and vertices."""
    report, end = reporter(progress, what)
    try:
        v, f, n, stats, *_ = polygonizer(*args, progress=report, **kwargs)
    finally:
        end()
    stats["triangles"] = len(f)
    stats["vertices"] = len(v)
    return Mesh(v, f, n, stats)


def _check_common(field, bounds, ambiguity, batch_size, memory_limit):
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
    _check_positive("batch_size", batch_size)
    if memory_limit is not None:
        _check_positive("memory_limit", memory_limit)
    return bounds, ambiguity


def _check_positive(name: str, value) -> None:
    """A ValueError naming ``name`` unless ``value`` is a positive integer."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
        raise ValueError(f"{name}: must be a positive integer, got {value!r}")


class Tessellator:
    """Surface tracking that keeps its caches and buffers between calls, for animation.

    Move the field (e.g. :meth:`BlobField.update`) and call :meth:`polygonize` again. The walk
    starts from the same seeds as ``polygonize(field, method="tracking")`` and finds the same
    mesh, triangle for triangle and bit for bit (only the order of vertices and triangles may
    differ): for a :class:`BlobField` every component (the dense mesh), for other fields every
    component that holds a seed.

    For a :class:`BlobField` the walk goes block by block (``blocks=True``, the default): a
    block of 7 × 7 × 7 cells is evaluated at once (all 8³ points, vectorised) when the walk first
    enters one of its cells, and within the block the walk is a flood over bit sets, one 64-bit
    word per plane of cells. When the walk ends, the crossed cells it did not reach in the blocks
    it evaluated, and the blocks it did not enter that the bounds of ``method="sparse"`` cannot
    rule out (evaluated then), start it again, so it finds the components no seed reaches; when
    the seeds reach everything, that costs the bounds of the blocks not entered and the few of
    them the bounds cannot rule out. It evaluates the points ``method="sparse"`` evaluates and is
    several times faster than the walk cell by cell; the blocks the previous call used are
    evaluated first, as an animation's surface moves little between frames (and then, as they
    and the bounds reach every component, no seed walks are made). Its output is ordered block
    by block and does not depend on earlier calls. With ``blocks=False``, and for
    other fields, the walk goes cell by cell with time-stamped caches of corner values and edge
    vertices (Triquet et al. §4.1, §4.4): nothing is cleared between calls, and for other fields
    that walk evaluates the fewest points, which pays for costly fields (a Python callable, a
    large variational fit). For a :class:`BlobField` it then also evaluates, block by block,
    every block the bounds cannot rule out, and walks on from the crossed cells it did not reach.
    In steady state neither walk reallocates its buffers; each call returns new arrays.

    Examples
    --------
    >>> blobs = BlobField(centers, radii=0.25)
    >>> tess = Tessellator()
    >>> for frame in range(100):
    ...     blobs.update(move(centers, frame))
    ...     mesh = tess.polygonize(blobs, resolution=64)
    """

    def __init__(self) -> None:
        self._core = _core.Tessellator()

    def polygonize(
        self,
        field: Field,
        *,
        bounds: Any = None,
        resolution: int | Sequence[int] = 64,
        seeds: Any = None,
        ambiguity: Ambiguity | str = Ambiguity.SEPARATE,
        normals: bool = True,
        batch_size: int = 262144,
        memory_limit: int | None = None,
        blocks: bool = True,
        progress: Any = False,
    ) -> Mesh:
        """Tracks the surface of ``field``; arguments as for :func:`polygonize` with
        ``method="tracking"``.

        Parameters
        ----------
        blocks : bool
            For a :class:`BlobField`, walk block by block (faster, the same mesh). Ignored for
            other fields, which are walked cell by cell.
        progress : bool or callable
            As for :func:`polygonize`.

        Returns
        -------
        Mesh
            A new mesh (its arrays are not shared with the caches). ``stats["evaluations"]``
            counts, cell by cell, the points the seed walks and the tracking evaluated, and for a
            :class:`BlobField` every point of the blocks evaluated to find the components no
            walk reaches; block by block, every point of each block evaluated: every block that
            the bounds cannot rule out, and only those (the points ``method="sparse"``
            evaluates), whichever blocks the walk entered or the previous call evaluated ahead.
        """
        bounds, ambiguity = _check_common(field, bounds, ambiguity, batch_size, memory_limit)
        if not isinstance(blocks, (bool, np.bool_)):
            raise ValueError(f"blocks: must be True or False, got {blocks!r}")
        return _mesh(
            self._core.polygonize,
            "track",
            progress,
            field,
            bounds,
            resolution,
            seeds=seeds,
            ambiguity=ambiguity,
            normals=normals,
            batch_size=batch_size,
            memory_limit=memory_limit,
            blocks=bool(blocks),
        )

    @property
    def capacity_bytes(self) -> int:
        """Bytes held by the caches and buffers (to check that memory stays flat)."""
        return self._core.capacity_bytes
