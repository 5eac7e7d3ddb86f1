"""Blob fields (Triquet et al.): our dense and sparse marching cubes and surface tracking against numpy
evaluation of the grid followed by VTK flying edges (pyvista) or scikit-image marching cubes, in
one run, plus an animation loop (a script, not a test).

    python -m benchmarks.bench_blobs [--quick] [--results DIR]

Cases (issue 4): 200 primitives (R = 0.25) and 7,000 primitives (R = 0.08), centres uniform in
[-0.8, 0.8]³ (fixed seed), strengths 1, threshold 0.5, at 20³, 128³ and 256³ cells over [-1, 1]³
(``--quick``: 20³ and 128³, 1-2 runs). Every peer contours the same (n + 1)³ lattice of the same
potential, computed by the fastest numpy we could write (checked against ``BlobField.evaluate``).
Animation: 200 primitives at 64³ moving smoothly, ``BlobField.update`` then polygonize each frame.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor

from benchmarks.timing import (
    RunRecord,
    Timing,
    cpu_snapshot,
    fmt_cpu_per_wall as _cpw,
    fmt_foreign_load as _fl,
    fmt_ratio,
    fmt_s,
    foreign_load,
    md_table,
    run_markdown,
    run_section,
    timeit_median,
)

SEED = 20240611
CASES = ((200, 0.25), (7000, 0.08))
RESOLUTIONS = (20, 128, 256)
THRESHOLD = 0.5
LO, HI = -1.0, 1.0
PAIRED_ROUNDS = {128: 9, 256: 7}  # ours / peer rounds for the target ratios
TARGETS = {128: 3.0, 256: 5.0}  # issue 4: ours ≥ this × faster than the fastest peer pipeline
ANIM_N, ANIM_R, ANIM_RES, ANIM_FPS = 200, 0.25, 64, 200.0
EVAL_TOL = 1e-12  # numpy grid vs BlobField.evaluate on the lattice points
CHECK_POINTS = 2_000_000  # lattice points checked (all of them when the lattice is smaller)


def log(msg: str) -> None:
    print(f"[bench_blobs {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------------
# The numpy peer: the potential on the (n + 1)³ lattice, as a (z, y, x) C-ordered array, so that
# its ravel() is x-fastest (what VTK's image data wants) without a copy.
# --------------------------------------------------------------------------------------------


def _boxes(centers, R: float, n: int):
    import numpy as np

    h = (HI - LO) / n
    m = n + 1
    x = LO + h * np.arange(m)
    i0 = np.clip(np.ceil((centers - R - LO) / h).astype(np.int64), 0, m)
    i1 = np.clip(np.floor((centers + R - LO) / h).astype(np.int64) + 1, 0, m)
    return x, i0, i1


def _splat_into(G, x, centers, i0, i1, R: float, z0: int, z1: int) -> None:
    """Adds A(1 − d²/R²)²₊ of every blob into G[z0:z1] (its bounding box, clipped to the slab)."""
    import numpy as np

    inv = 1.0 / (R * R)
    for (cx, cy, cz), (a0, b0, c0), (a1, b1, c1) in zip(centers.tolist(), i0.tolist(), i1.tolist()):
        c0, c1 = max(c0, z0), min(c1, z1)
        if a0 >= a1 or b0 >= b1 or c0 >= c1:
            continue
        ax = (x[a0:a1] - cx) ** 2 * inv
        ay = (x[b0:b1] - cy) ** 2 * inv
        az = (x[c0:c1] - cz) ** 2 * inv
        t = 1.0 - (az[:, None, None] + (ay[:, None] + ax[None, :])[None])
        np.maximum(t, 0.0, out=t)
        t *= t
        G[c0:c1, b0:b1, a0:a1] += t


def splat_loop(centers, R: float, n: int):
    """One blob at a time: broadcast the squared distances over its bounding box, add in place."""
    import numpy as np

    m = n + 1
    G = np.zeros((m, m, m))
    x, i0, i1 = _boxes(centers, R, n)
    _splat_into(G, x, centers, i0, i1, R, 0, m)
    return G


_POOL: ThreadPoolExecutor | None = None


def splat_threads(centers, R: float, n: int, threads: int = 2):
    """As :func:`splat_loop`, with the grid cut into ``threads`` z-slabs, one thread each (numpy
    releases the GIL inside the ufuncs; no two threads write the same points)."""
    import numpy as np

    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(threads)
    m = n + 1
    G = np.zeros((m, m, m))
    x, i0, i1 = _boxes(centers, R, n)
    cuts = [round(k * m / threads) for k in range(threads + 1)]
    futures = []
    for z0, z1 in zip(cuts[:-1], cuts[1:]):
        sel = (i0[:, 2] < z1) & (i1[:, 2] > z0)
        futures.append(_POOL.submit(_splat_into, G, x, centers[sel], i0[sel], i1[sel], R, z0, z1))
    for f in futures:
        f.result()
    return G


def splat_batched(centers, R: float, n: int, chunk: int = 4_000_000):
    """All blobs' (equal) boxes at once in chunks, summed with np.bincount; wins when the boxes
    are small (many small blobs on a coarse lattice)."""
    import numpy as np

    h = (HI - LO) / n
    m = n + 1
    x = LO + h * np.arange(m)
    k = min(int(np.floor(2 * R / h)) + 2, m)
    start = np.clip(np.ceil((centers - R - LO) / h).astype(np.int64), 0, m - k)
    off = np.arange(k)
    inv = 1.0 / (R * R)
    G = np.zeros(m**3)
    per = max(1, chunk // k**3)
    for s in range(0, len(centers), per):
        c, st = centers[s : s + per], start[s : s + per]
        idx = st[:, None, :] + off[None, :, None]  # (b, k, 3): x, y, z lattice indices
        d = (x[idx] - c[:, None, :]) ** 2 * inv
        t = 1.0 - (d[:, :, None, None, 2] + d[:, None, :, None, 1] + d[:, None, None, :, 0])
        np.maximum(t, 0.0, out=t)
        t *= t
        flat = (idx[:, :, None, None, 2] * m + idx[:, None, :, None, 1]) * m + idx[:, None, None, :, 0]
        G += np.bincount(flat.ravel(), t.ravel(), minlength=m**3)
    return G.reshape(m, m, m)


SPLATS = {
    "per-blob box loop": splat_loop,
    "per-blob box loop, 2 threads (z-slabs)": splat_threads,
    "all boxes at once + bincount": splat_batched,
}


def check_grid(field, G, n: int, rng) -> float:
    """max |(threshold − G) − field.evaluate| over the lattice (or CHECK_POINTS random points of it)."""
    import numpy as np

    m = n + 1
    ax = np.linspace(LO, HI, m)
    if m**3 <= CHECK_POINTS:
        k, j, i = (a.ravel() for a in np.meshgrid(np.arange(m), np.arange(m), np.arange(m), indexing="ij"))
    else:
        k, j, i = rng.integers(0, m, size=(3, CHECK_POINTS))
    P = np.stack([ax[i], ax[j], ax[k]], axis=1)
    return float(np.abs((THRESHOLD - G[k, j, i]) - field.evaluate(P)).max())


# --------------------------------------------------------------------------------------------
# The contouring peers
# --------------------------------------------------------------------------------------------


def vtk_contour(G, n: int, normals: bool) -> int:
    import pyvista as pv

    h = (HI - LO) / n
    m = n + 1
    grid = pv.ImageData(dimensions=(m, m, m), spacing=(h, h, h), origin=(LO, LO, LO))
    grid.point_data["F"] = G.ravel()  # (z, y, x) C order = x fastest: no copy
    out = grid.contour([THRESHOLD], scalars="F", method="flying_edges", compute_normals=normals,
                       compute_scalars=False)
    return int(out.n_cells)


def skimage_contour(G, n: int) -> int:
    import numpy as np
    from skimage.measure import marching_cubes

    h = (HI - LO) / n
    verts, faces, normals, _ = marching_cubes(G, THRESHOLD, spacing=(h, h, h))
    verts = verts[:, ::-1] + LO  # (z, y, x) → (x, y, z); the swap mirrors, so flip the faces too
    faces = np.ascontiguousarray(faces[:, ::-1])
    return int(len(faces))


def set_vtk_backend(name: str) -> str:
    import vtk

    vtk.vtkSMPTools.SetBackend(name)
    return vtk.vtkSMPTools.GetBackend()


# --------------------------------------------------------------------------------------------
# The benchmark
# --------------------------------------------------------------------------------------------


def missing_components(dense, track) -> str:
    """Which connected components of the dense mesh the tracking mesh lacks, and whether they
    are cavities (negative enclosed volume: faces are oriented outward)."""
    import collections

    import trimesh

    def comps(m):
        parts = trimesh.Trimesh(m.vertices, m.faces, process=False).split(only_watertight=False)
        return [(round(float(p.volume), 12), len(p.faces)) for p in parts]

    have = collections.Counter(comps(track))
    missing = []
    for c in comps(dense):
        if have[c] > 0:
            have[c] -= 1
        else:
            missing.append(c)
    if not missing:
        return "the same components, different triangles"
    cav = sum(v < 0 for v, _ in missing)
    return (f"{len(missing)} component(s) of the dense mesh missing from tracking ({sum(f for _, f in missing):,} "
            f"triangles), {cav} of them cavities (negative volume), which no seed walk from a centre along +x "
            "reaches (README, Known limits)")


def _same(cmp: dict | None, n_dense: int, n_track: int) -> str:
    if cmp is None:
        return "same count (not compared)" if n_dense == n_track else f"no ({n_track - n_dense:+,} triangles)"
    if cmp["missing"] == cmp["extra"] == 0:
        return "yes (same triangles)"
    return f"no ({cmp['missing']:,} missing, {cmp['extra']:,} extra)"


def pipelines(grid: float, vtk: float, vtk_normals: float, skimage: float) -> tuple[dict, dict]:
    """Seconds of the peer pipelines end to end (numpy grid + contour): (without normals, with normals)."""
    return ({"numpy + VTK": grid + vtk},
            {"numpy + VTK + normals": grid + vtk_normals, "numpy + skimage": grid + skimage})


def fastest(pipes: dict) -> tuple[str, float]:
    return min(pipes.items(), key=lambda kv: kv[1])


#: Our polygonizers in the order they are timed: (method, normals).
OURS = tuple((method, normals) for method in ("dense", "sparse", "tracking") for normals in (True, False))


def measure(a: argparse.Namespace) -> dict:
    import numpy as np

    import implicitmesh as im

    quick = a.quick
    resolutions = tuple(r for r in RESOLUTIONS if not (quick and r > 128))
    runs_for = {20: 2 if quick else 9, 128: 1 if quick else 5, 256: 3}
    frames = 30 if quick else 120
    warm_frames = 5 if quick else 10
    bounds = np.array([[LO] * 3, [HI] * 3])
    run = RunRecord("benchmarks.bench_blobs", quick)
    rng = np.random.default_rng(SEED)
    check_rng = np.random.default_rng(SEED + 1)
    import vtk

    vtk_default = f"{vtk.vtkSMPTools.GetBackend()} ({vtk.vtkSMPTools.GetEstimatedNumberOfThreads()} thread(s))"

    cases, notes = [], []
    for N, R in CASES:
        centers = rng.uniform(-0.8, 0.8, size=(N, 3))
        field = im.BlobField(centers, R, threshold=THRESHOLD)
        for n in resolutions:
            runs = runs_for[n]
            case = f"{N:,} × R={R}, {n}³"
            log(f"{case}: ours ({runs} runs)")
            ours: dict[tuple[str, bool], Timing] = {}
            for method, normals in OURS:
                ours[method, normals] = timeit_median(
                    lambda: im.polygonize(field, bounds=bounds, resolution=n, method=method, normals=normals),
                    runs, 1)
            dense, track = ours["dense", True].result, ours["tracking", True].result
            sp = ours["sparse", True].result
            counts = {k: len(t.result.faces) for k, t in ours.items()}
            # sparse must be dense exactly (the tests check it bit for bit); compared here too
            cmp_sp = im.compare(dense, sp) if n <= 128 else None
            sparse_same = (counts["sparse", True] == counts["dense", True] and counts["sparse", False] == counts["dense", True]
                           and (cmp_sp is None or (not cmp_sp["missing"] and not cmp_sp["extra"])))
            if not sparse_same:
                notes.append(f"{case}: SPARSE DIFFERS FROM DENSE: {cmp_sp}, counts {counts}")
            # triangle by triangle up to 128³ (at 256³ comparing and splitting 3M-triangle meshes
            # takes longer than the timings: counts only)
            cmp = im.compare(dense, track) if n <= 128 else None
            if counts["tracking", True] != counts["dense", True] or (cmp is not None and (cmp["missing"] or cmp["extra"])):
                notes.append(f"{case}: tracking {counts['tracking', True]:,} triangles, dense "
                             f"{counts['dense', True]:,}; " + (missing_components(dense, track) if n <= 128 else
                             "not compared triangle by triangle at this size"))

            # numpy grid: probe every variant once, keep the fastest, then time it
            log(f"{case}: numpy grid")
            probe = {}
            for name, fn in SPLATS.items():
                if fn is splat_batched and n > 128:
                    continue  # one (n + 1)³ bincount per chunk: seconds at 256³, never the fastest
                t0 = time.perf_counter()
                fn(centers, R, n)
                probe[name] = time.perf_counter() - t0
            best = min(probe, key=probe.get)
            t_np = timeit_median(lambda: SPLATS[best](centers, R, n), runs, 1)
            G = t_np.result
            err = check_grid(field, G, n, check_rng)
            if not err <= EVAL_TOL:
                raise AssertionError(f"{case}: numpy grid differs from BlobField.evaluate by {err:.2e}")

            log(f"{case}: VTK flying edges, skimage")
            vt: dict[bool, Timing] = {}
            vtk_backend: dict[bool, str] = {}
            for normals in (False, True):
                by_backend = {}
                for backend in ("Sequential", "STDThread"):
                    set_vtk_backend(backend)
                    by_backend[backend] = timeit_median(lambda: vtk_contour(G, n, normals), runs, 1)
                vtk_backend[normals] = min(by_backend, key=lambda b: by_backend[b].median)
                vt[normals] = by_backend[vtk_backend[normals]]
            set_vtk_backend("Sequential")
            t_sk = timeit_median(lambda: skimage_contour(G, n), runs, 1)

            pipes_nn, pipes_wn = pipelines(t_np.median, vt[False].median, vt[True].median, t_sk.median)
            best_any = fastest({**pipes_nn, **pipes_wn})
            # Paired rounds: ours, then the fastest peer pipeline, in turn, a ratio per round;
            # the median of those ratios is immune to the machine changing speed between the
            # blocks of runs above (seen here: a third, in both directions).
            ratios = None
            if TARGETS.get(n) is not None:
                rounds = PAIRED_ROUNDS[n]
                log(f"{case}: {rounds} paired rounds against {best_any[0]}")
                contour = {
                    "numpy + VTK": lambda G: vtk_contour(G, n, False),
                    "numpy + VTK + normals": lambda G: vtk_contour(G, n, True),
                    "numpy + skimage": lambda G: skimage_contour(G, n),
                }[best_any[0]]
                if "VTK" in best_any[0]:
                    set_vtk_backend(vtk_backend[best_any[0].endswith("normals")])
                ratios = []
                for _ in range(rounds):
                    t0 = time.perf_counter()
                    im.polygonize(field, bounds=bounds, resolution=n, method="sparse")
                    t1 = time.perf_counter()
                    contour(SPLATS[best](centers, R, n))
                    ratios.append((time.perf_counter() - t1) / (t1 - t0))
                set_vtk_backend("Sequential")
            cases.append({
                "primitives": N,
                "radius": R,
                "cells": n,
                "runs": runs,
                "ours": [{"method": m, "normals": nn, "timing": ours[m, nn].to_json(), "triangles": counts[m, nn]}
                         for m, nn in OURS],
                "sparse_compared": cmp_sp is not None,
                "sparse_same": sparse_same,
                "tracking_vs_dense": None if cmp is None else {"missing": int(cmp["missing"]), "extra": int(cmp["extra"])},
                "dense_evaluations": int(dense.stats["evaluations"]),
                "dense_normal_evaluations": int(dense.stats["normal_evaluations"]),
                "sparse_evaluations": int(sp.stats["evaluations"]),
                "sparse_evaluation_percent": float(sp.stats["evaluation_percent"]),
                "tracking_evaluations": int(track.stats["evaluations"]),
                "tracking_evaluation_percent": float(track.stats["evaluation_percent"]),
                "numpy_grid": best,
                "numpy_grid_probe": probe,
                "numpy_grid_timing": t_np.to_json(),
                "numpy_grid_max_abs_diff": err,
                "vtk_backend": [vtk_backend[False], vtk_backend[True]],
                "vtk": vt[False].to_json(),
                "vtk_normals": vt[True].to_json(),
                "vtk_triangles": int(vt[False].result),
                "skimage": t_sk.to_json(),
                "skimage_triangles": int(t_sk.result),
                "paired_peer_over_sparse": ratios,
            })
            log(f"{case}: ours sparse {ours['sparse', True].median:.4f} s, dense {ours['dense', True].median:.4f} s, "
                f"best peer {best_any[0]} {best_any[1]:.4f} s")
            del G, t_np

    # ---------------------------------------------------------------- animation
    log(f"animation: {ANIM_N} blobs, {ANIM_RES}³, {frames} frames after {warm_frames}")
    arng = np.random.default_rng(SEED + 2)
    base = arng.uniform(-0.8, 0.8, size=(ANIM_N, 3))
    phase = arng.uniform(0, 2 * np.pi, size=(ANIM_N, 3))

    def centers_at(frame: int):
        return base + 0.05 * np.sin(0.05 * frame + phase)

    def animate_all(makers):
        """Every method in turn on each frame (the order rotating from frame to frame), so that a
        change in the machine's speed during the run reaches all of them alike."""
        runs = []
        for label, make in makers:
            fld = im.BlobField(centers_at(0), ANIM_R, threshold=THRESHOLD)
            runs.append((label, fld, make(fld)))
        times = {label: [] for label, _ in makers}
        tris = {label: [] for label, _ in makers}
        evals = {label: [] for label, _ in makers}
        cpu = {label: 0.0 for label, _ in makers}
        s0 = None
        for f in range(warm_frames + frames):
            if f == warm_frames:
                log(f"animation: {frames} frames, all methods in turn")
                s0 = cpu_snapshot()
            c = centers_at(f)
            k = f % len(runs)
            for label, fld, step in runs[k:] + runs[:k]:
                c0, t0 = time.process_time(), time.perf_counter()
                fld.update(c)
                res = step()
                dt = time.perf_counter() - t0
                if f >= warm_frames:
                    times[label].append(dt)
                    cpu[label] += time.process_time() - c0
                    tris[label].append(res[0])
                    evals[label].append(res[1])
        fl = foreign_load(s0, cpu_snapshot())
        return {label: (times[label], tris[label], evals[label], fl, cpu[label] / sum(times[label]))
                for label, _ in makers}

    def ours_tracking(normals, blocks=True):
        def make(fld):
            tess = im.Tessellator()

            def step():
                m = tess.polygonize(fld, bounds=bounds, resolution=ANIM_RES, normals=normals, blocks=blocks)
                return len(m.faces), m.stats["evaluations"]
            return step
        return make

    def ours_method(method, normals):
        def make(fld):
            def step():
                m = im.polygonize(fld, bounds=bounds, resolution=ANIM_RES, method=method, normals=normals)
                return len(m.faces), m.stats["evaluations"]
            return step
        return make

    def peer_vtk(normals):
        def make(fld):
            def step():
                Gf = SPLATS[anim_splat](fld.centers, ANIM_R, ANIM_RES)
                return vtk_contour(Gf, ANIM_RES, normals), (ANIM_RES + 1) ** 3
            return step
        return make

    # the peer's best numpy grid and VTK backend at 64³, picked on the first frame
    c_probe = centers_at(0)
    probe = {}
    for name, fn in SPLATS.items():
        t0 = time.perf_counter()
        fn(c_probe, ANIM_R, ANIM_RES)
        probe[name] = time.perf_counter() - t0
    anim_splat = min(probe, key=probe.get)
    G64 = SPLATS[anim_splat](c_probe, ANIM_R, ANIM_RES)
    vb = {}
    for backend in ("Sequential", "STDThread"):
        set_vtk_backend(backend)
        vb[backend] = timeit_median(lambda: vtk_contour(G64, ANIM_RES, False), 5, 1).median
    anim_vtk = min(vb, key=vb.get)
    set_vtk_backend(anim_vtk)

    tess_label = "ours `Tessellator().polygonize` (tracking block by block, buffers kept)"
    dense_label = "ours `polygonize(method=\"dense\")`"
    sparse_label = "ours `polygonize(method=\"sparse\")`"
    makers = (
        (tess_label, ours_tracking(True)),
        ("ours `Tessellator().polygonize`, normals=False", ours_tracking(False)),
        ("ours `Tessellator().polygonize(blocks=False)` (tracking cell by cell, caches kept)",
         ours_tracking(True, blocks=False)),
        (dense_label, ours_method("dense", True)),
        ("ours `polygonize(method=\"dense\")`, normals=False", ours_method("dense", False)),
        (sparse_label, ours_method("sparse", True)),
        ("ours `polygonize(method=\"sparse\")`, normals=False", ours_method("sparse", False)),
        (f"peer: numpy grid ({anim_splat}) + VTK flying edges ({anim_vtk}), no normals", peer_vtk(False)),
        (f"peer: numpy grid + VTK flying edges ({anim_vtk}) + normals", peer_vtk(True)),
    )
    animation = []
    anim_tris = {}
    for label, (times, tris, evals, fl, cpw) in animate_all(makers).items():
        anim_tris[label] = tris
        animation.append({"label": label, "times": times, "triangles": tris, "evaluations": evals,
                          "foreign_load": fl, "cpu_per_wall": cpw})
    set_vtk_backend("Sequential")
    t_tris, d_tris = anim_tris[tess_label], anim_tris[dense_label]
    differ = sum(a != b for a, b in zip(t_tris, d_tris))
    sp_differ = sum(a != b for a, b in zip(anim_tris[sparse_label], d_tris))
    if sp_differ:
        notes.append(f"animation: SPARSE AND DENSE TRIANGLE COUNTS DIFFER in {sp_differ} of {frames} frames")
    if differ:
        notes.append(f"animation: tracking and dense triangle counts differ in {differ} of {frames} frames "
                     f"(at most {max(b - a for a, b in zip(t_tris, d_tris)):,} "
                     "triangles fewer for tracking; the frames' meshes are not analysed further)")
    return {
        "resolutions": list(resolutions),
        "runs": {str(r): runs_for[r] for r in resolutions},
        "vtk_default": vtk_default,
        "cases": cases,
        "frames": frames,
        "warm_frames": warm_frames,
        "animation": animation,
        "notes": notes,
        "run": run.finish(("numpy", "scikit-image", "pyvista", "vtk", "implicitmesh")),
    }


def _ours(case: dict) -> dict[tuple[str, bool], Timing]:
    return {(o["method"], o["normals"]): Timing.from_json(o["timing"]) for o in case["ours"]}


def _timing_rows(case: dict) -> list[tuple[str, Timing]]:
    """Every timing of a case, in the order they were taken, with what it timed."""
    rows = [(f"ours {o['method']}" + ("" if o["normals"] else ", normals=False"), Timing.from_json(o["timing"]))
            for o in case["ours"]]
    rows.append((f"numpy grid ({case['numpy_grid']})", Timing.from_json(case["numpy_grid_timing"])))
    for normals, key in ((False, "vtk"), (True, "vtk_normals")):
        rows.append((f"VTK flying edges{' + normals' if normals else ''} ({case['vtk_backend'][normals]})",
                     Timing.from_json(case[key])))
    rows.append(("skimage marching_cubes (normals always)", Timing.from_json(case["skimage"])))
    return rows


def render(raw: dict) -> str:
    run = raw["run"]
    quick = run["quick"]
    resolutions = raw["resolutions"]
    frames, warm_frames = raw["frames"], raw["warm_frames"]
    rows_s, rows_r, rows_c, all_timings = [], [], [], []
    for c in raw["cases"]:
        N, n = c["primitives"], c["cells"]
        case = f"{N:,} × R={c['radius']}, {n}³"
        all_timings += [(case, what, t) for what, t in _timing_rows(c)]
        ours = _ours(c)
        counts = {(o["method"], o["normals"]): o["triangles"] for o in c["ours"]}
        g = Timing.from_json(c["numpy_grid_timing"]).median
        vt = {False: Timing.from_json(c["vtk"]), True: Timing.from_json(c["vtk_normals"])}
        t_sk = Timing.from_json(c["skimage"])
        pipes_nn, pipes_wn = pipelines(g, vt[False].median, vt[True].median, t_sk.median)
        best_any = fastest({**pipes_nn, **pipes_wn})
        best_wn = fastest(pipes_wn)
        best_nn = fastest(pipes_nn)
        od, odn = ours["dense", True].median, ours["dense", False].median
        osp, ospn = ours["sparse", True].median, ours["sparse", False].median
        rows_s.append([
            f"{N:,}", f"{n}³",
            fmt_s(osp), fmt_s(ospn), fmt_s(od), fmt_s(odn),
            fmt_s(ours["tracking", True].median), fmt_s(ours["tracking", False].median),
            fmt_s(g), fmt_s(vt[False].median), fmt_s(vt[True].median), fmt_s(t_sk.median),
            fmt_s(pipes_nn["numpy + VTK"]), fmt_s(pipes_wn["numpy + VTK + normals"]),
            fmt_s(pipes_wn["numpy + skimage"]),
        ])
        target = TARGETS.get(n)
        strict = best_any[1] / osp
        lfl = min(best_wn[1] / osp, best_nn[1] / ospn)

        def met(r: float) -> str:
            return "—" if target is None else ("yes" if r >= target else "no")

        paired = "—"
        if c["paired_peer_over_sparse"] is not None:
            ratios = sorted(c["paired_peer_over_sparse"])
            mid = ratios[len(ratios) // 2]
            paired = f"{mid:.2f}× ({ratios[0]:.2f}–{ratios[-1]:.2f}×, {len(ratios)} rounds): {met(mid)}"
        rows_r.append([
            f"{N:,}", f"{n}³",
            f"{fmt_ratio(best_any[1], osp)} ({best_any[0]})",
            f"{fmt_ratio(best_wn[1], osp)} ({best_wn[0]})",
            f"{fmt_ratio(best_nn[1], ospn)} ({best_nn[0]})",
            fmt_ratio(best_any[1], od),
            fmt_ratio(best_any[1], min(t.median for t in ours.values())),
            "—" if target is None else f"≥ {target:g}×",
            met(strict), met(lfl), paired,
        ])
        vtk_tris, sk_tris, dense_tris = c["vtk_triangles"], c["skimage_triangles"], counts["dense", True]
        rows_c.append([
            f"{N:,}", f"{n}³", f"{dense_tris:,}",
            ("yes (same triangles)" if c["sparse_compared"] else "same count (not compared)") if c["sparse_same"] else "NO",
            f"{counts['tracking', True]:,}",
            _same(c["tracking_vs_dense"], dense_tris, counts["tracking", True]),
            f"{vtk_tris:,}" + ("" if vtk_tris == dense_tris else f" ({vtk_tris - dense_tris:+,})"),
            f"{sk_tris:,}" + ("" if sk_tris == dense_tris else f" ({sk_tris - dense_tris:+,})"),
            f"{c['dense_evaluations']:,}",
            f"{c['sparse_evaluations']:,} ({c['sparse_evaluation_percent']:.1f} %)",
            f"{c['tracking_evaluations']:,} ({c['tracking_evaluation_percent']:.1f} %)",
            f"{c['dense_normal_evaluations']:,}",
            f"{c['numpy_grid_max_abs_diff']:.1e}",
        ])
    anim_rows = []
    for r in raw["animation"]:
        label, times, cpw, fl = r["label"], r["times"], r["cpu_per_wall"], r["foreign_load"]
        med = statistics.median(times)
        fps = 1.0 / med
        anim_rows.append([
            label, f"{fps:.0f}", f"{1e3 * med:.2f}", f"{1e3 * statistics.quantiles(times, n=10)[-1]:.2f}",
            f"{statistics.median(r['triangles']):,.0f}", f"{statistics.median(r['evaluations']):,.0f}",
            "—" if cpw is None else f"{cpw:.1f}", "—" if fl is None else f"{fl:.1f}",
            ("yes" if fps > ANIM_FPS else "no") if label.startswith("ours") else "",
        ])
    notes = raw["notes"]
    paper_rows = [r for r in rows_s if r[0] == "200" and r[1] == "20³"]
    paper = ""
    if paper_rows:
        r = paper_rows[0]
        paper = (f"The paper's own scale point, 200 primitives at 20³: ours {r[2]} s sparse, {r[4]} s dense and {r[6]} s tracking "
                 "(with normals) here; Triquet et al. report 45 ms (2001 hardware).")
    splats = "; ".join(f"{c['primitives']:,} at {c['cells']}³: {c['numpy_grid']}" for c in raw["cases"])
    vtks = "; ".join(f"{c['primitives']:,} at {c['cells']}³{' + normals' if nn else ''}: {c['vtk_backend'][nn]}"
                     for c in raw["cases"] for nn in (False, True))
    runs_txt = ", ".join(f"{raw['runs'][str(r)]} at {r}³" for r in resolutions)
    vtk_default = raw["vtk_default"]
    out = [
        "## Blob fields: dense and sparse marching cubes and surface tracking against numpy + VTK / scikit-image",
        "",
        f"Run {run['date']} with `{run['command']}`"
        + (" (QUICK: few runs, no 256³; not representative)" if quick else "") + ". "
        f"Blob fields of issue 4: centres uniform in [-0.8, 0.8]³ (seed {SEED}), strengths 1, threshold "
        f"{THRESHOLD}, `BlobField(centers, R)`, polygonized with `polygonize(field, bounds=[[-1,-1,-1],[1,1,1]], "
        f"resolution=n, method=...)`. Wall-clock medians in seconds after one warm-up (runs: {runs_txt}). "
        "Every peer contours the same (n + 1)³ lattice of the same potential F at 0.5: the numpy grid is the "
        "fastest of three numpy evaluations we wrote (each blob's bounding box, broadcasting "
        "(x − cx)² + (y − cy)² + (z − cz)² over it, `np.maximum(1 − d²/R², 0)²` added into the grid; the "
        "same split into two z-slabs on two threads; all boxes at once summed by `np.bincount`), picked per "
        f"case by one probe run of each ({splats}), and equals `threshold − BlobField.evaluate` on the lattice "
        f"to ≤ {EVAL_TOL:g} (checked on every lattice point up to {CHECK_POINTS:,} points, else on "
        f"{CHECK_POINTS:,} random ones). The splat is elementwise numpy, not BLAS-bound, so OPENBLAS_NUM_THREADS "
        "does not matter and is left at its default. VTK: `pyvista.ImageData` over the grid (no copy), "
        "`contour([0.5], method=\"flying_edges\", compute_scalars=False)`, without normals (pyvista's "
        "default) and with `compute_normals=True`, each with the faster of VTK's SMP backends Sequential and "
        f"STDThread ({vtks}; VTK's default here: {vtk_default}). scikit-image: `marching_cubes(F, 0.5, "
        "spacing=…)` (Lewiner, which always computes normals). A peer pipeline end to end = numpy grid + "
        "contour (sum of the medians). Ours runs on rayon's thread pool (every core).",
        "",
        run_markdown(run),
        "",
        "### Seconds",
        "",
        md_table(
            ["primitives", "cells", "ours sparse", "ours sparse, no normals", "ours dense", "ours dense, no normals", "ours tracking",
             "ours tracking, no normals", "numpy grid", "VTK FE", "VTK FE + normals", "skimage (normals)",
             "numpy + VTK", "numpy + VTK + normals", "numpy + skimage"],
            rows_s,
        ),
        "",
        "### Ratios (peer / ours; above 1, ours is faster) and the issue's targets",
        "",
        md_table(
            ["primitives", "cells", "fastest peer pipeline / ours sparse (with normals)",
             "fastest peer with normals / ours sparse with normals",
             "peer without normals / ours sparse without normals", "fastest peer / ours dense (with normals)",
             "fastest peer / our fastest (any method)",
             "target (issue 4)", "met: fastest peer vs ours sparse with normals",
             "met: like for like (the smaller of the two)",
             "paired rounds: median of per-round ratios (range): met"],
            rows_r,
        ),
        "",
        "Targets from issue 4: at 128³ ours ≥ 3× faster than the fastest peer pipeline end to end, at 256³ "
        "≥ 5×. The first ratio is the issue's strict reading (our polygonizer for blobs, `method=\"sparse\"`, "
        "with normals, against whichever peer pipeline is fastest, named in the column); sparse gives the dense "
        "mesh (checked here, and bit for bit in the tests). The like-for-like column requires "
        "both the with-normals and the without-normals ratios to reach the target. The paired-rounds column "
        "times ours sparse (with normals) and then the fastest peer pipeline end to end (grid and contour), "
        "in turn, once per round, and reports the median of the per-round ratios with their range: this "
        "machine's speed shifts by about a third between blocks of runs, which moves the ratios of medians "
        "taken minutes apart but cancels within a round. "
        + paper + " Bloomenthal's polygonizer: about 1 s of CPU for 200 primitives at 128³ (shared/NOTES.md).",
        "",
        "### Exact counts (machine-independent) and checks",
        "",
        md_table(
            ["primitives", "cells", "triangles, dense", "sparse = dense", "triangles, tracking", "tracking = dense",
             "VTK triangles (vs ours)", "skimage triangles (vs ours)", "dense evaluations",
             "sparse evaluations (% of lattice)", "tracking evaluations (% of lattice)", "gradient evaluations (normals)", "numpy grid max |diff|"],
            rows_c,
        ),
        "",
        "Evaluations count lattice values (sparse evaluates the 8³ points of each block it cannot rule out, so "
        "points on faces shared by two such blocks count twice); vertex normals add one gradient evaluation per vertex. Our meshes "
        "with and without normals are checked to have the same triangle count (a note below flags any difference). VTK and scikit-image triangulate the same lattice "
        "with their own case tables (scikit-image's Lewiner tables resolve ambiguous faces and cube interiors "
        "topologically; VTK's flying edges uses the classic table), so their counts may differ slightly from "
        "ours; they are reported, not asserted.",
        "",
        f"### Animation: {ANIM_N} primitives (R = {ANIM_R}) at {ANIM_RES}³ over [-1, 1]³",
        "",
        f"Centres c + 0.05 sin(0.05 frame + phase) (random phase per coordinate); each frame "
        f"`BlobField.update(centers)` then polygonize (both timed); every method runs each frame in turn "
        f"(each on its own `BlobField`, the order rotating from frame to frame, so that the machine's drift "
        f"reaches all alike); median over {frames} frames after "
        f"{warm_frames} warm-up frames; frames per second = 1 / median. The peer rows recompute the numpy grid "
        "from the centres each frame (for orientation; the issue sets no peer for the animation).",
        "",
        md_table(
            ["per frame", "frames/s", "median ms", "90th percentile ms", "triangles", "evaluations",
             "CPU / wall", "other processes (cores)", f"> {ANIM_FPS:.0f} fps (target)"],
            anim_rows,
        ),
        "",
        "<details><summary>Every timing: runs, CPU seconds per wall second, other processes' load</summary>",
        "",
        md_table(
            ["case", "what", "median s", "min s", "runs", "CPU / wall", "other processes (cores)"],
            [[c, w, fmt_s(t.median), fmt_s(t.min), t.runs, _cpw(t), _fl(t)] for c, w, t in all_timings],
        ),
        "",
        "</details>",
        "",
    ]
    if notes:
        out += ["Notes:", ""] + [f"- {x}" for x in notes] + [""]
    return "\n".join(out)


def main() -> int:
    return run_section("blobs", measure, render, __doc__.split("\n")[0], quick_help="1-2 runs, 20³ and 128³ only, 30 frames")


if __name__ == "__main__":
    sys.exit(main())
