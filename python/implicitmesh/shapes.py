"""Built-in shapes: analytic fields as Python callables (with exact area and genus, for tests
and examples) and the bundled models used by the demo."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import numpy as np

__all__ = ["Sphere", "Torus", "Table", "Plates", "MODELS", "load_model", "fibonacci_sphere", "sample_vertices"]


@dataclass(frozen=True)
class Sphere:
    """Signed distance to a sphere, as a callable field: ``Sphere()(points)``.

    Attributes
    ----------
    center : (3,) float
    radius : float
    """

    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.8

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """points : (N, 3) float64 -> (N,) float64 signed distances (negative inside)."""
        return np.linalg.norm(np.asarray(points) - np.asarray(self.center), axis=1) - self.radius

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: a cube 10 % larger than the sphere."""
        c = np.asarray(self.center, dtype=float)
        r = 1.1 * self.radius
        return np.stack([c - r, c + r])

    @property
    def area(self) -> float:
        return 4.0 * np.pi * self.radius**2

    genus = 0


@dataclass(frozen=True)
class Torus:
    """Signed distance to a torus around the z axis, as a callable field.

    Attributes
    ----------
    center : (3,) float
    major : float
        Distance from the centre to the tube's centre line.
    minor : float
        Tube radius.
    """

    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    major: float = 0.6
    minor: float = 0.25

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """points : (N, 3) float64 -> (N,) float64 signed distances (negative inside)."""
        q = np.asarray(points) - np.asarray(self.center)
        rho = np.hypot(q[:, 0], q[:, 1])
        return np.hypot(rho - self.major, q[:, 2]) - self.minor

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: a cube 10 % larger than the torus."""
        c = np.asarray(self.center, dtype=float)
        r = 1.1 * (self.major + self.minor)
        return np.stack([c - r, c + r])

    @property
    def area(self) -> float:
        return 4.0 * np.pi**2 * self.major * self.minor

    genus = 1


def _box(points: np.ndarray, center, half) -> np.ndarray:
    q = np.abs(points - np.asarray(center, dtype=float)) - np.asarray(half, dtype=float)
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def _capsule(points: np.ndarray, a, b, radius: float) -> np.ndarray:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    pa, ba = points - a, b - a
    t = np.clip(pa @ ba / (ba @ ba), 0.0, 1.0)
    return np.linalg.norm(pa - t[:, None] * ba, axis=1) - radius


@dataclass(frozen=True)
class Table:
    """A thin-legged body, as a callable field (a distance bound: exact outside, ``|f|`` ≤ distance
    inside): a slab 1.4 × 1.0 × ``top`` on four legs of radius ``leg``, genus 0, inside
    [-0.8, 0.8]³. A hard case for fits: the legs are a few normal offsets thick.
    """

    leg: float = 0.035
    top: float = 0.12

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """points : (N, 3) float64 -> (N,) float64 (negative inside)."""
        p = np.asarray(points, dtype=float)
        d = _box(p, (0.0, 0.0, 0.5), (0.7, 0.5, self.top / 2))
        for x in (-0.6, 0.6):
            for y in (-0.4, 0.4):
                d = np.minimum(d, _capsule(p, (x, y, -0.8), (x, y, 0.5), self.leg))
        return d

    bounds = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    genus = 0


@dataclass(frozen=True)
class Plates:
    """Two parallel plates ``gap`` apart, each ``thickness`` thick and 2 × ``size`` wide, joined
    along one end, as a callable field (a distance bound): genus 0, inside [-0.8, 0.8]³. A hard case for fits: the
    outside between the plates is thinner than the default normal offsets reach.
    """

    gap: float = 0.02
    thickness: float = 0.05
    #: Half the plates' extent along x and y.
    size: tuple[float, float] = (0.7, 0.6)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """points : (N, 3) float64 -> (N,) float64 (negative inside)."""
        p = np.asarray(points, dtype=float)
        z = (self.gap + self.thickness) / 2
        sx, sy = self.size
        half = (sx, sy, self.thickness / 2)
        a = _box(p, (0.0, 0.0, z), half)
        b = _box(p, (0.0, 0.0, -z), half)
        joint = _box(p, (sx - 0.02, 0.0, 0.0), (0.05, sy, z + self.thickness / 2))
        return np.minimum(np.minimum(a, b), joint)

    bounds = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    genus = 0


#: Models bundled with the package (about 800 vertices each, inside [-0.9, 0.9]³):
#: ``knot`` (procedural trefoil tube, genus 1) and ``spot`` (Keenan Crane's cow, public domain).
MODELS = ("knot", "spot")


def load_model(name: str = "knot") -> tuple[np.ndarray, np.ndarray]:
    """Loads a bundled model.

    Parameters
    ----------
    name : {"knot", "spot"}

    Returns
    -------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    """
    if name not in MODELS:
        raise ValueError(f"name: unknown model {name!r}; available: {', '.join(MODELS)}")
    import trimesh

    path = resources.files("implicitmesh") / "data" / f"{name}_800.ply"
    with resources.as_file(path) as p:
        m = trimesh.load(str(p), process=False, force="mesh")
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def fibonacci_sphere(n: int, radius: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Evenly spread points on a sphere and their outward normals.

    Returns
    -------
    points : (n, 3) float64
    normals : (n, 3) float64
    """
    i = np.arange(n) + 0.5
    y = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - y * y)
    t = np.pi * (3.0 - np.sqrt(5.0)) * i
    normals = np.stack([r * np.cos(t), y, r * np.sin(t)], axis=1)
    return radius * normals, normals


def sample_vertices(
    vertices: np.ndarray,
    faces: np.ndarray,
    count: int,
    *,
    normals: str = "area",
    noise_degrees: float = 0.0,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """A random subset of a mesh's vertices with vertex normals, as a scan would give.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    count : int
        Vertices to keep (at most V).
    normals : {"area", "angle"}
        Vertex normals weighted by the adjacent faces' areas or by their angles at the vertex.
    noise_degrees : float
        Tilts each normal by a random angle of about this size (a normal perturbation of this
        standard deviation per component, in radians), as estimated normals are.
    seed : int

    Returns
    -------
    points : (count, 3) float64
    normals : (count, 3) float64, unit length
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if normals not in ("area", "angle"):
        raise ValueError(f"normals: expected 'area' or 'angle', got {normals!r}")
    if not 0 < count <= len(v):
        raise ValueError(f"count: must be between 1 and {len(v)}, got {count!r}")
    a, b, c = (v[f[:, k]] for k in range(3))
    face_normal = np.cross(b - a, c - a)  # length twice the area
    if normals == "angle":
        face_normal = face_normal / np.linalg.norm(face_normal, axis=1, keepdims=True)
    n = np.zeros_like(v)
    for k in range(3):
        w = 1.0
        if normals == "angle":
            p, q, r = (v[f[:, (k + j) % 3]] for j in range(3))
            e1, e2 = q - p, r - p
            cos = np.einsum("ij,ij->i", e1, e2) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
            w = np.arccos(np.clip(cos, -1.0, 1.0))[:, None]
        np.add.at(n, f[:, k], face_normal * w)
    rng = np.random.default_rng(seed)
    keep = np.sort(rng.choice(len(v), count, replace=False))
    n = n[keep]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    if noise_degrees > 0:
        n = n + rng.normal(0.0, np.radians(noise_degrees), n.shape)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
    return v[keep].copy(), n
