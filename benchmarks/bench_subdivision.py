"""Subdivision polygonizer (Jin et al.) on knot, star and spot at 800 vertices, levels 1–3, and
level 2 against our own marching cubes (dense, octree, tracking) at the same triangle count, in one
run (a script, not a test).

    python -m benchmarks.bench_subdivision [--quick] [--results DIR]

Every method works on the same surface: `VariationalSurface.from_mesh(d=0.015)` of the mesh
(1,600 constraints, r³). Marching cubes runs over the surface's default bounds at the resolution
whose triangle count is closest to subdivision level 2 (chosen once, before timing).
"""

from __future__ import annotations

import argparse
import statistics
import sys

from benchmarks.timing import (
    ROOT,
    RunRecord,
    Timing,
    fmt_ratio,
    fmt_s,
    md_table,
    run_markdown,
    run_section,
    timeit_median,
)

MESHES = ("knot", "star", "spot")
METHODS = ("dense", "octree", "tracking")
#: Jin et al. Table 1 (Pentium IV 2.0 GHz; their own models of these names): level 1 + level 2
#: seconds of subdivision, and Bloomenthal's continuation polygonizer at about the same count.
PAPER = {"knot": "0.70 + 2.94 s; 13.84 s", "star": "0.34 + 1.66 s; 8.56 s", "spot": "bunny: 3.02 + 13.25 s; 66.75 s"}


def log(msg: str) -> None:
    print(f"[bench_subdivision] {msg}", file=sys.stderr, flush=True)


def closest_resolution(im, surface, triangles: int) -> int:
    """The resolution (cells along the longest side of the default bounds) whose dense mesh has
    the triangle count closest to ``triangles``."""
    probe = im.polygonize(surface, resolution=48, method="octree")
    guess = int(round(48 * (triangles / len(probe.faces)) ** 0.5))
    counts = {r: len(im.polygonize(surface, resolution=r, method="octree").faces) for r in range(guess - 3, guess + 4)}
    return min(counts, key=lambda r: abs(counts[r] - triangles))


def measure(a: argparse.Namespace) -> dict:
    import numpy as np
    import trimesh

    import implicitmesh as im

    quick = a.quick
    runs = 2 if quick else 7
    top = 2 if quick else 3
    names = MESHES[:1] if quick else MESHES
    meshes_dir = ROOT / "tests" / "data" / "meshes"
    run = RunRecord("benchmarks.bench_subdivision", quick)
    meshes = []
    for name in names:
        m = trimesh.load(meshes_dir / f"{name}_800.ply", process=False)
        v, f = np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)
        t_fit = timeit_median(lambda: im.VariationalSurface.from_mesh(v, f, d=0.015), runs, 1)
        s = t_fit.result
        log(f"{name}: {len(s)} constraints, levels 1–{top}, {runs} runs")
        # Seconds per level: each run subdivides to the top level; the core times every level.
        per_level: list[list[float]] = [[] for _ in range(top + 1)]
        t_all = timeit_median(lambda: im.subdivide(v, f, levels=top, field=s), runs, 1)
        levels = t_all.result
        for _ in range(runs):
            for k, lv in enumerate(im.subdivide(v, f, levels=top, field=s)):
                per_level[k].append(lv.stats["seconds"])
        # Level 2 in one call (fit excluded, as in Jin's Table 1) against marching cubes.
        t_sub2 = timeit_median(lambda: im.subdivide(v, f, levels=2, field=s), runs, 1)
        n2 = len(t_sub2.result[2].faces)
        res = closest_resolution(im, s, n2)
        log(f"{name}: level 2 has {n2:,} triangles; marching cubes at {res} cells")
        mc = {}
        for method in METHODS:
            mc[method] = timeit_median(lambda: im.polygonize(s, resolution=res, method=method), runs, 1)
        st_t = mc["tracking"].result.stats
        meshes.append({
            "mesh": name,
            "fit": t_fit.to_json(),
            "level_seconds": per_level,
            "levels": [{"triangles": len(lv.faces), **{k: lv.stats[k] for k in LEVEL_STATS}} for lv in levels],
            "subdivision_level_2": t_sub2.to_json(),
            "level_2_triangles": n2,
            "level_2_evaluations": [int(lv.stats["evaluations"]) for lv in t_sub2.result],
            "mc_resolution": res,
            "mc_triangles": len(mc["dense"].result.faces),
            "mc": {k: t.to_json() for k, t in mc.items()},
            "tracking_evaluations": int(st_t["evaluations"]),
            "tracking_normal_evaluations": int(st_t["normal_evaluations"]),
            "quality_subdivision": _angles(t_sub2.result[2].quality()),
            "quality_mc": _angles(mc["dense"].result.quality()),
        })
    return {"runs": runs, "top": top, "meshes": meshes, "run": run.finish(("numpy", "implicitmesh"))}


#: The statistics of a subdivision level kept in the raw results.
LEVEL_STATS = ("projected", "iterations_mean", "iterations_max", "fallbacks", "not_converged", "evaluations",
               "batches", "max_abs_value")


def _angles(quality: dict) -> dict:
    return {k: float(quality[k]) for k in ("min_angle_mean", "min_angle_p5")}


def render(raw: dict) -> str:
    runs, top, run = raw["runs"], raw["top"], raw["run"]
    level_rows, newton_rows, mc_rows, quality_rows, eval_rows = [], [], [], [], []
    for r in raw["meshes"]:
        name, per_level = r["mesh"], r["level_seconds"]
        for k in range(1, top + 1):
            st = r["levels"][k]
            level_rows.append([
                name, k, f"{st['triangles']:,}", f"{st['projected']:,}",
                fmt_s(statistics.median(per_level[k])),
                fmt_s(sum(statistics.median(per_level[j]) for j in range(k + 1))),
            ])
            newton_rows.append([
                name, k, f"{st['iterations_mean']:.3f}", st["iterations_max"], st["fallbacks"], st["not_converged"],
                f"{st['evaluations']:,}", st["batches"], f"{st['max_abs_value']:.1e}",
            ])
        t_sub2 = Timing.from_json(r["subdivision_level_2"])
        mc = {k: Timing.from_json(t) for k, t in r["mc"].items()}
        fastest = min(METHODS, key=lambda k: mc[k].median)
        mc_rows.append([
            name, f"{r['level_2_triangles']:,}", fmt_s(t_sub2.median), r["mc_resolution"], f"{r['mc_triangles']:,}",
            *(fmt_s(mc[k].median) for k in METHODS), fastest,
            fmt_ratio(mc[fastest].median, t_sub2.median), PAPER.get(name, ""),
        ])
        # Exact field work of the same two calls: subdivision's value-and-gradient evaluations of
        # levels 0-2 (control normals, then Newton) against tracking's values and normal gradients.
        sub_ev = r["level_2_evaluations"]
        te, tn = r["tracking_evaluations"], r["tracking_normal_evaluations"]
        eval_rows.append([
            name, " + ".join(f"{e:,}" for e in sub_ev), f"{sum(sub_ev):,}", f"{te:,}", f"{tn:,}", f"{te + tn:,}",
        ])
        qs, qm = r["quality_subdivision"], r["quality_mc"]
        quality_rows.append([
            name, f"{qs['min_angle_mean']:.1f}°", f"{qs['min_angle_p5']:.1f}°",
            f"{qm['min_angle_mean']:.1f}°", f"{qm['min_angle_p5']:.1f}°", fmt_s(Timing.from_json(r["fit"]).median),
        ])
    out = [
        "## Subdivision polygonizer (Jin et al.) against our marching cubes",
        "",
        f"Run {run['date']} with `{run['command']}`. "
        "Each shared 800-vertex mesh (1,600 faces) fitted with `from_mesh(d=0.015)` (1,600 constraints, r³), then "
        f"`subdivide(levels=...)`; wall-clock medians in seconds of {runs} runs after one warm-up. Seconds per level "
        "are the core's own timing of each level (split, batched Newton projection, normals) in calls that run to "
        f"level {top}; the fit is timed apart and excluded, as in Jin et al.'s Table 1. Marching cubes: "
        "`polygonize(surface, resolution=N, method=...)` over the surface's default bounds, N chosen so that the "
        "triangle count is closest to subdivision level 2 (dense, octree and tracking give the same mesh).",
        "",
        run_markdown(run),
        "",
        "### Seconds per level",
        "",
        md_table(["mesh", "level", "triangles", "new vertices", "seconds (this level)", "seconds (levels 0…k)"],
                 level_rows),
        "",
        "### Newton projection (exact counts, machine-independent)",
        "",
        md_table(["mesh", "level", "evaluations per new vertex, mean", "max", "fallbacks", "not converged",
                  "field evaluations", "batched calls", "largest |f| after"], newton_rows),
        "",
        "Evaluations per new vertex count every value-and-gradient evaluation of the Newton loop, the last "
        "(converged) one included; fallbacks are vertices handed to the line search along the gradient.",
        "",
        "### Level 2 against marching cubes at the same triangle count",
        "",
        md_table(["mesh", "subdivision triangles", "subdivision levels 1–2 (s)", "MC cells", "MC triangles",
                  "dense (s)", "octree (s)", "tracking (s)", "fastest MC", "fastest MC / subdivision",
                  "Jin et al. (subdivision; continuation)"], mc_rows),
        "",
        "### Field evaluations of the level-2 comparison (exact counts, machine-independent)",
        "",
        md_table(["mesh", "subdivision levels 0 + 1 + 2 (value and gradient)", "subdivision total",
                  "tracking values", "tracking gradients (normals)", "tracking total"], eval_rows),
        "",
        "Subdivision evaluates the control vertices once (for the normals that shape Newton's start "
        "points), then every new vertex from the Hermite midpoint of its edge, about two Newton "
        "evaluations each.",
        "",
        "### Triangle quality at level 2 (minimum angles) and fit time",
        "",
        md_table(["mesh", "subdivision mean", "subdivision 5th percentile", "MC mean", "MC 5th percentile",
                  "fit (s)"], quality_rows),
        "",
    ]
    return "\n".join(out)


def main() -> int:
    return run_section("subdivision", measure, render, __doc__)


if __name__ == "__main__":
    sys.exit(main())
