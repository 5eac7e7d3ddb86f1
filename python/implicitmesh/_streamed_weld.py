"""The weld of tile meshes one tile at a time, as a tiled run's tiles arrive.

:class:`StreamedWeld` takes the tiles in the order of their windows (z, y, x of their corners,
the order ``_core.weld_tiles`` lists them in) and makes the mesh ``_core.weld_tiles`` makes of
all of them at once, array for array: the vertices tile after tile, each tile's in its order, a
vertex whose lattice edge an earlier tile has (its edge key among that tile's boundary keys)
joined to that tile's vertex; the triangles tile after tile. Each tile is written into the
output arrays when it is added and can then be freed, so the caller holds the output and the
tiles not yet added, never all the tiles and the output at once.

The output arrays are allocated for an estimate of the whole (the rows so far, per tile, times
the tiles), untouched beyond what is written; they grow in place (``ndarray.resize``: on Linux a
remapping, not a copy) when the estimate falls short, and are cut to their rows at the end.
"""

from __future__ import annotations

import numpy as np

#: Slack on the estimate of the output's rows.
_SLACK = 1.25


class _Rows:
    """An ``(N, 3)`` array filled from the front: ``n`` rows written of its capacity."""

    def __init__(self, dtype: type) -> None:
        self.a = np.empty((0, 3), dtype=dtype)
        self.n = 0

    def room(self, rows: int, estimate: int) -> np.ndarray:
        """The next ``rows`` rows (a view to write), growing the capacity to at least
        ``estimate`` rows when they do not fit; they count as written."""
        need = self.n + rows
        if need > len(self.a):
            size = max(need, estimate)
            if self.n == 0:
                self.a = np.empty((size, 3), dtype=self.a.dtype)
            else:
                self.a.resize((size, 3), refcheck=False)
        out = self.a[self.n : need]
        self.n = need
        return out

    def array(self) -> np.ndarray:
        """The rows written (the array itself, cut to them)."""
        if len(self.a) != self.n:
            self.a.resize((self.n, 3), refcheck=False)
        return self.a


class StreamedWeld:
    """Welds ``tiles`` tile meshes given one at a time in window order (see the module).

    Parameters
    ----------
    tiles : int
        The number of tiles that will be added (for the output's estimate).
    normals : bool or None
        Whether the tiles carry normals (one per vertex); None: as the first tile with
        vertices does.
    """

    def __init__(self, tiles: int, normals: bool | None) -> None:
        self.tiles, self.added = tiles, 0
        self.vertices, self.faces, self.normals = _Rows(np.float64), _Rows(np.int64), _Rows(np.float64)
        self.with_normals = normals
        #: Edge key -> welded vertex, for the boundary vertices of the tiles added.
        self.ids: dict[int, int] = {}

    def _estimate(self, rows: _Rows, more: int) -> int:
        per_tile = (rows.n + more) / (self.added + 1)
        return int(per_tile * self.tiles * _SLACK)

    def add(self, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, boundary: np.ndarray,
            keys: np.ndarray) -> None:
        """Adds the next tile: ``vertices`` (V, 3) float64, ``faces`` (F, 3) uint32,
        ``normals`` (V, 3) float64 (or (0, 3) without normals), ``boundary`` (B,) uint32 and
        ``keys`` (B,) uint64 as ``_core.polygonize(..., boundary=True)`` returns them.

        Raises ValueError (naming ``faces``, ``normals`` or ``tiles``) for a triangle index
        outside the tile, normals not one per vertex, or a vertex joined to one at other
        coordinates (tiles of different fields or lattices)."""
        nv = len(vertices)
        if self.with_normals is None and nv:
            self.with_normals = len(normals) == nv
        if len(faces) and int(faces.max()) >= nv:
            raise ValueError(f"faces: tile {self.added} has vertex index {int(faces.max())}, outside its {nv} vertices")
        if self.with_normals and len(normals) != nv:
            raise ValueError(f"normals: tile {self.added} has {len(normals)} normals for {nv} vertices")
        found = np.fromiter((self.ids.get(k, -1) for k in keys.tolist()), dtype=np.int64, count=len(keys))
        hit = found >= 0
        joined, to = boundary[hit], found[hit]
        if not np.array_equal(vertices[joined].view(np.uint64), self.vertices.a[to].view(np.uint64)):
            raise ValueError(f"tiles: tile {self.added} has a vertex of an edge an earlier tile has at other coordinates "
                             "(tiles of different fields or lattices?)")
        keep = np.ones(nv, dtype=bool)
        keep[joined] = False
        kept = nv - len(joined)
        first = self.vertices.n
        index = np.cumsum(keep, dtype=np.int64)
        index += first - 1
        index[joined] = to
        for rows, data in ((self.vertices, vertices), (self.normals, normals)):
            if rows is self.vertices or self.with_normals:
                np.compress(keep, data, axis=0, out=rows.room(kept, self._estimate(rows, kept)))
        np.take(index, faces, out=self.faces.room(len(faces), self._estimate(self.faces, len(faces))), mode="clip")
        new = ~hit
        self.ids.update(zip(keys[new].tolist(), index[boundary[new]].tolist()))
        self.added += 1

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(vertices (V, 3) float64, faces (F, 3) int64, normals (V, 3) float64 or (0, 3))``."""
        normals = self.normals.array() if self.with_normals else np.zeros((0, 3))
        return self.vertices.array(), self.faces.array(), normals
