"""Built-in shapes: analytic fields as Python callables (with exact area and genus, for tests
and examples) and the bundled models used by the demo."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import numpy as np

__all__ = ["Sphere", "Torus", "MODELS", "load_model", "fibonacci_sphere"]


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
