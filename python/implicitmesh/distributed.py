"""Tiled polygonization on Dask: the lattice cut into tiles of cells, one task per tile, the
tiles' meshes welded into the mesh :func:`implicitmesh.polygonize` makes on one machine.

Every tile is a window of the one lattice (``_core.polygonize(..., window=)``): its lattice
points and edge vertices are computed from the whole lattice's origin and indices, so a vertex on
a face two tiles share is the same number in both. Each tile reports the lattice edges of its
vertices on its boundary faces in the whole lattice's numbering (``boundary=True``), and the
weld joins the vertices of one edge: exact, one vertex per crossed edge as on one machine.
"""

from __future__ import annotations

import functools
import itertools
import json
import os
from concurrent.futures import CancelledError
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from . import _core, _cut_files, _tile_files, _weld_in_place
from ._progress import reporter
from .mesh import Mesh
from .polygonize import _check_common, _check_positive

__all__ = ["polygonize", "weld", "tiles", "cut_field", "TILE_METHODS"]

#: Methods :func:`polygonize` runs per tile (``"sparse"`` and ``"tracking"``: BlobField only).
TILE_METHODS = ("dense", "sparse", "octree", "tracking")

#: Keywords passed to each tile's polygonizer.
_TILE_OPTIONS = ("ambiguity", "normals", "project", "batch_size", "memory_limit", "start_level", "safety", "corner_test")

#: Name of the manifest ``output=DIR`` writes.
MANIFEST = "manifest.json"

#: Relative margin on a primitive's radius when cutting a blob field to a tile, far above
#: rounding, so that no primitive adding a non-zero term at a point of the tile is left out.
_RADIUS_MARGIN = 1e-6

#: Statistics of the tiles that add up to the whole run's.
_SUMMED = ("evaluations", "normal_evaluations", "lattice_points", "cells_visited", "cells_crossed", "cells_repaired")


def _import_distributed():
    try:
        import distributed
    except ImportError as e:  # pragma: no cover - the test extra installs it
        raise ImportError(
            "implicitmesh.distributed needs Dask: pip install 'implicitmesh[distributed]' "
            "(dask[distributed])"
        ) from e
    return distributed


def tile_box(origin: np.ndarray, cell: np.ndarray, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Corners of the tile of cells ``[lo, hi)`` as the core computes lattice points (per
    coordinate one product and one sum)."""
    return origin + np.asarray(lo, dtype=np.float64) * cell, origin + np.asarray(hi, dtype=np.float64) * cell


def _check_tile(tile: Any) -> tuple[int, int, int]:
    values = [tile] if np.ndim(tile) == 0 else list(np.asarray(tile, dtype=object).ravel())
    if len(values) == 1:
        values = values * 3
    if len(values) != 3:
        raise ValueError(f"tile: expected one positive integer or three, got {tile!r}")
    for v in values:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise ValueError(f"tile: cells per tile edge must be positive integers, got {tile!r}")
    return tuple(int(v) for v in values)  # type: ignore[return-value]


def tiles(cells: Sequence[int], tile: Sequence[int]) -> Iterator[tuple[tuple[int, int, int], tuple[int, int, int]]]:
    """The windows ``(lo, hi)`` of cells, ``lo <= i < hi`` per axis, that cut a lattice of
    ``cells`` cells into tiles of ``tile`` cells (the last tile along an axis holds what is
    left), z slowest, then y, then x."""
    ranges = [[(s, min(s + t, n)) for s in range(0, n, t)] for n, t in zip(cells, tile)]
    for rz, ry, rx in itertools.product(ranges[2], ranges[1], ranges[0]):
        yield (rx[0], ry[0], rz[0]), (rx[1], ry[1], rz[1])


def _reaches(centers: np.ndarray, reach: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Whether each sphere (``centers``, ``reach``) meets the box ``[lo, hi]``, with the core's
    arithmetic (``blob::tiles::sphere_meets_box``): the same answer, bit for bit."""
    near = np.maximum(np.maximum(lo - centers, centers - hi), 0.0)
    return (near[:, 0] * near[:, 0] + near[:, 1] * near[:, 1]) + near[:, 2] * near[:, 2] <= reach * reach


def cut_blobs(field: "_core.BlobField", lo: np.ndarray, hi: np.ndarray) -> "_core.BlobField | None":
    """The blob field of the primitives of ``field`` whose sphere of influence reaches the box
    ``[lo, hi]``, in their order (so values and gradients in the box are the same bits as the
    whole field's), or None when no primitive reaches it (the field is positive there)."""
    keep = _reaches(field.centers, field.radii * (1.0 + _RADIUS_MARGIN), lo, hi)
    return field._subset(np.flatnonzero(keep).astype(np.uint32)) if keep.any() else None


def _blob_tiles(field: "_core.BlobField", cells, origin: np.ndarray, cell: np.ndarray, tile) -> list:
    """:func:`cut_blobs` for every tile of :func:`tiles` at once, in its order (None for a tile
    no primitive reaches): the core tests each primitive against the tiles its sphere's bounding
    box meets (widened by a millionth of a tile against rounding), not against every tile, with
    :func:`cut_blobs`'s test, so each tile gets the same primitives."""
    index, start = field._tile_primitives(origin, cell, cells, tile, _RADIUS_MARGIN)
    return [field._subset(index[a:b]) if b > a else None for a, b in zip(start[:-1], start[1:])]


def _cut_per_tile(field: Any) -> bool:
    return isinstance(field, _core.BlobField) or (
        isinstance(field, _core.VariationalSurface) and field.method == "partition"
    )


def cut_field(field: Any, lo: np.ndarray, hi: np.ndarray) -> Any:
    """What a tile ``[lo, hi]`` (its box) needs of ``field``: for a :class:`BlobField` the
    primitives reaching the box (None when none does), for a partition
    :class:`VariationalSurface` the patches its points use, its octree split only where it
    meets the box and the constraints inside those patches; other fields whole. Values and
    gradients in the box are the same bits as the whole field's."""
    if isinstance(field, _core.BlobField):
        return cut_blobs(field, lo, hi)
    if isinstance(field, _core.VariationalSurface):
        return field._cut(np.stack([lo, hi]))
    return field


def _tile_fields(field: Any, shared: Any, cells, origin: np.ndarray, cell: np.ndarray, tile) -> Iterator[Any]:
    """What each tile of :func:`tiles` receives, in its order: ``shared`` (the whole field's
    future) when given, else :func:`cut_field` of the tile (None: not run)."""
    if shared is not None:
        return itertools.repeat(shared)
    if isinstance(field, _core.BlobField):
        return iter(_blob_tiles(field, cells, origin, cell, tile))
    return (cut_field(field, *tile_box(origin, cell, lo, hi)) for lo, hi in tiles(cells, tile))


def _run_tile(field, bounds, resolution, window, method, options, output, local=None):
    """One task: polygonizes the cells ``window`` of the lattice; returns the tile's mesh (in a
    file of the gathered run's directory when ``local = (directory, min_bytes)`` is given, this
    worker can write there and the tile is large enough, see :mod:`implicitmesh._tile_files`),
    or with ``output`` writes it to ``output/tile-….npz`` and returns its entry of the
    manifest; with ``local = (_weld_in_place.KEEP, min_bytes)``, returns its entry with its
    arrays in it (a dict) when they take fewer than ``min_bytes`` bytes, else the tuple of its
    entry and its arrays, which stay on the worker (see :mod:`implicitmesh._weld_in_place`).
    ``field`` may be a :class:`implicitmesh._cut_files.CutFile`, read here."""
    if isinstance(field, _cut_files.CutFile):
        field = field.load()
    v, f, n, stats, b, k = _core.polygonize(
        field, bounds, resolution, method=method, window=window, boundary=True, **options
    )
    stats = {k: stats[k] for k in _SUMMED}
    entry = {"window": [list(window[0]), list(window[1])], "vertices": len(v), "faces": len(f), "stats": stats}
    if output is None:
        entry["bytes"] = sum(int(a.nbytes) for a in (v, f, n, b, k))
    name = "tile-{}-{}-{}".format(*window[0])
    if output is None:
        arrays = dict(v=v, f=f, n=n, b=b, k=k)
        if isinstance(local, tuple) and local[0] == _weld_in_place.KEEP:
            if entry["bytes"] < local[1]:
                entry.update(arrays)
                return entry
            return entry, arrays
        if local is not None and _tile_files.write(local, name, arrays):
            entry["local"] = name
        else:
            entry.update(arrays)
        return entry
    name += ".npz"
    tmp = os.path.join(output, name + ".part")
    with open(tmp, "wb") as fh:
        np.savez(fh, vertices=v, faces=f, normals=n, boundary=b, keys=k)
    os.replace(tmp, os.path.join(output, name))
    entry["file"] = name
    return entry


def _tile_priority(part: Any) -> float:
    """The Dask priority of a tile's task. The tiles of a partition fit run the cuts with more
    constraints first (a tile's work grows with its constraints and varies several times between
    tiles), so that the last tasks to finish are short ones; all below
    ``_weld_in_place.WRITE_PRIORITY``, so that writes run before further tiles. Other tiles run
    in window order (0), the order the weld takes them in."""
    if isinstance(part, _core.VariationalSurface) and part.method == "partition":
        return -1.0 / (1.0 + len(part))
    return 0.0


def _submit_tile(client, args: tuple, kept: dict | None, part: Any, window, sent: "_SentCuts | None", i: int):
    """Submits the task of tile ``i`` (cells ``window``) with ``part`` of the field, and
    returns its future, whose result is the tile's manifest entry; ``args``: ``(bounds, resolution, method, options,
    output, local)``. With ``kept`` (a weld in place), the future is also ``kept[i]``: a tile
    too large to come back whole leaves its arrays on its worker, and a second task there gives
    its entry (:meth:`implicitmesh._weld_in_place.WeldInPlace.entry_task`). With ``sent``, a
    cut that :class:`_SentCuts` takes goes to the workers as it sends it; otherwise inside the
    task, through the scheduler."""
    priority = _tile_priority(part)
    if sent is not None and sent.takes(part):
        part = sent.send(part, i)
    tile = client.submit(_run_tile, part, *args[:2], window, *args[2:], pure=False, priority=priority)
    if kept is not None:
        kept[i] = tile
    return tile


class _SentCuts:
    """How the tiles' cuts of a partition fit, and those of a blob field of at least
    ``MIN_SENT_BLOBS`` primitives, reach the workers: through files in the run's ``directory``
    when every worker sees it (:mod:`implicitmesh._cut_files`), else scattered straight to a
    worker instead of travelling inside the task through the scheduler, which a ``LocalCluster``
    runs in the client's process. A cut's file is removed when its tile is done, unless
    ``keep_files`` (its tile's arrays stay on a worker, which Dask recomputes them on if the
    worker dies)."""

    #: Smaller blob cuts (under 1.3 MB, 40 bytes per primitive) travel inside their task, without
    #: a file or a round trip to a worker per tile.
    MIN_SENT_BLOBS = 1 << 15

    def __init__(self, client, directory: str | None, keep_files: bool):
        self.client, self.keep_files = client, keep_files
        self.directory = directory if directory is not None and self._workers_see(directory) else None
        self.scattered: dict[int, Any] = {}
        self.files: dict[int, _cut_files.CutFile] = {}

    def _workers_see(self, directory: str) -> bool:
        try:
            seen = self.client.run(os.path.isdir, directory)
        except Exception:  # a worker lost during the call: the cuts go through Dask
            return False
        return bool(seen) and all(seen.values())

    def takes(self, part: Any) -> bool:
        """Whether the cut ``part`` is sent this way."""
        if isinstance(part, _core.BlobField):
            return len(part) >= self.MIN_SENT_BLOBS
        return isinstance(part, _core.VariationalSurface)

    def send(self, part: "_core.VariationalSurface | _core.BlobField", i: int) -> Any:
        """What tile ``i``'s task receives for ``part``."""
        if self.directory is not None:
            cut = _cut_files.write(self.directory, i, part)
            if cut is not None:
                self.files[i] = cut
                return cut
        self.scattered[i] = self.client.scatter(part, direct=True, hash=False)
        return self.scattered[i]

    def lost(self, i: int, error: BaseException) -> bool:
        """Whether tile ``i`` failed with ``error`` because its cut did not reach its worker
        (its scattered cut lost with a worker: Dask does not recompute scattered data; or a
        worker that does not see its file): it is then sent again inside its task."""
        if isinstance(error, CancelledError) and self.scattered.pop(i, None) is not None:
            return True
        if isinstance(error, _cut_files.CutFileMissing) and i in self.files:
            _cut_files.remove(self.files.pop(i))
            return True
        return False

    def done(self, i: int) -> None:
        """Tile ``i``'s result has arrived: its cut is no longer needed."""
        self.scattered.pop(i, None)
        if not self.keep_files and i in self.files:
            _cut_files.remove(self.files.pop(i))

    def futures(self) -> list:
        return list(self.scattered.values())


def _collect(distributed, futures: list, sent: _SentCuts | None, resend: Callable, weld: Any, report: Any) -> list:
    """The tiles' manifest entries in window order (the order of ``futures``), each tile's mesh
    added to ``weld`` (when given) as soon as those before it are, then freed; ``report``
    gets the tiles done. A tile whose cut did not reach its worker (``sent``, see
    :meth:`_SentCuts.lost`) is sent again with ``resend(tile)``, its new future replacing the
    old in ``futures``; so does the task that gives the entry of a tile whose arrays stay on its
    worker (``weld.entry_task``)."""
    place = {fut.key: i for i, fut in enumerate(futures)}
    arrived: dict[int, dict] = {}
    entries: list = []
    pending = distributed.as_completed(futures)
    for fut in pending:
        i = place[fut.key]
        follow = None if weld is None or fut.status != "finished" else weld.entry_task(i, fut)
        if follow is not None:
            futures[i] = follow
            place[follow.key] = i
            pending.add(follow)
            continue
        try:
            arrived[i] = fut.result()
        except (CancelledError, _cut_files.CutFileMissing) as e:
            if sent is None or not sent.lost(i, e):
                raise
            # The failed task is dropped now: its exception's traceback, which holds this
            # frame, would keep it on the scheduler until Python's cycle collector ran.
            fut.release()
            again = futures[i] = resend(i)
            place[again.key] = i
            pending.add(again)
            continue
        if sent is not None:
            sent.done(i)
        # The worker need not keep a result the client holds (nor spill it to disk).
        fut.release()
        while len(entries) in arrived:
            entry = arrived.pop(len(entries))
            if weld is not None:
                _weld_tile(weld, entry, len(entries))
            entries.append(entry)
        if report is not None:
            report(len(entries) + len(arrived))
    return entries


class _StreamedWeld:
    """The weld of a gathered run in the client's memory (:class:`_core.StreamedWeld`), each
    tile read from its entry or from the file its worker left in the run's directory
    ``local``; the interface of :class:`implicitmesh._weld_in_place.WeldInPlace`."""

    def __init__(self, stream: "_core.StreamedWeld", local: str | None):
        self.stream, self.local = stream, local

    def tasks(self) -> list:
        return []

    def entry_task(self, tile: int, fut: Any) -> None:
        return None

    @property
    def vertices(self) -> int:
        return self.stream.vertices

    def add(self, entry: dict, tile: int) -> None:
        if "local" in entry:
            with _tile_files.read(self.local, entry.pop("local")) as a:
                self.stream.add(entry["window"], *(a[k] for k in ("v", "f", "n", "b", "k")))
        else:
            self.stream.add(entry["window"], *(entry.pop(k) for k in ("v", "f", "n", "b", "k")))

    def result(self) -> tuple:
        return self.stream.result()


def _weld_tile(weld: Any, entry: dict, tile: int) -> None:
    """Welds tile number ``tile`` (its task's manifest ``entry``) into ``weld``; the entry
    keeps its counts."""
    weld.add(entry, tile)


def _gathered_weld(client, local: str | None, kept: dict | None, tiles: int, cells, origin, cell, options: dict) -> Any:
    """The weld of a gathered run: in place in the run's directory (``kept``: the futures of
    the tiles' arrays, see :mod:`implicitmesh._weld_in_place`), else in the client's memory."""
    normals, limit = bool(options.get("normals", True)), options.get("memory_limit")
    if kept is not None:
        return _weld_in_place.WeldInPlace(client, local, kept, cells, origin, cell, normals, limit)
    return _StreamedWeld(_core.StreamedWeld(tiles, cells, origin, cell, normals, limit), local)


def _worker_threads(client) -> int:
    """The threads of the client's workers, in all."""
    return sum(client.nthreads().values())


def _pickled(field: Any) -> Callable[[], Any]:
    """A function returning ``field``, for a task; a TypeError naming ``field`` when it does not
    pickle (Dask sends it with cloudpickle)."""
    import cloudpickle

    try:
        data = cloudpickle.dumps(field)
    except Exception as e:
        raise TypeError(f"field: cannot be sent to the workers, it does not pickle: {e}") from e
    return functools.partial(cloudpickle.loads, data)


def _get_client(client):
    distributed = _import_distributed()
    if client is not None:
        return client, None
    try:
        return distributed.get_client(), None
    except ValueError:
        own = distributed.Client()
        return own, own


def polygonize(
    field: Any,
    *,
    bounds: Any = None,
    resolution: int | Sequence[int],
    method: str = "sparse",
    client: Any = None,
    tile: int | Sequence[int] = 256,
    output: str | os.PathLike[str] | None = None,
    progress: bool | Callable[[int], object] = False,
    **options: Any,
) -> Mesh | Path:
    """Polygonizes ``field`` on a Dask cluster, one task per tile of ``tile³`` cells, and welds
    the tiles into the mesh :func:`implicitmesh.polygonize` makes on one machine.

    The mesh has the same triangles, vertex for vertex and bit for bit, and the same normals;
    only the order of vertices and triangles differs (tile by tile).

    Parameters
    ----------
    field : VariationalSurface, BlobField or callable
        As for :func:`implicitmesh.polygonize`; it must pickle (a callable is sent with
        cloudpickle). Each task receives what its tile needs (:func:`cut_field`): for a
        :class:`BlobField` the primitives reaching the tile (tiles no primitive reaches are not
        run), for a partition :class:`VariationalSurface` the patches covering it, its octree
        pruned to it and the constraints inside those patches; other fields are sent to the
        workers once, whole.
    bounds : (2, 3) array_like, optional
        As for :func:`implicitmesh.polygonize` (defaults to ``field.bounds``).
    resolution : int or (3,) ints
        As for :func:`implicitmesh.polygonize`: the whole lattice.
    method : {"sparse", "dense", "octree", "tracking"}
        The polygonizer each tile runs. ``"sparse"`` (the default) and ``"tracking"`` need a
        :class:`BlobField` (for which both find every component, the dense mesh). ``"octree"``
        starts its hierarchy from each tile, so it meets the single-machine octree wherever
        both find the surface (the dense mesh on the components found).
    client : distributed.Client, optional
        Default: the current client, else a local cluster started (and closed) for this call.
    tile : int or (3,) ints
        Cells per tile edge (default 256); the last tile along an axis holds what is left.
    output : path, optional
        A directory: each task writes its tile as ``tile-i-j-k.npz`` (``vertices``, ``faces``,
        ``normals``, and ``boundary``, ``keys``: its vertices on lattice edges in its boundary
        faces and their edges' keys, which the weld joins by) when it finishes, and ``manifest.json`` is written last; nothing is
        gathered and the directory's path is returned; :func:`weld` joins the tiles. The
        workers must see the directory (one machine, or a shared file system).
    progress : bool or callable
        ``True``: show the tiles done (a tqdm bar or a line on standard error); a callable is
        called with the number of tiles done.
    **options
        Passed to :func:`implicitmesh.polygonize` per tile: ``ambiguity``, ``normals``,
        ``batch_size``, ``memory_limit`` (bytes, default 8 GiB: checked per tile, and on the
        client against the welded mesh as the tiles arrive), and the octree's ``start_level``,
        ``safety``, ``corner_test``. ``project=True`` moves the welded mesh's vertices onto the
        surface as :func:`implicitmesh.polygonize` does, on the client with the whole field
        (the tiles are welded by their lattice-edge vertices first); not with ``output``.

    Returns
    -------
    Mesh or pathlib.Path
        ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64, ``normals`` (V, 3) float64, and
        ``stats`` with the tiles' counts summed and ``tiles`` (tasks run); with ``output``, the
        directory.

    Raises
    ------
    ValueError
        For a bad ``tile``, ``method`` or ``output``, and as :func:`implicitmesh.polygonize`;
        naming ``memory_limit`` when the welded mesh would exceed it (every task is then
        cancelled: raise it, or pass ``output``).
    ImportError
        When Dask is not installed (the ``distributed`` extra).
    KeyboardInterrupt
        On Ctrl-C (also while the client welds the tiles): every task is cancelled.

    Notes
    -----
    Without ``output``, the client makes a directory for the run in ``/dev/shm`` (else the
    temporary directory) and removes it at its end. With tiles of at least 64³ cells, workers
    with at least as many threads in all as the client's machine has cores, and room there for
    ``memory_limit`` bytes, the welded mesh's arrays are files there, which the workers on the
    client's machine write each tile into (the client only plans the weld), and the mesh's
    arrays are those files mapped in memory (shared memory, freed with the arrays). Otherwise
    the client welds, beside the workers: workers on its machine hand their tiles over through
    files there, workers elsewhere, or that cannot write there, through Dask. The tiles' cuts
    of a partition fit reach the workers through files in that directory too when every worker
    sees it (with or without ``output``), else through Dask.
    """
    distributed = _import_distributed()
    tile3 = _check_tile(tile)
    if not isinstance(method, str) or method.lower() not in TILE_METHODS:
        raise ValueError(f"method: expected one of {TILE_METHODS} per tile, got {method!r}")
    method = method.lower()
    if method in ("sparse", "tracking") and not isinstance(field, _core.BlobField):
        raise ValueError(
            f'method: "{method}" per tile needs a BlobField (tracking other fields finds only the '
            'components seeded in each tile); use "dense" or "octree"'
        )
    unknown = sorted(set(options) - set(_TILE_OPTIONS))
    if unknown:
        raise TypeError(f"polygonize() got unexpected keyword arguments {unknown}; per tile it takes {_TILE_OPTIONS}")
    bounds, ambiguity = _check_common(
        field, bounds, options.get("ambiguity", "separate"), options.get("batch_size", 262144), options.get("memory_limit")
    )
    options["ambiguity"] = ambiguity
    project = options.pop("project", False)
    if not isinstance(project, (bool, np.bool_)):
        raise ValueError(f"project: must be True or False, got {project!r}")
    if project and output is not None:
        raise ValueError("project: not with output (the tiles are written as marching cubes makes them)")
    normals = options.get("normals", True)
    if project:
        options["normals"] = False  # taken at the projected vertices, after the weld
    bounds = np.asarray(bounds, dtype=np.float64)
    cells, origin, cell = _core.lattice(bounds, resolution)
    origin, cell = np.asarray(origin), np.asarray(cell)
    if not (isinstance(field, (_core.BlobField, _core.VariationalSurface)) or callable(field)):
        raise TypeError(f"field: expected a VariationalSurface, a BlobField or a callable, got {type(field).__name__}")
    if output is not None:
        output = Path(output)
        output.mkdir(parents=True, exist_ok=True)
        if not output.is_dir():
            raise ValueError(f"output: {str(output)!r} is not a directory")
    client, own = _get_client(client)
    futures, shared, sent, welder, welded = [], None, None, None, None
    cut = _cut_per_tile(field)
    # The run's directory: for the tiles' meshes of a gathered run, and the fields' cuts.
    local = _tile_files.make_directory() if output is None or cut else None
    limit = options.get("memory_limit") or _core.DEFAULT_MEMORY_LIMIT
    in_place = output is None and _weld_in_place.usable(local, limit, int(np.prod(tile3)), _worker_threads(client))
    kept: dict | None = {} if in_place else None
    report, end = reporter(progress, "tiles", None, "tiles")
    try:
        # Blob fields and partition fits are cut per tile; any other field is one task's result
        # that the tiles share (a task, not scattered data, so that Dask recomputes it if its
        # worker dies).
        shared = None if cut else client.submit(_pickled(field), pure=False)
        sent = _SentCuts(client, local, in_place) if cut else None
        submit = functools.partial(
            _submit_tile,
            client,
            (
                bounds,
                resolution,
                method,
                options,
                None if output is None else str(output),
                (_weld_in_place.KEEP, _weld_in_place.MIN_KEPT_BYTES) if in_place
                else None if local is None else (local, _tile_files.MIN_BYTES),
            ),
            kept,
        )
        windows: list = []
        for (lo, hi), part in zip(tiles(cells, tile3), _tile_fields(field, shared, cells, origin, cell, tile3)):
            if part is not None:
                futures.append(submit(part, (lo, hi), sent, len(windows)))
                windows.append((lo, hi))
        if output is None:
            welder = _gathered_weld(client, local, kept, len(futures), cells, origin, cell, options)

        def resend(i: int):
            return submit(cut_field(field, *tile_box(origin, cell, *windows[i])), windows[i], None, i)

        entries = _collect(distributed, futures, sent, resend, welder, report)
        if welder is not None:
            welded = welder.result()
    except BaseException:
        # Every task, done or not, and the shared field: a traceback that keeps this frame
        # must not keep their results on the workers.
        more = ([] if sent is None else sent.futures()) + list((kept or {}).values()) + ([] if welder is None else welder.tasks())
        client.cancel(futures + more + [f for f in (shared,) if f is not None])
        raise
    finally:
        end()
        _tile_files.remove_directory(local)
        if own is not None:
            own.close()
    info = {"cells": list(cells), "origin": origin.tolist(), "cell": cell.tolist(), "method": method}
    if output is not None:
        manifest = dict(info, bounds=bounds.tolist(), resolution=np.asarray(resolution).tolist(), tiles=entries)
        tmp = output / (MANIFEST + ".part")
        tmp.write_text(json.dumps(manifest, indent=1))
        os.replace(tmp, output / MANIFEST)
        return output
    v, f, n = welded
    mesh = Mesh(v, f, n, _stats(entries, info, len(v)))
    if not project:
        return mesh
    v, f, n, st = _core.project_mesh(
        field, bounds, resolution, mesh.vertices, mesh.faces, normals=normals,
        batch_size=options.get("batch_size", 262144),
    )
    mesh.stats["projection_evaluations"] = st["projection_evaluations"]
    mesh.stats["normal_evaluations"] = mesh.stats.get("normal_evaluations", 0) + st["normal_evaluations"]
    return Mesh(v, f, n, mesh.stats)


def weld(
    directory: str | os.PathLike[str],
    *,
    progress: bool | Callable[[int], object] = False,
    memory_limit: int | None = None,
) -> Mesh:
    """Joins the tiles that :func:`polygonize` wrote with ``output=directory`` into one mesh
    (the mesh :func:`polygonize` returns without ``output``, array for array). The tiles are
    read and welded one at a time, so the memory needed is the welded mesh's and one tile's.

    Parameters
    ----------
    directory : path
        The directory holding ``manifest.json`` and the tiles' ``.npz`` files.
    progress : bool or callable
        ``True``: show the tile vertices welded (a tqdm bar or a line on standard error); a
        callable is called with their number.
    memory_limit : int, optional
        Bytes the welded mesh may hold (default 8 GiB, as :func:`implicitmesh.polygonize`'s).

    Returns
    -------
    Mesh
        ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64, ``normals`` (V, 3) float64.

    Raises
    ------
    ValueError
        When the directory has no manifest (the run did not finish), a tile is missing, or a
        tile has no edge keys (written by an older implicitmesh); naming ``tiles`` for tiles of
        different fields or lattices, and ``memory_limit`` when the welded mesh would exceed it
        or it is not a positive integer.
    KeyboardInterrupt
        On Ctrl-C, between two steps of a tile.
    """
    if memory_limit is not None:
        _check_positive("memory_limit", memory_limit)
    directory = Path(directory)
    path = directory / MANIFEST
    if not path.is_file():
        raise ValueError(f"directory: no {MANIFEST} in {str(directory)!r} (a run that did not finish?)")
    manifest = json.loads(path.read_text())
    report, end = reporter(progress, "weld", sum(e["vertices"] for e in manifest["tiles"]), "vertices")
    stream = _core.StreamedWeld(
        len(manifest["tiles"]), manifest["cells"], manifest["origin"], manifest["cell"], memory_limit=memory_limit
    )
    done = 0
    try:
        # One tile in memory at a time besides the welded mesh.
        for e in manifest["tiles"]:
            file = directory / e["file"]
            if not file.is_file():
                raise ValueError(f"directory: tile {e['file']} listed in the manifest is missing")
            with np.load(file) as z:
                if "keys" not in z.files:
                    raise ValueError(
                        f"directory: tile {e['file']} has no edge keys (written by an older implicitmesh); "
                        "run polygonize again"
                    )
                stream.add(e["window"], z["vertices"], z["faces"], z["normals"], z["boundary"], z["keys"])
            done += e["vertices"]
            if report is not None:
                report(done)
    finally:
        end()
    v, f, n = stream.result()
    return Mesh(v, f, n, _stats(manifest["tiles"], manifest, len(v)))


def _stats(entries: list, info: dict, vertices: int) -> dict[str, Any]:
    """The tiles' statistics summed (their manifest ``entries``), with the whole lattice's and
    the welded mesh's ``vertices``."""
    stats: dict[str, Any] = {k: sum(int(e["stats"][k]) for e in entries) for k in _SUMMED}
    stats["lattice_points"] = int(np.prod(np.asarray(info["cells"], dtype=np.int64) + 1))
    stats.update(
        tiles=len(entries),
        triangles=sum(e["faces"] for e in entries),
        vertices=vertices,
        method=info["method"],
        resolution=tuple(info["cells"]),
    )
    return stats
