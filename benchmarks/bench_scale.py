"""Surface reconstruction from oriented points at scan scale: our variational surface (fit with
``method="auto"``, octree polygonization) against Open3D's screened Poisson and ferreus-rbf, in
one run, each peer at the same number of cells as ours (Poisson depth 8 and 10: 256 and 1024
cells; ferreus-rbf's isosurface at 128³).

Every method runs each size in a fresh process, so that its peak resident size (VmHWM in
/proc/self/status) is its own, on the same points: sampled uniformly on a ``_hires`` mesh with
its face normals. Accuracy is the symmetric Chamfer distance to that mesh as a fraction of its
bounding-box diagonal (see :func:`distances`).

    python -m benchmarks.bench_scale [--quick] [--results DIR]
    python -m benchmarks.bench_scale --largest    # 10⁷ points, ours and Poisson, merged into the results
    python -m benchmarks.bench_scale one METHOD POINTS [MODEL]   # one JSON line, in this process
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from benchmarks.timing import (ROOT, RunRecord, fmt_ratio, fmt_s, load_raw, md_table, record_section, results_dir,
                               run_case_process, run_markdown, section_parser)

MESH = ROOT / "tests" / "data" / "meshes"
MODEL = "knot"
#: Other models, ours only at the largest size and cells (full run): topology and distance.
OTHER_MODELS = ("spot", "torus2", "fandisk")
OTHER_CASE = ("ours-1024", 1_000_000)
#: Points per case (full, quick) and the methods run at each size, ours beside its peer.
SIZES = {False: (10_000, 100_000, 1_000_000), True: (10_000,)}
OURS = {"ours-128": 128, "ours-256": 256, "ours-256-tol": 256, "ours-1024": 1024}
POISSON = {"poisson-8": 8, "poisson-10": 10}
#: Ours projects the vertices (``project=True``) up to this many cells; at 1024 cells the cells
#: are finer than the fit's own error and projection only costs.
PROJECT_MAX_CELLS = 256
PEER = {"ours-128": "ferreus-128", "ours-256": "poisson-8", "ours-256-tol": "poisson-8", "ours-1024": "poisson-10"}
#: ``tolerance=`` of the "-tol" fit: about an eighth of a cell at 256 cells over the default
#: bounds of the model (largest side 1.8); run from TOLERANCE_MIN_POINTS points on.
TOLERANCE = 1e-3
TOLERANCE_MIN_POINTS = 100_000
#: ferreus-rbf runs only at the smallest size (about a minute there; hours above).
FERREUS_MAX_POINTS = 10_000
QUICK_METHODS = ("ours-256", "poisson-8")
#: Repetitions per case (each in its own process); the median is reported.
RUNS = {False: 3, True: 1}
#: Cases too long to repeat: run once.
ONCE = 1_000_000
#: The largest size (``--largest``, about 12 minutes and 12 GB): ours and its peer at 1024 cells,
#: once each, merged into the stored results; a full run keeps the stored cases of this size.
LARGEST = 10_000_000
LARGEST_METHODS = ("ours-1024", "poisson-10")


def vmhwm_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def samples(n: int, model: str = MODEL):
    """``n`` points on the model's ``_hires`` mesh with their face normals, and the mesh."""
    import numpy as np
    import trimesh

    m = trimesh.load(MESH / f"{model}_hires.ply", process=False)
    p, face = trimesh.sample.sample_surface(m, n, seed=7)
    return np.asarray(p), np.asarray(m.face_normals)[face], m


def reconstruct(method: str, p, n) -> tuple[object, dict]:
    """The mesh (trimesh) and the phase seconds of one method."""
    import numpy as np
    import trimesh

    out: dict = {}
    if method in OURS:
        import implicitmesh as im

        t = time.perf_counter()
        tolerance = TOLERANCE if method.endswith("-tol") else None
        s = im.VariationalSurface.fit(p, n, tolerance=tolerance, exact=True)
        out["fit_s"] = time.perf_counter() - t
        if s.reduction is not None:
            out["points_used"] = s.reduction["used"]
        out["fit_method"] = s.method
        t = time.perf_counter()
        mesh = im.polygonize(s, resolution=OURS[method], method="octree", normals=False,
                            project=OURS[method] <= PROJECT_MAX_CELLS)
        out["polygonize_s"] = time.perf_counter() - t
        out["evaluations"] = int(mesh.stats["evaluations"])
        out["max_abs_f_at_points"] = float(np.max(np.abs(s.evaluate(p))))
        return mesh.to_trimesh(), out
    if method == "ferreus-128":
        return ferreus(p, n, 128, out)
    import open3d as o3d

    t = time.perf_counter()
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(p)
    pcd.normals = o3d.utility.Vector3dVector(n)
    m, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=POISSON[method])
    out["fit_s"] = time.perf_counter() - t
    return trimesh.Trimesh(np.asarray(m.vertices), np.asarray(m.triangles), process=False), out


def ferreus(p, n, cells: int, out: dict) -> tuple[object, dict]:
    """ferreus-rbf (r³, linear drift, its default solver) fitted to the constraints our fit
    places (the same interpolation problem), meshed by its own isosurfacer over our default
    bounds with cells of the same volume as ours at ``cells``³."""
    import numpy as np
    import trimesh
    import ferreus_rbf
    from ferreus_rbf.interpolant_config import Drift, InterpolantSettings, RBFKernelType

    import implicitmesh as im

    s = im.VariationalSurface.fit(p, n, method="partition", exact=True)  # only for its constraints and bounds
    c = s.constraints
    lo, hi = np.asarray(s.bounds)
    t = time.perf_counter()
    settings = InterpolantSettings(RBFKernelType.Cubic, drift=Drift.Linear)
    f = ferreus_rbf.RBFInterpolator(np.ascontiguousarray(c["points"]), np.ascontiguousarray(c["values"]), settings)
    out["fit_s"] = time.perf_counter() - t
    h = float(np.max(hi - lo)) / cells
    t = time.perf_counter()
    iso = f.build_isosurface(np.concatenate([lo, hi]), h, 0.0)
    out["polygonize_s"] = time.perf_counter() - t
    out["max_abs_f_at_points"] = float(np.max(np.abs(np.ravel(f.evaluate(np.ascontiguousarray(p))))))
    return trimesh.Trimesh(np.asarray(iso.vertices), np.asarray(iso.facets), process=False), out


def one(method: str, n: int, model: str = MODEL) -> dict:
    p, normals, ref = samples(n, model)
    tm, out = reconstruct(method, p, normals)
    out["total_s"] = out.get("fit_s", 0.0) + out.get("polygonize_s", 0.0)
    out["peak_mib"] = vmhwm_mib()
    out.update(method=method, n=n, model=model, reference_euler=int(ref.euler_number),
               triangles=int(len(tm.faces)), watertight=bool(tm.is_watertight),
               euler=int(tm.euler_number), bodies=int(len(tm.split(only_watertight=False))))
    out.update(distances(ref, tm))
    return out


def distances(ref, mesh, samples: int = 500_000) -> dict:
    """Distances between the reference and a mesh, as fractions of the reference's bounding-box
    diagonal, from ``samples`` uniform samples of each: a sample's distance to the other surface
    is its distance to the plane of the nearest sample's triangle there (exact where the surface
    is flat at the sample spacing, which the distance between samples is not: that spacing would
    dominate). Chamfer is the mean of the two mean distances, Hausdorff the larger of the two
    largest nearest-sample distances."""
    import numpy as np
    from scipy.spatial import cKDTree
    import trimesh

    a, fa = trimesh.sample.sample_surface(ref, samples, seed=1)
    b, fb = trimesh.sample.sample_surface(mesh, samples, seed=2)
    na, nb = np.asarray(ref.face_normals)[fa], np.asarray(mesh.face_normals)[fb]
    dab, iab = cKDTree(b).query(a)
    dba, iba = cKDTree(a).query(b)
    plane_ab = np.abs(np.einsum("ij,ij->i", a - b[iab], nb[iab]))
    plane_ba = np.abs(np.einsum("ij,ij->i", b - a[iba], na[iba]))
    diag = float(np.linalg.norm(ref.bounds[1] - ref.bounds[0]))
    return {
        "chamfer_over_diagonal": float(0.5 * (plane_ab.mean() + plane_ba.mean()) / diag),
        "hausdorff_over_diagonal": float(max(dab.max(), dba.max()) / diag),
        "sample_spacing_over_diagonal": float(np.median(cKDTree(a).query(a, k=2)[0][:, 1]) / diag),
    }


def run_one(method: str, n: int, model: str = MODEL) -> dict:
    """:func:`one` in a fresh process."""
    return run_case_process("benchmarks.bench_scale", [method, str(n), model], {"method": method, "n": n})


def log(msg: str) -> None:
    print(f"[bench_scale] {msg}", file=sys.stderr, flush=True)


def measure_largest(a: argparse.Namespace) -> dict:
    """The :data:`LARGEST` cases, merged into the stored results (which must exist)."""
    raw = load_raw(results_dir(a.results, a.quick), "scale")
    if raw is None:
        raise SystemExit("--largest adds to stored results: run the full benchmark first")
    run = RunRecord("benchmarks.bench_scale", False)
    cases = []
    for method in LARGEST_METHODS:
        log(f"{method}, {LARGEST:,} points, 1 run")
        cases.append({"method": method, "n": LARGEST, "runs": [run_one(method, LARGEST)]})
    raw["cases"] = [c for c in raw["cases"] if c["n"] != LARGEST] + cases
    raw["largest_run"] = run.finish(("numpy", "open3d", "implicitmesh"))
    return raw


def measure(a: argparse.Namespace) -> dict:
    if a.largest:
        return measure_largest(a)
    run = RunRecord("benchmarks.bench_scale", a.quick)
    cases = []
    for n in SIZES[a.quick]:
        methods = [m for ours in OURS for m in (ours, PEER[ours])
                   if not (m == "ferreus-128" and n > FERREUS_MAX_POINTS) and not (m == "ours-128" and n > FERREUS_MAX_POINTS)
                   and not (m.endswith("-tol") and n < TOLERANCE_MIN_POINTS)]
        methods = list(dict.fromkeys(methods))  # a peer shared by two of ours runs once
        for method in QUICK_METHODS if a.quick else methods:
            repeats = 1 if n >= ONCE else RUNS[a.quick]
            log(f"{method}, {n:,} points, {repeats} run(s)")
            cases.append({"method": method, "n": n, "runs": [run_one(method, n) for _ in range(repeats)]})
    others = []
    if not a.quick:
        method, n = OTHER_CASE
        for model in OTHER_MODELS:
            log(f"{method}, {n:,} points of {model}, 1 run")
            others.append({"method": method, "n": n, "model": model, "runs": [run_one(method, n, model)]})
    raw = {"model": MODEL, "cases": cases, "others": others,
           "run": run.finish(("numpy", "scipy", "trimesh", "open3d", "ferreus_rbf", "implicitmesh"))}
    stored = None if a.quick else load_raw(results_dir(a.results, a.quick), "scale")
    if stored and "largest_run" in stored:
        raw["cases"] += [c for c in stored["cases"] if c["n"] == LARGEST]
        raw["largest_run"] = stored["largest_run"]
    return raw


def median(runs: list[dict], key: str) -> float | None:
    v = [r[key] for r in runs if key in r]
    return statistics.median(v) if v else None


def by_method(raw: dict) -> list[str]:
    """The methods in the order they ran."""
    return list(dict.fromkeys(c["method"] for c in raw["cases"]))


def render(raw: dict) -> str:
    run = raw["run"]
    by = {(c["method"], c["n"]): c["runs"] for c in raw["cases"]}
    sizes = sorted({c["n"] for c in raw["cases"]})
    rows = []
    for n in sizes:
        for method in [m for m in by_method(raw) if (m, n) in by]:
            runs = by[(method, n)]
            if "error" in runs[0]:
                rows.append([f"{n:,}", method, f"failed: {runs[0]['error']}"] + [""] * 8)
                continue
            r0 = runs[0]
            phases = f"{fmt_s(median(runs, 'fit_s'))} + {fmt_s(median(runs, 'polygonize_s'))}" if "polygonize_s" in r0 \
                else fmt_s(median(runs, "fit_s"))
            total = median(runs, "total_s")
            peer = by.get((PEER.get(method), n))
            ratio = fmt_ratio(median(peer, "total_s"), total) if peer and "error" not in peer[0] else ""
            label = method + (f" ({r0['fit_method']})" if "fit_method" in r0 else "")
            if "points_used" in r0:
                label += f", {r0['points_used']:,} points used"
            rows.append([
                f"{n:,}", label, phases, fmt_s(total), ratio, f"{median(runs, 'peak_mib'):,.0f}",
                f"{r0['triangles']:,}", f"{median(runs, 'chamfer_over_diagonal'):.2e}",
                f"{median(runs, 'hausdorff_over_diagonal'):.1e}",
                f"{'yes' if r0['watertight'] else 'no'}, χ = {r0['euler']}, {r0['bodies']} bod{'y' if r0['bodies'] == 1 else 'ies'}",
                str(len(runs)),
            ])
    other_rows = []
    for c in raw.get("others", []):
        r0 = c["runs"][0]
        if "error" in r0:
            other_rows.append([c["model"], f"{c['n']:,}", f"failed: {r0['error']}"] + [""] * 5)
            continue
        other_rows.append([
            c["model"], f"{c['n']:,}", f"{fmt_s(r0['fit_s'])} + {fmt_s(r0['polygonize_s'])}", f"{r0['peak_mib']:,.0f}",
            f"{r0['triangles']:,}", f"{r0['chamfer_over_diagonal']:.2e}", f"{r0['hausdorff_over_diagonal']:.1e}",
            f"{'yes' if r0['watertight'] else 'no'}, χ = {r0['euler']} (reference {r0['reference_euler']}), "
            f"{r0['bodies']} bod{'y' if r0['bodies'] == 1 else 'ies'}",
        ])
    others = [] if not other_rows else [
        f"Other models, ours only (`{OTHER_CASE[0]}`, {OTHER_CASE[1]:,} points, one run each): the same fit and "
        "polygonization on samples of other `_hires` meshes, for the topology and the distance to the reference.",
        "",
        md_table(["model", "points", "seconds (fit + mesh)", "peak MiB", "triangles", "Chamfer", "Hausdorff",
                  "watertight, χ, bodies"], other_rows),
        "",
    ]
    return "\n".join([
        "## Reconstruction at scan scale: variational surface against screened Poisson" + (" (QUICK)" if run["quick"] else ""),
        "",
        f"Run {run['date']} with `{run['command']}`. Points sampled uniformly on `{raw['model']}_hires` "
        "(`trimesh.sample.sample_surface`, seed 7) with their face normals; the same points for every method. "
        "Ours: `VariationalSurface.fit(points, normals, exact=True)` (method \"auto\") then `polygonize(method=\"octree\", "
        "normals=False)` at 128³, 256³ (with `project=True`) or 1024³ over the default bounds; `ours-256-tol` fits with "
        f"`tolerance={TOLERANCE}` (greedy reduction: only the points needed to pass within it of every point). ferreus-rbf: r³ with linear drift, its "
        "default solver, on the constraints our fit places, meshed by its `build_isosurface` at 128³. Open3D: "
        "`TriangleMesh.create_from_point_cloud_poisson(pcd, depth)` on a point cloud with the normals, its mesh "
        "untrimmed. Each case in a fresh process (peak resident size VmHWM its own); times are medians over the "
        "runs column, seconds of wall-clock time from points to mesh. "
        "Ratio: the peer's total over ours at the same cells (ferreus-rbf at 128, Poisson depth 8 at 256, "
        "depth 10 at 1024; above 1, ours is faster). Chamfer: the mean of the two mean distances from 5·10⁵ "
        "samples of each surface to the other (to the plane of the nearest sample's triangle, so that the "
        "sample spacing does not dominate); Hausdorff the larger of the two largest nearest-sample distances; "
        "both as fractions of the reference's bounding-box diagonal. The reference mesh is closed, "
        "genus 1 (χ = 0).",
        "",
        run_markdown(run),
        "",
        *largest_note(raw),
        md_table(["points", "method", "seconds (fit + mesh)", "total (s)", "peer / ours", "peak MiB", "triangles",
                  "Chamfer", "Hausdorff", "watertight, χ, bodies", "runs"], rows),
        "",
        *others,
    ])


def largest_note(raw: dict) -> list[str]:
    """The paragraph on the :data:`LARGEST` rows, which run apart (no lines when there are none)."""
    run = raw.get("largest_run")
    if not run or not any(c["n"] == LARGEST for c in raw["cases"]):
        return []
    foreign = run["foreign_load"]
    m = run["machine"]
    cpu = m["cpu"] + (f" ({m['vector']})" if "vector" in m else "")
    return [f"The {LARGEST:,}-point rows ran apart, {run['date']}, on {cpu}, with `{run['command']}` (implicitmesh "
            f"{run['machine'].get('implicitmesh', '?')}; other processes used "
            f"{foreign if foreign is None else round(foreign, 2)} cores on average), once each.", ""]


def main() -> int:
    if len(sys.argv) in (4, 5) and sys.argv[1] == "one":
        print(json.dumps(one(sys.argv[2], int(sys.argv[3]), *sys.argv[4:])))
        return 0
    parser = section_parser(__doc__.split("\n")[0], "10⁴ points, one run per case")
    parser.add_argument("--largest", action="store_true",
                        help=f"run only the {LARGEST:,}-point cases and add them to the stored results")
    return record_section("scale", measure, render, parser.parse_args())


if __name__ == "__main__":
    sys.exit(main())
