"""A tiled run on Dask in four steps: plan (:func:`._plan.make_plan`), submit (one task per
tile), collect (each tile welded as it arrives, in window order) and finish (the mesh, its
stats, the projection); and :func:`weld`, the weld of a run written to a directory."""

from __future__ import annotations

import functools
import json
import os
import warnings
from concurrent.futures import CancelledError
from dataclasses import dataclass, field as dataclass_field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .. import _core
from .._progress import reporter
from ..mesh import Mesh
from ..options import OctreeOptions, TrackingOptions
from ..polygonize import Ambiguity, _check_min_particles, _check_positive, _check_trim, trimmed, without_fragments
from . import _cut_files, _tile_files, _weld_in_place
from ._plan import Plan, Window, cut_field, cut_per_tile, make_plan, tile_fields, tile_priority
from ._tile import SUMMED, TileResult, run_tile
from ._transport import SentCuts, Transport
from ._weld import Weld, gathered_weld, weld_tile

#: Name of the manifest :func:`write_tiles` writes.
MANIFEST = "manifest.json"


def _import_distributed():
    try:
        import distributed
    except ImportError as e:  # pragma: no cover - the test extra installs it
        raise ImportError(
            "implicitmesh.distributed needs Dask: pip install 'implicitmesh[distributed]' "
            "(dask[distributed])"
        ) from e
    return distributed


def _worker_threads(client: Any) -> int:
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


def _get_client(client: Any) -> tuple[Any, Any]:
    """``(client, own)``: the client to use, and the one this run started (None if none)."""
    distributed = _import_distributed()
    if client is not None:
        return client, None
    try:
        return distributed.get_client(), None
    except ValueError:
        own = distributed.Client()
        return own, own


@dataclass
class _Run:
    """A run's state on the client: its ``plan``, the ``client``, the run's directory ``local``
    (tile files, cut files; None without one), the :class:`Transport` of the tiles' meshes, the
    futures of the tiles' tasks (``futures``, in window order, and their ``windows``), and, for a
    weld in place, ``kept``: the futures of the tasks whose mesh may stay on their worker."""

    plan: Plan
    client: Any
    local: str | None
    transport: Transport
    kept: dict[int, Any] | None
    futures: list = dataclass_field(default_factory=list)
    windows: list[Window] = dataclass_field(default_factory=list)
    shared: Any = None
    sent: SentCuts | None = None
    weld: Weld | None = None

    def submit_tile(self, part: Any, window: Window, i: int, sent: SentCuts | None) -> Any:
        """Submits the task of tile ``i`` (cells ``window``) with ``part`` of the field and
        returns its future. With ``kept`` (a weld in place), the future is also ``kept[i]``. With
        ``sent``, a cut that :class:`SentCuts` takes goes to the workers as it sends it;
        otherwise inside the task, through the scheduler."""
        plan = self.plan
        priority = tile_priority(part)
        if sent is not None and sent.takes(part):
            part = sent.send(part, i)
        fut = self.client.submit(
            run_tile, part, plan.bounds, plan.resolution, window, plan.method, plan.options, self.transport,
            pure=False, priority=priority,
        )
        if self.kept is not None:
            self.kept[i] = fut
        return fut

    def resend(self, i: int) -> Any:
        """Submits tile ``i`` again with its cut inside its task."""
        window = self.windows[i]
        return self.submit_tile(cut_field(self.plan.field, *self.plan.box(window)), window, i, None)

    def cancel(self) -> None:
        """Cancels every task, done or not, and the shared field: a traceback that keeps this
        run must not keep their results on the workers."""
        more = [] if self.sent is None else self.sent.futures()
        more += list((self.kept or {}).values())
        more += [] if self.weld is None else self.weld.tasks()
        self.client.cancel(self.futures + more + [f for f in (self.shared,) if f is not None])


def _start(plan: Plan, client: Any, output: Path | None) -> _Run:
    """A run of ``plan`` on ``client``, its tiles gathered (``output`` None) or written to
    ``output``: where the run's files go and how the tiles travel."""
    cut = cut_per_tile(plan.field)
    # The run's directory: for the tiles' meshes of a gathered run, and the fields' cuts.
    local = _tile_files.make_directory() if output is None or cut else None
    limit = plan.memory_limit or _core.DEFAULT_MEMORY_LIMIT
    tile_cells = int(np.prod(plan.tile))
    in_place = output is None and _weld_in_place.usable(local, limit, tile_cells, _worker_threads(client))
    if output is not None:
        transport = Transport.output(str(output))
    elif in_place:
        transport = Transport.keep(_weld_in_place.MIN_KEPT_BYTES)
    elif local is not None:
        transport = Transport.files(local, _tile_files.MIN_BYTES)
    else:
        transport = Transport.dask()
    return _Run(plan, client, local, transport, {} if in_place else None)


def _submit(run: _Run) -> None:
    """Submits one task per tile that receives something of the field. Blob fields and
    partition fits are cut per tile; any other field is one task's result that the tiles share
    (a task, not scattered data, so that Dask recomputes it if its worker dies)."""
    plan, cut = run.plan, cut_per_tile(run.plan.field)
    run.shared = None if cut else run.client.submit(_pickled(plan.field), pure=False)
    run.sent = SentCuts(run.client, run.local, run.kept is not None) if cut else None
    parts = tile_fields(plan.field, run.shared, plan.cells, plan.origin, plan.cell, plan.tile)
    for window, part in zip(plan.windows(), parts):
        if part is not None:
            run.futures.append(run.submit_tile(part, window, len(run.windows), run.sent))
            run.windows.append(window)


def _collect(distributed: Any, futures: list, sent: SentCuts | None, resend: Callable, weld: Weld | None, report: Any) -> list[TileResult]:
    """The tiles' results in window order (the order of ``futures``), each tile's mesh added to
    ``weld`` (when given) as soon as those before it are, then freed; ``report`` gets the tiles
    done. A tile whose cut did not reach its worker (``sent``, see :meth:`SentCuts.lost`) is
    sent again with ``resend(tile)``, its new future replacing the old in ``futures``; so does
    the task that gives the result of a tile whose mesh stays on its worker
    (``weld.entry_task``)."""
    place = {fut.key: i for i, fut in enumerate(futures)}
    arrived: dict[int, TileResult] = {}
    results: list[TileResult] = []
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
        while len(results) in arrived:
            result = arrived.pop(len(results))
            if weld is not None:
                weld_tile(weld, result, len(results))
            results.append(result)
        if report is not None:
            report(len(results) + len(arrived))
    return results


def _execute(plan: Plan, client: Any, progress: Any, output: Path | None) -> tuple[list[TileResult], Any]:
    """Submits and collects a run: the tiles' results and, gathered, the welded arrays."""
    distributed = _import_distributed()
    client, own = _get_client(client)
    run = _start(plan, client, output)
    report, end = reporter(progress, "tiles", None, "tiles")
    try:
        _submit(run)
        if output is None:
            run.weld = gathered_weld(client, run.local, run.kept, len(run.futures), plan)
        results = _collect(distributed, run.futures, run.sent, run.resend, run.weld, report)
        welded = None if run.weld is None else run.weld.result()
    except BaseException:
        run.cancel()
        raise
    finally:
        end()
        _tile_files.remove_directory(run.local)
        if own is not None:
            own.close()
    return results, welded


def _finish(plan: Plan, results: list[TileResult], welded: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Mesh:
    """The welded mesh with the tiles' stats, its vertices projected onto the surface when the
    plan says so (on the client, with the whole field)."""
    v, f, n = welded
    mesh = Mesh(v, f, n, _stats(results, plan.info(), len(v)))
    if not plan.project:
        return mesh
    v, f, n, st = _core.project_mesh(
        plan.field, plan.bounds, plan.resolution, mesh.vertices, mesh.faces, normals=plan.normals,
        batch_size=plan.batch_size,
    )
    mesh.stats["projection_evaluations"] = st["projection_evaluations"]
    mesh.stats["normal_evaluations"] = mesh.stats.get("normal_evaluations", 0) + st["normal_evaluations"]
    return Mesh(v, f, n, mesh.stats)


def _stats(results: list[TileResult], info: dict, vertices: int) -> dict[str, Any]:
    """The tiles' statistics summed, with the whole lattice's and the welded mesh's
    ``vertices``."""
    stats: dict[str, Any] = {k: sum(int(r.stats[k]) for r in results) for k in SUMMED}
    stats["lattice_points"] = int(np.prod(np.asarray(info["cells"], dtype=np.int64) + 1))
    stats.update(
        tiles=len(results),
        triangles=sum(r.faces for r in results),
        vertices=vertices,
        method=info["method"],
        resolution=tuple(info["cells"]),
    )
    return stats


def polygonize(
    field: Any,
    *,
    bounds: Any = None,
    resolution: int | Sequence[int] = 64,
    method: str = "sparse",
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
    progress: bool | Callable[[int], object] = False,
    client: Any = None,
    tile: int | Sequence[int] = 256,
    output: str | os.PathLike[str] | None = None,
) -> Mesh:
    """Polygonizes ``field`` on a Dask cluster, one task per tile of ``tile³`` cells, and welds
    the tiles into the mesh :func:`implicitmesh.polygonize` makes on one machine.

    The mesh has the same triangles, vertex for vertex and bit for bit, and the same normals;
    only the order of vertices and triangles differs (tile by tile). The keywords are
    :func:`implicitmesh.polygonize`'s, with the same defaults except ``method``, and three more:
    ``client``, ``tile`` and the deprecated ``output``.

    Parameters
    ----------
    field : VariationalSurface, BlobField or callable
        As for :func:`implicitmesh.polygonize`; it must pickle (a callable is sent with
        cloudpickle). Each task receives what its tile needs (:func:`cut_field`): for a
        :class:`BlobField` the primitives reaching the tile (tiles no primitive reaches are not
        run), for a partition :class:`VariationalSurface` the patches covering it, its octree
        pruned to it and the constraints inside those patches; other fields are sent to the
        workers once, whole.
    bounds : (2, 3) array_like of float, optional
        As for :func:`implicitmesh.polygonize` (defaults to ``field.bounds``).
    resolution : int or (3,) ints
        As for :func:`implicitmesh.polygonize`: the whole lattice. Default 64.
    method : {"sparse", "dense", "octree", "tracking"}
        The polygonizer each tile runs. Default ``"sparse"``, unlike
        :func:`implicitmesh.polygonize` (``"dense"``): tiled runs are for large blob fields,
        and the default is kept so that existing calls give the same arrays. ``"sparse"`` and
        ``"tracking"`` need a :class:`BlobField` (for which both find every component, the
        dense mesh); pass ``method="dense"`` or ``"octree"`` for other fields. ``"octree"``
        starts its hierarchy from each tile, so it meets the single-machine octree wherever
        both find the surface (the dense mesh on the components found).
    ambiguity, normals, batch_size
        As for :func:`implicitmesh.polygonize`, per tile.
    project : bool
        As for :func:`implicitmesh.polygonize`: the welded mesh's vertices are moved onto the
        surface on the client, with the whole field (the tiles are welded by their lattice-edge
        vertices first). Default ``False``.
    memory_limit : int, optional
        Bytes (default 8 GiB): checked per tile, and on the client against the welded mesh as
        the tiles arrive.
    start_level, safety, corner_test, options
        As for :func:`implicitmesh.polygonize` (``options``: an :class:`~implicitmesh.OctreeOptions`
        for ``"octree"``).
    trim, min_particles : optional
        As for :func:`implicitmesh.polygonize`: applied to the welded mesh on the client.
    seeds : None
        Not taken per tile (tracking a :class:`BlobField` finds every component): a TypeError
        when given.
    progress : bool or callable
        ``True``: show the tiles done (a tqdm bar or a line on standard error); a callable is
        called with the number of tiles done.
    client : distributed.Client, optional
        Default: the current client, else a local cluster started (and closed) for this call.
    tile : int or (3,) ints
        Cells per tile edge (default 256); the last tile along an axis holds what is left.
    output : path, optional
        Deprecated: use :func:`write_tiles`, which this then calls (and returns the directory).

    Returns
    -------
    Mesh
        ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64, ``normals`` (V, 3) float64 (or
        (0, 3) without normals), and ``stats`` with the tiles' counts summed and ``tiles``
        (tasks run).

    Raises
    ------
    ValueError
        For a bad ``tile``, ``method``, ``project`` or ``options``, and as
        :func:`implicitmesh.polygonize`; naming ``memory_limit`` when the welded mesh would
        exceed it (every task is then cancelled: raise it, or use :func:`write_tiles`).
    TypeError
        For a ``field`` that is not a field or does not pickle, and for ``seeds``.
    ImportError
        When Dask is not installed (the ``distributed`` extra).
    KeyboardInterrupt
        On Ctrl-C (also while the client welds the tiles): every task is cancelled.

    Notes
    -----
    The client makes a directory for the run in ``/dev/shm`` (else the temporary directory)
    and removes it at its end. With tiles of at least 64³ cells, workers with at least as many
    threads in all as the client's machine has cores, and room there for ``memory_limit``
    bytes, the welded mesh's arrays are files there, which the workers on the client's machine
    write each tile into (the client only plans the weld), and the mesh's arrays are those
    files mapped in memory (shared memory, freed with the arrays). Otherwise the client welds,
    beside the workers: workers on its machine hand their tiles over through files there,
    workers elsewhere, or that cannot write there, through Dask. The tiles' cuts of a partition
    fit reach the workers through files in that directory too when every worker sees it, else
    through Dask.
    """
    keywords = dict(
        bounds=bounds, resolution=resolution, method=method, ambiguity=ambiguity, normals=normals,
        batch_size=batch_size, memory_limit=memory_limit, start_level=start_level, safety=safety,
        corner_test=corner_test, seeds=seeds, options=options, progress=progress, client=client, tile=tile,
    )
    _check_trim(field, trim)
    _check_min_particles(field, min_particles)
    for name, value in (("trim", trim), ("min_particles", min_particles)):
        if value is not None and output is not None:
            raise ValueError(f"{name}: not with output (the tiles are written as marching cubes makes them)")
    if output is not None:
        warnings.warn(
            "implicitmesh.distributed.polygonize(output=DIR) is deprecated: use write_tiles(field, DIR, ...)",
            DeprecationWarning,
            stacklevel=2,
        )
        if project is not False:
            raise ValueError("project: not with output (the tiles are written as marching cubes makes them)")
        return write_tiles(field, output, **keywords)  # type: ignore[return-value]
    plan = _make_plan(field, project=project, **keywords)
    results, welded = _execute(plan, client, progress, None)
    return without_fragments(trimmed(_finish(plan, results, welded), field, trim), field, min_particles)


def _make_plan(field: Any, *, progress: Any, client: Any, project: Any = False, **keywords: Any) -> Plan:
    """:func:`._plan.make_plan` of a call's keywords."""
    method_options = {k: keywords.pop(k) for k in ("start_level", "safety", "corner_test", "seeds")}
    return make_plan(field, project=project, method_options=method_options, **keywords)


def write_tiles(
    field: Any,
    directory: str | os.PathLike[str],
    *,
    bounds: Any = None,
    resolution: int | Sequence[int] = 64,
    method: str = "sparse",
    ambiguity: Ambiguity | str = Ambiguity.SEPARATE,
    normals: bool = True,
    batch_size: int = 262144,
    memory_limit: int | None = None,
    start_level: int | None = None,
    safety: float | None = None,
    corner_test: bool | None = None,
    seeds: Any = None,
    options: OctreeOptions | TrackingOptions | None = None,
    progress: bool | Callable[[int], object] = False,
    client: Any = None,
    tile: int | Sequence[int] = 256,
) -> Path:
    """Polygonizes ``field`` on a Dask cluster as :func:`polygonize` does, but each task writes
    its tile to ``directory`` instead of sending it back: nothing is gathered, and
    :func:`weld` joins the tiles afterwards (into :func:`polygonize`'s mesh, array for array).

    Parameters
    ----------
    field
        As for :func:`polygonize`.
    directory : path
        Made if missing. Each task writes its tile as ``tile-i-j-k.npz`` (``vertices``,
        ``faces``, ``normals``, and ``boundary``, ``keys``: its vertices on lattice edges in its
        boundary faces and their edges' keys, which the weld joins by) when it finishes, and
        ``manifest.json`` is written last. The workers must see the directory (one machine, or
        a shared file system).
    bounds, resolution, method, ambiguity, normals, batch_size, memory_limit, start_level, safety, corner_test, seeds, options, progress, client, tile
        As for :func:`polygonize` (no ``project``: the tiles are written as marching cubes
        makes them).

    Returns
    -------
    pathlib.Path
        ``directory``.

    Raises
    ------
    ValueError
        As :func:`polygonize`, and naming ``directory`` when it is not a directory.
    """
    plan = _make_plan(
        field, bounds=bounds, resolution=resolution, method=method, ambiguity=ambiguity, normals=normals,
        batch_size=batch_size, memory_limit=memory_limit, start_level=start_level, safety=safety,
        corner_test=corner_test, seeds=seeds, options=options, progress=progress, client=client, tile=tile,
    )
    output = Path(directory)
    if output.exists() and not output.is_dir():
        raise ValueError(f"directory: {str(output)!r} is not a directory")
    output.mkdir(parents=True, exist_ok=True)
    results, _ = _execute(plan, client, progress, output)
    manifest = dict(
        plan.info(), bounds=plan.bounds.tolist(), resolution=np.asarray(plan.resolution).tolist(),
        tiles=[r.entry() for r in results],
    )
    tmp = output / (MANIFEST + ".part")
    tmp.write_text(json.dumps(manifest, indent=1))
    os.replace(tmp, output / MANIFEST)
    return output


def weld(
    directory: str | os.PathLike[str],
    *,
    progress: bool | Callable[[int], object] = False,
    memory_limit: int | None = None,
) -> Mesh:
    """Joins the tiles that :func:`write_tiles` wrote to ``directory`` into one mesh (the mesh
    :func:`polygonize` returns, array for array). The tiles are read and welded one at a time,
    so the memory needed is the welded mesh's and one tile's.

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
    results = [TileResult.from_entry(e) for e in manifest["tiles"]]
    report, end = reporter(progress, "weld", sum(r.vertices for r in results), "vertices")
    stream = _core.StreamedWeld(
        len(results), manifest["cells"], manifest["origin"], manifest["cell"], memory_limit=memory_limit
    )
    done = 0
    try:
        # One tile in memory at a time besides the welded mesh.
        for r in results:
            file = directory / str(r.file)
            if not file.is_file():
                raise ValueError(f"directory: tile {r.file} listed in the manifest is missing")
            with np.load(file) as z:
                if "keys" not in z.files:
                    raise ValueError(
                        f"directory: tile {r.file} has no edge keys (written by an older implicitmesh); "
                        "run polygonize again"
                    )
                window = [list(r.window[0]), list(r.window[1])]
                stream.add(window, z["vertices"], z["faces"], z["normals"], z["boundary"], z["keys"])
            done += r.vertices
            if report is not None:
                report(done)
    finally:
        end()
    v, f, n = stream.result()
    return Mesh(v, f, n, _stats(results, manifest, len(v)))
