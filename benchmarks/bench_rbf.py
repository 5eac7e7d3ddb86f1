"""Benchmark: variational (RBF, r³ + linear) surfaces — fit, evaluation and dense polygonization —
against scipy's RBFInterpolator (+ skimage marching cubes) and ferreus-rbf, in one run.

    python -m benchmarks.bench_rbf            # full: 10^6 points, 128³, 3-5 runs per case
    python -m benchmarks.bench_rbf --quick    # smoke test: 10^5 points, 64³, 1-2 runs

Writes the raw results to ``RESULTS/rbf.json`` and the markdown section rendered from them to
stdout and ``RESULTS/rbf.md`` (``--results RESULTS``, default ``benchmarks/results``); progress goes
to stderr. The scipy cases run in subprocesses of this module (``--worker scipy``),
once with ``OPENBLAS_NUM_THREADS=1`` and once with the OpenBLAS default, because the variable must
be set before numpy is imported (threadpoolctl is not installed); the faster setting is reported.

Problem: the bundled ``knot`` model (800 vertices) fitted with ``VariationalSurface.from_mesh``,
which places 800 normal constraints → 1,600 constraints (centres). Every peer gets the same 1,600
points and values (``surface.constraints``) and interpolates them with r³ and a degree-1
polynomial, which is the same interpolation problem as ``VariationalSurface.interpolate``.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import sys
import tempfile
import time

from benchmarks.timing import (  # no numpy at import time: workers set OPENBLAS_NUM_THREADS first
    RunRecord,
    Timing,
    fmt_cpu_per_wall as _cpw,
    fmt_foreign_load as _fl,
    fmt_ratio,
    fmt_s,
    machine_markdown,
    md_table,
    openblas_threads,
    record_section,
    run_worker,
    section_parser,
    timeit_median,
)

SEED = 20240607
REL_TOL = 1e-8  # ours vs scipy on the same interpolation problem, relative to max |f|
THREAD_CONFIGS = ((1, "OPENBLAS_NUM_THREADS=1"), (None, "OpenBLAS default"))


def log(msg: str) -> None:
    sys.stderr.write(f"[bench_rbf {time.strftime('%H:%M:%S')}] {msg}\n")
    sys.stderr.flush()


# --------------------------------------------------------------------------------------------
# scipy worker (runs in a subprocess with the OpenBLAS thread setting of its environment)
# --------------------------------------------------------------------------------------------


def scipy_worker(a: argparse.Namespace) -> int:
    import numpy as np
    from scipy.interpolate import RBFInterpolator

    d = np.load(a.data)
    P, V = d["points"], d["values"]
    out: dict = {
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
        "openblas_threads": openblas_threads(),
    }

    def fit():
        return RBFInterpolator(P, V, kernel="cubic", degree=1)

    tasks = a.tasks.split(",")
    if "fit" in tasks:
        t = timeit_median(fit, a.runs, a.warmup)
        out["fit"] = t.to_json()
        rbf = t.result
    else:
        rbf = fit()
    out["fit_residual"] = float(np.abs(rbf(P) - V).max())
    if "eval" in tasks:
        X = d["targets"]
        t = timeit_median(lambda: rbf(X), a.eval_runs, a.eval_warmup)
        out["eval"] = t.to_json()
        if a.values_out:
            np.save(a.values_out, t.result)
    if "grid" in tasks:
        from skimage.measure import marching_cubes

        lo, hi, n = d["lo"], d["hi"], int(d["n"])
        spacing = tuple(float(s) for s in (hi - lo) / n)
        parts: list[tuple[float, float]] = []

        def pipeline():
            t0 = time.perf_counter()
            axes = [np.linspace(lo[i], hi[i], n + 1) for i in range(3)]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
            volume = rbf(grid).reshape(n + 1, n + 1, n + 1)
            t1 = time.perf_counter()
            verts, faces, normals, _ = marching_cubes(volume, 0.0, spacing=spacing)
            verts += lo
            t2 = time.perf_counter()
            parts.append((t1 - t0, t2 - t1))
            return len(faces), len(verts), (n + 1) ** 3

        t = timeit_median(pipeline, a.grid_runs, a.grid_warmup)
        out["grid"] = t.to_json()
        timed = parts[a.grid_warmup :]
        out["grid_eval_times"] = [p[0] for p in timed]
        out["grid_mc_times"] = [p[1] for p in timed]
        out["grid_triangles"], out["grid_vertices"], out["grid_evaluations"] = t.result
    with open(a.json_out, "w") as f:
        json.dump(out, f)
    return 0


def run_scipy(data: str, tasks: str, threads: int | None, values_out: str | None, reps: dict) -> dict:
    """Runs :func:`scipy_worker` in a subprocess (``python -m benchmarks.bench_rbf --worker scipy``)."""
    args = ["--worker", "scipy", "--data", data, "--tasks", tasks]
    for k, v in reps.items():
        args += [f"--{k.replace('_', '-')}", str(v)]
    if values_out:
        args += ["--values-out", values_out]
    return run_worker("benchmarks.bench_rbf", args, threads)


# --------------------------------------------------------------------------------------------
# ferreus-rbf configuration
# --------------------------------------------------------------------------------------------


def ferreus_configs():
    """(settings, {name: Params}) for ferreus-rbf: cubic kernel r³, linear drift (polynomial)."""
    from ferreus_rbf.config import Params
    from ferreus_rbf.interpolant_config import Drift, InterpolantSettings, RBFKernelType

    settings = InterpolantSettings(RBFKernelType.Cubic, drift=Drift.Linear)
    params = {
        # library defaults: 1,600 > naive_solve_threshold (1,500) → iterative FGMRES with domain
        # decomposition preconditioner, relative tolerance 1e-6; direct evaluation (< 4,096 sources)
        "default": None,
        # dense direct solve (like scipy and ours), direct evaluation
        "direct": Params(RBFKernelType.Cubic, naive_solve_threshold=4096),
        # dense direct solve, FMM evaluation forced (direct_eval_threshold=0)
        "fmm": Params(RBFKernelType.Cubic, naive_solve_threshold=4096, direct_eval_threshold=0),
    }
    return settings, params


# --------------------------------------------------------------------------------------------
# the benchmark
# --------------------------------------------------------------------------------------------


def measure(a: argparse.Namespace) -> dict:
    import numpy as np

    import implicitmesh
    from implicitmesh import VariationalSurface, polygonize
    from implicitmesh.shapes import load_model

    import ferreus_rbf
    from ferreus_rbf import isosurfacing

    quick = a.quick
    n_points = a.points or (10**5 if quick else 10**6)
    res = a.resolution or (64 if quick else 128)
    R_FAST = 2 if quick else 5  # runs for cases under ~1 s
    R_MED = 1 if quick else 3  # runs for cases of a few seconds
    R_GRID = 1 if quick else 2  # runs of the slow scipy grid pipeline (no warm-up)
    run = RunRecord("benchmarks.bench_rbf", quick)
    core_built = _mtime(implicitmesh._core.__file__)  # before the run: the build being measured
    log(f"load average before: {run.load_before}")

    vertices, faces = load_model("knot")
    surface = VariationalSurface.from_mesh(vertices, faces)
    P = np.ascontiguousarray(surface.constraints["points"])
    V = np.ascontiguousarray(surface.constraints["values"])
    lo, hi = np.asarray(surface.bounds)
    rng = np.random.default_rng(SEED)
    X = rng.uniform(-1.0, 1.0, size=(n_points, 3))
    log(f"{len(vertices)} vertices → {len(P)} constraints; {n_points:,} targets; {res}³ cells")

    tmp = tempfile.TemporaryDirectory(prefix="bench_rbf_")
    data = os.path.join(tmp.name, "data.npz")
    np.savez(data, points=P, values=V, targets=X, lo=lo, hi=hi, n=res)

    warnings: list[str] = []
    # ---------------------------------------------------------------- 1. fit
    log("fit: ours")
    t_from_mesh = timeit_median(lambda: VariationalSurface.from_mesh(vertices, faces), R_FAST, 1)
    t_interp = timeit_median(lambda: VariationalSurface.interpolate(P, V), R_FAST, 1)
    ours_i = t_interp.result
    ours_fit_resid = float(np.abs(ours_i.evaluate(P) - V).max())

    settings, fparams = ferreus_configs()
    ferreus_fit: dict[str, Timing] = {}
    ferreus_resid: dict[str, float] = {}
    for name in ("default", "direct"):
        log(f"fit: ferreus-rbf ({name})")
        prm = fparams[name]
        kw = {} if prm is None else {"params": prm}
        t = timeit_median(lambda: ferreus_rbf.RBFInterpolator(P, V, settings, **kw), R_FAST, 1)
        ferreus_fit[name] = t
        ferreus_resid[name] = float(np.abs(np.ravel(t.result.evaluate(P)) - V).max())
    f_direct = ferreus_fit["direct"].result
    f_fmm = ferreus_rbf.RBFInterpolator(P, V, settings, params=fparams["fmm"])

    # scipy fit + evaluation, both thread settings, in subprocesses
    scipy_runs: dict[str, dict] = {}
    scipy_values: dict[str, str] = {}
    for threads, label in THREAD_CONFIGS:
        log(f"fit + evaluate {n_points:,}: scipy ({label}) in a subprocess")
        vals = os.path.join(tmp.name, f"scipy_values_{threads}.npy")
        scipy_runs[label] = run_scipy(
            data,
            "fit,eval",
            threads,
            vals,
            {"runs": R_FAST, "warmup": 1, "eval_runs": R_MED, "eval_warmup": 1},
        )
        scipy_values[label] = vals
    sc_eval = {k: Timing.from_json(v["eval"]) for k, v in scipy_runs.items()}
    best_eval = min(sc_eval, key=lambda k: sc_eval[k].median)

    # ---------------------------------------------------------------- 2. evaluation
    log(f"evaluate {n_points:,}: ours")
    t_eval = timeit_median(lambda: surface.evaluate(X), R_MED, 1)
    ours_vals = ours_i.evaluate(X)  # the interpolate() surface: the same problem scipy solves
    same_as_from_mesh = float(np.abs(ours_vals - t_eval.result).max())
    log(f"evaluate {n_points:,}: ferreus-rbf direct (one-shot evaluate)")
    t_f_direct = timeit_median(lambda: np.ravel(f_direct.evaluate(X)), R_MED, 1)
    log(f"evaluate {n_points:,}: ferreus-rbf FMM (one-shot evaluate)")
    t_f_fmm = timeit_median(lambda: np.ravel(f_fmm.evaluate(X)), R_MED, 1)
    # FMM with the evaluator built once and excluded from the timing
    ext = np.concatenate([np.minimum(P.min(0), X.min(0)), np.maximum(P.max(0), X.max(0))])
    t_f_fmm_build = timeit_median(lambda: f_fmm.build_evaluator(ext), R_FAST if not quick else 1, 0)
    t_f_fmm_targets = timeit_median(lambda: np.ravel(f_fmm.evaluate_targets(X)), R_MED, 1)

    scipy_vals = np.load(scipy_values[best_eval])
    scale = float(np.abs(scipy_vals).max())
    diff_scipy = float(np.abs(ours_vals - scipy_vals).max())
    rel_scipy = diff_scipy / scale
    diff_f_direct = float(np.abs(ours_vals - t_f_direct.result).max())
    diff_f_fmm = float(np.abs(ours_vals - t_f_fmm.result).max())
    diff_f_fmm_targets = float(np.abs(ours_vals - t_f_fmm_targets.result).max())
    if not rel_scipy <= REL_TOL:
        msg = (
            f"ours (interpolate) and scipy RBFInterpolator differ by {diff_scipy:.3e} "
            f"({rel_scipy:.3e} relative to max|f| = {scale:.3g}) > {REL_TOL:g}"
        )
        warnings.append(msg)
        sys.stderr.write("\n" + "!" * 78 + f"\n!!! WARNING: {msg}\n" + "!" * 78 + "\n\n")

    # ---------------------------------------------------------------- 3. dense polygonization
    log(f"polygonize {res}³ dense: ours")
    t_poly = timeit_median(lambda: polygonize(surface, resolution=res, method="dense"), R_MED, 1)
    mesh = t_poly.result
    t_poly_nn = timeit_median(
        lambda: polygonize(surface, resolution=res, method="dense", normals=False), R_MED, 1
    )
    grid_label = best_eval
    grid_threads = dict(THREAD_CONFIGS_INV)[grid_label]
    log(f"polygonize {res}³: scipy grid + skimage marching_cubes ({grid_label}), {R_GRID} run(s)")
    sc_grid = run_scipy(
        data, "grid", grid_threads, None, {"grid_runs": R_GRID, "grid_warmup": 0, "runs": 1, "warmup": 0}
    )

    h_cells = (hi - lo) / res
    h_iso = float(np.prod(h_cells) ** (1.0 / 3.0))  # same cell volume → same number of cells
    extents = np.concatenate([lo, hi])
    log(f"isosurface: ferreus-rbf build_isosurface(resolution={h_iso:.5f})")
    t_f_iso = timeit_median(lambda: f_direct.build_isosurface(extents, h_iso, 0.0), R_MED, 1)
    f_iso = t_f_iso.result
    f_iso_tris = int(np.asarray(f_iso.facets).shape[0])
    f_iso_verts = int(np.asarray(f_iso.vertices).shape[0])
    # exact evaluation count of ferreus's isosurfacer: its module-level build_isosurface with a
    # counting callback (seeded with the source points, as the method presumably is)
    counter = {"points": 0, "calls": 0}

    def counting(x):
        counter["points"] += len(x)
        counter["calls"] += 1
        return np.ravel(f_direct.evaluate(x))

    f_iso2 = isosurfacing.build_isosurface(P, extents, h_iso, 0.0, counting)
    f_iso2_tris = int(np.asarray(f_iso2.facets).shape[0])

    if _mtime(implicitmesh._core.__file__) != core_built:
        warnings.append("implicitmesh's extension was rebuilt during this run (another engineer?): "
                        "numbers are for the build loaded at the start.")
    tmp.cleanup()
    raw = {
        "points": n_points,
        "resolution": res,
        "vertices": len(vertices),
        "constraints": len(P),
        "implicitmesh_version": implicitmesh.__version__,
        "extension_built": core_built,
        "fit": {
            "ours_from_mesh": t_from_mesh.to_json(),
            "ours_from_mesh_residual": float(surface.residual),
            "ours_interpolate": t_interp.to_json(),
            "ours_interpolate_residual": ours_fit_resid,
            "ferreus": {k: t.to_json() for k, t in ferreus_fit.items()},
            "ferreus_residual": ferreus_resid,
        },
        "scipy": scipy_runs,
        "evaluation": {
            "ours": t_eval.to_json(),
            "ferreus_direct": t_f_direct.to_json(),
            "ferreus_fmm": t_f_fmm.to_json(),
            "ferreus_fmm_targets": t_f_fmm_targets.to_json(),
            "ferreus_fmm_build": t_f_fmm_build.to_json(),
            "scipy_max_abs": scale,
            "diff_scipy": diff_scipy,
            "diff_ferreus_direct": diff_f_direct,
            "diff_ferreus_fmm": diff_f_fmm,
            "diff_ferreus_fmm_targets": diff_f_fmm_targets,
            "diff_from_mesh_interpolate": same_as_from_mesh,
        },
        "polygonization": {
            "ours": t_poly.to_json(),
            "ours_evaluations": int(mesh.stats["evaluations"]),
            "ours_normal_evaluations": int(mesh.stats["normal_evaluations"]),
            "ours_triangles": len(mesh.faces),
            "ours_vertices": len(mesh.vertices),
            "ours_no_normals": t_poly_nn.to_json(),
            "ours_no_normals_evaluations": int(t_poly_nn.result.stats["evaluations"]),
            "ours_no_normals_triangles": len(t_poly_nn.result.faces),
            "ours_no_normals_vertices": len(t_poly_nn.result.vertices),
            "scipy_threads": grid_label,
            "scipy_skimage": sc_grid,
            "lo": lo.tolist(),
            "hi": hi.tolist(),
            "ferreus_step": h_iso,
            "ferreus": t_f_iso.to_json(),
            "ferreus_triangles": f_iso_tris,
            "ferreus_vertices": f_iso_verts,
            "ferreus_counted_evaluations": counter["points"],
            "ferreus_counted_batches": counter["calls"],
            "ferreus_counted_triangles": f_iso2_tris,
        },
        "warnings": warnings,
        "run": run.finish(("numpy", "scipy", "scikit-image", "ferreus_rbf", "implicitmesh")),
    }
    log(f"load average after: {raw['run']['loadavg_after']}; "
        f"other processes used {raw['run']['foreign_load']} cores on average")
    return raw


def render(raw: dict) -> str:
    run = raw["run"]
    quick = run["quick"]
    n_points, res = raw["points"], raw["resolution"]
    n_vertices, n_constraints = raw["vertices"], raw["constraints"]
    fit, ev, po = raw["fit"], raw["evaluation"], raw["polygonization"]
    scipy_runs = raw["scipy"]
    warnings = raw["warnings"]
    t_from_mesh = Timing.from_json(fit["ours_from_mesh"])
    t_interp = Timing.from_json(fit["ours_interpolate"])
    ferreus_fit = {k: Timing.from_json(v) for k, v in fit["ferreus"].items()}
    ferreus_resid = fit["ferreus_residual"]
    sc_fit = {k: Timing.from_json(v["fit"]) for k, v in scipy_runs.items()}
    sc_eval = {k: Timing.from_json(v["eval"]) for k, v in scipy_runs.items()}
    best_fit = min(sc_fit, key=lambda k: sc_fit[k].median)
    best_eval = min(sc_eval, key=lambda k: sc_eval[k].median)
    t_eval = Timing.from_json(ev["ours"])
    t_f_direct = Timing.from_json(ev["ferreus_direct"])
    t_f_fmm = Timing.from_json(ev["ferreus_fmm"])
    t_f_fmm_targets = Timing.from_json(ev["ferreus_fmm_targets"])
    t_f_fmm_build = Timing.from_json(ev["ferreus_fmm_build"])
    scale, diff_scipy = ev["scipy_max_abs"], ev["diff_scipy"]
    rel_scipy = diff_scipy / scale
    t_poly = Timing.from_json(po["ours"])
    t_poly_nn = Timing.from_json(po["ours_no_normals"])
    grid_label = po["scipy_threads"]
    sc_grid = po["scipy_skimage"]
    t_sc_grid = Timing.from_json(sc_grid["grid"])
    t_f_iso = Timing.from_json(po["ferreus"])
    lo, hi, h_iso = po["lo"], po["hi"], po["ferreus_step"]
    h_cells = [(b - a) / res for a, b in zip(lo, hi)]

    threads_note = {
        label: f"numpy {r['openblas_threads'].get('numpy', '?')} / scipy {r['openblas_threads'].get('scipy', '?')} threads"
        for label, r in scipy_runs.items()
    }
    L: list[str] = []
    L.append(f"## Variational (RBF) surfaces: fit, evaluation, dense polygonization{' (QUICK)' if quick else ''}")
    L.append("")
    L.append(
        f"Run {run['date']} with `{run['command']}`. "
        f"Problem: bundled `knot` model, {n_vertices} vertices, `VariationalSurface.from_mesh` → "
        f"{n_constraints:,} constraints (r³ kernel, linear polynomial); every peer interpolates the same "
        f"{n_constraints:,} points and values. Times are wall-clock medians in seconds after one untimed "
        "warm-up run unless stated; *runs* = timed runs; *CPU/wall* ≈ busy threads; "
        "ratio = peer / ours (above 1: ours is faster)."
    )
    L.append("")
    run_foreign = run["foreign_load"]
    L.append(machine_markdown(run["machine"], {
        "implicitmesh": f"{raw['implicitmesh_version']} (Rust core, its own threads; OpenBLAS not used; "
        f"extension built {raw['extension_built']})",
        "scipy runs (subprocesses)": "; ".join(f"{k}: {v}" for k, v in threads_note.items()),
        "load average (1/5/15 min) before → after": f"{tuple(run['loadavg_before'])} → {tuple(run['loadavg_after'])}",
        "other processes during the run": "—" if run_foreign is None else
        f"{run_foreign:.2f} of {run['machine']['cores']} cores on average (machine busy time from /proc/stat minus this "
        "run's own CPU time; column *other load* gives the same per case, over its timed runs)",
    }))
    L.append("")

    # 1. fit
    L.append(f"### 1. Fit of {n_constraints:,} constraints")
    L.append("")
    fi, fm = t_interp.median, t_from_mesh.median
    rows = [
        ["ours `from_mesh` (normals + constraint placement + solve)", fmt_s(fm), t_from_mesh.runs,
         _cpw(t_from_mesh), _fl(t_from_mesh), "—", "—", f"{fit['ours_from_mesh_residual']:.1e}"],
        ["ours `interpolate(points, values)`", fmt_s(fi), t_interp.runs, _cpw(t_interp), _fl(t_interp), "—", "—",
         f"{fit['ours_interpolate_residual']:.1e}"],
    ]
    for label in sc_fit:
        t = sc_fit[label]
        mark = " **(faster, reported)**" if label == best_fit else ""
        rows.append([f"scipy `RBFInterpolator(kernel='cubic', degree=1)`, {label}{mark}", fmt_s(t.median), t.runs,
                     _cpw(t), _fl(t), fmt_ratio(t.median, fi), fmt_ratio(t.median, fm),
                     f"{scipy_runs[label]['fit_residual']:.1e}"])
    for name, desc in (("default", "defaults (FGMRES + DDM, rel. tol 1e-6)"),
                       ("direct", "direct solve (`naive_solve_threshold=4096`)")):
        t = ferreus_fit[name]
        rows.append([f"ferreus-rbf Cubic + Linear drift, {desc}", fmt_s(t.median), t.runs, _cpw(t), _fl(t),
                     fmt_ratio(t.median, fi), fmt_ratio(t.median, fm), f"{ferreus_resid[name]:.1e}"])
    L.append(md_table(["case", "s", "runs", "CPU/wall", "other load", "ratio vs ours interpolate", "ratio vs ours from_mesh",
                       "max residual at constraints"], rows))
    L.append("")

    # 2. evaluation
    L.append(f"### 2. Evaluation of {n_points:,} random points in [-1, 1]³, {n_constraints:,} centres")
    L.append("")
    te = t_eval.median
    rows = [["ours `surface.evaluate`", fmt_s(te), t_eval.runs, _cpw(t_eval), _fl(t_eval), "—", "0 (reference)"]]
    for label in sc_eval:
        t = sc_eval[label]
        mark = " **(faster, reported)**" if label == best_eval else ""
        d = f"{diff_scipy:.1e}" if label == best_eval else "(same code)"
        rows.append([f"scipy `RBFInterpolator.__call__`, {label}{mark}", fmt_s(t.median), t.runs, _cpw(t), _fl(t),
                     fmt_ratio(t.median, te), d])
    rows.append(["ferreus-rbf direct, one-shot `evaluate`", fmt_s(t_f_direct.median), t_f_direct.runs,
                 _cpw(t_f_direct), _fl(t_f_direct), fmt_ratio(t_f_direct.median, te), f"{ev['diff_ferreus_direct']:.1e}"])
    rows.append(["ferreus-rbf FMM, one-shot `evaluate` (builds the FMM tree)", fmt_s(t_f_fmm.median), t_f_fmm.runs,
                 _cpw(t_f_fmm), _fl(t_f_fmm), fmt_ratio(t_f_fmm.median, te), f"{ev['diff_ferreus_fmm']:.1e}"])
    rows.append(["ferreus-rbf FMM, `evaluate_targets` with a prebuilt evaluator", fmt_s(t_f_fmm_targets.median),
                 t_f_fmm_targets.runs, _cpw(t_f_fmm_targets), _fl(t_f_fmm_targets), fmt_ratio(t_f_fmm_targets.median, te),
                 f"{ev['diff_ferreus_fmm_targets']:.1e}"])
    rows.append(["(ferreus-rbf FMM `build_evaluator` alone, no warm-up)", fmt_s(t_f_fmm_build.median),
                 t_f_fmm_build.runs, _cpw(t_f_fmm_build), _fl(t_f_fmm_build), "", ""])
    L.append(md_table(["case", "s", "runs", "CPU/wall", "other load", "ratio peer/ours", "max abs diff vs ours interpolate"], rows))
    L.append("")
    verdict = "OK" if rel_scipy <= REL_TOL else "**WARNING: above tolerance**"
    L.append(
        f"Agreement with scipy on the same interpolation problem (ours = `interpolate`): max |Δ| = "
        f"{diff_scipy:.2e}, {rel_scipy:.1e} relative to max |f| = {scale:.3g} (tolerance {REL_TOL:g}): {verdict}. "
        f"`from_mesh` and `interpolate` surfaces differ by {ev['diff_from_mesh_interpolate']:.1e} at these points."
    )
    L.append("")

    # 3. polygonization
    n_lat = (res + 1) ** 3
    L.append(f"### 3. Dense polygonization, {res}³ cells ({n_lat:,} lattice points) over `surface.bounds`")
    L.append("")
    tp = t_poly.median
    ge, gm = sc_grid["grid_eval_times"], sc_grid["grid_mc_times"]
    rows = [
        ["ours `polygonize(surface, resolution=%d, method='dense')` (with normals)" % res, fmt_s(tp), t_poly.runs,
         _cpw(t_poly), _fl(t_poly), "—", f"{po['ours_evaluations']:,} (+{po['ours_normal_evaluations']:,} gradients)",
         f"{po['ours_triangles']:,}", f"{po['ours_vertices']:,}"],
        ["ours, `normals=False`", fmt_s(t_poly_nn.median), t_poly_nn.runs, _cpw(t_poly_nn), _fl(t_poly_nn),
         fmt_ratio(t_poly_nn.median, tp) + " (of ours with normals)", f"{po['ours_no_normals_evaluations']:,}",
         f"{po['ours_no_normals_triangles']:,}", f"{po['ours_no_normals_vertices']:,}"],
        [f"scipy grid evaluation + skimage `marching_cubes` ({grid_label}; no warm-up)", fmt_s(t_sc_grid.median),
         t_sc_grid.runs, _cpw(t_sc_grid), _fl(t_sc_grid), fmt_ratio(t_sc_grid.median, tp), f"{sc_grid['grid_evaluations']:,}",
         f"{sc_grid['grid_triangles']:,}", f"{sc_grid['grid_vertices']:,}"],
        ["  of which scipy grid evaluation", fmt_s(_median(ge)), len(ge), "", "", fmt_ratio(_median(ge), tp), "", "", ""],
        ["  of which skimage marching_cubes (Lewiner)", fmt_s(_median(gm)), len(gm), "", "", "", "", ""],
        [f"ferreus-rbf `build_isosurface(extents, resolution={h_iso:.5f}, isovalue=0.0)` (marching tetrahedra, "
         "seeded)", fmt_s(t_f_iso.median), t_f_iso.runs, _cpw(t_f_iso), _fl(t_f_iso), fmt_ratio(t_f_iso.median, tp),
         f"{po['ferreus_counted_evaluations']:,} ({po['ferreus_counted_batches']} batches)†",
         f"{po['ferreus_triangles']:,}", f"{po['ferreus_vertices']:,}"],
    ]
    L.append(md_table(["case", "s", "runs", "CPU/wall", "other load", "ratio peer/ours", "field evaluations (exact)",
                       "triangles", "vertices"], rows))
    L.append("")
    L.append(
        f"Our lattice: cells of {h_cells[0]:.5f} × {h_cells[1]:.5f} × {h_cells[2]:.5f} over "
        f"[{', '.join(f'{v:.4f}' for v in lo)}] – [{', '.join(f'{v:.4f}' for v in hi)}]. ferreus-rbf takes one "
        f"isotropic step; we gave it the geometric mean {h_iso:.5f} (same cell volume, so about the same number "
        "of cells in the box). Its extractor is seeded and follows the surface, so it evaluates far fewer "
        "points than a dense lattice: its evaluation count is not comparable to dense marching cubes. "
        f"† counted with `ferreus_rbf.isosurfacing.build_isosurface(points, extents, {h_iso:.5f}, 0.0, fn)` "
        f"seeded with the {n_constraints:,} source points and a counting `fn` (same mesh size: {po['ferreus_counted_triangles']:,} "
        "triangles); includes its central-difference gradient evaluations."
    )
    L.append("")
    if warnings:
        L.append("**Warnings:** " + " ".join(warnings))
        L.append("")
    return "\n".join(L)


THREAD_CONFIGS_INV = tuple((label, threads) for threads, label in THREAD_CONFIGS)


def _mtime(path: str) -> str:
    try:
        return _dt.datetime.fromtimestamp(os.path.getmtime(path)).astimezone().strftime("%Y-%m-%d %H:%M %Z")
    except OSError:
        return "unknown"


def _median(xs):
    import statistics

    return statistics.median(xs) if xs else None


def parse(argv=None) -> argparse.Namespace:
    p = section_parser(__doc__.split("\n")[0], "smoke test: 10^5 points, 64³, fewer runs")
    p.add_argument("--points", type=int, default=None, help="evaluation points (default 10^6, quick 10^5)")
    p.add_argument("--resolution", type=int, default=None, help="polygonization cells per axis (default 128, quick 64)")
    # worker mode (internal)
    p.add_argument("--worker", choices=["scipy"], help=argparse.SUPPRESS)
    p.add_argument("--data", help=argparse.SUPPRESS)
    p.add_argument("--tasks", default="fit,eval", help=argparse.SUPPRESS)
    p.add_argument("--runs", type=int, default=5, help=argparse.SUPPRESS)
    p.add_argument("--warmup", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument("--eval-runs", type=int, default=3, help=argparse.SUPPRESS)
    p.add_argument("--eval-warmup", type=int, default=1, help=argparse.SUPPRESS)
    p.add_argument("--grid-runs", type=int, default=2, help=argparse.SUPPRESS)
    p.add_argument("--grid-warmup", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--values-out", help=argparse.SUPPRESS)
    p.add_argument("--json-out", help=argparse.SUPPRESS)
    return p.parse_args(argv)


def main(argv=None) -> int:
    a = parse(argv)
    if a.worker == "scipy":
        return scipy_worker(a)
    return record_section("rbf", measure, render, a)


if __name__ == "__main__":
    sys.exit(main())
