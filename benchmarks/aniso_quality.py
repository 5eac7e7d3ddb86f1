"""Anisotropic kernels against round ones on the ``slab`` layout of ``bench_particles``: time from
particles to mesh (``method="sparse"``, normals off, cells of r/2), the fluid's volume, and the
smoothness of the slab's flat top (a 10 r × 10 r patch a quarter of the side in from a corner,
away from the sphere): the RMS distance of its vertices to their least-squares plane, and the
mean angle between the normals of faces sharing an edge.

    python -m benchmarks.aniso_quality [--sizes 100000,1000000] [--runs 3] [--precision single]
        [--k-s 1.0] [--smoothing 0.9] [--neighbour-radius 2.0] [--min-neighbours 25] [--k-r 4]

Prints one line per field; not a test (times depend on the machine).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import implicitmesh as im
from benchmarks.bench_particles import S, slab_and_sphere


def flatness(mesh, centre_xy, half, z_min):
    """RMS distance to the fitted plane and mean dihedral angle (degrees) of the patch."""
    v, f = mesh.vertices, mesh.faces
    inside = (np.abs(v[:, 0] - centre_xy[0]) < half) & (np.abs(v[:, 1] - centre_xy[1]) < half) & (v[:, 2] > z_min)
    pts = v[inside]
    a = np.c_[pts[:, 0], pts[:, 1], np.ones(len(pts))]
    coef, *_ = np.linalg.lstsq(a, pts[:, 2], rcond=None)
    n = np.array([-coef[0], -coef[1], 1.0])
    dist = (pts[:, 2] - a @ coef) / np.linalg.norm(n)
    faces = f[inside[f].all(axis=1)]
    tri = v[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.linalg.norm(fn, axis=1)[:, None]
    edges = {}
    pairs = []
    for k, (x, y, z) in enumerate(faces.tolist()):
        for e in ((x, y), (y, z), (z, x)):
            key = (min(e), max(e))
            if key in edges:
                pairs.append((edges[key], k))
            else:
                edges[key] = k
    p = np.array(pairs)
    cos = np.clip((fn[p[:, 0]] * fn[p[:, 1]]).sum(axis=1), -1.0, 1.0)
    return float(np.sqrt((dist**2).mean())), float(np.degrees(np.arccos(cos)).mean()), len(pts)


def run(points, r, anisotropic, precision, runs):
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        f = im.BlobField.from_particles(points, r, precision=precision, anisotropic=anisotropic)
        lo, hi = f.bounds
        cells = int(np.ceil((hi - lo).max() / (0.5 * r)))
        mesh = im.polygonize(f, bounds=(lo, lo + cells * 0.5 * r), resolution=cells, method="sparse", normals=False)
        times.append(time.perf_counter() - t)
    return float(np.median(times)), mesh


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="100000")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--precision", default="double")
    for name, default in (("k-s", None), ("smoothing", None), ("neighbour-radius", None), ("k-r", None), ("k-n", None)):
        ap.add_argument(f"--{name}", type=float, default=default)
    ap.add_argument("--min-neighbours", type=int, default=None)
    a = ap.parse_args()
    options = im.AnisotropyOptions(neighbour_radius=a.neighbour_radius, k_r=a.k_r, k_s=a.k_s, k_n=a.k_n,
                                   min_neighbours=a.min_neighbours, smoothing=a.smoothing)
    r = S / 2
    for n in (int(s) for s in a.sizes.split(",")):
        slab, ball, side = slab_and_sphere(n)
        points = np.vstack([slab, ball])
        top = slab[:, 2].max()
        base = None
        for label, aniso in (("isotropic", False), ("anisotropic", options)):
            t, mesh = run(points, r, aniso, a.precision, a.runs)
            rms, angle, count = flatness(mesh, (side / 4, side / 4), 5 * r, top - 4 * S)
            base = base or (t, mesh.volume)
            print(f"{len(points)} particles {label:12s} {a.precision}: {t:.3f} s ({t / base[0]:.2f}x), "
                  f"volume {mesh.volume:.6g} ({mesh.volume / base[1] - 1:+.2%}), flat patch RMS {rms / r:.4f} r, "
                  f"mean normal angle {angle:.2f} deg ({count} vertices), {len(mesh.faces)} faces", flush=True)


if __name__ == "__main__":
    main()
