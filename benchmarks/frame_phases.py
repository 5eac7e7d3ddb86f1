"""Where our time goes on a real frame: the colour field's construction against the sparse
polygonizer's phases (its ``stats["seconds"]``), over cells of r/2 and r/4, single and double
precision, normals off and on, beside splashsurf f32 at the same cells, all in this one process
(machine drift cancels in the ratios; not a peak-memory measurement).

    python -m benchmarks.frame_phases [--scene dam-break-1e5] [--time 1.0] [--runs 3] [--frames DIR]

Prints one JSON line per configuration (medians over the runs after a warm-up) and a table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

from benchmarks import frame_cases, sph_frames


def ours(p, r: float, cell: float, precision: str, normals: bool) -> dict:
    import implicitmesh as im

    h = cell * r
    lo = p.min(axis=0) - 4 * r - 2 * h
    import numpy as np

    cells = np.ceil((p.max(axis=0) + 4 * r + 2 * h - lo) / h).astype(int)
    bounds = np.stack([lo, lo + cells * h])
    t, c = time.perf_counter(), frame_cases.cpu_seconds()
    field = im.BlobField.from_particles(p, r, iso_surface_threshold=frame_cases.ISO, precision=precision)
    field_s, field_cpu = time.perf_counter() - t, frame_cases.cpu_seconds() - c
    mesh = im.polygonize(field, bounds=bounds, resolution=[int(n) for n in cells], method="sparse", normals=normals)
    total, cpu = time.perf_counter() - t, frame_cases.cpu_seconds() - c
    s = mesh.stats
    return {"total_s": total, "cpu_s": cpu, "field_cpu_s": field_cpu, "field_s": field_s, "polygonize_s": total - field_s,
            **{f"phase_{k}_s": v for k, v in s["seconds"].items()},
            "evaluations": s["evaluations"], "normal_evaluations": s["normal_evaluations"],
            "lattice_points": s["lattice_points"], "cells_visited": s["cells_visited"],
            "cells_crossed": s["cells_crossed"], "triangles": len(mesh.faces)}


def splashsurf(p, r: float, cell: float) -> dict:
    import numpy as np
    import pysplashsurf

    q = np.ascontiguousarray(p, dtype=np.float32)
    t, c = time.perf_counter(), frame_cases.cpu_seconds()
    out = pysplashsurf.reconstruct_surface(q, particle_radius=r, smoothing_length=2.0, cube_size=cell,
                                           iso_surface_threshold=frame_cases.ISO)
    total = time.perf_counter() - t
    return {"total_s": total, "cpu_s": frame_cases.cpu_seconds() - c, "triangles": len(frame_cases.mesh_arrays(out)[1])}


def medians(fn, runs: int) -> dict:
    fn()
    rows = [fn() for _ in range(runs)]
    return {k: statistics.median(r[k] for r in rows) for k in rows[0]}


def main(argv=None) -> int:
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("--scene", default="dam-break-1e5", choices=sph_frames.SCENES)
    a.add_argument("--time", type=float, default=1.0)
    a.add_argument("--runs", type=int, default=3)
    a.add_argument("--frames", default=None, metavar="DIR")
    args = a.parse_args(argv)
    if args.frames:
        os.environ[sph_frames.ENV_CACHE] = str(sph_frames.cache_dir(args.frames))
    p, info = frame_cases.frame_particles(args.scene, int(round(1000 * args.time)))
    r = float(info["particle_radius"])
    rows = []
    for cell in (0.5, 0.25):
        peer = medians(lambda: splashsurf(p, r, cell), args.runs)
        rows.append({"config": f"splashsurf-f32 cells r*{cell}", **peer})
        print(json.dumps(rows[-1]), flush=True)
        for precision in ("single", "double"):
            for normals in (False, True):
                m = medians(lambda: ours(p, r, cell, precision, normals), args.runs)
                m["ratio"] = peer["total_s"] / m["total_s"]
                m["cpu_ratio"] = peer["cpu_s"] / m["cpu_s"]
                rows.append({"config": f"colour {precision}{' +normals' if normals else ''} cells r*{cell}", **m})
                print(json.dumps(rows[-1]), flush=True)
    keys = sorted({k for r_ in rows for k in r_ if k.startswith("phase_")})
    print(f"\n{args.scene} t={args.time} s, {len(p):,} particles, r={r}, medians of {args.runs}")
    print(" | ".join(["config", "total s", "CPU s", "field CPU s", "field s", "polygonize s", *keys, "splashsurf/ours (CPU)", "evaluations",
                      "triangles"]))
    for r_ in rows:
        print(" | ".join([r_["config"], f"{r_['total_s']:.3f}", f"{r_['cpu_s']:.3f}",
                          f"{r_.get('field_cpu_s', float('nan')):.3f}", f"{r_.get('field_s', float('nan')):.3f}",
                          f"{r_.get('polygonize_s', float('nan')):.3f}",
                          *[f"{r_.get(k, float('nan')):.3f}" for k in keys],
                          f"{r_.get('ratio', float('nan')):.2f} (CPU {r_.get('cpu_ratio', float('nan')):.2f})",
                          f"{r_.get('evaluations', 0):,}", f"{r_['triangles']:,}"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
