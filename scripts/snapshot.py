"""Record every polygonizer's, fit's and subdivision's output arrays, or compare two records.

A refactoring that must not change behaviour is proven by running ``save`` before and after it
(each with its own build installed) and ``compare``: every array must be equal, bit for bit.

    python scripts/snapshot.py save before.npz
    python scripts/snapshot.py save after.npz
    python scripts/snapshot.py compare before.npz after.npz
"""

from __future__ import annotations

import sys

import numpy as np

import implicitmesh as im

BOX = [[-1.2, -1.2, -1.2], [1.2, 1.2, 1.2]]


def _mesh(out: dict, name: str, mesh) -> None:
    out[f"{name}/vertices"] = mesh.vertices
    out[f"{name}/faces"] = mesh.faces
    out[f"{name}/normals"] = mesh.normals
    for key, value in sorted(mesh.stats.items()):
        if key != "seconds" and isinstance(value, (int, float, np.integer)) and not isinstance(value, bool) and "second" not in key:
            out[f"{name}/stats/{key}"] = np.asarray(value)


def _surface(out: dict, name: str, s, probe: np.ndarray) -> None:
    out[f"{name}/values"] = s.evaluate(probe)
    out[f"{name}/gradients"] = s.gradient(probe)
    state = s.to_state()
    for key, value in sorted(state.items()):
        if isinstance(value, np.ndarray):
            out[f"{name}/state/{key}"] = value


def record() -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    rng = np.random.default_rng(7)
    probe = rng.uniform(-1.2, 1.2, (2000, 3))
    vertices, faces = im.shapes.load_model("knot")
    hv, hf = im.shapes.load_model("spot") if hasattr(im.shapes, "load_model") else (vertices, faces)

    fields = {}
    fields["knot"] = im.VariationalSurface.from_mesh(vertices, faces)
    # Points with normals from the knot's faces, enough for the partition fit.
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    pick = rng.integers(0, len(faces), 6000)
    a, b = rng.random((2, 6000))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    pts = tri[pick, 0] + a[:, None] * (tri[pick, 1] - tri[pick, 0]) + b[:, None] * (tri[pick, 2] - tri[pick, 0])
    fields["partition"] = im.VariationalSurface.fit(pts, n[pick], exact=True)
    fields["global"] = im.VariationalSurface.fit(pts[:1500], n[pick][:1500], method="global", exact=True)
    fields["within"] = im.VariationalSurface.fit(pts, n[pick], tolerance=1e-3, exact=True)
    for name, s in fields.items():
        _surface(out, f"fit/{name}", s, probe)
    centers = rng.uniform(-0.8, 0.8, (200, 3))
    fields["blobs"] = im.BlobField(centers, 0.25)
    particles = rng.uniform(-0.5, 0.5, (4000, 3))
    fields["particles"] = im.BlobField.from_particles(particles, 0.03)
    fields["sphere"] = lambda p: np.linalg.norm(p, axis=1) - 0.8

    for name, f in fields.items():
        res = 48 if name in ("partition", "within") else 64
        for method in ("dense", "octree", "tracking", "sparse"):
            if method == "sparse" and name not in ("blobs", "particles"):
                continue
            extra = {"seeds": [[0.8, 0.0, 0.0]]} if method == "tracking" and name == "sphere" else {}
            mesh = im.polygonize(f, bounds=BOX, resolution=res, method=method, **extra)
            _mesh(out, f"polygonize/{name}/{method}", mesh)
    tess = im.Tessellator()
    blobs = fields["blobs"]
    for frame in range(3):
        blobs.update(centers + 0.01 * frame)
        _mesh(out, f"tessellator/{frame}", tess.polygonize(blobs, bounds=BOX, resolution=48))
    for k, level in enumerate(im.subdivide(vertices, faces, levels=2)):
        _mesh(out, f"subdivide/{k}", level)
    bf = im.butterfly(vertices, faces, levels=2)
    for k, level in enumerate(bf):
        _mesh(out, f"butterfly/{k}", level)
    sub = im.subdivide(vertices, faces, levels=2)
    _mesh(out, "blend", im.blend(sub[-1], bf[-1], 0.5))
    return out


def compare(a_path: str, b_path: str) -> int:
    a, b = np.load(a_path), np.load(b_path)
    missing = sorted(set(a.files) ^ set(b.files))
    differ = [k for k in sorted(set(a.files) & set(b.files)) if a[k].shape != b[k].shape or a[k].dtype != b[k].dtype or a[k].tobytes() != b[k].tobytes()]
    same = len(set(a.files) & set(b.files)) - len(differ)
    print(f"{same} arrays equal, {len(differ)} differ, {len(missing)} in one record only")
    for k in differ + missing:
        print("  ", k)
    return 0 if not differ and not missing else 1


if __name__ == "__main__":
    if sys.argv[1] == "save":
        np.savez(sys.argv[2], **record())
    else:
        sys.exit(compare(sys.argv[2], sys.argv[3]))
