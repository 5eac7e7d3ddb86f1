"""Partition-of-unity fits at scan scale: fit time, peak memory, polygonization and accuracy.

Each measurement runs in a fresh process, so that the peak resident size (VmHWM in
/proc/self/status) is that run's.

    python -m benchmarks.bench_partition scale 10000 100000      # points sampled on knot_hires
    python -m benchmarks.bench_partition crossover 500 1000 2000  # global vs partition fit time

It prints one JSON line per size (the tables of ``docs/variational.md``); it has no section in
BENCHMARKS.md.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.timing import ROOT

MESH = ROOT / "tests" / "data" / "meshes"


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
            fits[method] = im.VariationalSurface.fit(p, nn, method=method)
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
    s = im.VariationalSurface.fit(p, normals, method="partition")
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


def main() -> None:
    kind, *sizes = sys.argv[1:]
    if kind == "one":
        k, n, model, res = sizes
        print(json.dumps(one(k, int(n), model, int(res))))
        return
    for n in sizes:
        r = subprocess.run(
            [sys.executable, "-m", "benchmarks.bench_partition", "one", kind, n, "knot", "256"],
            capture_output=True, text=True, check=True, cwd=ROOT,
        )
        print(r.stdout.strip(), flush=True)


if __name__ == "__main__":
    main()
