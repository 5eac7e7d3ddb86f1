"""The weld of a gathered run: one protocol (:class:`Weld`), two welds: in the client's memory
(:class:`StreamedWeld`) and in place in the run's directory
(:class:`._weld_in_place.WeldInPlace`)."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from .. import _core
from . import _tile_files, _weld_in_place
from ._plan import Plan
from ._tile import TileMesh, TileResult


class Weld(Protocol):
    """What the client's collection of a gathered run needs of a weld: each tile's
    :class:`TileResult` ``add``-ed in window order, then the welded arrays."""

    def entry_task(self, tile: int, fut: Any) -> Any:
        """For tile ``tile``'s finished task ``fut``: the future of a follow-up task whose result
        is the tile's :class:`TileResult` to add instead (its mesh stayed on its worker), or None
        (add ``fut``'s own result)."""
        ...

    def add(self, result: TileResult, tile: int) -> None:
        """Welds tile number ``tile`` (tiles come in window order); ``result`` keeps its counts
        and lets go of its arrays."""
        ...

    @property
    def vertices(self) -> int:
        """Welded vertices so far."""
        ...

    def tasks(self) -> list:
        """The futures of the weld's own tasks (cancelled with the run)."""
        ...

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The welded ``(vertices (V, 3) float64, faces (F, 3) int64, normals (V, 3) or (0, 3)
        float64)`` once every tile is added."""
        ...


class StreamedWeld:
    """The weld of a gathered run in the client's memory (:class:`_core.StreamedWeld`), each
    tile read from its result or from the file its worker left in the run's directory
    ``local``."""

    def __init__(self, stream: _core.StreamedWeld, local: str | None):
        self.stream, self.local = stream, local

    def tasks(self) -> list:
        return []

    def entry_task(self, tile: int, fut: Any) -> None:
        return None

    @property
    def vertices(self) -> int:
        return self.stream.vertices

    def add(self, result: TileResult, tile: int) -> None:
        window = [list(result.window[0]), list(result.window[1])]
        if result.file is not None:
            assert self.local is not None
            with _tile_files.read(self.local, result.file) as arrays:
                self.stream.add(window, *TileMesh.from_file_arrays(arrays).weld_arrays())
            result.file = None
        else:
            m, result.mesh = result.mesh, None
            assert m is not None
            self.stream.add(window, *m.weld_arrays())

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.stream.result()


def gathered_weld(client: Any, local: str | None, kept: dict | None, tiles: int, plan: Plan) -> Weld:
    """The weld of a gathered run of ``tiles`` tiles: in place in the run's directory ``local``
    (``kept``: the futures of the tiles' tasks, see :mod:`._weld_in_place`), else in the
    client's memory."""
    normals, limit = bool(plan.options["normals"]), plan.memory_limit
    if kept is not None:
        assert local is not None
        return _weld_in_place.WeldInPlace(client, local, kept, plan.cells, plan.origin, plan.cell, normals, limit)
    return StreamedWeld(_core.StreamedWeld(tiles, plan.cells, plan.origin, plan.cell, normals, limit), local)


def weld_tile(weld: Weld, result: TileResult, tile: int) -> None:
    """Welds tile number ``tile`` (its task's ``result``) into ``weld`` (a seam for tests and
    benchmarks to watch each tile arrive)."""
    weld.add(result, tile)
