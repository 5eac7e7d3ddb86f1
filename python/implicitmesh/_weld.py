"""The exact weld of tile meshes: tiles are windows of one lattice, so the vertex of a lattice
edge on a face two tiles share is the same number in both; joining them gives the mesh of the
whole lattice, vertex for vertex.

A vertex not at a lattice point lies on exactly one lattice edge, so its position names the edge
and is its key. At a lattice point several edges can give the same position (where the field is
zero there, or the crossing rounds to the point), and a tile then holds several vertices there:
such a vertex is matched, per tile face it lies on, by its position and the positions of its
neighbours along the tile's open mesh edges in that face. Those edges are the cut of the surface
by the face (the segments marching cubes draws on the cell faces in it), which both tiles make
alike from the same corner values, around each edge of the face; a vertex of an edge that leaves
the face into one tile has no such neighbours in that face and is not matched through it.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["tile_box", "weld_tiles"]

#: A tile mesh: ``(window, vertices, faces, normals)``, window ``(lo, hi)`` of cells.
Tile = tuple


def tile_box(origin: np.ndarray, cell: np.ndarray, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Corners of the tile of cells ``[lo, hi)`` as the core computes lattice points (per
    coordinate one product and one sum)."""
    return origin + np.asarray(lo, dtype=np.float64) * cell, origin + np.asarray(hi, dtype=np.float64) * cell


def _at_lattice_points(v: np.ndarray, origin: np.ndarray, cell: np.ndarray) -> np.ndarray:
    index = np.rint((v - origin) / cell)
    return (origin + index * cell == v).all(axis=1)


def _open_edges(f: np.ndarray) -> np.ndarray:
    """Mesh edges used by one triangle, as (E, 2) vertex pairs (smaller index first)."""
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, uses = np.unique(edges, axis=0, return_counts=True)
    return uniq[uses == 1]


def _rank_within(keys: np.ndarray, tile_of: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Representative of each of ``ids``: the first vertex with its key and its rank among its
    tile's vertices with that key (``keys`` (N, K) uint64 rows)."""
    order = np.lexsort((ids, tile_of) + tuple(keys[:, k] for k in reversed(range(keys.shape[1]))))
    sid, st, sk = ids[order], tile_of[order], keys[order]
    new_key = np.ones(len(sid), dtype=bool)
    new_key[1:] = (sk[1:] != sk[:-1]).any(axis=1)
    new_run = new_key.copy()
    new_run[1:] |= st[1:] != st[:-1]
    run_start = np.maximum.accumulate(np.where(new_run, np.arange(len(sid)), 0))
    rank = np.arange(len(sid)) - run_start
    key_id = np.cumsum(new_key) - 1
    _, first, inverse = np.unique(np.stack([key_id, rank], axis=1), axis=0, return_index=True, return_inverse=True)
    rep = np.empty(len(ids), dtype=np.int64)
    rep[order] = sid[first][inverse.ravel()]
    return rep


def _find(parent: dict, a: int) -> int:
    while parent.setdefault(a, a) != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


def _lattice_point_links(tiles: Sequence[Tile], starts: np.ndarray, at_point: list, origin, cell) -> dict:
    """Union-find parents joining the vertices at lattice points on tile faces that stand for
    the same lattice edge (see the module's notes)."""
    groups: dict = {}
    for t, (window, v, f, _) in enumerate(tiles):
        ids = np.flatnonzero(at_point[t])
        if len(ids) == 0:
            continue
        bounds = tile_box(origin, cell, *window)
        opened = _open_edges(f)
        pairs = np.concatenate([opened, opened[:, ::-1]])
        pairs = pairs[at_point[t][pairs[:, 0]]]
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
        bits = v.view(np.uint64).reshape(-1, 3)
        for i in ids:
            nbrs = pairs[np.searchsorted(pairs[:, 0], i) : np.searchsorted(pairs[:, 0], i, side="right"), 1]
            for axis in range(3):
                for side in (0, 1):
                    plane = bounds[side][axis]
                    if v[i, axis] != plane:
                        continue
                    in_plane = nbrs[v[nbrs, axis] == plane]
                    if len(in_plane) == 0:
                        continue
                    # Neighbours at the vertex's own position (segments of length zero, which
                    # may lie on another face through the point) only say that there are some.
                    apart = in_plane[(v[in_plane] != v[i]).any(axis=1)]
                    key = (axis, bits[i].tobytes(), tuple(sorted(map(tuple, bits[apart].tolist()))))
                    groups.setdefault(key, []).append((t, int(starts[t] + i)))
    parent: dict = {}
    for members in groups.values():
        rank: dict = {}
        firsts: dict = {}
        for t, gid in members:
            r = rank.get(t, 0)
            rank[t] = r + 1
            if r in firsts:
                parent[_find(parent, gid)] = _find(parent, firsts[r])
            else:
                firsts[r] = gid
    return parent


def weld_tiles(tiles: Sequence[Tile], origin: np.ndarray, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joins tile meshes into one: ``(vertices (V, 3) float64, faces (F, 3) int64, normals
    (V, 3) float64)``, normals empty unless every tile has them. Vertices keep the order of the
    tiles and, within a tile, their order; a joined vertex takes its first tile's place."""
    verts = [np.asarray(t[1], dtype=np.float64).reshape(-1, 3) for t in tiles]
    tris = [np.asarray(t[2], dtype=np.intp).reshape(-1, 3) for t in tiles]
    norms = [np.asarray(t[3], dtype=np.float64).reshape(-1, 3) for t in tiles]
    counts = np.array([len(v) for v in verts], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    total = int(starts[-1])
    if total == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3))
    at_point, on_face, face_bits = [], [], []
    for (window, _, _, _), x, start in zip(tiles, verts, starts):
        a, b = tile_box(origin, cell, *window)
        on = x == a
        on |= x == b
        face = np.flatnonzero(on[:, 0] | on[:, 1] | on[:, 2])
        point = _at_lattice_points(x[face], origin, cell)
        at_point.append(np.zeros(len(x), dtype=bool))
        at_point[-1][face[point]] = True
        on_face.append(start + face[~point])
        face_bits.append(x[face[~point]].view(np.uint64).reshape(-1, 3))
    rep = np.arange(total)
    ids = np.concatenate(on_face)
    if len(ids):
        tile_of = np.searchsorted(starts, ids, side="right") - 1
        rep[ids] = _rank_within(np.concatenate(face_bits), tile_of, ids)
    parent = _lattice_point_links(tiles, starts, at_point, origin, cell)
    roots: dict = {}
    for gid in parent:
        r = _find(parent, gid)
        roots[r] = min(roots.get(r, r), gid)
    for gid in parent:
        rep[gid] = roots[_find(parent, gid)]
    keep = rep == np.arange(total)
    remap = np.cumsum(keep) - 1
    remap = remap[rep]
    v = _kept_rows(verts, starts, keep)
    has_normals = all(len(n) == len(x) for n, x in zip(norms, verts))
    n = _kept_rows(norms, starts, keep) if has_normals else np.zeros((0, 3))
    return v, _renumbered(tris, starts, remap), n


def _renumbered(tris: list, starts: np.ndarray, remap: np.ndarray) -> np.ndarray:
    """The tiles' triangles, one after another, with each tile's vertex indices mapped through
    its slice of ``remap`` (the welded mesh's index of every tile vertex)."""
    f = np.empty((sum(len(t) for t in tris), 3), dtype=np.int64)
    at = 0
    for t, s, e in zip(tris, starts[:-1], starts[1:]):
        np.take(remap[s:e], t, out=f[at : at + len(t)], mode="clip")  # indices are in range
        at += len(t)
    return f


def _kept_rows(rows: list, starts: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The rows of the tiles' ``(n, 3)`` arrays that ``keep`` marks, one tile after another."""
    out = np.empty((int(np.count_nonzero(keep)), 3), dtype=np.float64)
    at = 0
    for r, s, e in zip(rows, starts[:-1], starts[1:]):
        k = int(np.count_nonzero(keep[s:e]))
        np.compress(keep[s:e], r, axis=0, out=out[at : at + k])
        at += k
    return out
