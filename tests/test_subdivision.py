"""Subdivision interpolating implicit surfaces (Jin et al. 2003), butterfly and blending."""

from __future__ import annotations

import numpy as np
import pytest

import implicitmesh
from implicitmesh import Mesh, VariationalSurface, blend, butterfly, subdivide

from conftest import MESH_NAMES, D, genus_of, require_mesh_dir


@pytest.fixture(scope="module")
def icosahedron():
    import trimesh

    path = require_mesh_dir() / "icosahedron_12.ply"
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
    levels = subdivide(v, f, levels=5, field=s)
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
    levels = subdivide(v, f, levels=2, field=s)
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


@pytest.mark.parametrize("name", MESH_NAMES)
def test_newton_prediction_keeps_residual_and_normals(shared, name):
    """Newton starts at the edge's Hermite midpoint and accepts a step without a confirming
    evaluation when quadratic convergence predicts the next one below the tolerance: on every
    shared mesh, the vertices still satisfy |f| <= 1e-6 (measured here, not predicted), the
    reported largest |f| is of the order of the measured one, the normals are the unit gradients
    at the final points, and level 2 needs about two evaluations per new vertex (exact counts:
    3.2-3.8 before, with the flat midpoint and a confirming evaluation)."""
    v, f = shared.arrays(name)
    s = shared.surface(name)
    levels = subdivide(v, f, levels=3, field=s)
    for k in range(1, 4):
        m, prev = levels[k], levels[k - 1]
        new = m.vertices[len(prev.vertices) :]
        values = np.abs(s.evaluate(new))
        assert values.max() <= 1e-6, (name, k)
        assert m.stats["fallbacks"] == 0 and m.stats["not_converged"] == 0, (name, k)
        assert m.stats["max_abs_value"] <= 1e-6
        # The reported value is predicted for steps accepted without evaluation; the field's
        # rounding noise here is a few 1e-10.
        assert values.max() <= max(10 * m.stats["max_abs_value"], 1e-9), (name, k)
        g = s.gradient(new)
        normals = g / np.linalg.norm(g, axis=1)[:, None]
        assert np.abs(normals - m.normals[len(prev.vertices) :]).max() <= 1e-5, (name, k)
        assert m.stats["evaluations"] == round(m.stats["iterations_mean"] * m.stats["projected"])
    assert levels[2].stats["iterations_mean"] <= 2.5, levels[2].stats


def test_open_mesh_keeps_boundary(shared):
    v, f = shared.arrays("knot")
    s = shared.surface("knot")
    centroids = v[f].mean(axis=1)
    drop = np.argsort(np.linalg.norm(centroids - v[0], axis=1))[:10]
    f_open = np.delete(f, drop, axis=0)
    _, counts = edges_of(f_open)
    boundary = int((counts == 1).sum())
    assert boundary > 0
    levels = subdivide(v, f_open, levels=2, field=s)
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
    imp = subdivide(v, f, levels=3, field=s)
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
    a = subdivide(v, f, levels=2, field=s)[2]
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
        subdivide(v, f, levels=-1, field=s)
    with pytest.raises(ValueError, match="levels"):
        subdivide(v, f, levels=20, field=s)
    with pytest.raises(ValueError, match="levels"):
        butterfly(v, f, levels=-1)
    with pytest.raises(ValueError, match="levels"):
        butterfly(v, f, levels=20)
    bad = f.copy()
    bad[3, 1] = 99
    with pytest.raises(ValueError, match="faces"):
        subdivide(v, bad, levels=1, field=s)
    with pytest.raises(ValueError, match="faces"):
        butterfly(v, bad, levels=1)
    with pytest.raises(ValueError, match="faces"):
        subdivide(v, np.vstack([f, [[0, 1, 2]]]), levels=1, field=s)
    with pytest.raises(ValueError, match="vertices"):
        subdivide(v[:, :2], f, levels=1, field=s)
    with pytest.raises(ValueError, match="tolerance"):
        subdivide(v, f, levels=1, field=s, tolerance=-1.0)
    with pytest.raises(ValueError, match="max_steps"):
        subdivide(v, f, levels=1, field=s, max_steps=0)
    with pytest.raises(ValueError, match="field"):
        subdivide(v, f, levels=1, field="sphere")
    with pytest.raises(ValueError, match="w"):
        butterfly(v, f, levels=1, w=float("nan"))


def test_zero_levels_is_control_mesh(icosahedron):
    v, f, s = icosahedron
    (m,) = subdivide(v, f, levels=0, field=s)
    assert isinstance(m, Mesh)
    assert np.array_equal(m.vertices, v) and np.array_equal(m.faces, f)
    assert m.stats["projected"] == 0


# --- Progress ---------------------------------------------------------------------------------------


def test_progress_counts_the_vertices_placed(icosahedron):
    v, f, s = icosahedron
    counts: list[int] = []
    levels = subdivide(v, f, levels=4, field=s, progress=counts.append)
    assert counts and counts == sorted(counts)
    assert counts[-1] == len(levels[-1].vertices)
    # The fallback's vertices count too, and a callable field reports once, at the end.
    counts.clear()
    sphere = implicitmesh.shapes.Sphere(radius=float(np.linalg.norm(v, axis=1).mean()))
    levels = subdivide(v, f, levels=3, field=sphere, max_steps=1, progress=counts.append)
    assert levels[1].stats["fallbacks"] > 0
    assert counts == [len(levels[-1].vertices)]
    counts.clear()
    levels = butterfly(v, f, levels=3, progress=counts.append)
    assert counts and counts == sorted(counts) and counts[-1] == len(levels[-1].vertices)


def test_progress_true_writes_a_line_or_a_bar(icosahedron, capsys):
    from implicitmesh.subdivision import _vertex_total

    v, f, s = icosahedron
    levels = subdivide(v, f, levels=2, field=s, progress=True)
    assert _vertex_total(f, v, 2) == len(levels[-1].vertices)
    butterfly(v, f, levels=2, progress=True)
    err = capsys.readouterr().err
    assert "subdivide" in err and "butterfly" in err
    with pytest.raises(ValueError, match="progress"):
        subdivide(v, f, levels=1, field=s, progress="yes")
    with pytest.raises(ValueError, match="progress"):
        butterfly(v, f, levels=1, progress=1)


# --- Any field: blobs, analytic shapes, Python callables -----------------------------------------


def test_icosahedron_onto_sphere_callable(icosahedron):
    v, f, _ = icosahedron
    r = float(np.linalg.norm(v, axis=1).mean())
    sphere = implicitmesh.shapes.Sphere(radius=r)
    levels = subdivide(v, f, levels=5, field=sphere)
    assert [len(m.faces) for m in levels] == [20 * 4**k for k in range(6)]
    errors = []
    for k, m in enumerate(levels):
        assert np.abs(np.linalg.norm(m.vertices, axis=1) - r).max() <= 1e-6, k
        assert np.array_equal(m.vertices[: len(v)], v)
        assert np.allclose(m.normals, m.vertices / r, atol=1e-6)
        assert m.to_trimesh().is_watertight
        errors.append(4 * np.pi * r**2 - m.to_trimesh().area)
        if k:
            assert m.stats["not_converged"] == 0 and m.stats["fallbacks"] == 0
            # Value and difference gradient: 7 field values per point and Newton step.
            assert m.stats["evaluations"] % 7 == 0 or m.stats["evaluations"] > 7 * m.stats["projected"]
    # The inscribed area converges to 4πr² from below, at second order (the error quarters).
    errors = np.asarray(errors)
    assert np.all(errors > 0) and np.all(np.diff(errors) < 0)
    assert errors[-1] / (4 * np.pi * r**2) < 1e-3
    assert 3.5 < errors[-2] / errors[-1] < 4.5


def test_torus_callable_and_call_batches():
    from conftest import CountingField

    torus = implicitmesh.shapes.Torus()
    coarse = implicitmesh.polygonize(torus, resolution=12)
    counting = CountingField(torus)
    levels = subdivide(coarse.vertices, coarse.faces, levels=2, field=counting)
    assert not counting.bad_inputs
    # Batched: a few calls per Newton step for the whole level, never one per point.
    assert counting.calls < 100 and counting.points > 10 * counting.calls
    for m in levels[1:]:
        # Marching-cubes control vertices are near the surface, the new ones on it.
        new = m.vertices[len(coarse.vertices) :]
        assert np.abs(torus(new)).max() <= 1e-6
        assert m.stats["not_converged"] == 0
        assert genus_of(m.euler_number) == 1
    assert abs(levels[2].to_trimesh().area / torus.area - 1) < 0.02


def test_blob_field():
    blobs = implicitmesh.BlobField(np.array([[0.0, 0.0, 0.0], [0.35, 0.1, 0.0]]), radii=0.6)
    coarse = implicitmesh.polygonize(blobs, bounds=[[-1, -1, -1], [1.4, 1, 1]], resolution=14)
    levels = subdivide(coarse.vertices, coarse.faces, levels=2, field=blobs)
    for m in levels[1:]:
        new = m.vertices[len(coarse.vertices) :]
        assert np.abs(blobs.evaluate(new)).max() <= 1e-6
        assert m.stats["not_converged"] == 0
        assert m.stats["evaluations"] < 7 * m.stats["projected"] * 30  # exact gradients, no 7×
        assert m.to_trimesh().is_watertight


def test_field_errors(icosahedron):
    v, f, s = icosahedron
    sphere = implicitmesh.shapes.Sphere(radius=1.0)
    for bad in (3, "sphere", np.zeros(3), object()):
        with pytest.raises(ValueError, match="field"):
            subdivide(v, f, levels=1, field=bad)
    with pytest.raises(ValueError, match="field.*shape"):
        subdivide(v, f, levels=1, field=lambda p: np.zeros(3))
    with pytest.raises(ValueError, match="non-finite"):
        subdivide(v, f, levels=1, field=lambda p: np.full(len(p), np.nan))
    with pytest.raises(ZeroDivisionError):
        subdivide(v, f, levels=1, field=lambda p: 1 / 0)
    for name, kw in (("d", {"d": 0.01}), ("w", {"w": 0.01}), ("kernel", {"kernel": "biharmonic"})):
        with pytest.raises(ValueError, match=name):
            subdivide(v, f, levels=1, field=sphere, **kw)
    with pytest.raises(ValueError, match="step"):
        subdivide(v, f, levels=1, field=sphere, step=0.0)
    with pytest.raises(ValueError, match="step"):
        subdivide(v, f, levels=1, field=s, step=1e-6)
    with pytest.raises(ValueError, match="step"):
        subdivide(v, f, levels=1, step=1e-6)
    # An explicit step works and gives the same mesh to rounding.
    a = subdivide(v, f, levels=2, field=sphere)[2].vertices
    b = subdivide(v, f, levels=2, field=sphere, step=1e-5)[2].vertices
    assert np.abs(a - b).max() < 1e-9


# --- Butterfly near the boundary -------------------------------------------------------------------


def bent_strip():
    """Six faces around the interior edge (0, 1) whose two ends are boundary vertices, symmetric
    under x -> 1 - x and y -> -y."""
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [0.5, 1, 0.3], [0.5, -1, 0.3], [-0.5, 1, 0.7], [1.5, 1, 0.7], [-0.5, -1, 0.7], [1.5, -1, 0.7]],
        dtype=float,
    )
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 2, 4], [2, 1, 5], [3, 0, 6], [1, 3, 7]])
    return v, f


@pytest.mark.parametrize("w", [0.0, 1 / 16])
def test_butterfly_edge_between_boundary_vertices(w):
    v, f = bent_strip()
    levels = butterfly(v, f, levels=3, w=w)
    assert [len(m.faces) for m in levels] == [6, 24, 96, 384]
    # The new vertex of edge (0, 1): the 10-point stencil, every outer vertex present here.
    new = levels[1].vertices[len(v) :]
    want = (0.5 - w) * (v[0] + v[1]) + (1 / 8 + 2 * w) * (v[2] + v[3]) - (1 / 16 + w) * v[4:].sum(axis=0) + w * (v[0] + v[1])
    got = new[np.argmin(np.linalg.norm(new - want, axis=1))]
    assert np.abs(got - want).max() < 1e-14
    assert abs(got[0] - 0.5) < 1e-15 and abs(got[1]) < 1e-15  # symmetric configuration, symmetric point
    # The whole mesh keeps both mirror symmetries at every level.
    for m in levels:
        key = {tuple(np.round(p, 9)) for p in m.vertices}
        for p in m.vertices:
            assert tuple(np.round([1 - p[0], p[1], p[2]], 9)) in key
            assert tuple(np.round([p[0], -p[1], p[2]], 9)) in key
    # Relabelling the vertices does not change the surface.
    perm = np.array([5, 2, 7, 0, 1, 6, 3, 4])  # new index of each old vertex
    v2 = np.empty_like(v)
    v2[perm] = v
    other = butterfly(v2, perm[f], levels=2, w=w)[2].vertices
    assert {tuple(np.round(p, 9)) for p in other} == {tuple(np.round(p, 9)) for p in levels[2].vertices}


def test_butterfly_open_planar_strip_stays_planar():
    # A zig-zag strip: every vertex on the boundary, every diagonal an interior edge between two
    # boundary vertices; tilted out of the coordinate planes.
    n = 8
    x = np.arange(n + 1) + 0.2 * (np.arange(n + 1) % 3)
    lower = np.stack([x, 0.1 * (np.arange(n + 1) % 2)], axis=1)
    upper = np.stack([x + 0.4, 1 + 0.07 * (np.arange(n + 1) % 3)], axis=1)
    uv = np.empty((2 * n + 2, 2))
    uv[0::2], uv[1::2] = lower, upper
    e1, e2 = np.array([1.0, 0.2, 0.3]), np.array([-0.1, 1.0, 0.5])
    v = 0.3 + uv[:, :1] * e1 + uv[:, 1:] * e2
    f = np.array([t for i in range(n) for t in ([2 * i, 2 * i + 2, 2 * i + 3], [2 * i, 2 * i + 3, 2 * i + 1])])
    normal = np.cross(e1, e2) / np.linalg.norm(np.cross(e1, e2))
    for w in (0.0, 1 / 16):
        levels = butterfly(v, f, levels=3, w=w)
        assert [len(m.faces) for m in levels] == [len(f) * 4**k for k in range(4)]
        for m in levels:
            assert np.abs((m.vertices - v[0]) @ normal).max() < 1e-12
            _, counts = edges_of(m.faces)
            assert counts.max() == 2


# --- Jin's claim: better triangles than marching cubes at the same count ---------------------------


def marching_cubes_near(surface, triangles: int):
    """Our marching cubes (octree: the same mesh as dense) at the resolution whose triangle count
    is closest to `triangles`."""
    probe = implicitmesh.polygonize(surface, resolution=48, method="octree")
    guess = int(round(48 * np.sqrt(triangles / len(probe.faces))))
    meshes = [implicitmesh.polygonize(surface, resolution=r, method="octree") for r in range(guess - 2, guess + 3)]
    return min(meshes, key=lambda m: abs(len(m.faces) - triangles))


@pytest.fixture(scope="module")
def jin_quality(shared):
    out = {}
    for name in ("knot", "star", "spot"):
        v, f = shared.arrays(name)
        s = shared.surface(name)
        levels = subdivide(v, f, levels=2, field=s)
        mc = marching_cubes_near(s, len(levels[2].faces))
        out[name] = (levels[0].quality(), levels[2].quality(), mc.quality(), len(levels[2].faces), len(mc.faces))
    return out


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(
            "knot",
            marks=pytest.mark.xfail(
                strict=True,
                reason="measured: knot_800's own triangles are thin (mean minimum angle 24°) and subdivision "
                "keeps them (24.2° at level 2), while marching cubes gets a 31° mean; the 5th percentile is "
                "better (9.4° vs 4.6°). Jin's limitation (2): subdivision does not improve the control mesh.",
            ),
        ),
        "star",
        "spot",
    ],
)
def test_jin_claim_better_angles_than_marching_cubes(jin_quality, name):
    _, sub, mc, n_sub, n_mc = jin_quality[name]
    assert abs(n_mc - n_sub) / n_sub < 0.05
    assert sub["min_angle_mean"] > mc["min_angle_mean"], (sub["min_angle_mean"], mc["min_angle_mean"])
    assert sub["min_angle_p5"] > mc["min_angle_p5"], (sub["min_angle_p5"], mc["min_angle_p5"])


@pytest.mark.parametrize("name", ["knot", "star", "spot"])
def test_subdivision_keeps_control_quality_and_beats_mc_worst_triangles(jin_quality, name):
    control, sub, mc, n_sub, n_mc = jin_quality[name]
    assert abs(n_mc - n_sub) / n_sub < 0.05
    # The thin triangles of marching cubes: the 5th percentile of minimum angles is far lower.
    assert sub["min_angle_p5"] > 1.5 * mc["min_angle_p5"]
    # Subdivision inherits the control mesh's angles (Jin §7, limitation 2).
    assert abs(sub["min_angle_mean"] - control["min_angle_mean"]) < 1.5


def test_surface_is_the_deprecated_name_of_field(icosahedron):
    """``surface=`` still works, with a DeprecationWarning: the same levels, array for array, and
    errors that name ``surface``; given with ``field=`` it is refused."""
    v, f, s = icosahedron
    with pytest.warns(DeprecationWarning, match="field="):
        old = subdivide(v, f, levels=2, surface=s)
    new = subdivide(v, f, levels=2, field=s)
    assert len(old) == len(new) == 3
    for a, b in zip(old, new):
        for x, y in ((a.vertices, b.vertices), (a.faces, b.faces), (a.normals, b.normals)):
            assert x.dtype == y.dtype and np.array_equal(x, y)
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="surface.*shape"):
        subdivide(v, f, levels=1, surface=lambda p: np.zeros(3))
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="surface"):
        subdivide(v, f, levels=1, surface=s, field=s)
