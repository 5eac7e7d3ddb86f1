"""Reconstruction from simulated scans: our variational surface against Open3D's screened Poisson
on the same points, by topology, distance to the true surface and time (issue 53's targets).

Every closed ``_hires`` mesh of ``tests/data/meshes`` is scanned by :func:`implicitmesh.scanner.scan`
(12 views at elevations 0°, 25° and 50°, none from below; PCA normals over 20 neighbours per
view, oriented towards the view's camera) in each condition of :data:`CONDITIONS`, at each size of
:data:`SIZES`; every method of :data:`METHODS` reconstructs the same points, one after the other,
in one fresh process per case (after one untimed call of each). A method is a function of (points, normals, size) returning a mesh: a new fit
becomes a new entry of :data:`METHODS` (a new column group of the tables).

Measures of each reconstruction (:func:`measures`): bodies (connected components), watertight
(every edge in exactly two triangles), each body's genus from its Euler characteristic, the
Chamfer distance (the mean of the two one-sided mean distances between 2·10⁵ uniform samples of
each surface and the other surface, exact point-to-triangle distances through the core's BVH),
the 99th percentile distance (the larger of the two one-sided 99th percentiles) and the normal
consistency (the mean |cos| between the reconstruction's face normal at its samples and the true
face normal at their closest points); distances as fractions of the true mesh's bounding-box
diagonal.

    python -m benchmarks.bench_scans [--quick] [--sizes 50000 500000] [--meshes NAME ...]
                                     [--conditions CONDITION ...] [--results DIR]
    python -m benchmarks.bench_scans --sizes 5000000 --meshes knot --conditions "σ 0.05 %"

From :data:`ALONE_FROM` points on (the 5·10⁶ size, which runs only when asked for) the scan is
saved, and each of :data:`ALONE_METHODS` runs once in a process of its own, whose peak resident
size is reported beside its time.

A run of some cases keeps the other stored cases (each with its own run's record).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Callable

from benchmarks.timing import (ROOT, RunRecord, fmt_ratio, fmt_s, load_raw, md_table, record_section, results_dir,
                               run_case_process, run_markdown, section_parser)

MESHES = ROOT / "tests" / "data" / "meshes"
#: The scanner's conditions: keyword arguments of ``scan`` besides the mesh and the size.
CONDITIONS = {
    "clean": {},
    "σ 0.05 %": {"noise": 5e-4},
    "σ 0.2 %": {"noise": 2e-3},
    "misregistered 0.1 %, σ 0.05 %": {"noise": 5e-4, "misregistration": 1e-3},
    "0.2 % outliers, σ 0.05 %": {"noise": 5e-4, "outliers": 2e-3},
}
#: Points per scan → (our cells, Poisson's depth, timed runs per method after one warm-up).
SIZES = {50_000: (256, 8, 3), 500_000: (512, 9, 1), 5_000_000: (1024, 10, 1)}
#: From this many points on, each method runs once, without a warm-up, in a process of its own
#: (the scan saved in between), and its peak resident size (VmHWM) is reported.
ALONE_FROM = 1_000_000
#: The methods run at those sizes (the interpolant's many bodies are shown at the smaller ones).
ALONE_METHODS = ("ours", "poisson")
#: The quick run: these meshes and conditions at the smallest size, one timed run.
QUICK_MESHES = ("knot", "spot")
QUICK_CONDITIONS = ("clean", "σ 0.05 %")
#: Uniform samples of each surface for the distances.
SAMPLES = 200_000
SCAN_SEED = 53


def log(msg: str) -> None:
    print(f"[bench_scans] {msg}", file=sys.stderr, flush=True)


def closed_meshes() -> list[str]:
    """The names of the ``_hires`` meshes that are closed (every edge in two triangles)."""
    import trimesh

    names = []
    for path in sorted(MESHES.glob("*_hires.ply")):
        m = trimesh.load(path, process=False)
        if topology(m.vertices, m.faces)["watertight"]:
            names.append(path.name[: -len("_hires.ply")])
    return names


# --- the methods -------------------------------------------------------------------------------------------


def ours(points, normals, n: int):
    """The scan fit, ``VariationalSurface.fit(points, normals)`` (the default), then
    ``polygonize(surface, resolution=R, method="octree")``."""
    import implicitmesh as im

    s = im.VariationalSurface.fit(points, normals)
    m = im.polygonize(s, resolution=SIZES[n][0], method="octree")
    return m.vertices, m.faces


def exact(points, normals, n: int):
    """The interpolating fit, ``VariationalSurface.fit(points, normals, exact=True)``, then the
    same polygonization."""
    import implicitmesh as im

    s = im.VariationalSurface.fit(points, normals, exact=True)
    m = im.polygonize(s, resolution=SIZES[n][0], method="octree")
    return m.vertices, m.faces


def poisson(points, normals, n: int):
    """Open3D's screened Poisson at depth d on a point cloud with the normals, untrimmed."""
    import numpy as np
    import open3d as o3d

    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(points)
    pcd.normals = o3d.utility.Vector3dVector(normals)
    m, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=SIZES[n][1])
    return np.asarray(m.vertices), np.asarray(m.triangles)


#: The methods compared, in the tables' order: name → (function, a label given the size).
METHODS: dict[str, tuple[Callable, Callable[[int], str]]] = {
    "ours": (ours, lambda n: f"ours (scan fit), {SIZES[n][0]} cells"),
    "exact": (exact, lambda n: f"ours (exact=True), {SIZES[n][0]} cells"),
    "poisson": (poisson, lambda n: f"Poisson, depth {SIZES[n][1]}"),
}
#: The method the others are compared with in the summary ("faster by", "closer").
REFERENCE = "poisson"


# --- measures ----------------------------------------------------------------------------------------------


def topology(vertices, faces) -> dict:
    """Bodies (connected components of the triangles), watertight (every edge in exactly two
    triangles) and each body's genus from its Euler characteristic (V − E + F = 2 − 2g for a
    closed orientable body), largest body first."""
    import numpy as np
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return {"bodies": 0, "watertight": False, "genera": []}
    used, f = np.unique(f, return_inverse=True)
    f = f.reshape(-1, 3)
    nv = len(used)
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    edges, counts = np.unique(e, axis=0, return_counts=True)
    watertight = bool(np.all(counts == 2))
    g = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(nv, nv))
    bodies, label = connected_components(g, directed=False)
    v_b = np.bincount(label, minlength=bodies)
    e_b = np.bincount(label[edges[:, 0]], minlength=bodies)
    f_b = np.bincount(label[f[:, 0]], minlength=bodies)
    chi = v_b - e_b + f_b
    order = np.argsort(-f_b, kind="stable")
    genera = [int((2 - c) // 2) for c in chi[order]]
    return {"bodies": int(bodies), "watertight": watertight, "genera": genera[:8]}


def sample_surface(vertices, faces, count: int, seed: int):
    """``count`` points uniform on the triangles (by area), and their triangles' unit normals."""
    import numpy as np

    rng = np.random.default_rng(seed)
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area = np.linalg.norm(cross, axis=1)
    tri = rng.choice(len(v), size=count, p=area / area.sum())
    r1, r2 = rng.random(count), rng.random(count)
    s = np.sqrt(r1)
    a, b = 1 - s, s * (1 - r2)
    c = s * r2
    p = a[:, None] * v[tri, 0] + b[:, None] * v[tri, 1] + c[:, None] * v[tri, 2]
    normal = cross[tri] / np.where(area[tri] > 0, area[tri], 1.0)[:, None]
    return p, normal


def measures(truth, vertices, faces, genus: int) -> dict:
    """The topology and distances of a reconstruction (``vertices``, ``faces``) against the true
    mesh ``truth`` (a trimesh), as described in the module's documentation."""
    import numpy as np
    from implicitmesh import _core

    out = topology(vertices, faces)
    out["triangles"] = int(len(faces))
    out["true_genus_one_body"] = bool(out["bodies"] == 1 and out["watertight"] and out["genera"] == [genus])
    if len(faces) == 0:
        return out
    diag = float(np.linalg.norm(truth.bounds[1] - truth.bounds[0]))
    tv, tf = np.asarray(truth.vertices, dtype=np.float64), np.asarray(truth.faces, dtype=np.int64)
    true_normals = np.asarray(truth.face_normals)
    rp, rn = sample_surface(vertices, faces, SAMPLES, seed=1)
    tp, _ = sample_surface(tv, tf, SAMPLES, seed=2)
    _, d_rt, tri = _core.closest_points(tv, tf, rp)
    _, d_tr, _ = _core.closest_points(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), tp)
    out.update(
        chamfer=float(0.5 * (d_rt.mean() + d_tr.mean()) / diag),
        p99=float(max(np.percentile(d_rt, 99), np.percentile(d_tr, 99)) / diag),
        largest=float(max(d_rt.max(), d_tr.max()) / diag),
        normal_consistency=float(np.mean(np.abs(np.einsum("ij,ij->i", rn, true_normals[tri])))),
    )
    return out


# --- the run -----------------------------------------------------------------------------------------------


def run_case(truth, genus: int, scan, n: int, runs: int) -> dict:
    """Every method on one scan: its seconds (``runs`` timed calls) and its last mesh's measures."""
    out = {}
    for name, (fn, _) in METHODS.items():
        times, mesh = [], None
        try:
            for _ in range(runs):
                t0 = time.perf_counter()
                mesh = fn(scan.points, scan.normals, n)
                times.append(time.perf_counter() - t0)
        except Exception as e:  # noqa: BLE001 - a failing method is a result
            out[name] = {"error": f"{type(e).__name__}: {e}"}
            continue
        out[name] = {"times": times, "seconds": statistics.median(times), **measures(truth, *mesh, genus)}
    return out


def one(model: str, condition: str, n: int, runs: int) -> dict:
    """One case in this process: the scan, one untimed call of each method (imports, thread pools
    and allocators warm), then :func:`run_case`."""
    import trimesh

    import implicitmesh as im

    truth = trimesh.load(MESHES / f"{model}_hires.ply", process=False)
    genus = topology(truth.vertices, truth.faces)["genera"][0]
    t0 = time.perf_counter()
    s = im.scanner.scan(truth.vertices, truth.faces, n, seed=SCAN_SEED, **CONDITIONS[condition])
    scan_s = time.perf_counter() - t0
    for fn, _ in METHODS.values():
        try:
            fn(s.points, s.normals, n)
        except Exception:  # noqa: BLE001 - run_case records the failure
            pass
    return {"model": model, "genus": genus, "condition": condition, "n": n, "points": len(s),
            "resolution": s.parameters.resolution, "outliers": int(len(s.outliers)), "scan_s": scan_s,
            "methods": run_case(truth, genus, s, n, runs)}


def vmhwm_mib() -> float:
    """This process's peak resident size in MiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def scan_to(model: str, condition: str, n: int, path: str) -> dict:
    """Makes the scan of one case and saves its points and normals to ``path`` (.npz)."""
    import numpy as np
    import trimesh

    import implicitmesh as im

    truth = trimesh.load(MESHES / f"{model}_hires.ply", process=False)
    t0 = time.perf_counter()
    s = im.scanner.scan(truth.vertices, truth.faces, n, seed=SCAN_SEED, **CONDITIONS[condition])
    np.savez(path, points=s.points, normals=s.normals)
    return {"model": model, "genus": topology(truth.vertices, truth.faces)["genera"][0], "condition": condition,
            "n": n, "points": len(s), "resolution": s.parameters.resolution, "outliers": int(len(s.outliers)),
            "scan_s": time.perf_counter() - t0}


def method_alone(model: str, n: int, method: str, path: str, genus: int) -> dict:
    """One method once on the scan saved at ``path``, in this process: seconds, peak memory
    (the points included) and the measures of its mesh."""
    import numpy as np
    import trimesh

    truth = trimesh.load(MESHES / f"{model}_hires.ply", process=False)
    data = np.load(path)
    points, normals = data["points"], data["normals"]
    t0 = time.perf_counter()
    mesh = METHODS[method][0](points, normals, n)
    seconds = time.perf_counter() - t0
    peak = vmhwm_mib()
    return {"times": [seconds], "seconds": seconds, "peak_mib": peak, **measures(truth, *mesh, genus)}


def case_alone(model: str, condition: str, n: int) -> dict:
    """One case at a size of :data:`ALONE_FROM` or more: the scan in one process, then each of
    :data:`ALONE_METHODS` in its own."""
    import tempfile

    case = {"model": model, "condition": condition, "n": n}
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "scan.npz")
        c = run_case_process("benchmarks.bench_scans", ["scan", model, condition, str(n), path], case)
        if "error" in c:
            return {**case, "genus": None, "points": 0, "methods": {m: {"error": c["error"]} for m in ALONE_METHODS}}
        c["methods"] = {}
        for m in ALONE_METHODS:
            r = run_case_process("benchmarks.bench_scans", ["method", model, str(n), m, path, str(c["genus"])], {})
            c["methods"][m] = r
    return c


def measure(a: argparse.Namespace) -> dict:
    run = RunRecord("benchmarks.bench_scans", a.quick)
    meshes = [m for m in closed_meshes() if (not a.quick or m in QUICK_MESHES) and (not a.meshes or m in a.meshes)]
    conditions = [c for c in CONDITIONS
                  if (not a.quick or c in QUICK_CONDITIONS) and (not a.conditions or c in a.conditions)]
    sizes = [min(SIZES)] if a.quick else [int(s) for s in a.sizes]
    cases = []
    for n in sizes:
        runs = 1 if a.quick else SIZES[n][2]
        for model in meshes:
            for condition in conditions:
                log(f"{model}, {condition}, {n:,} points, {runs} run(s) per method")
                # Each case in a fresh process: a crash of one method costs one case, not the run.
                case = {"model": model, "condition": condition, "n": n}
                if n >= ALONE_FROM:
                    c = case_alone(model, condition, n)
                else:
                    c = run_case_process("benchmarks.bench_scans", [model, condition, str(n), str(runs)], case)
                if "error" in c:
                    c = {**case, "genus": None, "points": 0, "methods": {m: {"error": c["error"]} for m in METHODS}}
                cases.append(c)
                log("  " + "; ".join(
                    f"{m}: " + (r["error"] if "error" in r else
                                f"{r['seconds']:.2f} s, {r['bodies']} bodies, genus {r['genera'][:3]}, "
                                f"Chamfer {r['chamfer']:.2e}") for m, r in c["methods"].items()))
    raw = {"cases": cases, "methods": list(METHODS), "reference": REFERENCE, "samples": SAMPLES,
           "sizes": {str(n): list(SIZES[n]) for n in sizes}, "conditions": {c: CONDITIONS[c] for c in conditions},
           "run": run.finish(("numpy", "scipy", "trimesh", "open3d", "implicitmesh"))}
    # A run of some cases keeps the other stored cases, each with its own run's record.
    stored = None if a.quick else load_raw(results_dir(a.results, a.quick), "scans")
    if stored:
        ran = {(c["model"], c["condition"], c["n"]) for c in cases}
        kept = [c for c in stored["cases"] if (c["model"], c["condition"], c["n"]) not in ran]
        for c in kept:
            c.setdefault("run", stored["run"])
        raw["cases"] += kept
        raw["sizes"].update({k: v for k, v in stored["sizes"].items() if k not in raw["sizes"]})
        raw["conditions"].update({k: v for k, v in stored["conditions"].items() if k not in raw["conditions"]})
    return raw


# --- the markdown ------------------------------------------------------------------------------------------


def _topology_cell(r: dict) -> str:
    if "error" in r:
        return f"failed: {r['error']}"
    g = ", ".join(str(x) for x in r["genera"][:3]) + (", …" if len(r["genera"]) > 3 else "")
    return f"{r['bodies']} ({'watertight' if r['watertight'] else 'open'}; genus {g})" + (
        " ✓" if r["true_genus_one_body"] else "")


def render(raw: dict) -> str:
    run = raw["run"]
    methods = raw["methods"]
    ref = raw["reference"]
    others = [m for m in methods if m != ref]
    sizes = sorted({c["n"] for c in raw["cases"]})
    order = {c: i for i, c in enumerate(CONDITIONS)}
    raw["cases"].sort(key=lambda c: (c["n"], c["model"], order.get(c["condition"], len(order))))
    conditions = list(dict.fromkeys(c["condition"] for c in raw["cases"]))
    label = {"ours": "ours", "poisson": "Poisson"}
    name = lambda m: label.get(m, m)  # noqa: E731
    parts = [
        "## Reconstruction from simulated scans: variational surface against screened Poisson"
        + (" (QUICK)" if run["quick"] else ""),
        "",
        f"Run {run['date']} with `{run['command']}`. Each closed `_hires` mesh scanned by "
        "`implicitmesh.scanner.scan(vertices, faces, N, seed=53, ...)`: 12 views at azimuths 30° apart and "
        "elevations 0°, 25°, 50° (none from below), a square pixel grid per view, hits beyond 80° from the "
        "surface normal dropped, PCA normals over 20 neighbours of the same view oriented towards its camera. "
        "Conditions: noise along the rays with σ a fraction of the bounding-box diagonal; misregistered: each "
        "view moved by 0.1 % of the diagonal and rotated by 0.1°; outliers: 0.2 % of the points replaced by "
        "uniform points in the box with random normals. Ours: `VariationalSurface.fit(points, normals)` (the scan fit, the default) then "
        "`polygonize(surface, resolution=R, method=\"octree\")` (R = 256 at 5·10⁴ points, 512 at 5·10⁵, "
        "1024 at 5·10⁶); "
        "exact: the same with `fit(..., exact=True)`, the interpolant; "
        "Poisson: Open3D's `create_from_point_cloud_poisson(pcd, depth=d)` (d = 8, 9), untrimmed; both on "
        "the same points in the same process (a fresh one per case), seconds end to end (median of the timed "
        "runs after one warm-up call of each method; from 10⁶ points on, each method runs once in a fresh "
        "process of its own, and its peak resident size, the points included, is given). Bodies: connected components, with watertightness and each body's "
        "genus from its Euler characteristic, largest first ((2 − χ) / 2, which is a genus only for a closed body: "
        "on an open or non-manifold mesh it is a count and can be negative); ✓: one watertight body of the true genus. "
        f"Chamfer: the mean of the two one-sided mean distances between {raw['samples']:,} uniform samples of "
        "each surface and the other surface (exact distances to the triangles); p99: the larger one-sided "
        "99th percentile; both as fractions of the diagonal. NC: mean |cos| between the reconstruction's "
        "normals at its samples and the true normals at their closest points.",
        "",
        run_markdown(run),
        "",
    ]
    for n in sizes:
        cases = [c for c in raw["cases"] if c["n"] == n]
        if not cases:
            continue
        cells, depth, runs = raw["sizes"][str(n)]
        parts += [f"### {n:,} points ({cells} cells against depth {depth}; {runs if not run['quick'] else 1} "
                  "timed run(s))", ""]
        earlier: dict[str, tuple[dict, list]] = {}
        for c in cases:
            if "run" in c:
                earlier.setdefault(c["run"]["date"], (c["run"], []))[1].append(c)
        current = [c for c in cases if "run" not in c]
        named = lambda cc: "; ".join(f"{c['model']}, {c['condition']}" for c in cc)  # noqa: E731
        for other_run, cc in earlier.values():
            if len(earlier) == 1:
                which = f"Every case but {named(current)}" if current else "Every case"
            else:
                which = named(cc)
            load = other_run["foreign_load"]
            parts += [f"{which}: measured in an earlier run, {other_run['date']} (`{other_run['command']}`; other "
                      f"processes used {load if load is None else round(load, 2)} cores on average).", ""]
        # The summary per condition, as issue 53 states its targets.
        rows = []
        for cond in conditions:
            cc = [c for c in cases if c["condition"] == cond]
            if not cc:
                continue
            ok = lambda m: sum(1 for c in cc if c["methods"].get(m, {}).get("true_genus_one_body"))  # noqa: E731
            med = lambda m, k: statistics.median(  # noqa: E731
                [c["methods"].get(m, {})[k] for c in cc if k in c["methods"].get(m, {})] or [float("nan")])
            row = [cond, " / ".join(f"{ok(m)} of {len(cc)}" for m in methods),
                   " / ".join(f"{med(m, 'chamfer'):.1e}" for m in methods),
                   " / ".join(f"{med(m, 'p99'):.1e}" for m in methods),
                   " / ".join(f"{med(m, 'normal_consistency'):.3f}" for m in methods)]
            for m in others:
                closer = sum(1 for c in cc if c["methods"].get(m, {}).get("chamfer", 1e9) <= c["methods"].get(ref, {}).get("chamfer", -1))
                ratios = [c["methods"].get(ref, {})["seconds"] / c["methods"].get(m, {})["seconds"] for c in cc
                          if "seconds" in c["methods"].get(m, {}) and "seconds" in c["methods"].get(ref, {})]
                row += [f"{closer} of {len(cc)}", f"{statistics.median(ratios):.2f}×" if ratios else "—"]
            rows.append(row)
        slash = " / ".join(name(m) for m in methods)
        parts += [md_table(["condition", f"one watertight body of the true genus: {slash}",
                            f"median Chamfer: {slash}", f"median p99: {slash}", f"median NC: {slash}"]
                           + [h for m in others for h in (f"{name(m)} closer", f"{name(m)} faster by (median)")],
                           rows), ""]
        # Every case, every method.
        rows = []
        for c in cases:
            for m in methods:
                r = c["methods"].get(m)
                if r is None:  # a method added after this case was measured
                    continue
                if "error" in r:
                    rows.append([c["model"], c["condition"], f"{c['points']:,}", name(m), "—", _topology_cell(r),
                                 "", "", ""])
                    continue
                speed = fmt_ratio(c["methods"].get(ref, {}).get("seconds"), r["seconds"]) if m != ref else ""
                peak = f"; {r['peak_mib']:,.0f} MiB" if "peak_mib" in r else ""
                rows.append([c["model"], c["condition"], f"{c['points']:,}", name(m),
                             fmt_s(r["seconds"]) + (f" ({speed})" if speed else "") + peak, _topology_cell(r),
                             f"{r['chamfer']:.2e}", f"{r['p99']:.2e}", f"{r['normal_consistency']:.4f}"])
        parts += [md_table(["mesh (true genus)", "condition", "points", "method",
                            "seconds (Poisson ÷ it)" + ("; peak memory" if n >= ALONE_FROM else ""),
                            "bodies", "Chamfer", "p99", "NC"],
                           [[f"{r[0]} ({next(c['genus'] for c in cases if c['model'] == r[0])})", *r[1:]]
                            for r in rows]), ""]
    return "\n".join(parts)


def main() -> int:
    if len(sys.argv) == 6 and sys.argv[1] == "one":
        print(json.dumps(one(sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]))))
        return 0
    if len(sys.argv) == 7 and sys.argv[1] == "one" and sys.argv[2] == "scan":
        print(json.dumps(scan_to(sys.argv[3], sys.argv[4], int(sys.argv[5]), sys.argv[6])))
        return 0
    if len(sys.argv) == 8 and sys.argv[1] == "one" and sys.argv[2] == "method":
        print(json.dumps(method_alone(sys.argv[3], int(sys.argv[4]), sys.argv[5], sys.argv[6], int(sys.argv[7]))))
        return 0
    parser = section_parser(__doc__.split("\n")[0], "knot and spot, clean and σ 0.05 %%, 5·10⁴ points, one run")
    parser.add_argument("--sizes", nargs="+", type=int, default=[n for n in sorted(SIZES) if n < ALONE_FROM],
                        choices=sorted(SIZES), help="points per scan (default those below %d)" % ALONE_FROM)
    parser.add_argument("--meshes", nargs="+", default=None, metavar="NAME",
                        help="only these meshes (names before _hires; default every closed one)")
    parser.add_argument("--conditions", nargs="+", default=None, choices=list(CONDITIONS), metavar="CONDITION",
                        help="only these conditions (default all: "
                        + ", ".join(repr(c) for c in CONDITIONS).replace("%", "%%") + ")")
    return record_section("scans", measure, render, parser.parse_args())


if __name__ == "__main__":
    sys.exit(main())
