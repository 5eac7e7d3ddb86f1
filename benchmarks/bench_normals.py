"""Normals of points without them: ours (``implicitmesh.estimate_normals``) against Open3D's
``estimate_normals(KDTreeSearchParamKNN(15))`` + ``orient_normals_consistent_tangent_plane(15)``.

Points: each closed ``_hires`` mesh of ``tests/data/meshes`` scanned by
:func:`implicitmesh.scanner.scan` (σ = 0, 0.05 %, 0.2 % of the diagonal) with the normals dropped,
or sampled uniformly on the mesh (``uniform``). A normal is wrong when it is more than 90° from the
true one (the face normal of the triangle the point lies on; outliers are not counted). Each method
runs each case in a fresh process, so that its peak resident size (VmHWM) is its own; seconds are
medians. End to end (``--end-to-end``): positions → our scan fit (``VariationalSurface.fit(points)``,
octree at 256 cells) against Open3D estimate + orient + screened Poisson (depth 8), topology and
Chamfer distance measured as in ``bench_scans``.

    python -m benchmarks.bench_normals [--sizes 100000 1000000] [--meshes knot ...] [--methods ours open3d]
"""

from __future__ import annotations

import json
import statistics
import sys
import time

from .bench_scans import MESHES, closed_meshes, measures, topology
from .timing import RunRecord, load_raw, md_table, record_section, results_dir, run_case_process, run_markdown, section_parser

#: Sources of points: the scanner's conditions, and uniform samples.
SOURCES = {"σ 0": {"noise": 0.0}, "σ 0.05 %": {"noise": 5e-4}, "σ 0.2 %": {"noise": 2e-3}, "uniform": None}
SEED = 54
#: Timed runs per size.
RUNS = {100_000: 3, 1_000_000: 1, 10_000_000: 1}


def log(msg: str) -> None:
    print(f"[normals] {msg}", file=sys.stderr, flush=True)


def peak_mib() -> float:
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def points_of(model: str, source: str, n: int):
    """Points, their true normals, and the indices that have one (outliers have none)."""
    import numpy as np
    import trimesh

    import implicitmesh as im

    truth = trimesh.load(MESHES / f"{model}_hires.ply", process=False)
    v, f = np.asarray(truth.vertices, float), np.asarray(truth.faces, np.int64)
    fn = np.asarray(truth.face_normals)
    if SOURCES[source] is None:
        p, face = trimesh.sample.sample_surface(truth, n, seed=SEED)
        return np.asarray(p, float), fn[face], truth
    s = im.scanner.scan(v, f, n, seed=SEED, **SOURCES[source])
    return s.points, fn[s.triangle], truth


def ours(points):
    import implicitmesh as im

    return im.estimate_normals(points)


def open3d(points):
    import numpy as np
    import open3d as o3d

    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(points)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(15))
    pcd.orient_normals_consistent_tangent_plane(15)
    return np.asarray(pcd.normals)


def e2e_ours(points):
    import implicitmesh as im

    s = im.VariationalSurface.fit(points)
    m = im.polygonize(s, resolution=256, method="octree")
    return m.vertices, m.faces


def e2e_open3d(points):
    import numpy as np
    import open3d as o3d

    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(points)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(15))
    pcd.orient_normals_consistent_tangent_plane(15)
    m, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=8)
    return np.asarray(m.vertices), np.asarray(m.triangles)


METHODS = {"ours": ours, "open3d": open3d, "e2e_ours": e2e_ours, "e2e_open3d": e2e_open3d}


def one(method: str, model: str, source: str, n: int) -> dict:
    """One method on one case in this process: a warm-up call at 2·10⁴ points, timed runs, the
    fraction wrong (or the mesh's measures end to end) and the process's peak memory."""
    import numpy as np

    fn = METHODS[method]
    points, truth_n, truth = points_of(model, source, n)
    small, *_ = points_of(model, source, 20_000)
    fn(small)
    times = []
    for _ in range(RUNS[n]):
        t0 = time.perf_counter()
        out = fn(points)
        times.append(time.perf_counter() - t0)
    r = {"method": method, "model": model, "source": source, "n": n, "points": len(points),
         "times": times, "seconds": statistics.median(times), "peak_mib": peak_mib()}
    if method.startswith("e2e"):
        genus = topology(truth.vertices, truth.faces)["genera"][0]
        r.update(measures(truth, *out, genus))
    else:
        known = np.all(np.isfinite(truth_n), axis=1)
        dots = np.einsum("ij,ij->i", out[known], truth_n[known])
        r["wrong"] = float(np.mean(dots <= 0))
    return r


def measure(a) -> dict:
    run = RunRecord("benchmarks.bench_normals", a.quick)
    meshes = [m for m in closed_meshes() if not a.meshes or m in a.meshes]
    sources = a.sources or list(SOURCES)
    cases = []
    for n in a.sizes:
        for model in meshes:
            for source in sources:
                for method in a.methods:
                    log(f"{method}: {model}, {source}, {n:,} points")
                    case = {"method": method, "model": model, "source": source, "n": n}
                    c = run_case_process("benchmarks.bench_normals", [method, model, source, str(n)], case)
                    cases.append(c)
                    log("  " + (c["error"] if "error" in c else json.dumps({k: v for k, v in c.items() if k in (
                        "seconds", "wrong", "peak_mib", "bodies", "chamfer", "genera")})))
    raw = {"cases": cases, "run": run.finish(("numpy", "trimesh", "open3d", "implicitmesh"))}
    stored = None if a.quick else load_raw(results_dir(a.results, a.quick), "normals")
    if stored:
        done = {(c["method"], c["model"], c["source"], c["n"]) for c in cases}
        for c in stored["cases"]:
            if (c["method"], c["model"], c["source"], c["n"]) not in done:
                c.setdefault("run", stored["run"])
                raw["cases"].append(c)
    return raw


def _pct(x):
    return f"{100 * x:.3f} %"


def render(raw: dict) -> str:
    run = raw["run"]
    by = {(c["method"], c["model"], c["source"], c["n"]): c for c in raw["cases"]}
    keys = sorted({(c["model"], c["source"], c["n"]) for c in raw["cases"]}, key=lambda k: (k[2], k[0], list(SOURCES).index(k[1])))
    rows = []
    for model, source, n in keys:
        o, p = by.get(("ours", model, source, n)), by.get(("open3d", model, source, n))
        if not o and not p:
            continue
        cell = lambda c, f: "—" if c is None else (f"failed: {c['error']}" if "error" in c else f(c))  # noqa: E731
        ratio = (f"{p['seconds'] / o['seconds']:.1f}×" if o and p and "error" not in o and "error" not in p else "—")
        rows.append([model, source, f"{n:,}", cell(o, lambda c: _pct(c["wrong"])), cell(p, lambda c: _pct(c["wrong"])),
                     cell(o, lambda c: f"{c['seconds']:.2f}"), cell(p, lambda c: f"{c['seconds']:.2f}"), ratio,
                     cell(o, lambda c: f"{c['peak_mib']:.0f}"), cell(p, lambda c: f"{c['peak_mib']:.0f}")])
    parts = [
        "## Normals of points without them: ours against Open3D" + (" (QUICK)" if run["quick"] else ""),
        "",
        f"Run {run['date']} with `{run['command']}`. Points: each closed `_hires` mesh scanned by "
        f"`implicitmesh.scanner.scan(vertices, faces, N, seed={SEED}, noise=σ)` with its normals dropped, or sampled "
        "uniformly (`uniform`). Wrong: more than 90° from the true face normal. Ours: `estimate_normals(points)` "
        "(20 neighbours); Open3D: `estimate_normals(KDTreeSearchParamKNN(15))` + "
        "`orient_normals_consistent_tangent_plane(15)`. Each method and case in a fresh process (peak = VmHWM of "
        "that process, the points included); seconds are medians of 3 runs at 10⁵ points, single runs above.",
        "",
        run_markdown(run),
        "",
        md_table(["mesh", "points from", "N", "wrong: ours", "wrong: Open3D", "s: ours", "s: Open3D",
                  "ours faster by", "peak MiB: ours", "peak MiB: Open3D"], rows),
        "",
    ]
    e2e = [c for c in raw["cases"] if c["method"].startswith("e2e")]
    if e2e:
        rows = []
        for c in sorted(e2e, key=lambda c: (c["n"], c["model"], c["source"], c["method"])):
            rows.append([c["model"], c["source"], f"{c['n']:,}", "ours (scan fit, 256 cells)" if c["method"] == "e2e_ours"
                         else "Open3D estimate + orient + Poisson depth 8",
                         *(["failed: " + c["error"], "", "", ""] if "error" in c else
                           [f"{c['seconds']:.2f}", f"{c['bodies']} ({'watertight' if c['watertight'] else 'open'}; genus "
                            + ", ".join(map(str, c["genera"][:3])) + ")" + (" ✓" if c["true_genus_one_body"] else ""),
                            f"{c['chamfer']:.2e}", f"{c['peak_mib']:.0f}"])])
        parts += ["End to end, from positions alone (✓: one watertight body of the true genus; Chamfer as a fraction of "
                  "the diagonal, as in the scans section):", "",
                  md_table(["mesh", "points from", "N", "method", "seconds", "bodies", "Chamfer", "peak MiB"], rows), ""]
    return "\n".join(parts)


def main() -> int:
    if len(sys.argv) == 6 and sys.argv[1] == "one":
        print(json.dumps(one(sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5]))))
        return 0
    parser = section_parser(__doc__.split("\n")[0], "knot, σ 0.05 %, 10⁵ points")
    parser.add_argument("--sizes", nargs="+", type=int, default=[100_000], choices=sorted(RUNS))
    parser.add_argument("--meshes", nargs="+", default=None, metavar="NAME")
    parser.add_argument("--sources", nargs="+", default=None, choices=list(SOURCES))
    parser.add_argument("--methods", nargs="+", default=["ours", "open3d"], choices=list(METHODS))
    a = parser.parse_args()
    if a.quick:
        a.meshes, a.sources, a.sizes = ["knot"], ["σ 0.05 %"], [100_000]
    return record_section("normals", measure, render, a)


if __name__ == "__main__":
    sys.exit(main())
