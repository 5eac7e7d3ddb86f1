"""Subdivision interpolating implicit surfaces (Jin et al. 2003), butterfly and blending."""

from __future__ import annotations

import numpy as np
import pytest

import implicitmesh
from implicitmesh import Mesh, VariationalSurface, blend, butterfly, subdivide

from conftest import D, genus_of, require_mesh_dir


@pytest.fixture(scope="module")
def icosahedron():
    import trimesh

    path = require_mesh_dir() / "icosahedron_12.ply"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    m = trimesh.load(path, process=False)
    v = np.asarray(m.vertices, dtype=np.float64)
    f = np.asarray(m.faces, dtype=np.int64)
    return v, f, VariationalSurface.from_mesh(v, f)


def edges_of(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique undirected edges and how many faces use each."""
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def test_exported():
    assert implicitmesh.subdivide is subdivide
    assert {"subdivide", "butterfly", "blend"} <= set(implicitmesh.__all__)


def test_icosahedron_levels(icosahedron):
    v, f, s = icosahedron
    levels = subdivide(v, f, levels=5, surface=s)
    assert [len(m.faces) for m in levels] == [20, 80, 320, 1280, 5120, 20480]
    for k, m in enumerate(levels):
        assert m.stats["level"] == k
        # Control vertices are kept bit for bit, and every level is a prefix of the next.
        assert np.array_equal(m.vertices[: len(v)], v)
        if k:
            prev = levels[k - 1]
            assert np.array_equal(m.vertices[: len(prev.vertices)], prev.vertices)
            assert np.array_equal(m.faces.max() + 1, len(m.vertices))
        assert np.abs(s.evaluate(m.vertices)).max() <= 1e-6, k
        assert m.normals.shape == m.vertices.shape
        assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0)
        assert m.euler_number == 2
        t = m.to_trimesh()
        assert t.is_watertight and t.is_winding_consistent
        assert m.volume > 0
        assert m.stats["not_converged"] == 0
    # The subdivided sphere-like surface has well-shaped triangles.
    assert levels[5].quality()["min_angle_mean"] > 40


def test_default_fit_is_used(icosahedron):
    v, f, _ = icosahedron
    levels = subdivide(v, f, levels=1)
    s = VariationalSurface.from_mesh(v, f)
    assert np.abs(s.evaluate(levels[1].vertices)).max() <= 1e-6


@pytest.mark.parametrize("name", ["knot", "star", "spot"])
def test_shared_meshes(shared, name):
    v, f = shared.arrays(name)
    s = shared.surface(name)
    genus = genus_of(shared.trimesh(name).euler_number)
    levels = subdivide(v, f, levels=2, surface=s)
    assert len(levels) == 3
    for k, m in enumerate(levels):
        assert len(m.faces) == len(f) * 4**k
        t = m.to_trimesh()
        assert t.is_watertight, (name, k)
        assert t.is_winding_consistent, (name, k)
        assert genus_of(m.euler_number) == genus
        assert np.array_equal(m.vertices[: len(v)], v)
        assert np.abs(s.evaluate(m.vertices)).max() <= 1e-6, (name, k)
        if k:
            assert m.stats["not_converged"] == 0
            assert m.stats["projected"] == len(m.vertices) - len(levels[k - 1].vertices)
            assert 1 <= m.stats["iterations_mean"] <= m.stats["iterations_max"] <= 30


def test_open_mesh_keeps_boundary(shared):
    v, f = shared.arrays("knot")
    s = shared.surface("knot")
    centroids = v[f].mean(axis=1)
    drop = np.argsort(np.linalg.norm(centroids - v[0], axis=1))[:10]
    f_open = np.delete(f, drop, axis=0)
    _, counts = edges_of(f_open)
    boundary = int((counts == 1).sum())
    assert boundary > 0
    levels = subdivide(v, f_open, levels=2, surface=s)
    for k, m in enumerate(levels):
        assert len(m.faces) == len(f_open) * 4**k
        _, c = edges_of(m.faces)
        assert int((c == 1).sum()) == boundary * 2**k
        assert int((c > 2).sum()) == 0
        t = m.to_trimesh()
        assert not t.is_watertight
        assert t.is_winding_consistent
        assert np.abs(s.evaluate(m.vertices)).max() <= 1e-6


def planar_grid(n: int = 6, z: float = 0.3):
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="xy")
    x = i + 0.15 * ((3 * i + 5 * j) % 4)
    y = j + 0.1 * ((2 * i + j) % 3)
    v = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1).astype(float)
    idx = lambda a, b: b * (n + 1) + a  # noqa: E731
    f = []
    for b in range(n):
        for a in range(n):
            if (a + b) % 2:
                f += [[idx(a, b), idx(a + 1, b), idx(a + 1, b + 1)], [idx(a, b), idx(a + 1, b + 1), idx(a, b + 1)]]
            else:
                f += [[idx(a, b), idx(a + 1, b), idx(a, b + 1)], [idx(a + 1, b), idx(a + 1, b + 1), idx(a, b + 1)]]
    return v, np.asarray(f)


@pytest.mark.parametrize("w", [0.0, 1 / 16, -0.02, 0.1])
def test_butterfly_reproduces_planes(w):
    v, f = planar_grid()
    levels = butterfly(v, f, levels=3, w=w)
    assert [len(m.faces) for m in levels] == [len(f) * 4**k for k in range(4)]
    for m in levels:
        assert np.abs(m.vertices[:, 2] - 0.3).max() <= 1e-12
        assert np.array_equal(m.vertices[: len(v)], v)
    # Not merely midpoints: on this irregular grid the stencils move new vertices within the plane.
    lin = subdivide_midpoints(v, f)
    assert np.abs(levels[1].vertices - lin).max() > 1e-3


def subdivide_midpoints(v, f):
    """Level-1 vertices of plain midpoint subdivision, numbered like the package's split
    (new vertices in order of first appearance, edges of each face in order ab, bc, ca)."""
    out, seen = list(v), {}
    for t in f:
        for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            key = (min(a, b), max(a, b))
            if key not in seen:
                seen[key] = len(out)
                out.append(0.5 * (v[a] + v[b]))
    return np.asarray(out)


def test_butterfly_and_implicit_share_connectivity(icosahedron):
    v, f, s = icosahedron
    imp = subdivide(v, f, levels=3, surface=s)
    bf = butterfly(v, f, levels=3, w=0.0)
    for a, b in zip(imp, bf):
        assert np.array_equal(a.faces, b.faces)
        assert np.array_equal(b.vertices[: len(v)], v)
        t = b.to_trimesh()
        assert t.is_watertight and t.is_winding_consistent
    # Butterfly and implicit surfaces differ, but not by much on a sphere-like control mesh.
    diff = np.linalg.norm(imp[3].vertices - bf[3].vertices, axis=1)
    assert 0 < diff.max() < 0.2


def test_blend_identities(icosahedron):
    v, f, s = icosahedron
    a = subdivide(v, f, levels=2, surface=s)[2]
    b = butterfly(v, f, levels=2, w=0.05)[2]
    assert np.array_equal(blend(a, b, 0).vertices, a.vertices)
    assert np.array_equal(blend(a, b, 1.0).vertices, b.vertices)
    h = blend(a, b, 0.25)
    assert np.allclose(h.vertices, 0.75 * a.vertices + 0.25 * b.vertices, rtol=0, atol=1e-15)
    assert np.array_equal(h.faces, a.faces)
    with pytest.raises(ValueError, match="lam"):
        blend(a, b, 1.5)
    with pytest.raises(ValueError, match="lam"):
        blend(a, b, -0.1)
    with pytest.raises(ValueError, match="butterfly"):
        blend(a, butterfly(v, f, levels=1)[1], 0.5)


def test_bad_input(icosahedron):
    v, f, s = icosahedron
    with pytest.raises(ValueError, match="levels"):
        subdivide(v, f, levels=-1, surface=s)
    with pytest.raises(ValueError, match="levels"):
        subdivide(v, f, levels=20, surface=s)
    with pytest.raises(ValueError, match="levels"):
        butterfly(v, f, levels=-1)
    with pytest.raises(ValueError, match="levels"):
        butterfly(v, f, levels=20)
    bad = f.copy()
    bad[3, 1] = 99
    with pytest.raises(ValueError, match="faces"):
        subdivide(v, bad, levels=1, surface=s)
    with pytest.raises(ValueError, match="faces"):
        butterfly(v, bad, levels=1)
    with pytest.raises(ValueError, match="faces"):
        subdivide(v, np.vstack([f, [[0, 1, 2]]]), levels=1, surface=s)
    with pytest.raises(ValueError, match="vertices"):
        subdivide(v[:, :2], f, levels=1, surface=s)
    with pytest.raises(ValueError, match="tolerance"):
        subdivide(v, f, levels=1, surface=s, tolerance=-1.0)
    with pytest.raises(ValueError, match="max_steps"):
        subdivide(v, f, levels=1, surface=s, max_steps=0)
    with pytest.raises(ValueError, match="surface"):
        subdivide(v, f, levels=1, surface="sphere")
    with pytest.raises(ValueError, match="w"):
        butterfly(v, f, levels=1, w=float("nan"))


def test_zero_levels_is_control_mesh(icosahedron):
    v, f, s = icosahedron
    (m,) = subdivide(v, f, levels=0, surface=s)
    assert isinstance(m, Mesh)
    assert np.array_equal(m.vertices, v) and np.array_equal(m.faces, f)
    assert m.stats["projected"] == 0
