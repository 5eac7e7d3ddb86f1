"""The real-frame cases of ``benchmarks.bench_particles``: frames of SPlisHSPlasH's dam break
(:mod:`benchmarks.sph_frames`) meshed by our colour field and by splashsurf, plain and smoothed,
with the smoothness of each mesh on the pool's flat parts (:mod:`benchmarks.smoothness`).

A case is (scene, method, frame) with the scene a layout of ``bench_particles``
(``dam-break-1e5``, ``dam-break-5e5``) and the frame given by its simulated time in
milliseconds (its "particles" slot). With r the frame's particle radius (particles 2r apart):

- ``splashsurf-f32``: ``pysplashsurf.reconstruct_surface(P, particle_radius=r, smoothing_length=2.0,
  cube_size=0.5, iso_surface_threshold=0.6)``, P float32 (support 4r, cells r/2);
- ``splashsurf-smooth-f32``: its ``reconstruction_pipeline`` at the same parameters with
  ``mesh_smoothing_weights=True, mesh_smoothing_iters=25, normals_smoothing_iters=10,
  mesh_cleanup=True`` (Löschner et al.'s weighted Laplacian smoothing, Moore and Warren's cleanup);
- ``colour``, ``colour-f32``: ``BlobField.from_particles(P, r, precision=...)`` (splashsurf's colour
  field) meshed by ``polygonize(method="sparse")`` over cells of exactly r/2, normals off;
- ``colour-aniso-f32``: the same with ``anisotropic=True`` (Yu and Turk's kernels); skipped with a
  message while ``BlobField.from_particles`` does not take that argument.

:data:`METHODS` is the list to extend: a name and a function ``(P, r) -> (vertices, faces,
facts)`` in :data:`RECONSTRUCT`.
"""

from __future__ import annotations

import time
from typing import Callable

from benchmarks import sph_frames

#: The frame layouts (scenes).
SCENES = tuple(sph_frames.SCENES)
#: The colour field's threshold (splashsurf's default).
ISO = 0.6
#: Smoothing of splashsurf's pipeline (the issue's settings).
SMOOTHING = {"mesh_smoothing_weights": True, "mesh_smoothing_iters": 25, "normals_smoothing_iters": 10,
             "mesh_cleanup": True}


class Skipped(Exception):
    """A method this installation cannot run yet (the message says why)."""


def cpu_seconds() -> float:
    """User and system CPU seconds of this process so far (all threads)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def mesh_arrays(m) -> tuple:
    """(vertices float64, faces int64) of a pysplashsurf mesh (or mesh-with-data)."""
    import numpy as np

    m = getattr(m, "mesh", m)
    v, f = (m.vertices, m.triangles) if hasattr(m, "vertices") else m
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


def splashsurf(p, r: float, smooth: bool) -> tuple:
    import numpy as np
    import pysplashsurf

    q = np.ascontiguousarray(p, dtype=np.float32)
    args = dict(particle_radius=r, smoothing_length=2.0, cube_size=0.5, iso_surface_threshold=ISO)
    t, c = time.perf_counter(), cpu_seconds()
    if smooth:
        out = pysplashsurf.reconstruction_pipeline(q, **args, **SMOOTHING)
        mesh = out[0] if isinstance(out, tuple) else out
    else:
        mesh = pysplashsurf.reconstruct_surface(q, **args)
    facts = {"total_s": time.perf_counter() - t, "cpu_s": cpu_seconds() - c}
    v, f = mesh_arrays(mesh)
    return v, f, facts


def lattice(p, r: float):
    """Bounds and cells per axis with cells of exactly r/2 around the particles (a margin of the
    support 4r and two cells)."""
    import numpy as np

    h = r / 2
    lo = p.min(axis=0) - 4 * r - 2 * h
    cells = np.ceil((p.max(axis=0) + 4 * r + 2 * h - lo) / h).astype(int)
    return np.stack([lo, lo + cells * h]), [int(c) for c in cells]


def colour(p, r: float, precision: str, anisotropic: bool = False, normals: bool = False) -> tuple:
    import inspect

    import implicitmesh as im

    extra = {}
    if anisotropic:
        if "anisotropic" not in inspect.signature(im.BlobField.from_particles).parameters:
            raise Skipped("BlobField.from_particles takes no anisotropic argument in this build")
        extra["anisotropic"] = True
    bounds, cells = lattice(p, r)
    t, c = time.perf_counter(), cpu_seconds()
    field = im.BlobField.from_particles(p, r, iso_surface_threshold=ISO, precision=precision, **extra)
    field_s = time.perf_counter() - t
    mesh = im.polygonize(field, bounds=bounds, resolution=cells, method="sparse", normals=normals)
    total = time.perf_counter() - t
    facts = {"total_s": total, "cpu_s": cpu_seconds() - c, "field_s": field_s, "polygonize_s": total - field_s,
             "evaluations": int(mesh.stats["evaluations"])}
    return mesh.vertices, mesh.faces, facts


#: Method name → reconstruction ``(P float64 (N, 3), r) -> (vertices, faces, facts)``.
RECONSTRUCT: dict[str, Callable] = {
    "splashsurf-f32": lambda p, r: splashsurf(p, r, smooth=False),
    "splashsurf-smooth-f32": lambda p, r: splashsurf(p, r, smooth=True),
    "colour-f32": lambda p, r: colour(p, r, "single"),
    "colour": lambda p, r: colour(p, r, "double"),
    "colour-aniso-f32": lambda p, r: colour(p, r, "single", anisotropic=True),
}
#: The methods, in the order they run and are shown.
METHODS = tuple(RECONSTRUCT)
#: Frames (simulated milliseconds) of each scene that the benchmark runs by default.
FRAMES = {"dam-break-1e5": (900, 1000, 1200), "dam-break-5e5": (600, 700, 800)}


def frame_particles(scene: str, ms: int):
    """The particles of a frame, float64 (P, 3) z up, and the scene's facts (``scene.json``)."""
    info = sph_frames.scene_info(scene)
    if info is None:
        raise Skipped(f"no frames of {scene}: make them with `python -m benchmarks.sph_frames {scene}`")
    if not any(f["time"] == ms / 1000 for f in info["frames"]):
        raise Skipped(f"no frame at {ms / 1000} s of {scene} (frames at "
                      f"{', '.join(str(f['time']) for f in info['frames'])} s)")
    return sph_frames.load_frame(scene, ms / 1000), info


def one(scene: str, method: str, ms: int, peak: Callable[[], float]) -> dict:
    """One case in this process: the mesh timed, then (untimed, after the peak memory is read)
    its triangles, enclosed volume and smoothness on the frame's flat patches."""
    from benchmarks import smoothness

    try:
        p, info = frame_particles(scene, ms)
        r = float(info["particle_radius"])
        v, f, out = RECONSTRUCT[method](p, r)
    except Skipped as e:
        return {"layout": scene, "method": method, "n": ms, "skipped": str(e)}
    out["peak_mib"] = peak()
    box = info["box"]
    patches = smoothness.flat_patches(p, r, walls=(box[0][:2], box[1][:2]), floor=box[0][2])
    out.update(layout=scene, method=method, n=ms, particles=int(len(p)), particle_radius=r, triangles=int(len(f)),
               volume=smoothness.enclosed_volume(v, f), flat_patches=int(len(patches)),
               **smoothness.smoothness(v, f, patches, r))
    return out


def render(raw: dict, ratio: Callable, seconds: Callable, median: Callable, table: Callable) -> list[str]:
    """The real frames' paragraph and table (no lines when the results hold no frame case)."""
    cases = [c for c in raw["cases"] if c["layout"] in SCENES]
    if not cases:
        return []
    by = {(c["layout"], c["method"], c["n"]): c["runs"] for c in cases}
    rows, skipped = [], {}
    for c in cases:
        runs = c["runs"]
        r0 = runs[0]
        if "skipped" in r0:
            skipped.setdefault(r0["skipped"], []).append(c["method"])
            continue
        head = [c["layout"], f"{c['n'] / 1000:.1f} s", f"{r0.get('particles', 0):,}", c["method"]]
        if "error" in r0:
            rows.append(head + [f"failed: {r0['error']}"] + [""] * 10)
            continue
        total = median(runs, "total_s")
        peer = by.get((c["layout"], "splashsurf-f32", c["n"]))
        iso = by.get((c["layout"], "colour", c["n"])) or by.get((c["layout"], "colour-f32", c["n"]))
        dv = "—"
        if iso and "volume" in iso[0]:
            dv = f"{100 * (r0['volume'] / iso[0]['volume'] - 1):+.2f} %"
        ok = peer and "total_s" in peer[0]
        cpu = median(runs, "cpu_s")
        rows.append(head + [seconds(total), seconds(cpu), ratio(median(peer, "total_s"), total) if ok else "—",
                            ratio(median(peer, "cpu_s"), cpu) if ok else "—",
                            f"{median(runs, 'peak_mib'):,.0f}", f"{r0['triangles']:,}", f"{r0['volume']:.4f}", dv,
                            "—" if r0.get("plane_rms_r") is None else f"{r0['plane_rms_r']:.4f}",
                            "—" if r0.get("normal_angle_deg") is None else f"{r0['normal_angle_deg']:.2f}",
                            f"{r0.get('patches', 0)} / {r0.get('flat_patches', 0)}"])
    lines = [
        "### Real frames: SPlisHSPlasH's dam break",
        "",
        "Frames of a real simulation (`python -m benchmarks.sph_frames`): SPlisHSPlasH 2.19 (`pip install "
        "pysplishsplash`, DFSPH) runs its `DamBreakModel.json` with the fluid block enlarged to 1 × 1 × 1.4 m in a "
        "4 × 1.5 m tank, particle radius r = 0.0125 m (`dam-break-1e5`) or 0.007 m (`dam-break-5e5`); the frame's "
        "simulated time in the table (the wave's front reaches the far wall at about 0.85 s and climbs it). With r the particle radius (particles 2r "
        "apart): `splashsurf-f32` is `reconstruct_surface(P, particle_radius=r, smoothing_length=2.0, "
        "cube_size=0.5, iso_surface_threshold=0.6)` on float32 particles (support 4r, cells r/2); "
        "`splashsurf-smooth-f32` its `reconstruction_pipeline` at the same parameters with "
        "`mesh_smoothing_weights=True, mesh_smoothing_iters=25, normals_smoothing_iters=10, mesh_cleanup=True`; "
        "`colour` and `colour-f32` are `BlobField.from_particles(P, r, precision=\"double\" / \"single\")` meshed by "
        "`polygonize(method=\"sparse\")` over cells of r/2, normals off. Each case in a fresh process, medians "
        "over the runs (CPU s: user and system seconds of all threads over the same span), peak resident size "
        "VmHWM (particles included).",
        "",
        "Smoothness on the pool's flat parts (`benchmarks/smoothness.py`): patches 10 r across, chosen from the "
        "particles (the same patches for every method: columns filled from the floor, tops within 10° of "
        "horizontal and 2r of a plane, at least 20 r from the walls); plane RMS is the root mean square distance "
        "of a patch's vertices from its own least-squares plane, in units of r; normal angle the mean angle "
        "between neighbouring faces' normals there; patches measured / flat patches. ΔV is the enclosed volume "
        "against our isotropic colour field's.",
        "",
        table(["scene", "frame", "particles", "method", "seconds", "CPU s", "splashsurf f32 / ours",
               "the same in CPU s", "peak MiB", "triangles", "volume m³", "ΔV", "plane RMS / r", "normal angle °",
               "patches"], rows, "llrlrrrrrrrrrrr"),
        "",
    ]
    run = raw["run"]
    busy = run.get("foreign_load")
    if busy is not None and busy > 0.3 and ("--cases" not in run["command"] or any(x in run["command"] for x in SCENES)):
        lines[-2:-2] = [
            f"Measured in the run of {run['date']} while other processes kept {busy:.2f} cores busy on average (of "
            f"{run['machine']['cores']}): the wall-clock seconds and their ratios varied by up to 2× between "
            "neighbouring cases; the CPU seconds (all threads of the process) are the steadier comparison.", ""]
    lines += [f"- skipped ({', '.join(f'`{m}`' for m in dict.fromkeys(methods))}): {why}"
              for why, methods in skipped.items()]
    return lines + ([""] if skipped else [])
