"""One tile of a tiled run: the task that polygonizes it on a worker (:func:`run_tile`) and what
it gives back (:class:`TileResult`, and :class:`KeptTile` on the worker for a weld in place)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _core
from . import _cut_files, _tile_files
from ._plan import Window
from ._transport import Transport

#: Statistics of the tiles that add up to the whole run's.
SUMMED = ("evaluations", "normal_evaluations", "lattice_points", "cells_visited", "cells_crossed", "cells_repaired")


@dataclass
class TileMesh:
    """A tile's mesh as the weld takes it: ``vertices`` (V, 3) float64, ``faces`` (F, 3)
    uint32, ``normals`` (V, 3) or (0, 3) float64, and its vertices on lattice edges in its
    boundary faces, ``boundary`` (B,) uint32 (their indices) and ``keys`` (B,) uint64 (their
    edges' keys in the whole lattice's numbering)."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    boundary: np.ndarray
    keys: np.ndarray

    #: The arrays' order in a tile file (8-byte elements first, so that every array's data is
    #: aligned in it).
    FILE_ORDER = ("vertices", "normals", "keys", "faces", "boundary")

    @property
    def nbytes(self) -> int:
        return sum(int(a.nbytes) for a in self.weld_arrays())

    def weld_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(vertices, faces, normals, boundary, keys)``, as ``_core.StreamedWeld.add`` takes them."""
        return self.vertices, self.faces, self.normals, self.boundary, self.keys

    def file_arrays(self) -> list[np.ndarray]:
        return [getattr(self, k) for k in self.FILE_ORDER]

    @classmethod
    def from_file_arrays(cls, arrays: list[np.ndarray]) -> "TileMesh":
        return cls(**dict(zip(cls.FILE_ORDER, arrays)))


@dataclass
class TileResult:
    """What a tile's task gives the client: its ``window`` of cells, its counts and ``stats``
    (those of ``SUMMED``), ``nbytes`` its mesh's bytes, and its mesh in one place: ``mesh``
    (through Dask), ``file`` (a file in the run's directory, or the ``.npz`` of a run written to a
    directory), or ``boundary`` alone, ``(indices, keys, positions)`` of its boundary vertices,
    for a tile whose mesh stays on its worker (a weld in place plans with it)."""

    window: Window
    vertices: int
    faces: int
    stats: dict[str, int]
    nbytes: int = 0
    mesh: TileMesh | None = None
    file: str | None = None
    boundary: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def kept(self) -> bool:
        """Whether the tile's mesh stays on its worker."""
        return self.boundary is not None

    def entry(self) -> dict[str, Any]:
        """The tile's entry in a run directory's manifest."""
        return {
            "window": [list(self.window[0]), list(self.window[1])],
            "vertices": self.vertices,
            "faces": self.faces,
            "stats": self.stats,
            "file": self.file,
        }

    @classmethod
    def from_entry(cls, entry: dict[str, Any]) -> "TileResult":
        """A tile of a run directory, from its manifest ``entry``."""
        lo, hi = entry["window"]
        return cls((tuple(lo), tuple(hi)), entry["vertices"], entry["faces"], entry["stats"], file=entry["file"])


@dataclass
class KeptTile:
    """A tile's result and its mesh, held by its worker (``Transport.keep``) until the weld in
    place has them written."""

    result: TileResult
    mesh: TileMesh


def tile_name(window: Window) -> str:
    return "tile-{}-{}-{}".format(*window[0])


def run_tile(
    field: Any, bounds: Any, resolution: Any, window: Window, method: str, options: dict[str, Any], transport: Transport
) -> TileResult | KeptTile:
    """One task: polygonizes the cells ``window`` of the lattice (``bounds``, ``resolution``)
    with ``method`` and the keywords ``options``; its mesh travels as ``transport`` says (a
    :class:`KeptTile` when it stays on this worker). ``field`` may be a
    :class:`._cut_files.CutFile`, read here."""
    if isinstance(field, _cut_files.CutFile):
        field = field.load()
    v, f, n, stats, b, k = _core.polygonize(
        field, bounds, resolution, method=method, window=window, boundary=True, **options
    )
    mesh = TileMesh(v, f, n, b, k)
    result = TileResult(window, len(v), len(f), {key: stats[key] for key in SUMMED}, mesh.nbytes)
    name = tile_name(window)
    if transport.kind == "output":
        assert transport.directory is not None
        result.file = name + ".npz"
        tmp = os.path.join(transport.directory, result.file + ".part")
        with open(tmp, "wb") as fh:
            np.savez(fh, vertices=v, faces=f, normals=n, boundary=b, keys=k)
        os.replace(tmp, os.path.join(transport.directory, result.file))
        return result
    large = result.nbytes >= transport.min_bytes
    if transport.kind == "keep" and large:
        return KeptTile(result, mesh)
    if (
        transport.kind == "files"
        and large
        and transport.directory is not None
        and _tile_files.write(transport.directory, name, mesh.file_arrays())
    ):
        result.file = name
    else:
        result.mesh = mesh
    return result
