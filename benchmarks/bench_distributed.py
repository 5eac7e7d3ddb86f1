"""Tiled polygonization on Dask (``implicitmesh.distributed.polygonize``) against
``implicitmesh.polygonize`` in one process, on a blob field and on a partition fit.

Setups, each in a fresh process (its peak resident size its own):

- ``single``: ``implicitmesh.polygonize`` in one process with all its threads (rayon's pool, one
  thread per core);
- ``dask-1`` and ``dask-2``: a ``LocalCluster`` of 1 or 2 worker processes, each with one Dask
  thread and one rayon thread (``RAYON_NUM_THREADS=1`` in the workers' environment, set by the
  nannies), so that a worker uses one core: on 2 cores, ``dask-2`` uses the cores ``single``
  uses, and ``dask-2`` against ``dask-1`` measures how independent the tasks are (a worker whose
  polygonizer ran on both cores would leave nothing for a second worker to gain). The client
  welds each tile as it arrives;
- ``dask-2-dir``: ``dask-2`` with ``write_tiles(field, DIR)`` (each worker writes its tiles to a directory
  on local disk, nothing is gathered), timed to the manifest; ``weld(DIR)`` afterwards is timed
  on its own.

Fields: ``blobs``, primitives with centres uniform in [-0.8, 0.8]³ (radius chosen so that the
spheres of influence cover the cube about 1.6 times: a foam of merged blobs), method
``"sparse"``; ``variational``, a partition fit (``VariationalSurface.fit(method="partition", exact=True)``)
of points sampled on the knot's ``_hires`` mesh with their face normals (as in bench_scale),
method ``"octree"``, ``normals=False``, at 256³ cells in tiles of 128³ and at 512³ in tiles of
256³ (eight times the work per tile); ``particles``, 10⁷ particles of bench_particles' ``slab``
layout as the colour field of ``BlobField.from_particles``, method ``"sparse"``, on that
benchmark's lattice of cells of s/4 around them, in tiles of 256³. Each field is made once, saved with
:func:`implicitmesh.save`, and loaded by every case. ``many``: a small blob field in about 10⁴
tiles of 4³ cells on 2 workers, and 10⁴ no-op tasks, for the scheduler's and the weld's cost per
tile.

    python -m benchmarks.bench_distributed [--quick] [--results DIR]
    python -m benchmarks.bench_distributed one FIELD SETUP FILE RESOLUTION TILE RUNS   # one JSON line
    (SETUP ``many``: RUNS is the number of no-op tasks)
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.bench_scale import samples, vmhwm_mib
from benchmarks.timing import RunRecord, fmt_s, md_table, run_case_process, run_markdown, run_section

BOX = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]
#: The particles' lattice (0 in place of a resolution): bench_particles' cells of s/4 around
#: them, saved beside the field (:func:`lattice_of`).
PARTICLE_LATTICE = 0
#: Per field (full, quick): size (primitives or points) and its lattices: (cells per lattice edge,
#: cells per tile edge). The quick blob field is the full one scaled by 1/4 in cells (1/64 of the
#: primitives, 4 times the radius): the same foam, coarser. The variational fit at 512³ has the
#: 256³ case's tiles eight times the work.
CASES = {
    False: {"blobs": (200_000, [(512, 128)]), "variational": (100_000, [(256, 128), (512, 256)]),
            "particles": (10_000_000, [(PARTICLE_LATTICE, 256)])},
    True: {"blobs": (3_125, [(128, 64)]), "variational": (10_000, [(64, 32)]),
           "particles": (100_000, [(PARTICLE_LATTICE, 64)])},
}
#: Blob radius at 200,000 primitives; it scales with the cube root of 1 / primitives.
BLOB_RADIUS = 0.02
SETUPS = ("single", "dask-1", "dask-2", "dask-2-dir")
#: The setups the targets compare.
COMPARED = ("single", "dask-1", "dask-2")
METHOD = {"blobs": "sparse", "variational": "octree", "particles": "sparse"}
OPTIONS = {"blobs": {}, "variational": {"normals": False}, "particles": {}}
#: Many small tiles, for the scheduler's and the weld's cost per tile: the quick blob field over
#: MANY_BOUNDS (every tile reached by primitives), lattice cells and cells per tile edge.
MANY = {False: (88, 4), True: (40, 4)}
MANY_BOUNDS = [[-0.75] * 3, [0.75] * 3]
#: No-op tasks, for the scheduler's cost per task alone.
NOOP_TASKS = {False: 10_000, True: 1_000}
#: The workers' environment: one rayon thread each (one Dask thread each too), so a worker uses
#: one core.
WORKER_ENV = {"RAYON_NUM_THREADS": "1"}
#: Timed runs per case (after one warm-up on a small lattice), by field (full, quick); the median
#: is reported. The variational runs take under a second and vary more than the blobs'.
RUNS = {False: {"blobs": 3, "variational": 9, "particles": 1}, True: {"blobs": 1, "variational": 1, "particles": 1}}
#: Targets of issue 25.
SPEEDUP_TARGET = 1.6
OVERHEAD_TARGET = 0.25


def cpu_seconds() -> float:
    """CPU seconds (user and system) this process has used, all its threads."""
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def log(msg: str) -> None:
    print(f"[bench_distributed] {msg}", file=sys.stderr, flush=True)


def make_field(name: str, size: int):
    import numpy as np

    import implicitmesh as im

    if name == "blobs":
        centers = np.random.default_rng(11).uniform(-0.8, 0.8, (size, 3))
        return im.BlobField(centers, BLOB_RADIUS * (200_000 / size) ** (1 / 3))
    p, n, _ = samples(size)
    return im.VariationalSurface.fit(p, n, method="partition", exact=True)


class Phases:
    """Wraps ``tile_fields`` and ``weld_tile`` of :mod:`implicitmesh.distributed._run` (the
    gathered run's weld, one tile at a time as the tiles arrive: in place, the client plans it
    and the workers write the rows) to count the client's seconds cutting the field for the
    tiles and welding, the vertices the weld joins and the bytes of each tile's mesh (the
    tiles' fields are cut before the first is submitted)."""

    def __init__(self, imd):
        from implicitmesh.distributed import _run

        self.cut, self.add = _run.tile_fields, _run.weld_tile
        self.reset()
        _run.tile_fields = self._cut
        phases = self

        def add(weld, result, tile):
            nv, nbytes = result.vertices, result.nbytes
            t, before = time.perf_counter(), weld.vertices
            phases.add(weld, result, tile)
            phases.weld_s += time.perf_counter() - t
            phases.tile_vertices += nv
            phases.welded_vertices += nv - (weld.vertices - before)
            phases.tile_bytes.append(nbytes)

        _run.weld_tile = add

    def reset(self) -> None:
        self.cut_s = self.weld_s = 0.0
        self.tile_vertices = self.welded_vertices = 0
        self.tile_bytes: list[int] = []

    def _cut(self, field, shared, *a):
        if shared is not None:
            return self.cut(field, shared, *a)
        t = time.perf_counter()
        parts = list(self.cut(field, shared, *a))
        self.cut_s += time.perf_counter() - t
        return parts


def save_field(name: str, size: int, file: str) -> None:
    """Makes the field and saves it to ``file``; for particles, their lattice beside it."""
    import implicitmesh as im

    if name == "particles":
        from benchmarks.bench_particles import ISO, S, lattice, particles

        p = particles("slab", size)
        bounds, cells = lattice(p)
        Path(file + ".lattice.json").write_text(json.dumps({"bounds": bounds.tolist(), "cells": cells}))
        im.save(file, im.BlobField.from_particles(p, S / 2, iso_surface_threshold=ISO))
        return
    im.save(file, make_field(name, size))


def lattice_of(file: str, resolution: int) -> tuple:
    """(bounds, resolution) of a case: BOX and ``resolution``, or the particles' lattice saved
    beside their field (``resolution`` 0)."""
    if resolution != PARTICLE_LATTICE:
        return BOX, resolution
    saved = json.loads(Path(file + ".lattice.json").read_text())
    return saved["bounds"], saved["cells"]


def pickled_parts(field, bounds, resolution, tile: int) -> list[int]:
    """Bytes each task's field pickles to (what :func:`implicitmesh.distributed.cut_field`
    gives its tile; tiles it gives nothing are not run)."""
    import numpy as np

    from implicitmesh import _core
    from implicitmesh import distributed as imd

    cells, origin, cell = _core.lattice(np.asarray(bounds), resolution)
    parts = (imd.cut_field(field, *imd.tile_box(np.asarray(origin), np.asarray(cell), lo, hi))
             for lo, hi in imd.tiles(cells, (tile,) * 3))
    return [len(pickle.dumps(p)) for p in parts if p is not None]


def one(name: str, setup: str, file: str, resolution: int, tile: int, runs: int) -> dict:
    """Polygonizes the saved field ``runs`` times with ``setup``; timings, counts and peaks."""
    import implicitmesh as im

    if setup == "many":
        return many(file, resolution, tile, runs)
    field = im.load(file)
    method, options = METHOD[name], OPTIONS[name]
    box, lattice = lattice_of(file, resolution)
    out: dict = {"field": name, "setup": setup, "resolution": lattice, "tile": tile}
    if setup == "single":
        im.polygonize(field, bounds=box, resolution=16, method=method, **options)  # warm-up
        times, cpu = [], []
        for _ in range(runs):
            mesh = None  # the peak is one run's: the last run's mesh is not kept during the next
            c, t = cpu_seconds(), time.perf_counter()
            mesh = im.polygonize(field, bounds=box, resolution=lattice, method=method, **options)
            times.append(time.perf_counter() - t)
            cpu.append(cpu_seconds() - c)
        out.update(times=times, triangles=len(mesh.faces), vertices=len(mesh.vertices), peak_mib=vmhwm_mib(),
                   client_cpu=cpu)
        return out

    import distributed

    from implicitmesh import distributed as imd

    workers = int(setup.split("-")[1])
    to_dir = setup.endswith("-dir")
    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None, memory_limit=0, env=WORKER_ENV)
    with distributed.Client(cluster) as client:
        phases = Phases(imd)
        def run(res: int, t: int):
            if to_dir:
                out = tempfile.mkdtemp(prefix="bench_distributed_tiles_")
                return imd.write_tiles(field, out, bounds=box, resolution=res, method=method, client=client, tile=t,
                                       **options)
            return imd.polygonize(field, bounds=box, resolution=res, method=method, client=client, tile=t, **options)

        warm = run(16, 8)  # warm-up: the workers import implicitmesh
        if to_dir:
            shutil.rmtree(warm)
        times, stream, client_cpu, worker_cpu = [], None, [], []
        for i in range(runs):
            phases.reset()
            mesh = None  # as in the single setup
            last = i == runs - 1
            before = (cpu_seconds(), client.run(cpu_seconds))
            t = time.perf_counter()
            if last:
                with distributed.get_task_stream(client) as ts:
                    mesh = run(lattice, tile)
                stream = ts.data
            else:
                mesh = run(lattice, tile)
            times.append(time.perf_counter() - t)
            after = (cpu_seconds(), client.run(cpu_seconds))
            client_cpu.append(after[0] - before[0])
            worker_cpu.append(sum(after[1][w] - before[1][w] for w in before[1]))
            if to_dir and not last:
                shutil.rmtree(mesh)
        cut_s, weld_s, welded = phases.cut_s, phases.weld_s, (phases.tile_vertices, phases.welded_vertices)
        if to_dir:
            directory = mesh
            manifest = json.loads((Path(directory) / imd.MANIFEST).read_text())
            t = time.perf_counter()
            mesh = imd.weld(directory)
            weld_s = time.perf_counter() - t
            shutil.rmtree(directory)
            in_tiles = sum(e["vertices"] for e in manifest["tiles"])
            welded = (in_tiles, in_tiles - len(mesh.vertices))
        field_bytes = pickled_parts(field, box, lattice, tile)
        tasks = [r for r in stream if str(r["key"]).startswith("run_tile")]
        compute = [sum(s["stop"] - s["start"] for s in r["startstops"] if s["action"] == "compute") for r in tasks]
        result_bytes = phases.tile_bytes
        peaks = client.run(vmhwm_mib)
        out.update(
            times=times, triangles=len(mesh.faces), vertices=len(mesh.vertices), tiles=mesh.stats["tiles"],
            tile_seconds=compute, result_bytes=result_bytes, field_bytes=field_bytes,
            cut_s=cut_s, weld_s=weld_s, tile_vertices=welded[0], welded_vertices=welded[1],
            worker_peak_mib=sorted(peaks.values()), peak_mib=vmhwm_mib(),
            client_cpu=client_cpu, worker_cpu=worker_cpu,
        )
    cluster.close()
    return out


def many(file: str, resolution: int, tile: int, noop_tasks: int) -> dict:
    """Tiles of a few cells on 2 worker processes: the scheduler's and the weld's cost per tile,
    and no-op tasks for the scheduler's cost alone."""
    os.environ["RAYON_NUM_THREADS"] = "1"  # the single-process comparison below: one thread
    import distributed

    import implicitmesh as im
    from implicitmesh import distributed as imd

    field = im.load(file)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None, memory_limit=0, env=WORKER_ENV)
    with distributed.Client(cluster) as client:
        phases = Phases(imd)
        imd.polygonize(field, bounds=MANY_BOUNDS, resolution=16, client=client, tile=8)  # warm-up
        client.gather(client.map(int, range(100), pure=False))
        t = time.perf_counter()
        client.gather(client.map(int, range(noop_tasks), pure=False))
        noop_s = time.perf_counter() - t
        phases.reset()
        t = time.perf_counter()
        mesh = imd.polygonize(field, bounds=MANY_BOUNDS, resolution=resolution, client=client, tile=tile)
        tiled_s = time.perf_counter() - t
        out = {"field": "many", "setup": "many", "resolution": resolution, "tile": tile, "tiles": mesh.stats["tiles"],
               "triangles": len(mesh.faces), "seconds": tiled_s, "noop_tasks": noop_tasks, "noop_s": noop_s,
               "cut_s": phases.cut_s, "weld_s": phases.weld_s, "tile_vertices": phases.tile_vertices,
               "welded_vertices": phases.welded_vertices}
    cluster.close()
    t = time.perf_counter()
    whole = im.polygonize(field, bounds=MANY_BOUNDS, resolution=resolution, method="sparse")
    out.update(single_s=time.perf_counter() - t, peak_mib=vmhwm_mib())
    assert len(whole.faces) == out["triangles"]
    return out


def run_one(name: str, setup: str, file: str, resolution: int, tile: int, runs: int) -> dict:
    """:func:`one` in a fresh process."""
    args = [name, setup, file, str(resolution), str(tile), str(runs)]
    return run_case_process("benchmarks.bench_distributed", args,
                            {"field": name, "setup": setup, "resolution": resolution, "tile": tile})


def measure(a: argparse.Namespace) -> dict:
    import implicitmesh as im

    run = RunRecord("benchmarks.bench_distributed", a.quick)
    cases = []
    with tempfile.TemporaryDirectory(prefix="bench_distributed_") as tmp:
        for name, (size, lattices) in CASES[a.quick].items():
            file = str(Path(tmp) / f"{name}.npz")
            t = time.perf_counter()
            save_field(name, size, file)
            log(f"{name}: {size:,} made and saved in {time.perf_counter() - t:.1f} s")
            for resolution, tile in lattices:
                for setup in SETUPS:
                    where = "their lattice" if resolution == PARTICLE_LATTICE else f"{resolution}³"
                    log(f"{name}, {where}, tile {tile}, {setup}")
                    r = run_one(name, setup, file, resolution, tile, RUNS[a.quick][name])
                    cases.append({**r, "size": size})
            if name == "blobs":
                quick_size = CASES[True]["blobs"][0]
                im.save(file, make_field(name, quick_size))
                resolution, tile = MANY[a.quick]
                log(f"{quick_size:,} blobs, {resolution}³, tile {tile}: many small tiles")
                r = run_one(name, "many", file, resolution, tile, NOOP_TASKS[a.quick])
                cases.append({**r, "size": quick_size})
    return {"cases": cases, "run": run.finish(("numpy", "dask", "distributed", "implicitmesh"))}


def _mean_max(values: list, scale: float = 1.0, fmt: str = "{:.2f}") -> str:
    if not values:
        return "—"
    return f"{fmt.format(statistics.mean(values) * scale)} / {fmt.format(max(values) * scale)}"


def render(raw: dict) -> str:
    run = raw["run"]
    rows, checks = [], []
    by = {(c["field"], _lattice_label(c.get("resolution")), c["setup"]): c for c in raw["cases"]}
    for name, resolution in dict.fromkeys((c["field"], _lattice_label(c.get("resolution"))) for c in raw["cases"]
                                          if c["field"] != "many"):
        cases = [by.get((name, resolution, s), {}) for s in SETUPS]
        single, d1, d2 = cases[:3]
        t = {s: statistics.median(c["times"]) if "times" in c else None for s, c in zip(SETUPS, cases)}
        for setup, c in zip(SETUPS, cases):
            if "error" in c or not c:
                rows.append([name, setup, f"failed: {c.get('error', 'not run')}"] + [""] * 11)
                continue
            dask = setup != "single"
            rows.append([
                f"{name}, {c['size']:,}, {resolution}" + (f", tile {c['tile']}" if dask else ""),
                setup, fmt_s(t[setup]),
                f"{t['dask-1'] / t[setup]:.2f}×" if dask and t["dask-1"] else "",
                f"{t[setup] / t['single'] - 1:+.0%}" if dask and t["single"] else "",
                f"{c['triangles']:,}",
                str(c.get("tiles", "")),
                _mean_max(c["tile_seconds"], fmt="{:.3f}") if dask else "",
                _mean_max(c["field_bytes"], 1e-6) + " / " + _mean_max(c["result_bytes"], 1e-6) if dask else "",
                f"{fmt_s(c['cut_s'])} / {fmt_s(c['weld_s'])}" if dask else "",
                f"{c['welded_vertices']:,} of {c['tile_vertices']:,}" if dask else "",
                _cpu(c),
                (" / ".join(f"{m:,.0f}" for m in c["worker_peak_mib"]) + f"; client {c['peak_mib']:,.0f}") if dask
                else f"{c['peak_mib']:,.0f}",
                str(len(c["times"])),
            ])
        if all(t[s] for s in COMPARED) and single.get("triangles") == d1.get("triangles") == d2.get("triangles"):
            speedup, overhead = t["dask-1"] / t["dask-2"], t["dask-2"] / t["single"] - 1
            bound, cores = _bound(t["dask-1"], d2), _cores(t["dask-1"], d1)
            checks.append(f"- {name}, {resolution}: 2 workers {speedup:.2f}× one (target ≥ {SPEEDUP_TARGET}×: "
                          f"{'met' if speedup >= SPEEDUP_TARGET else 'not met'}"
                          + (f"; `dask-1` already kept {cores:.2f} cores busy on average (its worker's and its "
                             f"client's CPU over its time), so two cores can make it at most {2 / cores:.2f}× as fast "
                             "without the work itself shrinking" if cores else "")
                          + (f"; the CPU that `dask-2`'s workers and client used, spread over two cores, allows at most {bound:.2f}×"
                             if bound else "")
                          + f"); overhead of 2 workers against one "
                          f"process {overhead:+.0%} (target ≤ {OVERHEAD_TARGET:.0%}: "
                          f"{'met' if overhead <= OVERHEAD_TARGET else 'not met'}).")
        elif all(t[s] for s in COMPARED):
            checks.append(f"- {name}, {resolution}: the setups' triangle counts differ (see the table).")
    return "\n".join([
        "## Tiled polygonization on Dask" + (" (QUICK)" if run["quick"] else ""),
        "",
        f"Run {run['date']} with `{run['command']}`. `single`: `implicitmesh.polygonize` in one process with "
        "all its threads. `dask-1`, `dask-2`: `implicitmesh.distributed.polygonize` on a `LocalCluster` of 1 or 2 "
        "worker processes of one Dask thread and one rayon thread each (`RAYON_NUM_THREADS=1`), so a worker uses "
        "one core: on 2 cores `dask-2` has the cores `single` has, and `dask-2` against `dask-1` shows how "
        "independent the tasks are; `dask-2-dir` is `dask-2` with `write_tiles(field, DIR)` on local disk (nothing gathered); the client welds each tile as it arrives (`weld(DIR)` with all its threads). Blobs: centres uniform in [-0.8, 0.8]³ (seed 11), one radius (0.02 at "
        "200,000 primitives, scaled with the cube root of 1 / primitives), `method=\"sparse\"`. Variational: "
        "a partition fit of points sampled on `knot_hires` with their face normals (bench_scale's samples), "
        "`method=\"octree\"`, `normals=False`, at 256³ in tiles of 128³ and at 512³ in tiles of 256³. Bounds [-1, 1]³. "
        "Particles: 10⁷ particles of bench_particles' `slab` layout, the colour field of `BlobField.from_particles`, "
        "`method=\"sparse\"`, on that benchmark's lattice (cells of s/4 around the particles), in tiles of 256³. Each setup in a fresh process, after a warm-up "
        "at 16³; times are wall-clock medians of the runs column, cluster start-up excluded. "
        "Speed-up: `dask-1`'s time over this row's; overhead: this row's time over `single`'s, minus 1. "
        "Per tile: the task's compute seconds (Dask's task stream) and the megabytes of its field (pickled) "
        "and of its mesh, mean / max over tasks. The workers share the client's machine: `dask-2`'s fill its cores, so "
        "its gathered run welds in place (`implicitmesh.distributed._weld_in_place`: the client plans the weld from each tile's "
        "counts and boundary vertices, and the worker holding a tile writes its rows into the welded mesh's files in "
        "`/dev/shm`); `dask-1` leaves the client a core, so the client welds each tile as it arrives, the tiles passing "
        "through files in `/dev/shm` (`implicitmesh.distributed._tile_files`). Client: seconds cutting the field per tile and "
        "welding (the sum over the tiles as they arrive: planning them, and writing the tiles under 8 MB "
        "(`_weld_in_place.MIN_KEPT_BYTES`), which come back whole, in place; "
        "welding them otherwise; for `dask-2-dir`, `weld(DIR)` after the run, not in its seconds). Welded: vertices joined by the weld, of the tiles' vertices. "
        "CPU: seconds of CPU (user and system, `getrusage`) of the workers (summed) and of the client's process (which "
        "runs the `LocalCluster`'s scheduler too) during a run, medians; for `single`, its process's. Peak "
        "memory: VmHWM of each worker process and of the client process (MiB).",
        "",
        run_markdown(run),
        "",
        *many_lines([c for c in raw["cases"] if c["field"] == "many"]),
        md_table(["field, size, lattice", "setup", "seconds", "speed-up vs dask-1", "overhead vs single",
                  "triangles", "tiles", "per tile: seconds (mean / max)",
                  "per tile: MB field / MB result (mean / max each)", "client: cut / weld (s)", "welded vertices",
                  "CPU s: workers / client", "peak MiB", "runs"], rows),
        "",
        *checks,
        "",
    ])


def _lattice_label(resolution) -> str:
    """``512³`` for a resolution, ``1,329 × 1,329 × 1,150`` for cells per axis."""
    if isinstance(resolution, (list, tuple)):
        return " × ".join(f"{r:,}" for r in resolution)
    return f"{resolution}³"


def _cpu(c: dict) -> str:
    """The median CPU seconds of a case's runs: workers / client, or the single process's."""
    if "client_cpu" not in c:
        return ""
    if "worker_cpu" not in c:
        return fmt_s(statistics.median(c["client_cpu"]))
    return f"{fmt_s(statistics.median(c['worker_cpu']))} / {fmt_s(statistics.median(c['client_cpu']))}"


def _cores(one_worker_s: float, one: dict) -> float | None:
    """The cores one worker's run kept busy on average: the CPU seconds its worker and its
    client used (medians) over its time."""
    if "worker_cpu" not in one:
        return None
    return (statistics.median(one["worker_cpu"]) + statistics.median(one["client_cpu"])) / one_worker_s


def _bound(one_worker_s: float, two: dict) -> float | None:
    """The most 2 workers can gain over one on 2 cores: one worker's seconds over the CPU
    seconds the 2 workers and the client used (medians), shared by two cores."""
    if "worker_cpu" not in two:
        return None
    used = statistics.median(two["worker_cpu"]) + statistics.median(two["client_cpu"])
    return one_worker_s / (used / 2)


def many_lines(cases: list[dict]) -> list[str]:
    """The paragraph on many small tiles."""
    lines = []
    for c in cases:
        if "error" in c:
            lines += [f"Many small tiles: failed: {c['error']}", ""]
            continue
        rest = c["seconds"] - c["cut_s"] - c["weld_s"]
        lines += [
            f"Many small tiles ({c['size']:,} blobs over [-0.75, 0.75]³, {c['resolution']}³ in tiles of "
            f"{c['tile']}³, 2 workers): {c['tiles']:,} tasks, {c['triangles']:,} triangles in "
            f"{fmt_s(c['seconds'])} s (one process, one rayon thread: {fmt_s(c['single_s'])} s): the client cut "
            f"the field in {fmt_s(c['cut_s'])} s ({c['cut_s'] / c['tiles'] * 1e3:.2f} ms per tile) and welded "
            f"{c['tile_vertices']:,} vertices ({c['welded_vertices']:,} joined) in {fmt_s(c['weld_s'])} s "
            f"({c['weld_s'] / c['tiles'] * 1e3:.2f} ms per tile); the rest, {fmt_s(rest)} s, is "
            f"{rest / c['tiles'] * 1e3:.2f} ms per task. {c['noop_tasks']:,} no-op tasks took "
            f"{fmt_s(c['noop_s'])} s ({c['noop_s'] / c['noop_tasks'] * 1e3:.2f} ms per task).",
            "",
        ]
    return lines


def main() -> int:
    if len(sys.argv) == 8 and sys.argv[1] == "one":
        name, setup, file, resolution, tile, runs = sys.argv[2:]
        print(json.dumps(one(name, setup, file, int(resolution), int(tile), int(runs))))
        return 0
    return run_section("distributed", measure, render, __doc__.split("\n")[0], "smaller fields, one run per setup")


if __name__ == "__main__":
    sys.exit(main())
