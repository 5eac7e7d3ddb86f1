"""The plan of a tiled run: its arguments checked, the lattice cut into tiles of cells, and what
each tile receives of the field (its cut)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field as dataclass_field
from typing import Any, Iterator, Sequence

import numpy as np

from .. import _core
from ..options import _method_keywords
from ..polygonize import _check_common

#: Methods :func:`implicitmesh.distributed.polygonize` runs per tile (``"sparse"`` and
#: ``"tracking"``: BlobField only).
TILE_METHODS = ("dense", "sparse", "octree", "tracking")

#: Relative margin on a primitive's radius when cutting a blob field to a tile, far above
#: rounding, so that no primitive adding a non-zero term at a point of the tile is left out.
RADIUS_MARGIN = 1e-6

#: A window of cells ``(lo, hi)``, ``lo <= i < hi`` per axis.
Window = tuple[tuple[int, int, int], tuple[int, int, int]]


def check_tile(tile: Any) -> tuple[int, int, int]:
    """``tile`` (one positive integer or three) as three cells per tile edge; a ValueError
    naming ``tile`` otherwise."""
    values = [tile] if np.ndim(tile) == 0 else list(np.asarray(tile, dtype=object).ravel())
    if len(values) == 1:
        values = values * 3
    if len(values) != 3:
        raise ValueError(f"tile: expected one positive integer or three, got {tile!r}")
    for v in values:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise ValueError(f"tile: cells per tile edge must be positive integers, got {tile!r}")
    return (int(values[0]), int(values[1]), int(values[2]))


def tiles(cells: Sequence[int], tile: Sequence[int]) -> Iterator[Window]:
    """The windows ``(lo, hi)`` of cells, ``lo <= i < hi`` per axis, that cut a lattice of
    ``cells`` cells into tiles of ``tile`` cells (the last tile along an axis holds what is
    left), z slowest, then y, then x."""
    ranges = [[(s, min(s + t, n)) for s in range(0, n, t)] for n, t in zip(cells, tile)]
    for rz, ry, rx in itertools.product(ranges[2], ranges[1], ranges[0]):
        yield (rx[0], ry[0], rz[0]), (rx[1], ry[1], rz[1])


def tile_box(origin: np.ndarray, cell: np.ndarray, lo: Any, hi: Any) -> tuple[np.ndarray, np.ndarray]:
    """Corners, (3,) float64 each, of the tile of cells ``[lo, hi)`` as the core computes
    lattice points (per coordinate one product and one sum)."""
    return origin + np.asarray(lo, dtype=np.float64) * cell, origin + np.asarray(hi, dtype=np.float64) * cell


def cut_blobs(field: _core.BlobField, lo: np.ndarray, hi: np.ndarray) -> _core.BlobField | None:
    """The blob field of the primitives of ``field`` whose sphere of influence reaches the box
    ``[lo, hi]`` ((3,) float each), in their order (so values and gradients in the box are the
    same bits as the whole field's), or None when no primitive reaches it (the field is
    positive there)."""
    return field._cut(np.stack([lo, hi]), RADIUS_MARGIN)


def blob_tiles(field: _core.BlobField, cells: Sequence[int], origin: np.ndarray, cell: np.ndarray, tile: Sequence[int]) -> list:
    """:func:`cut_blobs` for every tile of :func:`tiles` at once, in its order (None for a tile
    no primitive reaches): the core tests each primitive against the tiles its sphere's bounding
    box meets (widened by a millionth of a tile against rounding), not against every tile, with
    :func:`cut_blobs`'s test, so each tile gets the same primitives."""
    index, start = field._tile_primitives(origin, cell, cells, tile, RADIUS_MARGIN)
    return [field._subset(index[a:b]) if b > a else None for a, b in zip(start[:-1], start[1:])]


def cut_per_tile(field: Any) -> bool:
    """Whether each tile receives its own cut of ``field`` (a blob field, a partition fit),
    rather than the whole field once."""
    return isinstance(field, _core.BlobField) or (
        isinstance(field, _core.VariationalSurface) and field.method == "partition"
    )


def cut_field(field: Any, lo: np.ndarray, hi: np.ndarray) -> Any:
    """What a tile ``[lo, hi]`` (its box, (3,) float each) needs of ``field``: for a
    :class:`BlobField` the primitives reaching the box (None when none does), for a partition
    :class:`VariationalSurface` the patches its points use, its octree split only where it
    meets the box and the constraints inside those patches; other fields whole. Values and
    gradients in the box are the same bits as the whole field's."""
    if isinstance(field, _core.BlobField):
        return cut_blobs(field, lo, hi)
    if isinstance(field, _core.VariationalSurface):
        return field._cut(np.stack([lo, hi]))
    return field


def tile_fields(field: Any, shared: Any, cells: Sequence[int], origin: np.ndarray, cell: np.ndarray, tile: Sequence[int]) -> Iterator[Any]:
    """What each tile of :func:`tiles` receives, in its order: ``shared`` (the whole field's
    future) when given, else :func:`cut_field` of the tile (None: not run)."""
    if shared is not None:
        return itertools.repeat(shared)
    if isinstance(field, _core.BlobField):
        return iter(blob_tiles(field, cells, origin, cell, tile))
    return (cut_field(field, *tile_box(origin, cell, lo, hi)) for lo, hi in tiles(cells, tile))


def tile_priority(part: Any) -> float:
    """The Dask priority of a tile's task. The tiles of a partition fit run the cuts with more
    constraints first (a tile's work grows with its constraints and varies several times between
    tiles), so that the last tasks to finish are short ones; all below the weld's writes
    (``_weld_in_place.WRITE_PRIORITY``), so that writes run before further tiles. Other tiles
    run in window order (0), the order the weld takes them in."""
    if isinstance(part, _core.VariationalSurface) and part.method == "partition":
        return -1.0 / (1.0 + len(part))
    return 0.0


@dataclass(frozen=True)
class Plan:
    """A tiled run's checked arguments and lattice: ``cells`` per axis, ``origin`` and ``cell``
    ((3,) float64), ``tile`` cells per tile edge, ``options`` the keywords of each tile's
    ``_core.polygonize`` (``ambiguity``, ``normals``, ``batch_size``, ``memory_limit`` and the
    method's own), ``project`` and ``normals`` what the client does after the weld."""

    field: Any
    bounds: np.ndarray
    resolution: Any
    method: str
    cells: tuple[int, int, int]
    origin: np.ndarray
    cell: np.ndarray
    tile: tuple[int, int, int]
    options: dict[str, Any] = dataclass_field(default_factory=dict)
    project: bool = False
    normals: bool = True

    @property
    def batch_size(self) -> int:
        return self.options["batch_size"]

    @property
    def memory_limit(self) -> int | None:
        return self.options["memory_limit"]

    def windows(self) -> Iterator[Window]:
        """The tiles' windows (:func:`tiles`)."""
        return tiles(self.cells, self.tile)

    def box(self, window: Window) -> tuple[np.ndarray, np.ndarray]:
        """The box of the tile ``window`` (:func:`tile_box`)."""
        return tile_box(self.origin, self.cell, *window)

    def info(self) -> dict[str, Any]:
        """The lattice and method, as a manifest and the stats record them."""
        return {"cells": list(self.cells), "origin": self.origin.tolist(), "cell": self.cell.tolist(), "method": self.method}


def make_plan(
    field: Any,
    *,
    bounds: Any,
    resolution: Any,
    method: Any,
    tile: Any,
    ambiguity: Any,
    normals: Any,
    project: Any,
    batch_size: Any,
    memory_limit: Any,
    method_options: dict[str, Any],
    options: Any,
) -> Plan:
    """Checks a tiled run's arguments (each once; the core checks the rest per tile) and plans
    its lattice. ``method_options``: the flat per-method keywords (``start_level``,
    ``safety``, ``corner_test``, ``seeds``; None when not given)."""
    tile3 = check_tile(tile)
    if not isinstance(method, str) or method.lower() not in TILE_METHODS:
        raise ValueError(f"method: expected one of {TILE_METHODS} per tile, got {method!r}")
    method = method.lower()
    if method in ("sparse", "tracking") and not isinstance(field, _core.BlobField):
        raise ValueError(
            f'method: "{method}" per tile needs a BlobField (tracking other fields finds only the '
            'components seeded in each tile); use "dense" or "octree"'
        )
    per_method = _method_keywords(method, options, method_options)
    if per_method.pop("seeds", None) is not None:
        raise TypeError("seeds: not taken per tile (tracking a BlobField per tile finds every component)")
    for name, value in per_method.items():
        if value is not None and method != "octree":
            # Checked here, not in each task.
            raise ValueError(f'{name}: applies to method="octree" only')
    bounds, ambiguity = _check_common(field, bounds, ambiguity, batch_size, memory_limit)
    if not isinstance(project, (bool, np.bool_)):
        raise ValueError(f"project: must be True or False, got {project!r}")
    bounds = np.asarray(bounds, dtype=np.float64)
    cells, origin, cell = _core.lattice(bounds, resolution)
    if not (isinstance(field, (_core.BlobField, _core.VariationalSurface)) or callable(field)):
        raise TypeError(f"field: expected a VariationalSurface, a BlobField or a callable, got {type(field).__name__}")
    tile_options = dict(
        ambiguity=ambiguity,
        # With project, normals are taken at the projected vertices, after the weld.
        normals=False if project else normals,
        batch_size=batch_size,
        memory_limit=memory_limit,
        **{k: v for k, v in per_method.items() if v is not None},
    )
    return Plan(
        field=field,
        bounds=bounds,
        resolution=resolution,
        method=method,
        cells=(int(cells[0]), int(cells[1]), int(cells[2])),
        origin=np.asarray(origin),
        cell=np.asarray(cell),
        tile=tile3,
        options=tile_options,
        project=bool(project),
        normals=normals,
    )
