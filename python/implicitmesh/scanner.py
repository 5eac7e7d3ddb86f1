"""A simulated range scanner: what a scanner hands its user, made from a closed mesh.

Range images are taken from a ring of viewpoints at several elevations, none from below (Berger
et al., "A benchmark for surface reconstruction", ACM TOG 2013, simulate scanners this way).
Each view casts one ray per pixel of a square grid from its camera towards the object and keeps
the first hit; hits seen at a grazing angle are dropped; each hit is moved along its ray by
Gaussian noise; each view is moved by a small rigid misregistration; normals are estimated per
view by PCA over the view's own nearest points and oriented towards its camera; finally a
fraction of the points is replaced by outliers, uniform in the mesh's bounding box with random
normals.

>>> import implicitmesh as im
>>> v, f = im.shapes.load_model("knot")
>>> s = im.scanner.scan(v, f, 20_000, noise=5e-4, seed=1)
>>> s.points.shape[1], s.normals.shape[1]
(3, 3)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from . import _core

__all__ = ["Scan", "ScanParameters", "scan"]

#: Rays per side of each view's calibration grid, which measures how many of a view's rays hit.
_CALIBRATION = 64


@dataclass(frozen=True)
class ScanParameters:
    """The settings a :func:`scan` was made with.

    Attributes
    ----------
    points : int
        The number of points asked for.
    resolution : int
        Pixels per side of every view's square grid (chosen from ``points``).
    views : int
        The number of viewpoints.
    elevations : tuple of float
        Elevations of the viewpoints in degrees above the plane through the box's centre normal
        to ``up``; view ``i`` uses ``elevations[i % len(elevations)]``.
    up : (3,) tuple of float
        The unit vector no view looks against (no view is below the object).
    distance : float
        Distance of each camera from the box's centre, as a multiple of the box's diagonal.
    max_angle : float
        Hits whose surface normal is further than this from the reversed ray (degrees) were
        dropped.
    noise : float
        Standard deviation of the noise along each ray, as a fraction of the box's diagonal.
    misregistration : float
        Length of each view's translation, as a fraction of the box's diagonal.
    rotation : float
        Angle of each view's rotation about the box's centre, in degrees.
    outliers : float
        The fraction of the points replaced by outliers.
    neighbours : int
        Neighbours (the point itself included) of each PCA normal.
    seed : int
        The seed of the random generator.
    diagonal : float
        The mesh's bounding-box diagonal.
    """

    points: int
    resolution: int
    views: int
    elevations: tuple[float, ...]
    up: tuple[float, float, float]
    distance: float
    max_angle: float
    noise: float
    misregistration: float
    rotation: float
    outliers: float
    neighbours: int
    seed: int
    diagonal: float


@dataclass(frozen=True)
class Scan:
    """A simulated scan: points with estimated normals, and how they were made.

    Attributes
    ----------
    points : (N, 3) float64
        The scanned points, views one after another, outliers among them.
    normals : (N, 3) float64
        Unit normals: PCA over each point's nearest points of its view, oriented towards that
        view's camera (``cameras[view]``); random for outliers.
    view : (N,) int64
        The view of each point (outliers keep the view of the point they replaced).
    triangle : (N,) int64
        The mesh triangle each point's ray hit; -1 for outliers.
    cameras : (V, 3) float64
        Each view's camera, moved by its misregistration as its points were.
    rotations : (V, 3, 3) float64
        Each view's misregistration: a point ``p`` of view ``v`` was moved to
        ``rotations[v] @ (p - center) + center + translations[v]``.
    translations : (V, 3) float64
        See ``rotations``.
    center : (3,) float64
        The centre of the mesh's bounding box, about which the views were rotated.
    outliers : (M,) int64
        Indices of the outliers in ``points``, increasing.
    parameters : ScanParameters
        The settings of the scan.
    """

    points: np.ndarray
    normals: np.ndarray
    view: np.ndarray
    triangle: np.ndarray
    cameras: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    center: np.ndarray
    outliers: np.ndarray
    parameters: ScanParameters

    def __len__(self) -> int:
        return len(self.points)


def _nonnegative(name: str, value: float, upper: float | None = None) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(x) or x < 0 or (upper is not None and x >= upper):
        bound = f" and below {upper}" if upper is not None else ""
        raise ValueError(f"{name}: must be finite, at least 0{bound}, got {value!r}")
    return x


def _count(name: str, value: int, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    if value < least:
        raise ValueError(f"{name}: must be at least {least}, got {value}")
    return int(value)


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation matrix by ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _unit_vectors(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _view_rays(camera: np.ndarray, target: np.ndarray, up: np.ndarray, half: float, pixels: int):
    """The (pixels², 3) unit directions of a square pinhole camera at ``camera`` looking at
    ``target`` with half-angle ``half`` (radians) to the sides of its image."""
    forward = target - camera
    forward /= np.linalg.norm(forward)
    side = np.cross(forward, up)
    if np.linalg.norm(side) < 1e-9:  # looking along `up`: any side
        side = np.cross(forward, np.array([1.0, 0.0, 0.0]) if abs(forward[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
    side /= np.linalg.norm(side)
    top = np.cross(side, forward)
    s = math.tan(half) * ((np.arange(pixels) + 0.5) / pixels * 2 - 1)
    u, w = np.meshgrid(s, s, indexing="xy")
    d = forward + u.reshape(-1, 1) * side + w.reshape(-1, 1) * top
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def scan(
    vertices,
    faces,
    points: int = 100_000,
    *,
    views: int = 12,
    elevations: Sequence[float] = (0.0, 25.0, 50.0),
    up: Sequence[float] = (0.0, 0.0, 1.0),
    noise: float = 0.0,
    misregistration: float = 0.0,
    rotation: float | None = None,
    outliers: float = 0.0,
    max_angle: float = 80.0,
    neighbours: int = 20,
    distance: float = 2.0,
    seed: int = 0,
) -> Scan:
    """Simulates a range scan of a closed mesh.

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        The mesh's vertices.
    faces : (F, 3) array_like of int
        Its triangles, vertex indices. The mesh should be closed: rays that would enter it
        through a hole see its inside.
    points : int, default 100_000
        About how many points to make (the pixel grid is chosen from a calibration pass so that
        the views' hits, after grazing ones are dropped, come to about this many; at least 100).
    views : int, default 12
        The number of viewpoints, at azimuths ``360° × i / views`` about ``up``.
    elevations : sequence of float, default (0, 25, 50)
        Elevations in degrees, each in [0, 90): view ``i`` has ``elevations[i % len]``. None
        may be negative (no view from below).
    up : (3,) sequence of float, default (0, 0, 1)
        The up direction (normalized here).
    noise : float, default 0
        Standard deviation of Gaussian noise along each ray, as a fraction of the mesh's
        bounding-box diagonal (e.g. 5e-4 for 0.05 %).
    misregistration : float, default 0
        Each view is translated by this fraction of the diagonal, in a random direction.
    rotation : float, optional
        Each view is also rotated by this many degrees about a random axis through the box's
        centre; by default 0.1° when ``misregistration`` is positive, else 0.
    outliers : float, default 0
        The fraction of the points (in [0, 1)) replaced by points uniform in the bounding box
        with uniformly random unit normals.
    max_angle : float, default 80
        Hits where the angle between the surface normal and the reversed ray exceeds this (in
        degrees, in (0, 90]) are dropped.
    neighbours : int, default 20
        Points (the point included) of each PCA normal, from the point's own view (fewer when
        a view has fewer points; at least 3).
    distance : float, default 2
        Cameras sit this many diagonals from the box's centre (more than 0.5: outside it).
    seed : int, default 0
        The random generator's seed: the same arguments give the same scan.

    Returns
    -------
    Scan
        The points (N, 3) float64, normals (N, 3) float64, view (N,) int64, triangle (N,)
        int64, cameras (V, 3), rotations (V, 3, 3), translations (V, 3), center (3,), outlier
        indices (M,) int64 and the :class:`ScanParameters`.

    Raises
    ------
    ValueError
        Naming the argument: a bad mesh, a count or fraction out of range, a negative elevation.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
        raise ValueError(f"vertices: expected an array of shape (V, 3) with V >= 3, got shape {vertices.shape}")
    if not np.all(np.isfinite(vertices)):
        raise ValueError("vertices: not all finite")
    faces_arr = np.asarray(faces)
    if faces_arr.ndim != 2 or faces_arr.shape[1] != 3 or len(faces_arr) == 0:
        raise ValueError(f"faces: expected an array of shape (F, 3) with F >= 1, got shape {faces_arr.shape}")
    points = _count("points", points, 100)
    views = _count("views", views, 1)
    neighbours = _count("neighbours", neighbours, 3)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed: expected an integer, got {seed!r}")
    elev = tuple(float(e) for e in np.atleast_1d(np.asarray(elevations, dtype=np.float64)))
    if not elev or not all(0.0 <= e < 90.0 for e in elev):
        raise ValueError(f"elevations: each must be in [0, 90) degrees (no view from below), got {elevations!r}")
    up_v = np.asarray(up, dtype=np.float64)
    if up_v.shape != (3,) or not np.all(np.isfinite(up_v)) or np.linalg.norm(up_v) == 0:
        raise ValueError(f"up: expected a non-zero finite 3-vector, got {up!r}")
    up_v = up_v / np.linalg.norm(up_v)
    noise = _nonnegative("noise", noise)
    misregistration = _nonnegative("misregistration", misregistration)
    rotation = (0.1 if misregistration > 0 else 0.0) if rotation is None else _nonnegative("rotation", rotation)
    outliers = _nonnegative("outliers", outliers, 1.0)
    max_angle = _nonnegative("max_angle", max_angle)
    if not 0 < max_angle <= 90:
        raise ValueError(f"max_angle: must be in (0, 90] degrees, got {max_angle}")
    distance = _nonnegative("distance", distance)
    if distance <= 0.5:
        raise ValueError(f"distance: must exceed 0.5 diagonals (cameras outside the box), got {distance}")

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    center = (lo + hi) / 2
    diagonal = float(np.linalg.norm(hi - lo))
    if diagonal == 0:
        raise ValueError("vertices: all coincide")
    rng = np.random.default_rng(int(seed))

    # Cameras: azimuths spread over the circle about `up`, elevations cycled.
    e1 = np.cross(up_v, [1.0, 0.0, 0.0])
    if np.linalg.norm(e1) < 1e-6:
        e1 = np.cross(up_v, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up_v, e1)
    radius = distance * diagonal
    cameras = np.empty((views, 3))
    for i in range(views):
        az = 2 * math.pi * i / views
        el = math.radians(elev[i % len(elev)])
        cameras[i] = center + radius * (math.cos(el) * (math.cos(az) * e1 + math.sin(az) * e2) + math.sin(el) * up_v)
    # The image covers the bounding sphere of the box.
    half = math.asin(min(0.5 / distance, 1.0))
    cos_max = math.cos(math.radians(max_angle))

    tri = faces_arr.astype(np.int64)
    corners = vertices[tri]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    lengths = np.linalg.norm(face_normals, axis=1, keepdims=True)
    face_normals = face_normals / np.where(lengths > 0, lengths, 1.0)

    def cast(pixels: int):
        dirs = np.concatenate([_view_rays(c, center, up_v, half, pixels) for c in cameras])
        origins = np.repeat(cameras, pixels * pixels, axis=0)
        t, hit = _core.ray_cast(vertices, tri, origins, dirs)
        keep = hit >= 0
        cosine = np.zeros(len(hit))
        cosine[keep] = -np.einsum("ij,ij->i", dirs[keep], face_normals[hit[keep]])
        keep &= cosine >= cos_max
        return origins, dirs, t, hit, keep

    # Calibration: the fraction of rays kept at a coarse grid gives the pixel grid.
    kept = int(cast(_CALIBRATION)[4].sum())
    if kept == 0:
        raise ValueError("vertices: no view sees the mesh (is it degenerate?)")
    fraction = kept / (views * _CALIBRATION**2)
    resolution = max(2, int(round(math.sqrt(points / (views * fraction)))))
    origins, dirs, t, hit, keep = cast(resolution)
    view = np.repeat(np.arange(views, dtype=np.int64), resolution * resolution)[keep]
    dirs, t, hit, origins = dirs[keep], t[keep], hit[keep], origins[keep]
    n = len(t)

    # Noise along the rays, then each view's rigid misregistration.
    depth = t + (rng.normal(scale=noise * diagonal, size=n) if noise > 0 else 0.0)
    pts = origins + depth[:, None] * dirs
    rotations = np.empty((views, 3, 3))
    translations = np.empty((views, 3))
    axes = _unit_vectors(rng, views)
    shifts = _unit_vectors(rng, views) * misregistration * diagonal
    moved_cameras = cameras.copy()
    for v in range(views):
        rotations[v] = _rotation(axes[v], math.radians(rotation))
        translations[v] = shifts[v]
        sel = view == v
        pts[sel] = (pts[sel] - center) @ rotations[v].T + center + translations[v]
        moved_cameras[v] = rotations[v] @ (cameras[v] - center) + center + translations[v]

    # Normals per view: PCA over the view's own points, towards its camera.
    normals = np.empty_like(pts)
    for v in range(views):
        sel = np.flatnonzero(view == v)
        if len(sel) == 0:
            continue
        if len(sel) < 3:
            nv = moved_cameras[v] - pts[sel]
            normals[sel] = nv / np.linalg.norm(nv, axis=1, keepdims=True)
            continue
        nv = _core.pca_normals(np.ascontiguousarray(pts[sel]), min(neighbours, len(sel)))
        flip = np.einsum("ij,ij->i", nv, moved_cameras[v] - pts[sel]) < 0
        nv[flip] *= -1
        normals[sel] = nv

    # Outliers: points replaced by uniform points in the box with random normals.
    count = int(round(outliers * n))
    out_idx = np.sort(rng.choice(n, size=count, replace=False)).astype(np.int64) if count else np.zeros(0, np.int64)
    if count:
        pts[out_idx] = rng.uniform(lo, hi, size=(count, 3))
        normals[out_idx] = _unit_vectors(rng, count)
        hit = hit.copy()
        hit[out_idx] = -1

    params = ScanParameters(
        points=points, resolution=resolution, views=views, elevations=elev, up=tuple(float(x) for x in up_v),
        distance=float(distance), max_angle=float(max_angle), noise=noise, misregistration=misregistration,
        rotation=float(rotation), outliers=outliers, neighbours=neighbours, seed=int(seed), diagonal=diagonal,
    )
    return Scan(points=pts, normals=normals, view=view, triangle=hit.astype(np.int64), cameras=moved_cameras,
                rotations=rotations, translations=translations, center=center, outliers=out_idx, parameters=params)
