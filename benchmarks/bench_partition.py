"""Partition-of-unity fits at scan scale: fit time, peak memory, polygonization and accuracy.

Each measurement runs in a fresh process, so that the peak resident size (VmHWM in
/proc/self/status) is that run's.

    python -m benchmarks.bench_partition [--quick] [--results DIR]  # the section of BENCHMARKS.md
    python -m benchmarks.bench_partition scale 10000 100000         # one JSON line per size
    python -m benchmarks.bench_partition crossover 500 1000 2000    # global vs partition fit
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.timing import ROOT, RunRecord, fmt_s, md_table, run_markdown, run_section

MESH = ROOT / "tests" / "data" / "meshes"
MODEL, RESOLUTION = "knot", 256
#: Points of the scale runs and of the global-against-partition runs (full, quick).
SCALE = {False: (10_000, 100_000, 1_000_000), True: (10_000,)}
CROSSOVER = {False: (300, 500, 1000, 2000, 3000), True: (500, 1000)}


def vmhwm_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def one(kind: str, n: int, model: str, resolution: int) -> dict:
    import numpy as np
    import trimesh
    from scipy.spatial import cKDTree

    import implicitmesh as im

    m = trimesh.load(MESH / f"{model}_hires.ply", process=False)
    out: dict = {"kind": kind, "n": n, "model": model}
    if kind == "crossover":
        v, f = np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)
        p, nn = im.shapes.sample_vertices(v, f, n, seed=1)
        fits = {}
        for method in ("global", "partition"):
            t = time.perf_counter()
            fits[method] = im.VariationalSurface.fit(p, nn, method=method, exact=True)
            out[f"{method}_s"] = time.perf_counter() - t
        b = fits["global"].bounds
        cell = float(np.max(b[1] - b[0])) / 128
        a = im.polygonize(fits["global"], bounds=b, resolution=128, normals=False)
        c = im.polygonize(fits["partition"], bounds=b, resolution=128, normals=False)
        d = np.concatenate([cKDTree(c.vertices).query(a.vertices)[0], cKDTree(a.vertices).query(c.vertices)[0]])
        out["vertex_distance_cells"] = {"mean": float(d.mean() / cell), "max": float(d.max() / cell)}
        ref, _ = trimesh.sample.sample_surface(m, 200_000, seed=1)
        diag = float(np.linalg.norm(m.bounds[1] - m.bounds[0]))
        for method, mesh in (("global", a), ("partition", c)):
            dd = cKDTree(mesh.vertices).query(ref)[0]
            out[f"{method}_ref_distance_over_diagonal"] = {"mean": float(dd.mean() / diag), "max": float(dd.max() / diag)}
        return out
    p, face = trimesh.sample.sample_surface(m, n, seed=7)
    normals = np.asarray(m.face_normals)[face]
    t = time.perf_counter()
    s = im.VariationalSurface.fit(p, normals, method="partition", exact=True)
    out["fit_s"] = time.perf_counter() - t
    out["fit_peak_mib"] = vmhwm_mib()
    sizes = s.patches["sizes"]
    out["patches"] = int(len(sizes))
    out["patch_size"] = {"mean": float(sizes.mean()), "median": float(np.median(sizes)), "max": int(sizes.max())}
    out["residual"] = s.residual
    out["max_abs_f_at_points"] = float(np.max(np.abs(s.evaluate(p))))
    t = time.perf_counter()
    mesh = im.polygonize(s, resolution=resolution, method="octree", normals=False)
    out["polygonize_s"] = time.perf_counter() - t
    out["evaluations"] = int(mesh.stats["evaluations"])
    out["triangles"] = int(len(mesh.faces))
    tm = mesh.to_trimesh()
    out["watertight"] = bool(tm.is_watertight)
    out["euler"] = int(mesh.euler_number)
    # Symmetric Chamfer distance (mean of the two mean nearest distances) between 2·10⁵ samples
    # of each surface, in units of the reference's bounding-box diagonal.
    a, _ = trimesh.sample.sample_surface(m, 200_000, seed=1)
    b, _ = trimesh.sample.sample_surface(tm, 200_000, seed=2)
    dab = cKDTree(b).query(a)[0]
    dba = cKDTree(a).query(b)[0]
    diag = float(np.linalg.norm(m.bounds[1] - m.bounds[0]))
    out["chamfer_over_diagonal"] = float(0.5 * (dab.mean() + dba.mean()) / diag)
    out["hausdorff_over_diagonal"] = float(max(dab.max(), dba.max()) / diag)
    out["peak_mib"] = vmhwm_mib()
    return out


def run_one(kind: str, n: int) -> dict:
    """:func:`one` in a fresh process (``python -m benchmarks.bench_partition one ...``)."""
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks.bench_partition", "one", kind, str(n), MODEL, str(RESOLUTION)],
        capture_output=True, text=True, check=True, cwd=ROOT,
    )
    return json.loads(r.stdout)


def log(msg: str) -> None:
    print(f"[bench_partition] {msg}", file=sys.stderr, flush=True)


def measure(a: argparse.Namespace) -> dict:
    run = RunRecord("benchmarks.bench_partition", a.quick)
    scale, crossover = [], []
    for n in SCALE[a.quick]:
        log(f"scale: {n:,} points")
        scale.append(run_one("scale", n))
    for n in CROSSOVER[a.quick]:
        log(f"crossover: {n:,} points")
        crossover.append(run_one("crossover", n))
    return {"model": MODEL, "resolution": RESOLUTION, "scale": scale, "crossover": crossover,
            "run": run.finish(("numpy", "scipy", "trimesh", "implicitmesh"))}


def render(raw: dict) -> str:
    run, model, res = raw["run"], raw["model"], raw["resolution"]
    scale_rows = [[
        f"{r['n']:,}", fmt_s(r["fit_s"]), f"{r['fit_peak_mib']:,.0f}", f"{r['patches']:,}",
        f"{r['patch_size']['mean']:.0f} / {r['patch_size']['max']:,}",
        f"{fmt_s(r['polygonize_s'])} ({r['evaluations']:,})", f"{r['triangles']:,}",
        f"{r['chamfer_over_diagonal']:.2e} / {r['hausdorff_over_diagonal']:.1e}",
        f"{'watertight' if r['watertight'] else 'not watertight'}, Euler characteristic {r['euler']}",
        f"{r['peak_mib']:,.0f}",
    ] for r in raw["scale"]]
    crossover_rows = [[
        f"{r['n']:,}", fmt_s(r["global_s"]), fmt_s(r["partition_s"]),
        f"{r['global_ref_distance_over_diagonal']['mean']:.2e} / {r['global_ref_distance_over_diagonal']['max']:.1e}",
        f"{r['partition_ref_distance_over_diagonal']['mean']:.2e} / "
        f"{r['partition_ref_distance_over_diagonal']['max']:.1e}",
        f"{r['vertex_distance_cells']['mean']:.3f} / {r['vertex_distance_cells']['max']:.2f}",
    ] for r in raw["crossover"]]
    out = [
        "## Partition-of-unity fits at scan scale" + (" (QUICK)" if run["quick"] else ""),
        "",
        f"Run {run['date']} with `{run['command']}`. Points sampled on `{model}_hires` with their face normals "
        "(`trimesh.sample.sample_surface`), fitted with `VariationalSurface.fit(points, normals, "
        f"method=\"partition\")`, polygonized with `method=\"octree\"` at {res}³ over the default bounds; each size "
        "in a fresh process, so that its peak resident size (VmHWM) is its own. Seconds are single runs. "
        "Chamfer distance: the mean of the two mean nearest distances between 2·10⁵ samples of each surface; "
        "Hausdorff: the larger of the two largest; both as fractions of the reference's bounding-box diagonal.",
        "",
        run_markdown(run),
        "",
        "### Scale",
        "",
        md_table(["points", "fit (s)", "peak memory after the fit (MiB)", "patches", "patch size mean / max",
                  "polygonize (s) (evaluations)", "triangles", "Chamfer / Hausdorff (fraction of the diagonal)",
                  "mesh", "peak memory at the end (MiB)"], scale_rows),
        "",
        "### Global against partition fit",
        "",
        "`method=\"global\"` and `method=\"partition\"` on the same points (`shapes.sample_vertices` of the "
        "model), both polygonized at 128³ over the global fit's bounds (without normals).",
        "",
        md_table(["points", "global fit (s)", "partition fit (s)",
                  "global: distance to the reference, mean / max (fraction of the diagonal)",
                  "partition: distance to the reference, mean / max", "vertices global ↔ partition, mean / max (cells)"],
                 crossover_rows),
        "", exact=True
    )
    return "\n".join(out)


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] in ("one", "scale", "crossover"):
        return measure_sizes(sys.argv[1], sys.argv[2:])
    return run_section("partition", measure, render, __doc__.split("\n")[0], "10⁴ points; 500 and 1,000 for the crossover")


def measure_sizes(kind: str, sizes: list[str]) -> int:
    """Prints one JSON line per size: ``one`` measures in this process, ``scale`` and
    ``crossover`` run each size in a fresh one."""
    if kind == "one":
        k, n, model, res = sizes
        print(json.dumps(one(k, int(n), model, int(res))))
        return 0
    for n in sizes:
        print(json.dumps(run_one(kind, int(n))), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
