"""Shared fixtures and helpers for the implicitmesh test suite.

The development meshes come with the repository, in ``tests/data/meshes`` (``SOURCES.md`` there
says where each came from and its licence). Every mesh is fitted once and polygonized once per
session.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

MESH_DIR = Path(__file__).resolve().parent / "data" / "meshes"

#: The ``_800`` meshes documented in tests/data/meshes/SOURCES.md.
MESH_NAMES = ("fandisk", "icosahedron", "knot", "spot", "star", "torus2")

#: Offset of the normal constraints used for every shared mesh (the papers' value for [-1, 1]³).
D = 0.015

KERNELS = ("triharmonic", "biharmonic", "thin_plate")


def require_mesh_dir() -> Path:
    """The development meshes' folder; a missing file is an error, not a skip."""
    missing = [n for n in MESH_NAMES if not (MESH_DIR / f"{n}_800.ply").is_file()]
    assert not missing, f"development meshes missing from {MESH_DIR}: {missing}"
    return MESH_DIR


def genus_of(euler: int, bodies: int = 1) -> int:
    """Genus of a closed orientable surface with `bodies` components, from its Euler number."""
    assert (2 * bodies - euler) % 2 == 0, f"odd Euler number {euler} for a closed surface"
    return (2 * bodies - euler) // 2


def vertex_normals_area_weighted(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals (what from_mesh documents), computed independently."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    fn = np.cross(b - a, c - a)  # length = twice the area
    n = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def surface_samples(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> np.ndarray:
    """Points on every triangle on a barycentric grid no coarser than `spacing` (deterministic):
    the distance to these points overestimates the distance to the surface by less than `spacing`."""
    out = [vertices]
    tri = vertices[faces]
    longest = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    steps = np.maximum(1, np.ceil(longest / spacing).astype(int))
    for k in np.unique(steps):
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = i + j <= k
        u, w = i[keep] / k, j[keep] / k
        t = tri[steps == k]
        pts = t[:, None, 0] * (1 - u - w)[None, :, None] + t[:, None, 1] * u[None, :, None] + t[:, None, 2] * w[None, :, None]
        out.append(pts.reshape(-1, 3))
    return np.vstack(out)


def winding_number(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Generalised winding number of a closed triangle mesh at `points` (Van Oosterom & Strackee):
    about 1 inside an outward-oriented closed mesh, 0 outside."""
    points = np.asarray(points, dtype=float)
    out = np.zeros(len(points))
    tri = vertices[faces]
    for start in range(0, len(points), 256):
        p = points[start : start + 256]
        a = tri[None, :, 0, :] - p[:, None, :]
        b = tri[None, :, 1, :] - p[:, None, :]
        c = tri[None, :, 2, :] - p[:, None, :]
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("ijk,ijk->ij", a, np.cross(b, c))
        den = (
            la * lb * lc
            + np.einsum("ijk,ijk->ij", a, b) * lc
            + np.einsum("ijk,ijk->ij", b, c) * la
            + np.einsum("ijk,ijk->ij", c, a) * lb
        )
        out[start : start + 256] = (2.0 * np.arctan2(det, den)).sum(axis=1) / (4.0 * np.pi)
    return out


def lattice_points(bounds, n: int) -> np.ndarray:
    """The lattice points of a dense polygonization, with the package's arithmetic
    (origin + i × cell, cell = (max − min) / n), in x-fastest order, as (n+1, n+1, n+1, 3)
    indexed [i, j, k]."""
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    cell = (hi - lo) / n
    i = np.arange(n + 1, dtype=float)
    gx, gy, gz = np.meshgrid(lo[0] + i * cell[0], lo[1] + i * cell[1], lo[2] + i * cell[2], indexing="ij")
    return np.stack([gx, gy, gz], axis=-1)


def count_ambiguous_faces(inside: np.ndarray) -> int:
    """Cube faces of the lattice whose two diagonally opposite corners are inside and the other
    two outside. `inside` is an (n+1, n+1, n+1) bool array."""
    count = 0
    for axis in range(3):
        a = np.moveaxis(inside, axis, 0)
        c00, c11 = a[:, :-1, :-1], a[:, 1:, 1:]
        c01, c10 = a[:, :-1, 1:], a[:, 1:, :-1]
        count += int(np.sum((c00 == c11) & (c01 == c10) & (c00 != c01)))
    return count


class CountingField:
    """Wraps a callable field and records every batched call (number of points per call)."""

    def __init__(self, fn):
        self.fn = fn
        self.sizes: list[int] = []
        self.bad_inputs: list[str] = []

    def __call__(self, points):
        if not (isinstance(points, np.ndarray) and points.dtype == np.float64 and points.ndim == 2 and points.shape[1] == 3):
            self.bad_inputs.append(repr(type(points)))
        self.sizes.append(len(points))
        return self.fn(points)

    @property
    def calls(self) -> int:
        return len(self.sizes)

    @property
    def points(self) -> int:
        return int(sum(self.sizes))


class SharedMeshes:
    """Loads, fits (d=0.015) and polygonizes (64³, default bounds) each shared mesh at most once."""

    def __init__(self, folder: Path):
        self.folder = folder
        self._meshes: dict = {}
        self._surfaces: dict = {}
        self._polygonized: dict = {}

    def trimesh(self, name: str):
        if name not in self._meshes:
            import trimesh

            path = self.folder / f"{name}_800.ply"
            self._meshes[name] = trimesh.load(path, process=False)
        return self._meshes[name]

    def arrays(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        m = self.trimesh(name)
        return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)

    def surface(self, name: str):
        if name not in self._surfaces:
            from implicitmesh import VariationalSurface

            v, f = self.arrays(name)
            self._surfaces[name] = VariationalSurface.from_mesh(v, f, d=D)
        return self._surfaces[name]

    def polygonized(self, name: str):
        if name not in self._polygonized:
            import implicitmesh

            self._polygonized[name] = implicitmesh.polygonize(self.surface(name), resolution=64)
        return self._polygonized[name]


@pytest.fixture(scope="session")
def mesh_dir() -> Path:
    return require_mesh_dir()


@pytest.fixture(scope="session")
def shared(mesh_dir) -> SharedMeshes:
    return SharedMeshes(mesh_dir)


@pytest.fixture(scope="session")
def sphere_data():
    """300 points evenly spread on a sphere of radius 0.8 with outward normals."""
    from implicitmesh import shapes

    return shapes.fibonacci_sphere(300)


@pytest.fixture(scope="session")
def sphere_surfaces(sphere_data):
    """The sphere data fitted with each kernel (default d, w)."""
    from implicitmesh import VariationalSurface

    p, n = sphere_data
    return {k: VariationalSurface.fit(p, n, kernel=k, exact=True) for k in KERNELS}


@pytest.fixture(scope="session")
def knot_subset(shared):
    """An irregular point set with normals: every third vertex of knot_800 with its vertex normal."""
    v, f = shared.arrays("knot")
    n = vertex_normals_area_weighted(v, f)
    return v[::3].copy(), n[::3].copy()
