"""Particles to surfaces: our blob fields (``method="sparse"``) against splashsurf
(pysplashsurf, f32 and f64) on the same SPH particles at the same cells.

Two layouts of particles on a jittered lattice of spacing s (jitter ±0.1 s per axis): ``slab``, a
slab of fluid with a sphere falling onto it, and ``droplets``, a shallow pool under randomly
placed droplets of 2–6 s radius. splashsurf: ``reconstruct_surface(P, particle_radius=s/2,
smoothing_length=2.0, cube_size=0.5, iso_surface_threshold=0.6)`` (pysplashsurf 0.14 reads the
last two relative to the particle radius: support 2s, cells s/4). Ours over the same cells of
s/4: ``BlobField.from_particles(P, s/2)`` (splashsurf's colour field, the cubic spline) and
``BlobField(P, 2s, 1.0, T, kernel="triquet")`` with T placing the surface where the colour field
lies on a flat face of the fluid (see :func:`triquet_threshold`), each with normals off and on, in
double precision and (``-f32``) with ``precision="single"``.

Every case runs in a fresh process (its peak resident size VmHWM is its own, particles included);
times are wall-clock seconds from particles to mesh, medians over the runs. The results (JSON and
markdown) are written again as each case finishes, so a run stopped early keeps what it measured.
``--sizes`` and ``--cases`` run some cases only and keep the other cases already in the results
(run the 10⁶ and the 4·10⁶ particles separately, say). Above :data:`ONE_RUN_ABOVE` particles
(``--sizes 10000000 --cases slab/triquet``, the issue's 10⁷ at cells of s/4: ours only is
enough) each case runs once.

The animation (``--cases anim``, or ``anim/METHOD`` for one case, e.g. ``anim/sparse-f32@s/2``):
the ``slab`` layout moving over 64 frames (:func:`frame`), each frame ``BlobField.update`` and a
mesh, ``sparse`` or ``tessellator``, f64 or ``-f32``, normals off or ``+normals``, at cells of
s/4, s/2 and s (``@s/4``, ``@s/2``, ``@s``), beside splashsurf f32 per frame at the same cells;
10⁵ particles (``--sizes`` sets them too; 2·10⁴ with ``--quick``), one process per case (the
frames are the repetitions).

Real frames (``--cases dam-break-1e5``, ``dam-break-5e5``, or ``SCENE/METHOD``): frames of
SPlisHSPlasH's dam break made by :mod:`benchmarks.sph_frames` (in its cache, ``--frames DIR``;
missing frames make the cases skip; a run without ``--cases`` runs the scenes whose frames exist), meshed by splashsurf plain and smoothed and by our colour field
(isotropic, and anisotropic once the core has it), with the smoothness metrics of
:mod:`benchmarks.smoothness`; see :mod:`benchmarks.frame_cases`. For these the "particles" slot of
a case (and of ``one``) is the frame's simulated time in milliseconds.

    python -m benchmarks.bench_particles [--quick] [--results DIR] [--sizes N,...] [--cases NAME,...]
    python -m benchmarks.bench_particles --cases dam-break-1e5 [--frames DIR]
    python -m benchmarks.bench_particles one LAYOUT METHOD PARTICLES   # one JSON line
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from functools import lru_cache

from benchmarks import frame_cases
from benchmarks.bench_scale import median, vmhwm_mib
from benchmarks.timing import (RunRecord, fmt_ratio, fmt_s, load_raw, md_table, results_dir, run_case_process,
                               run_markdown, save_raw, section_parser)

#: Particle spacing.
S = 0.01
LAYOUTS = ("slab", "droplets")
#: Particles per case (full, quick).
SIZES = {False: (100_000, 1_000_000, 4_000_000), True: (20_000,)}
OURS = ("colour", "colour+normals", "triquet", "triquet+normals",
        "colour-f32", "colour-f32+normals", "triquet-f32", "triquet-f32+normals")
PEERS = ("splashsurf-f32", "splashsurf-f64")
#: Repetitions per case, each in its own process; the median is reported.
RUNS = {False: 3, True: 1}
#: Particles above which a case runs once (10⁷ particles take minutes and gigabytes).
ONE_RUN_ABOVE = 4_500_000
#: The colour field's threshold (splashsurf's default).
ISO = 0.6
#: The results' name: NAME.json and NAME.md in the results directory.
NAME = "particles"
#: The animation's cases (``--cases anim`` or ``anim/METHOD``): the ``slab`` layout moving over
#: :data:`FRAMES` frames, each frame meshed again (see :func:`animate`).
ANIM = "anim"
#: Particles of the animation (full, quick) when ``--sizes`` does not say.
ANIM_SIZES = {False: (100_000,), True: (20_000,)}
#: Frames timed per animation case, after one untimed frame.
FRAMES = 64
#: Cell sizes of the animation, as fractions of the spacing s.
CELLS = {"s/4": 0.25, "s/2": 0.5, "s": 1.0}
ANIM_PEERS = tuple(f"splashsurf-f32@{c}" for c in CELLS)
ANIM_OURS = tuple(f"{engine}{precision}{normals}@{c}" for c in CELLS for engine in ("sparse", "tessellator")
                  for precision in ("", "-f32") for normals in ("", "+normals"))
ANIM_METHODS = ANIM_PEERS + ANIM_OURS
#: The real-frame layouts (scenes of :mod:`benchmarks.sph_frames`) and their methods.
SCENES = frame_cases.SCENES
SCENE_METHODS = frame_cases.METHODS


def lattice_ball(radius: float, center, rng):
    """Jittered lattice points of spacing S inside a ball."""
    import numpy as np

    k = int(np.ceil(radius / S))
    i = np.arange(-k, k + 1) * S
    g = np.stack(np.meshgrid(i, i, i, indexing="ij"), axis=-1).reshape(-1, 3)
    g = g[np.linalg.norm(g, axis=1) <= radius]
    return g + np.asarray(center) + rng.uniform(-0.1 * S, 0.1 * S, g.shape)


def lattice_box(lo, counts, rng):
    """Jittered lattice points of spacing S, ``counts`` per axis from ``lo``."""
    import numpy as np

    axes = [lo[a] + np.arange(counts[a]) * S for a in range(3)]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return g + rng.uniform(-0.1 * S, 0.1 * S, g.shape)


def slab_and_sphere(n: int):
    """The ``slab`` layout of about ``n`` particles in its two parts: (slab (P, 3), sphere
    (Q, 3), the slab's side L). A slab L × L × L/4 and a sphere of radius L/5 two radii above
    it: volume 0.2835 L³."""
    import numpy as np

    rng = np.random.default_rng(7)
    side = (n * S**3 / (0.25 + 4 / 3 * np.pi / 125)) ** (1 / 3)
    c = int(round(side / S))
    slab = lattice_box((0.0, 0.0, 0.0), (c, c, max(1, c // 4)), rng)
    ball = lattice_ball(side / 5, (side / 2, side / 2, side / 4 + 2 * side / 5 + 4 * S), rng)
    return slab, ball, side


def particles(layout: str, n: int):
    """About ``n`` particles of ``layout`` (deterministic), float64 (P, 3)."""
    import numpy as np

    if layout == "slab":
        return np.vstack(slab_and_sphere(n)[:2])
    rng = np.random.default_rng(7)
    # A pool of a quarter of the particles, 6 layers deep, and droplets of radius 2–6 s above it.
    c = int(round(np.sqrt(n / 4 / 6)))
    side = c * S
    parts = [lattice_box((0.0, 0.0, 0.0), (c, c, 6), rng)]
    count = len(parts[0])
    while count < n:
        r = rng.uniform(2, 6) * S
        centre = (rng.uniform(0, side), rng.uniform(0, side), rng.uniform(6 * S + 2 * r, 6 * S + side / 2))
        parts.append(lattice_ball(r, centre, rng))
        count += len(parts[-1])
    return np.vstack(parts)


@lru_cache(maxsize=None)
def triquet_threshold() -> float:
    """T for ``BlobField(P, 2s, 1.0, T)``: the Triquet potential where the colour field (cubic
    spline, support 2s) crosses 0.6 on the line out of the middle of a face of a lattice block."""
    import numpy as np

    import implicitmesh as im

    g = np.stack(np.meshgrid(*[np.arange(16) * S] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    colour = im.BlobField.from_particles(g, S / 2, iso_surface_threshold=ISO)
    triquet = im.BlobField(g, 2 * S, 1.0, 0.5)
    mid = 7.5 * S
    lo, hi = 15 * S, 17 * S  # the last layer, and two spacings out
    for _ in range(60):
        x = 0.5 * (lo + hi)
        lo, hi = (x, hi) if colour.potential(np.array([[x, mid, mid]]))[0] > ISO else (lo, x)
    return float(triquet.potential(np.array([[0.5 * (lo + hi), mid, mid]]))[0])


def lattice(p):
    """Bounds and cells per axis with cells of exactly s/4 around the particles (a margin of the
    support 2s and two cells)."""
    import numpy as np

    h = S / 4
    lo = p.min(axis=0) - 2 * S - 2 * h
    cells = np.ceil((p.max(axis=0) + 2 * S + 2 * h - lo) / h).astype(int)
    return np.stack([lo, lo + cells * h]), [int(c) for c in cells]


def reconstruct(method: str, p) -> tuple[object, object, dict]:
    """(vertices, faces, extra facts) of one method."""
    import numpy as np

    out: dict = {}
    if method.startswith("splashsurf"):
        import pysplashsurf

        q = np.ascontiguousarray(p, dtype=np.float32 if method.endswith("f32") else np.float64)
        t, c = time.perf_counter(), cpu_seconds()
        r = pysplashsurf.reconstruct_surface(q, particle_radius=S / 2, smoothing_length=2.0, cube_size=0.5,
                                             iso_surface_threshold=ISO)
        out["total_s"] = time.perf_counter() - t
        out["cpu_s"] = cpu_seconds() - c
        m = r.mesh if hasattr(r, "mesh") else r
        v, f = (m.vertices, m.triangles) if hasattr(m, "vertices") else m
        return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64), out
    import implicitmesh as im

    normals = method.endswith("+normals")
    precision = "single" if "-f32" in method else "double"
    bounds, cells = lattice(p)
    if not method.startswith("colour"):
        out["threshold"] = triquet_threshold()
    t, c = time.perf_counter(), cpu_seconds()
    if method.startswith("colour"):
        field = im.BlobField.from_particles(p, S / 2, iso_surface_threshold=ISO, precision=precision)
    else:
        field = im.BlobField(p, 2 * S, 1.0, out["threshold"], precision=precision)
    out["field_s"] = time.perf_counter() - t
    mesh = im.polygonize(field, bounds=bounds, resolution=cells, method="sparse", normals=normals)
    out["total_s"] = time.perf_counter() - t
    out["polygonize_s"] = out["total_s"] - out["field_s"]
    out["evaluations"] = int(mesh.stats["evaluations"])
    out["cpu_s"] = cpu_seconds() - c
    return mesh.vertices, mesh.faces, out


def cpu_seconds() -> float:
    """User and system CPU seconds of this process so far (all threads)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def check_case(layout: str, method: str) -> None:
    """Refuses a layout or method this benchmark does not know (ValueError naming the choices)."""
    if layout in SCENES:
        if method not in SCENE_METHODS:
            raise ValueError(f"unknown method {method!r} of a real frame; choose from {', '.join(SCENE_METHODS)}")
        return
    if layout == ANIM:
        if method not in ANIM_METHODS:
            raise ValueError(f"unknown animation method {method!r}; choose from {', '.join(ANIM_METHODS)}")
        return
    if layout not in LAYOUTS:
        raise ValueError(f"unknown layout {layout!r}; choose from {', '.join(LAYOUTS + (ANIM,) + SCENES)}")
    if method not in PEERS + OURS:
        raise ValueError(f"unknown method {method!r}; choose from {', '.join(PEERS + OURS)}")


def one(layout: str, method: str, n: int) -> dict:
    import numpy as np

    check_case(layout, method)
    if layout == ANIM:
        return animate(method, n, FRAMES)
    if layout in SCENES:
        return frame_cases.one(layout, method, n, vmhwm_mib)

    p = particles(layout, n)
    if method.startswith("triquet"):
        triquet_threshold()  # outside the timed part
    v, f, out = reconstruct(method, p)
    out["peak_mib"] = vmhwm_mib()
    a, b, c = (v[f[:, k]] for k in range(3))
    out.update(layout=layout, method=method, n=int(len(p)), triangles=int(len(f)),
               area=float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()),
               volume=float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0))
    return out


def frame(slab, ball, side: float, k: int, frames: int):
    """Frame ``k`` of ``frames`` of the animation, float64 (P, 3): the sphere fallen by
    (k / frames)² of 9/10 of its gap above the slab, and every particle moved by a smooth
    displacement of amplitude s/10 (a wave of wavelength 16 s per axis, one period over the
    animation), as a fluid's frames move."""
    import numpy as np

    t = k / frames
    fall = 0.9 * (side / 5 + 4 * S) * t * t
    p = np.vstack([slab, ball - np.array([0.0, 0.0, fall])])
    p += 0.1 * S * np.sin(2 * np.pi * (p[:, [1, 2, 0]] / (16 * S) + t))
    return p


def animate(method: str, n: int, frames: int) -> dict:
    """One animation case: the ``slab`` layout of about ``n`` particles over ``frames`` timed
    frames (after an untimed first one that makes the field), each frame ``BlobField.update``
    and a mesh (``polygonize(method="sparse")`` or one ``Tessellator``'s ``polygonize``) over
    one lattice that holds every frame, cells of the size after ``@``; splashsurf
    reconstructs each frame from float32 particles with cells of the same size. Seconds per
    frame (particles to mesh, the frame's positions made outside the timed span), CPU seconds
    over the timed frames, triangles per frame."""
    import numpy as np

    engine, cells_name = method.split("@")
    h = S * CELLS[cells_name]
    slab, ball, side = slab_and_sphere(n)
    p = np.vstack([slab, ball])
    margin = 0.1 * S + 2 * S + 2 * h
    lo = p.min(axis=0) - margin
    cells = np.ceil((p.max(axis=0) + margin - lo) / h).astype(int)
    bounds = np.stack([lo, lo + cells * h])
    resolution = [int(c) for c in cells]
    normals = engine.endswith("+normals")
    precision = "single" if "-f32" in engine else "double"
    threshold = None if engine.startswith("splashsurf") else triquet_threshold()
    tess, field = None, None
    if engine.startswith("tessellator"):
        import implicitmesh as im

        tess = im.Tessellator()

    def mesh_of(q):
        nonlocal field
        if engine.startswith("splashsurf"):
            import pysplashsurf

            r = pysplashsurf.reconstruct_surface(q.astype(np.float32), particle_radius=S / 2,
                                                 smoothing_length=2.0, cube_size=2 * CELLS[cells_name],
                                                 iso_surface_threshold=ISO)
            m = r.mesh if hasattr(r, "mesh") else r
            return len(m.triangles if hasattr(m, "triangles") else m[1])
        import implicitmesh as im

        if field is None:
            field = im.BlobField(q, 2 * S, 1.0, threshold, precision=precision)
        else:
            field.update(q)
        if tess is not None:
            return len(tess.polygonize(field, bounds=bounds, resolution=resolution, normals=normals).faces)
        return len(im.polygonize(field, bounds=bounds, resolution=resolution, method="sparse",
                                 normals=normals).faces)

    mesh_of(frame(slab, ball, side, 0, frames))
    times, triangles, cpu = [], [], 0.0
    for k in range(1, frames + 1):
        q = frame(slab, ball, side, k, frames)
        t, c = time.perf_counter(), cpu_seconds()
        triangles.append(mesh_of(q))
        times.append(time.perf_counter() - t)
        cpu += cpu_seconds() - c
    return {"layout": ANIM, "method": method, "n": int(len(p)), "frames": frames, "frame_s": times,
            "cells": resolution, "cpu_s": cpu, "wall_s": float(sum(times)), "triangles": triangles,
            "peak_mib": vmhwm_mib(), **({} if threshold is None else {"threshold": threshold})}


def run_one(layout: str, method: str, n: int) -> dict:
    """:func:`one` in a fresh process."""
    return run_case_process("benchmarks.bench_particles", [layout, method, str(n)],
                            {"layout": layout, "method": method, "n": n})


def log(msg: str) -> None:
    print(f"[bench_particles] {msg}", file=sys.stderr, flush=True)


def selected(a: argparse.Namespace) -> list[tuple[str, str, int]]:
    """The (layout, method, particles) cases ``a`` asks for, in the order they run."""
    sizes = a.sizes or SIZES[a.quick]
    names = a.cases or []
    unknown = [c for c in names if c not in LAYOUTS + PEERS + OURS + (ANIM,) + SCENES
               and not (c.count("/") == 1 and c.split("/")[0] in LAYOUTS and c.split("/")[1] in PEERS + OURS)
               and not (c.startswith(ANIM + "/") and c[len(ANIM) + 1:] in ANIM_METHODS)
               and not (c.count("/") == 1 and c.split("/")[0] in SCENES and c.split("/")[1] in SCENE_METHODS)]
    if unknown:
        raise ValueError(f"unknown case {unknown[0]!r}: give layouts ({', '.join(LAYOUTS + (ANIM,))}), methods "
                         f"({', '.join(PEERS + OURS)}), LAYOUT/METHOD, {ANIM}/METHOD ({', '.join(ANIM_METHODS)}), "
                         f"scenes ({', '.join(SCENES)}) or SCENE/METHOD ({', '.join(SCENE_METHODS)})")
    wanted = lambda layout, method: not names or bool({layout, method, f"{layout}/{method}"} & set(names))
    anim = [(ANIM, method, n) for n in a.sizes or ANIM_SIZES[a.quick] for method in ANIM_METHODS
            if not names or ANIM in names or f"{ANIM}/{method}" in names]
    scenes = [(scene, method, ms) for scene in SCENES for ms in frame_cases.FRAMES[scene] for method in SCENE_METHODS
              if scene in names or f"{scene}/{method}" in names
              or (not names and frame_cases.sph_frames.scene_info(scene) is not None)]
    return [(layout, method, n) for layout in LAYOUTS for n in sizes for method in PEERS + OURS
            if wanted(layout, method)] + anim + scenes


def case_order(case: dict) -> tuple:
    """Sort key of a result: layout, particles asked for, method, in the order they run."""
    methods = SCENE_METHODS if case["layout"] in SCENES else PEERS + OURS + ANIM_METHODS
    return (LAYOUTS + (ANIM,) + SCENES).index(case["layout"]), case["n"], methods.index(case["method"])


def measure(a: argparse.Namespace, save) -> dict:
    """Runs the cases ``a`` selects; after each, calls ``save`` with the results so far. With
    ``--sizes`` or ``--cases``, the cases of ``a.previous`` that this run does not repeat are
    kept."""
    run = RunRecord("benchmarks.bench_particles", a.quick)
    todo = selected(a)
    kept = [c for c in (a.previous or {}).get("cases", [])
            if (c["layout"], c["method"], c["n"]) not in set(todo)]
    earlier = [r for r in (a.previous or {}).get("earlier_runs", []) + [(a.previous or {}).get("run")] if r]
    cases: list = []

    def raw() -> dict:
        return {"spacing": S, "iso_surface_threshold": ISO, "cases": sorted(kept + cases, key=case_order),
                "run": run.finish(("numpy", "pysplashsurf", "implicitmesh")),
                "earlier_runs": earlier if kept else []}

    for layout, method, n in todo:
        runs = 1 if n > ONE_RUN_ABOVE or layout == ANIM else RUNS[a.quick]
        log(f"{layout}, {method}, " + (f"frame {n / 1000} s" if layout in SCENES else f"{n:,} particles")
            + f", {runs} run(s)")
        cases.append({"layout": layout, "method": method, "n": n,
                      "runs": [run_one(layout, method, n) for _ in range(runs)]})
        save(raw())
    return raw()


def render(raw: dict) -> str:
    run = raw["run"]
    rows = []
    by = {(c["layout"], c["method"], c["n"]): c["runs"] for c in raw["cases"]}
    for c in raw["cases"]:
        if c["layout"] == ANIM or c["layout"] in SCENES:
            continue
        runs = c["runs"]
        head = [c["layout"], f"{runs[0].get('n', c['n']):,}", c["method"]]
        if "error" in runs[0]:
            rows.append(head + [f"failed: {runs[0]['error']}"] + [""] * 7)
            continue
        total = median(runs, "total_s")
        peer = by.get((c["layout"], "splashsurf-f32", c["n"]))
        ratio = fmt_ratio(median(peer, "total_s"), total) if peer and "error" not in peer[0] else "—"
        r0 = runs[0]
        cpu = fmt_s(median(runs, "cpu_s")) if "cpu_s" in r0 else "—"
        rows.append(head + [fmt_s(total), cpu, ratio, f"{median(runs, 'peak_mib'):,.0f}", f"{r0['triangles']:,}",
                            f"{r0['area']:.4g}", f"{r0['volume']:.4g}"])
    t = next((r["threshold"] for c in raw["cases"] for r in c["runs"] if "threshold" in r), None)
    return "\n".join([
        "## Particles to surfaces: blob fields against splashsurf" + (" (QUICK)" if run["quick"] else ""),
        "",
        f"Run {run['date']} with `{run['command']}`. Particles on a jittered lattice of spacing s = {raw['spacing']} "
        "(±0.1 s per axis): `slab`, a slab L × L × L/4 with a sphere of radius L/5 above it; `droplets`, a pool "
        "six layers deep under droplets of radius 2–6 s. splashsurf: `pysplashsurf.reconstruct_surface(P, "
        "particle_radius=s/2, smoothing_length=2.0, cube_size=0.5, iso_surface_threshold=0.6)` with P as float32 "
        "or float64 (support 2s, cells s/4). Ours, `polygonize(method=\"sparse\")` over cells of s/4, normals off "
        "unless `+normals`, `-f32` with `precision=\"single\"`: `colour` is `BlobField.from_particles(P, s/2)` (splashsurf's colour field, cubic "
        "spline), `triquet` is `BlobField(P, 2s, 1.0, T)` with T = "
        f"{'—' if t is None else f'{t:.4f}'} (the Triquet potential where the colour field crosses 0.6 outside a "
        "face of a lattice block). Each case in a fresh process (peak resident size VmHWM its own, the particles "
        "included); seconds of wall-clock time from particles to mesh (CPU s: user and system seconds of all "
        "threads over the same span), medians over the runs. splashsurf f32 / "
        "ours: above 1, ours is faster.",
        "",
        run_markdown(run),
        *[f"- cases kept from the run of {r['date']} (`{r['command']}`)" for r in raw.get("earlier_runs", [])],
        "",
        md_table(["layout", "particles", "method", "seconds", "CPU s", "splashsurf f32 / ours", "peak MiB",
                  "triangles", "area", "volume"], rows, "llrrrrrrrr"),
        "",
        *render_animation(raw),
        *frame_cases.render(raw, fmt_ratio, fmt_s, median, md_table),
    ])


def render_animation(raw: dict) -> list[str]:
    """The animation's paragraph and table (no lines when the results hold no animation case)."""
    import numpy as np

    cases = [c for c in raw["cases"] if c["layout"] == ANIM]
    if not cases:
        return []
    by = {(c["method"], c["n"]): c["runs"][0] for c in cases}
    rows = []
    for c in cases:
        r = c["runs"][0]
        engine, cells = c["method"].split("@")
        head = [f"{r.get('n', c['n']):,}", cells, engine]
        if "error" in r:
            rows.append(head + [f"failed: {r['error']}"] + [""] * 7)
            continue
        t = np.asarray(r["frame_s"])
        peer = by.get((f"splashsurf-f32@{cells}", c["n"]))
        ratio = fmt_ratio(float(np.median(peer["frame_s"])), float(np.median(t))) if peer and "error" not in peer else "—"
        rows.append(head + [f"{1 / np.median(t):.1f}", f"{1e3 * np.median(t):.1f}", f"{1e3 * np.percentile(t, 90):.1f}",
                            f"{1e3 * r['cpu_s'] / len(t):.1f}", f"{r['cpu_s'] / r['wall_s']:.2f}", ratio, f"{np.median(r['triangles']):,.0f}",
                            f"{r['peak_mib']:,.0f}"])
    frames = cases[0]["runs"][0].get("frames", "—")
    return [
        "### Animation: a mesh per frame",
        "",
        f"The `slab` layout in motion over {frames} timed frames (after an untimed first frame that makes the field): "
        "frame k of K has the sphere fallen by (k/K)² of 9/10 of its gap above the slab and every particle moved by "
        "a smooth displacement of amplitude s/10 (a wave of wavelength 16 s per axis, one period over the "
        "animation). Each frame, ours: `field.update(P)` on `BlobField(P, 2s, 1.0, T)` (T as above), then "
        "`polygonize(field, method=\"sparse\")` (`sparse`) or one `Tessellator`'s `polygonize` (`tessellator`), "
        "over one lattice holding every frame with cells of s/4, s/2 or s; splashsurf f32: "
        "`reconstruct_surface` of the frame's float32 particles with `cube_size` 0.5, 1 or 2 (the same cells). "
        "Frames/s is 1 / the median seconds per frame (particles to mesh; the frame's positions are made outside "
        "the timed span); p90 the 90th percentile; CPU ms per frame and CPU / wall over the timed frames (user and "
        "system time of all threads; 2 cores: at most 2); splashsurf f32 / ours from the medians; each case in one "
        "fresh process.",
        "",
        md_table(["particles", "cells", "method", "frames/s", "ms per frame", "p90 ms", "CPU ms per frame", "CPU / wall",
                  "splashsurf f32 / ours", "triangles", "peak MiB"], rows, "llrrrrrrrrr"),
        "",
    ]


def count_list(text: str) -> list[int]:
    """Particle counts from ``N,N,...`` (``1e6`` and ``1_000_000`` both read)."""
    try:
        counts = [int(float(t)) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected particle counts like 1000000,4e6, got {text!r}") from None
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"expected positive particle counts, got {text!r}")
    return counts


def main() -> int:
    if len(sys.argv) == 5 and sys.argv[1] == "one":
        try:
            check_case(sys.argv[2], sys.argv[3])
        except ValueError as e:
            print(f"bench_particles: {e}", file=sys.stderr)
            return 2
        print(json.dumps(one(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        return 0
    p = section_parser(__doc__.split("\n")[0], "2·10⁴ particles, one run per case")
    p.add_argument("--sizes", type=count_list, metavar="N,...",
                   help="particle counts to run (default 10⁵, 10⁶ and 4·10⁶; with --quick 2·10⁴)")
    p.add_argument("--cases", type=lambda t: [c.strip() for c in t.split(",") if c.strip()], metavar="NAME,...",
                   help=f"only these layouts ({', '.join(LAYOUTS)}), methods ({', '.join(PEERS + OURS)}), "
                        f"LAYOUT/METHOD pairs, {ANIM} (the animation) or {ANIM}/METHOD, real-frame scenes "
                        f"({', '.join(SCENES)}) or SCENE/METHOD ({', '.join(SCENE_METHODS)})")
    p.add_argument("--frames", default=None, metavar="DIR",
                   help="the real frames' cache (default $IMPLICITMESH_SPH_FRAMES or ~/.cache/implicitmesh/sph)")
    a = p.parse_args()
    if a.frames:
        os.environ[frame_cases.sph_frames.ENV_CACHE] = str(frame_cases.sph_frames.cache_dir(a.frames))
    try:
        selected(a)
    except ValueError as e:
        p.error(str(e))
    results = results_dir(a.results, a.quick)
    a.previous = load_raw(results, NAME) if (a.sizes or a.cases) else None

    def save(raw: dict) -> None:
        save_raw(results, NAME, raw)
        (results / f"{NAME}.md").write_text(render(load_raw(results, NAME)))

    save(measure(a, save))
    sys.stdout.write((results / f"{NAME}.md").read_text())
    log(f"wrote {results / NAME}.json and .md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
