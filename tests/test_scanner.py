"""The scanner simulator (implicitmesh.scanner) and the core queries it stands on (_core.ray_cast,
closest_points, k_nearest, pca_normals): small scans of the shared ``_hires`` meshes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

import implicitmesh as im
from implicitmesh import _core
from implicitmesh.scanner import scan

MESHES = Path(__file__).parent / "data" / "meshes"


def hires(name: str):
    m = trimesh.load(MESHES / f"{name}_hires.ply", process=False)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def face_normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def diagonal(v):
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))


@pytest.fixture(scope="module")
def knot():
    return hires("knot")


@pytest.fixture(scope="module")
def spot():
    return hires("spot")


# --- the core queries --------------------------------------------------------------------------------------


def test_closest_points_agree_with_brute_force_and_ray_hits_lie_on_the_mesh(knot):
    v, f = knot
    rng = np.random.default_rng(3)
    q = rng.uniform(v.min(axis=0) - 0.2, v.max(axis=0) + 0.2, (50, 3))
    c, d, tri = _core.closest_points(v, f, q)
    # Brute force: the closest point of every triangle (trimesh's per-triangle routine).
    tris = v[f]
    brute = np.array([
        np.linalg.norm(trimesh.triangles.closest_point(tris, np.repeat(p[None], len(f), axis=0)) - p, axis=1).min()
        for p in q])
    np.testing.assert_allclose(d, brute, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(c - q, axis=1), d, atol=1e-12)
    # A ray from each query towards its closest point hits the mesh no further than it.
    t, hit = _core.ray_cast(v, f, q, c - q)
    assert np.all(hit >= 0) and np.all(t <= 1 + 1e-9)
    # Misses report inf and -1.
    t, hit = _core.ray_cast(v, f, np.array([[0.0, 0.0, 50.0]]), np.array([[0.0, 0.0, 1.0]]))
    assert t[0] == np.inf and hit[0] == -1


def test_k_nearest_and_pca_normals_agree_with_brute_force():
    rng = np.random.default_rng(4)
    p = rng.normal(size=(700, 3))
    idx, dist = _core.k_nearest(p, 6)
    full = np.linalg.norm(p[:, None] - p[None], axis=2)
    want = np.argsort(full, axis=1, kind="stable")[:, :6]
    np.testing.assert_array_equal(idx, want)
    np.testing.assert_allclose(dist, np.take_along_axis(full, want, axis=1), atol=1e-15)
    # Queries apart from the points; a Fortran-ordered float32 copy gives the same neighbours.
    q = rng.normal(size=(40, 3))
    idx_q, _ = _core.k_nearest(p, 3, q)
    np.testing.assert_array_equal(idx_q, np.argsort(np.linalg.norm(q[:, None] - p[None], axis=2), axis=1)[:, :3])
    idx_f, _ = _core.k_nearest(np.asfortranarray(p), 3, np.asfortranarray(q))
    np.testing.assert_array_equal(idx_f, idx_q)
    # PCA normals of points on a plane are the plane's normal.
    n = np.array([0.2, -0.5, 0.8]) / np.linalg.norm([0.2, -0.5, 0.8])
    u = np.cross(n, [1.0, 0, 0])
    u /= np.linalg.norm(u)
    w = np.cross(n, u)
    plane = rng.uniform(-1, 1, (500, 1)) * u + rng.uniform(-1, 1, (500, 1)) * w
    assert np.all(np.abs(_core.pca_normals(plane, 10) @ n) > 1 - 1e-9)


@pytest.mark.parametrize("call, name", [
    (lambda v, f: _core.ray_cast(v, f, np.zeros((2, 3)), np.ones((3, 3))), "directions"),
    (lambda v, f: _core.ray_cast(v, f, np.zeros((1, 3)), np.zeros((1, 3))), "directions"),
    (lambda v, f: _core.ray_cast(v, f, np.full((1, 3), np.nan), np.ones((1, 3))), "origins"),
    (lambda v, f: _core.ray_cast(v, f[:, :2], np.zeros((1, 3)), np.ones((1, 3))), "faces"),
    (lambda v, f: _core.closest_points(v, f + len(v), np.zeros((1, 3))), "faces"),
    (lambda v, f: _core.closest_points(v[:, :2], f, np.zeros((1, 3))), "vertices"),
    (lambda v, f: _core.closest_points(v, f, np.zeros((1, 4))), "points"),
    (lambda v, f: _core.k_nearest(v, 0), "k"),
    (lambda v, f: _core.k_nearest(v, len(v) + 1), "k"),
    (lambda v, f: _core.k_nearest(v, 3, np.full((1, 3), np.inf)), "queries"),
    (lambda v, f: _core.pca_normals(v, 2), "k"),
    (lambda v, f: _core.pca_normals(np.zeros((0, 3))), "points"),
])
def test_bad_input_to_the_core_queries_names_the_argument(knot, call, name):
    with pytest.raises(ValueError, match=f"^{name}"):
        call(*knot)


# --- the scanner -------------------------------------------------------------------------------------------


def test_points_lie_on_the_mesh_within_the_noise(knot):
    v, f = knot
    diag = diagonal(v)
    clean = scan(v, f, 8000, seed=1)
    _, d, _ = _core.closest_points(v, f, clean.points)
    assert d.max() < 1e-9 * diag
    sigma = 2e-3
    noisy = scan(v, f, 8000, noise=sigma, seed=1)
    _, d, _ = _core.closest_points(v, f, noisy.points)
    # Distance to the surface is at most the offset along the ray, |N(0, σ)|: mean 0.80 σ
    # times the cosine of the ray's angle with the surface (at least cos 80°).
    assert d.max() < 6 * sigma * diag
    assert 0.3 * sigma * diag < d.mean() < 0.8 * sigma * diag
    # The caller sets the size: about the points asked for.
    assert abs(len(noisy) - 8000) < 0.1 * 8000
    big = scan(v, f, 30_000, seed=1)
    assert abs(len(big) - 30_000) < 0.1 * 30_000


def test_no_point_is_seen_from_below_or_at_a_grazing_angle():
    box = trimesh.creation.box(extents=(1.0, 0.6, 0.4))
    v, f = np.asarray(box.vertices), np.asarray(box.faces)
    s = scan(v, f, 5000, seed=2)
    n = face_normals(v, f)[s.triangle]
    # Nothing on the bottom face; every other face seen (the top and the four sides).
    assert not np.any(n[:, 2] < -0.5)
    seen = {tuple(np.round(x).astype(int)) for x in n}
    assert seen == {(0, 0, 1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)}
    # Every hit faces its camera within max_angle (80°).
    for name in ("knot", "spot"):
        v, f = hires(name)
        s = scan(v, f, 5000, seed=3, max_angle=80)
        ray = s.points - s.cameras[s.view]
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        cos = -np.einsum("ij,ij->i", ray, face_normals(v, f)[s.triangle])
        assert cos.min() >= math.cos(math.radians(80)) - 1e-9
        # No camera is below the box's centre.
        assert np.all(s.cameras[:, 2] >= s.center[2] - 1e-9)


def test_outliers_are_counted_and_indexed(spot):
    v, f = spot
    s = scan(v, f, 10_000, noise=5e-4, outliers=2e-3, seed=4)
    m = len(s.outliers)
    assert m == round(2e-3 * len(s)) and m > 0
    assert np.all(np.diff(s.outliers) > 0)
    np.testing.assert_array_equal(np.flatnonzero(s.triangle < 0), s.outliers)
    lo, hi = v.min(axis=0), v.max(axis=0)
    assert np.all((s.points[s.outliers] >= lo) & (s.points[s.outliers] <= hi))
    np.testing.assert_allclose(np.linalg.norm(s.normals[s.outliers], axis=1), 1.0)
    # The outliers are off the surface (most of the box is away from it); the rest within noise.
    _, d, _ = _core.closest_points(v, f, s.points)
    diag = diagonal(v)
    inliers = np.setdiff1d(np.arange(len(s)), s.outliers)
    assert d[inliers].max() < 6 * 5e-4 * diag
    assert np.median(d[s.outliers]) > 10 * 5e-4 * diag
    # Without outliers, the same points with no index listed.
    assert len(scan(v, f, 10_000, noise=5e-4, seed=4).outliers) == 0


def test_normals_face_their_camera_and_agree_with_the_true_normals(spot):
    v, f = spot
    s = scan(v, f, 20_000, seed=5)
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=1), 1.0, atol=1e-12)
    assert np.all(np.einsum("ij,ij->i", s.normals, s.cameras[s.view] - s.points) > 0)
    agree = np.einsum("ij,ij->i", s.normals, face_normals(v, f)[s.triangle])
    # Clean scan: at least 95 % within 25° of the true face normal, and none flipped by more
    # than 90° on more than 1 % of the points (thin parts seen edge-on).
    assert np.mean(agree > math.cos(math.radians(25))) >= 0.95
    assert np.mean(agree < 0) < 0.01
    # With noise σ = 0.2 % the PCA over 20 neighbours still finds most normals within 25°.
    noisy = scan(v, f, 20_000, noise=2e-3, seed=5)
    agree = np.einsum("ij,ij->i", noisy.normals, face_normals(v, f)[noisy.triangle])
    assert np.mean(agree > math.cos(math.radians(25))) >= 0.8


def test_misregistration_moves_each_view_rigidly(knot):
    v, f = knot
    diag = diagonal(v)
    a = scan(v, f, 6000, noise=5e-4, seed=6)
    b = scan(v, f, 6000, noise=5e-4, misregistration=1e-3, seed=6)
    np.testing.assert_array_equal(a.view, b.view)
    np.testing.assert_array_equal(a.triangle, b.triangle)
    assert b.parameters.rotation == 0.1
    angles = []
    for k in range(a.parameters.views):
        sel = a.view == k
        r, t = b.rotations[k], b.translations[k]
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(b.points[sel], (a.points[sel] - a.center) @ r.T + a.center + t, atol=1e-12)
        np.testing.assert_allclose(b.normals[sel], a.normals[sel] @ r.T, atol=1e-6)
        assert math.isclose(np.linalg.norm(t), 1e-3 * diag, rel_tol=1e-9)
        angles.append(math.degrees(math.acos((np.trace(r) - 1) / 2)))
        np.testing.assert_allclose(b.cameras[k], r @ (a.cameras[k] - a.center) + a.center + t, atol=1e-12)
    np.testing.assert_allclose(angles, 0.1, atol=1e-6)
    # The views were not all moved alike.
    assert np.ptp(b.translations, axis=0).max() > 1e-4 * diag


def test_scans_are_deterministic_given_the_seed(knot):
    v, f = knot
    kw = dict(noise=5e-4, misregistration=1e-3, outliers=2e-3)
    a, b = scan(v, f, 5000, seed=7, **kw), scan(v, f, 5000, seed=7, **kw)
    for field in ("points", "normals", "view", "triangle", "cameras", "outliers"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert a.parameters == b.parameters
    c = scan(v, f, 5000, seed=8, **kw)
    assert not np.array_equal(a.points, c.points)


@pytest.mark.parametrize("kwargs, name", [
    (dict(elevations=(0, -10)), "elevations"),
    (dict(outliers=1.0), "outliers"),
    (dict(noise=-1e-3), "noise"),
    (dict(points=10), "points"),
    (dict(views=0), "views"),
    (dict(neighbours=2), "neighbours"),
    (dict(max_angle=95), "max_angle"),
    (dict(distance=0.3), "distance"),
    (dict(up=(0, 0, 0)), "up"),
    (dict(seed=1.5), "seed"),
])
def test_bad_scanner_arguments_name_the_argument(knot, kwargs, name):
    v, f = knot
    with pytest.raises(ValueError, match=f"^{name}"):
        scan(v, f, **{"points": 1000, **kwargs})
    with pytest.raises(ValueError, match="^vertices"):
        scan(v[:, :2], f, 1000)
    with pytest.raises(ValueError, match="^faces"):
        scan(v, f[:, :2], 1000)


def test_the_scanner_is_public():
    assert im.scanner.scan is scan
