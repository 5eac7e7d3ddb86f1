"""A gathered run's weld written in place: the welded mesh's arrays are files in the run's
directory in shared memory, and each tile's rows are written straight into them.

The client plans the weld from each tile's counts and boundary vertices alone
(``_core.WeldPlan``, in window order, as :class:`_core.StreamedWeld` welds): where the tile's
kept vertices and its triangles go, and which of its vertices join an earlier tile's. A tile
that its worker keeps (``Transport.keep``: a :class:`._tile.KeptTile`) is then written by a
second task there, which writes the tile's rows where the plan puts them
(``_core.write_welded_tile``); a tile that came back through Dask's comms is written by the
client. At the end the client maps the files: the mesh's arrays are those
pages, not a copy. So the client never copies the tiles, and the pages of the welded mesh are
first written by the workers, in parallel; the result is :class:`_core.StreamedWeld`'s, array
for array.

Each region is allocated (``posix_fallocate``) before it is mapped, so a full shared memory
raises ``OSError`` instead of a bus error.
"""

from __future__ import annotations

import mmap
import os
from contextlib import ExitStack, contextmanager
from typing import Any, Iterator

import numpy as np

from .. import _core
from . import _tile_files
from ._tile import KeptTile, TileResult

#: The welded arrays, their dtypes (three columns each).
ARRAYS = {"vertices": np.float64, "faces": np.int64, "normals": np.float64}

#: Tiles written by workers run before tiles not yet polygonized (Dask runs higher first), so
#: that their arrays are freed early.
WRITE_PRIORITY = 1

#: Runs of smaller tiles weld in the client (``_core.StreamedWeld``): their meshes are small, and
#: the second task per tile that the weld in place needs costs more than it saves.
MIN_TILE_CELLS = 64**3

#: Tiles of fewer bytes come back whole from their task and the client writes them: below this
#: size, the two more tasks that keep a tile on its worker cost more than the client's writing
#: of its rows.
MIN_KEPT_BYTES = 8 << 20


def usable(directory: str | None, memory_limit: int, tile_cells: int, worker_threads: int) -> bool:
    """Whether a run of tiles of ``tile_cells`` cells welds in place: tiles of at least
    ``MIN_TILE_CELLS``, workers with ``worker_threads`` threads in all that leave the client no
    core of this machine (else the client welds, beside them), and a directory in shared memory
    (tmpfs) with room for ``memory_limit`` bytes (the most the welded mesh may take)."""
    if tile_cells < MIN_TILE_CELLS or worker_threads < (os.cpu_count() or 1):
        return False
    if directory is None or not directory.startswith(_tile_files.SHARED_MEMORY + os.sep):
        return False
    try:
        st = os.statvfs(directory)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize >= memory_limit


@contextmanager
def _region(path: str, row: int, rows: int, dtype: Any) -> Iterator[np.ndarray]:
    """Rows ``row`` to ``row + rows`` of the (N, 3) array in file ``path``, allocated and mapped
    writable for the ``with`` block."""
    itemsize = 3 * np.dtype(dtype).itemsize
    if rows == 0:
        yield np.empty((0, 3), dtype)
        return
    start, size = row * itemsize, rows * itemsize
    base = start - start % mmap.ALLOCATIONGRANULARITY
    fd = os.open(path, os.O_RDWR)
    try:
        os.posix_fallocate(fd, start, size)
        populate = getattr(mmap, "MAP_POPULATE", 0)
        mapped = mmap.mmap(fd, start + size - base, flags=mmap.MAP_SHARED | populate, offset=base)
    finally:
        os.close(fd)
    view = np.frombuffer(mapped, dtype=dtype, count=3 * rows, offset=start - base).reshape(rows, 3)
    try:
        yield view
    finally:
        del view
        try:
            mapped.close()
        except BufferError:  # a view of it is still referenced: it is unmapped with the last one
            pass


def write_rows(paths: dict[str, str], v, f, n, first_vertex: int, first_face: int, joined: np.ndarray) -> None:
    """Writes one tile's rows (``v``, ``f``, ``n`` its vertices, faces and normals) into the
    welded arrays' files ``paths`` where the plan (``first_vertex``, ``first_face``,
    ``joined``) puts them; normals only when ``paths`` has a ``"normals"`` file."""
    kept = len(v) - len(joined)
    with ExitStack() as stack:
        rooms = [
            stack.enter_context(_region(paths["vertices"], first_vertex, kept, np.float64)),
            stack.enter_context(_region(paths["faces"], first_face, len(f), np.int64)),
        ]
        if "normals" in paths:
            rooms.append(stack.enter_context(_region(paths["normals"], first_vertex, kept, np.float64)))
        _core.write_welded_tile(v, f, n, first_vertex, joined, *rooms)
        rooms.clear()  # the maps close only without views of them


def tile_entry(result: KeptTile | TileResult) -> TileResult:
    """A task on the worker that holds a tile (a :class:`KeptTile`): the result the client plans
    the weld with, with its boundary vertices' indices, keys and positions. A tile that came back
    whole is its own result."""
    if isinstance(result, TileResult):
        return result
    m = result.mesh
    return TileResult(**{**vars(result.result), "boundary": (m.boundary, m.keys, m.vertices[m.boundary])})


def write_kept(kept: KeptTile, paths: dict[str, str], first_vertex: int, first_face: int, joined) -> tuple | None:
    """A task on the worker that holds a tile (a :class:`KeptTile`): writes its rows into the
    welded arrays' files ``paths``; a worker that does not see them (another machine) or cannot
    write them (another user, shared memory full) returns ``(vertices, faces, normals)`` for the
    client to write."""
    m = kept.mesh
    if not os.path.isdir(os.path.dirname(paths["vertices"])):
        return m.vertices, m.faces, m.normals
    try:
        write_rows(paths, m.vertices, m.faces, m.normals, first_vertex, first_face, joined)
    except OSError:
        return m.vertices, m.faces, m.normals
    return None


#: How Dask names the type of a tile that came back whole (it reports a result's type without
#: sending the result).
_WHOLE = (TileResult, f"{TileResult.__module__}.{TileResult.__qualname__}")


class WeldInPlace:
    """The weld of a gathered run into files of its ``directory`` (a :class:`._weld.Weld`):
    ``add`` each tile's result in window order, then ``result``. ``kept`` holds the futures of
    the tiles' tasks by tile (filled as they are submitted); each is released once its write is
    submitted."""

    def __init__(self, client: Any, directory: str, kept: dict, cells, origin, cell, normals: bool, memory_limit: int | None):
        self.client, self.kept = client, kept
        self.plan = _core.WeldPlan(cells, origin, cell, normals, memory_limit)
        self.paths = {k: os.path.join(directory, f"welded-{k}") for k in ARRAYS if normals or k != "normals"}
        for path in self.paths.values():
            open(path, "wb").close()
        #: (future, plan) of the tiles' writes.
        self.writes: list = []

    def tasks(self) -> list:
        """The futures of the writes."""
        return [w[0] for w in self.writes]

    def entry_task(self, tile: int, fut: Any) -> Any:
        """For tile ``tile``'s finished task ``fut``: the future of a task on its worker giving
        its :class:`TileResult` when the tile stays there (a :class:`KeptTile`), else None (the
        tile came back whole)."""
        if self.kept.get(tile) is not fut or fut.type in _WHOLE:
            return None
        return self.client.submit(tile_entry, fut, pure=False)

    @property
    def vertices(self) -> int:
        """Welded vertices planned so far."""
        return self.plan.vertices

    def add(self, result: TileResult, tile: int) -> None:
        """Plans tile number ``tile`` from its task's ``result`` and has its rows written (the
        result keeps its counts, not its arrays)."""
        if result.boundary is not None:
            b, k, p = result.boundary
            result.boundary = None
            plan = self.plan.add(result.window, result.vertices, result.faces, b, k, p)
            arrays = self.kept.pop(tile)
            fut = self.client.submit(write_kept, arrays, self.paths, *plan, pure=False, priority=WRITE_PRIORITY)
            # Released here, the tile's arrays stay on its worker until the write has run.
            arrays.release()
            self.writes.append((fut, plan))
            return
        m, result.mesh = result.mesh, None
        assert m is not None
        plan = self.plan.add(result.window, len(m.vertices), len(m.faces), m.boundary, m.keys, m.vertices[m.boundary])
        write_rows(self.paths, m.vertices, m.faces, m.normals, *plan)
        fut = self.kept.pop(tile, None)
        if fut is not None:
            fut.release()

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The welded ``(vertices, faces, normals)`` once every tile is written (the rows that
        workers returned written by the client): the files mapped (writable)."""
        returned = self.client.gather([w[0] for w in self.writes])
        for rows, (_, plan) in zip(returned, self.writes):
            if rows is not None:
                write_rows(self.paths, *rows, *plan)
        self.writes = []
        rows = {"vertices": self.plan.vertices, "faces": self.plan.faces, "normals": self.plan.vertices}
        out = [_mapped(self.paths[k], rows[k], ARRAYS[k]) if k in self.paths else np.zeros((0, 3)) for k in ARRAYS]
        return out[0], out[1], out[2]


def _mapped(path: str, rows: int, dtype: Any) -> np.ndarray:
    """The (rows, 3) array of file ``path``, mapped writable (the file may be deleted after)."""
    if rows == 0:
        return np.empty((0, 3), dtype)
    size = rows * 3 * np.dtype(dtype).itemsize
    fd = os.open(path, os.O_RDWR)
    try:
        os.ftruncate(fd, size)
        mapped = mmap.mmap(fd, size, flags=mmap.MAP_SHARED | getattr(mmap, "MAP_POPULATE", 0))
    finally:
        os.close(fd)
    return np.frombuffer(mapped, dtype=dtype).reshape(rows, 3)
