"""VariationalSurface: exact interpolation, constraint placement (Cuno's rule), sign convention,
analytic gradients, and the public model (centers, weights, polynomial)."""

from __future__ import annotations

import zlib

import numpy as np
import pytest
from scipy.spatial import cKDTree

from implicitmesh import VariationalSurface, shapes

from conftest import D, KERNELS, MESH_NAMES, surface_samples, vertex_normals_area_weighted, winding_number

INTERP_TOL = 1e-9


def max_constraint_error(surface) -> float:
    c = surface.constraints
    return float(np.max(np.abs(surface.evaluate(c["points"]) - c["values"])))


# --------------------------------------------------------------------------- exact interpolation


@pytest.mark.parametrize("name", MESH_NAMES)
def test_from_mesh_interpolates_constraints_exactly(shared, name):
    s = shared.surface(name)
    v, _ = shared.arrays(name)
    c = s.constraints
    assert c["points"].shape == (2 * len(v), 3)
    assert c["values"].shape == (2 * len(v),)
    assert len(s) == 2 * len(v)
    assert max_constraint_error(s) <= INTERP_TOL
    # The reported residual is the largest constraint error too.
    assert 0.0 <= s.residual <= INTERP_TOL
    # __call__ is evaluate.
    np.testing.assert_array_equal(s(c["points"][:50]), s.evaluate(c["points"][:50]))


@pytest.mark.parametrize("kernel", KERNELS)
def test_fit_interpolates_exactly_every_kernel_sphere(sphere_surfaces, kernel):
    s = sphere_surfaces[kernel]
    assert s.kernel == kernel
    assert max_constraint_error(s) <= INTERP_TOL


@pytest.mark.parametrize("kernel", KERNELS)
def test_fit_interpolates_exactly_every_kernel_irregular(knot_subset, kernel):
    p, n = knot_subset
    s = VariationalSurface.fit(p, n, d=D, kernel=kernel, exact=True)
    assert s.kernel == kernel
    assert s.constraints["boundary"] == len(p)
    assert max_constraint_error(s) <= INTERP_TOL
    # The data points themselves are on the zero set.
    assert np.max(np.abs(s.evaluate(p))) <= INTERP_TOL


@pytest.mark.parametrize("kernel", KERNELS)
def test_interpolate_reproduces_values(kernel):
    rng = np.random.default_rng(7)
    p = rng.uniform(-1.0, 1.0, size=(250, 3))
    values = rng.normal(size=250)
    s = VariationalSurface.interpolate(p, values, kernel=kernel)
    assert s.kernel == kernel
    np.testing.assert_allclose(s.evaluate(p), values, rtol=0, atol=INTERP_TOL)
    # No normal constraints are added.
    assert len(s) == len(p)
    np.testing.assert_array_equal(s.constraints["points"], p)
    np.testing.assert_array_equal(s.constraints["values"], values)


def test_interpolate_reproduces_a_linear_function_everywhere():
    # The interpolant contains the linear polynomial, so linear data is reproduced exactly
    # (zero RBF weights) away from the data too.
    rng = np.random.default_rng(11)
    p = rng.uniform(-1.0, 1.0, size=(60, 3))
    lin = lambda x: 0.3 - 1.2 * x[:, 0] + 0.5 * x[:, 1] + 2.0 * x[:, 2]  # noqa: E731
    s = VariationalSurface.interpolate(p, lin(p))
    q = rng.uniform(-2.0, 2.0, size=(100, 3))
    np.testing.assert_allclose(s.evaluate(q), lin(q), atol=1e-8)
    np.testing.assert_allclose(s.gradient(q), np.tile([-1.2, 0.5, 2.0], (100, 1)), atol=1e-8)


def test_smoothing_relaxes_interpolation():
    rng = np.random.default_rng(5)
    p = rng.uniform(-1.0, 1.0, size=(120, 3))
    values = rng.normal(size=120)
    exact = VariationalSurface.interpolate(p, values)
    smooth = VariationalSurface.interpolate(p, values, smoothing=1.0)
    assert np.max(np.abs(exact.evaluate(p) - values)) <= INTERP_TOL
    # With smoothing the data is approximated, not interpolated.
    assert np.max(np.abs(smooth.evaluate(p) - values)) > 1e-3


# --------------------------------------------------------------------------- constraint placement


def check_placement(surface, points, unit_normals, d, w_over_d=0.75, caps=None):
    """Boundary values 0, normal values w_i = (w/d)·d_i (or min(w/d, caps_i)·d_i), normal points
    at q_i + d_i n_i, and Cuno's rule with the halving of d_i."""
    c = surface.constraints
    n = len(points)
    assert c["boundary"] == n
    cp, cv, di = c["points"], c["values"], c["d"]
    assert cp.shape == (2 * n, 3) and cv.shape == (2 * n,) and di.shape == (n,)
    # Boundary constraints: the data points, value 0.
    np.testing.assert_array_equal(cp[:n], points)
    np.testing.assert_array_equal(cv[:n], 0.0)
    # Offsets: positive, at most d, and d halved a whole number of times.
    assert np.all(di > 0) and np.all(di <= d)
    halvings = np.log2(d / di)
    np.testing.assert_allclose(halvings, np.round(halvings), atol=1e-9)
    # Normal constraints: q_i + d_i n_i, value w_i = (w/d) d_i.
    np.testing.assert_allclose(cp[n:], points + di[:, None] * unit_normals, rtol=0, atol=1e-12)
    ratio = w_over_d if caps is None else np.minimum(w_over_d, caps)
    np.testing.assert_allclose(cv[n:], ratio * di, rtol=1e-12, atol=0)
    # Cuno's rule: no data point is nearer to a normal constraint than d_i (q_i itself is at d_i).
    tree = cKDTree(points)
    dist, _ = tree.query(cp[n:], k=1)
    assert np.all(dist >= di * (1 - 1e-9)), "a data point is nearer to a normal constraint than d_i"
    # ... and d_i was not shrunk more than needed: where d_i < d, the doubled offset breaks the rule.
    shrunk = np.flatnonzero(di < d)
    for i in shrunk:
        p2 = points[i] + 2 * di[i] * unit_normals[i]
        others = np.delete(points, i, axis=0)
        assert np.min(np.linalg.norm(others - p2, axis=1)) < 2 * di[i], f"d_{i} shrunk more than needed"
    return shrunk


@pytest.mark.parametrize("name", MESH_NAMES)
def test_from_mesh_constraint_placement(shared, name):
    v, f = shared.arrays(name)
    s = shared.surface(name)
    normals = vertex_normals_area_weighted(v, f)
    # Crease caps: w_i/d_i ≤ max(0.5, 0.9 × the smallest cosine between the vertex normal and
    # the normals of the faces around it).
    a, b, c = (v[f[:, k]] for k in range(3))
    fn = np.cross(b - a, c - a)
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    cmin = np.ones(len(v))
    for k in range(3):
        np.minimum.at(cmin, f[:, k], np.einsum("ij,ij->i", normals[f[:, k]], fn))
    caps = np.maximum(0.9 * cmin, 0.5)
    check_placement(s, v, normals, D, caps=caps)
    if name in ("knot", "torus2"):
        # Smooth meshes: almost every vertex keeps Cuno's w/d = 3/4.
        assert np.mean(caps >= 0.75) > 0.95


def test_fit_placement_default_d_and_custom_w(sphere_data):
    p, n = sphere_data
    # Normals of any non-zero length are normalised.
    s = VariationalSurface.fit(p, 3.0 * n, exact=True)
    default_d = 0.0075 * np.ptp(p, axis=0).max()
    check_placement(s, p, n, default_d)
    s2 = VariationalSurface.fit(p, n, d=0.02, w=0.05, exact=True)
    check_placement(s2, p, n, 0.02, w_over_d=0.05 / 0.02)
    assert max_constraint_error(s2) <= INTERP_TOL


def test_cuno_rule_shrinks_offsets_near_other_points():
    # A data point 0.03 above point 0 of a sphere, nearer than d = 0.05 to point 0's normal
    # constraint, forces point 0's offset to shrink (0.05 -> 0.025 -> 0.0125).
    p, n = shapes.fibonacci_sphere(100, radius=0.5)
    extra_p = p[0] + 0.03 * n[0]  # a data point just outside point 0, inside its offset d = 0.05
    points = np.vstack([p, extra_p])
    normals = np.vstack([n, n[0]])
    s = VariationalSurface.fit(points, normals, d=0.05, exact=True)
    shrunk = check_placement(s, points, normals, 0.05)
    assert 0 in shrunk
    assert s.constraints["d"][0] < 0.05


# --------------------------------------------------------------------------- sign convention


@pytest.mark.parametrize("kernel", KERNELS)
def test_sphere_negative_inside_positive_outside(sphere_data, sphere_surfaces, kernel):
    s = sphere_surfaces[kernel]
    inside = np.array([[0.0, 0.0, 0.0], [0.1, -0.2, 0.15], [0.0, 0.0, 0.6], [-0.5, 0.3, 0.1]])
    outside = np.array([[0.0, 0.0, 1.0], [0.9, 0.0, 0.0], [0.7, 0.7, 0.7], [-1.5, 0.2, 0.3]])
    assert np.all(s.evaluate(inside) < 0)
    assert np.all(s.evaluate(outside) > 0)
    # Outward normals: the gradient at the data points points along the given normal.
    p, n = sphere_data
    g = s.gradient(p)
    assert np.all(np.einsum("ij,ij->i", g, n) > 0)


def test_triharmonic_far_field_positive(shared):
    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(500, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    for name in MESH_NAMES:
        s = shared.surface(name)
        for radius in (2.0, 10.0, 1000.0):
            assert np.all(s.evaluate(radius * dirs) > 0), f"{name}: negative at distance {radius}"


@pytest.mark.parametrize("name", MESH_NAMES)
def test_sign_matches_inside_outside_of_the_mesh(shared, name):
    """Away from the surface, f < 0 exactly where the input mesh's winding number says inside."""
    v, f = shared.arrays(name)
    s = shared.surface(name)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    n = vertex_normals_area_weighted(v, f)
    pick = rng.choice(len(v), size=150, replace=False)
    q = np.vstack(
        [
            rng.uniform(-0.95, 0.95, size=(400, 3)),
            v[pick] - 0.07 * n[pick],  # mostly inside, where the solid is thick enough
            v[pick] + 0.07 * n[pick],
        ]
    )
    # Keep points at least ~0.04 from the mesh (the fit stays within a few thousandths of it).
    dist, _ = cKDTree(surface_samples(v, f, 0.01)).query(q)
    q = q[dist > 0.05]
    wn = winding_number(q, v, f)
    assert np.all((np.abs(wn) < 1e-6) | (np.abs(wn - 1) < 1e-6)), "input mesh is not closed/outward"
    inside = wn > 0.5
    assert inside.sum() > 30 and (~inside).sum() > 30
    values = s.evaluate(q)
    wrong = np.flatnonzero((values < 0) != inside)
    assert len(wrong) == 0, f"{name}: {len(wrong)} points with the wrong sign, e.g. {q[wrong[:3]]}"


# --------------------------------------------------------------------------- gradients


def central_differences(surface, p, h):
    """(f(p + h e) − f(p − h e)) / 2h per axis, Richardson-extrapolated from steps h and h/2 so
    that the truncation error (large near the centres for the biharmonic kernel r) stays far below
    the tolerance."""

    def cd(step):
        return np.stack(
            [(surface.evaluate(p + step * e) - surface.evaluate(p - step * e)) / (2 * step) for e in np.eye(3)],
            axis=1,
        )

    return (4.0 * cd(h / 2) - cd(h)) / 3.0


@pytest.mark.parametrize("kernel", KERNELS)
def test_gradient_matches_central_differences(sphere_data, sphere_surfaces, kernel):
    s = sphere_surfaces[kernel]
    rng = np.random.default_rng(21)
    p_data, n_data = sphere_data
    pts = np.vstack(
        [
            rng.uniform(-1.2, 1.2, size=(200, 3)),
            # near the surface, between the data points
            p_data[::5] * 1.01 + 0.003 * rng.normal(size=(60, 3)),
        ]
    )
    g = s.gradient(pts)
    assert g.shape == (len(pts), 3) and g.dtype == np.float64
    fd = central_differences(s, pts, 1e-5)
    err = np.linalg.norm(g - fd, axis=1) / np.maximum(np.linalg.norm(g, axis=1), 1e-3)
    assert err.max() < 1e-5, f"{kernel}: relative gradient error {err.max():.2e}"


@pytest.mark.parametrize("kernel", KERNELS)
def test_gradient_matches_central_differences_irregular(knot_subset, kernel):
    p, n = knot_subset
    s = VariationalSurface.fit(p, n, d=D, kernel=kernel, exact=True)
    rng = np.random.default_rng(22)
    pts = rng.uniform(-1.0, 1.0, size=(200, 3))
    g = s.gradient(pts)
    fd = central_differences(s, pts, 1e-5)
    err = np.linalg.norm(g - fd, axis=1) / np.maximum(np.linalg.norm(g, axis=1), 1e-3)
    assert err.max() < 1e-5, f"{kernel}: relative gradient error {err.max():.2e}"


# --------------------------------------------------------------------------- the public model


def phi(kernel, r):
    if kernel == "triharmonic":
        return r**3
    if kernel == "biharmonic":
        return r
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(r > 0, r * r * np.log(np.where(r > 0, r, 1.0)), 0.0)


@pytest.mark.parametrize("kernel", KERNELS)
def test_centers_weights_polynomial_reproduce_evaluate(knot_subset, kernel):
    """f(x) = Σ λ_j φ(|x − c_j|) + a + b·x with the documented centers/weights/polynomial, in the
    caller's coordinates (the fit works in normalised ones internally)."""
    p, n = knot_subset
    # Data far from the unit box, so that a normalisation bug cannot hide.
    s = VariationalSurface.fit(10.0 * p + [3.0, -4.0, 5.0], n, kernel=kernel, exact=True)
    c, w, poly = s.centers, s.weights, s.polynomial
    assert c.shape == (len(s), 3) and w.shape == (len(s),) and poly.shape == (4,)
    np.testing.assert_array_equal(c, s.constraints["points"])
    # Orthogonality conditions of the RBF system.
    scale = np.abs(w).sum()
    assert abs(w.sum()) <= 1e-9 * scale
    assert np.all(np.abs(w @ c) <= 1e-9 * scale * np.abs(c).max())
    rng = np.random.default_rng(2)
    q = 10.0 * rng.uniform(-1, 1, size=(40, 3)) + [3.0, -4.0, 5.0]
    terms = phi(kernel, np.linalg.norm(q[:, None, :] - c[None, :, :], axis=2)) * w
    direct = terms.sum(axis=1) + poly[0] + q @ poly[1:]
    tol = 1e-10 * np.abs(terms).sum(axis=1).max() + 1e-10
    np.testing.assert_allclose(direct, s.evaluate(q), rtol=0, atol=tol)


def test_scale_and_translation_equivariance(sphere_data):
    p, n = sphere_data
    s1 = VariationalSurface.fit(p, n, d=0.01, exact=True)
    s10 = VariationalSurface.fit(10.0 * p + 5.0, n, d=0.1, exact=True)
    q = np.random.default_rng(4).uniform(-1, 1, size=(50, 3))
    np.testing.assert_allclose(s10.evaluate(10.0 * q + 5.0), 10.0 * s1.evaluate(q), rtol=1e-8, atol=1e-9)


def test_bounds_contain_the_data_with_margin(shared):
    for name in MESH_NAMES:
        v, _ = shared.arrays(name)
        b = shared.surface(name).bounds
        assert b.shape == (2, 3)
        lo, hi = v.min(axis=0), v.max(axis=0)
        # A cube centred on the data's box, side 1.2 × its largest side.
        half = 0.6 * (hi - lo).max()
        np.testing.assert_allclose(b[0], (lo + hi) / 2 - half, atol=1e-12)
        np.testing.assert_allclose(b[1], (lo + hi) / 2 + half, atol=1e-12)


def test_from_mesh_merges_duplicate_vertices(shared):
    """A mesh with vertices split along a seam (as read from STL/OBJ) gives the same surface as
    the welded mesh."""
    v, f = shared.arrays("icosahedron")
    # Duplicate every vertex used by the first 200 faces and point those faces at the copies.
    f2 = f.copy()
    used = np.unique(f[:200])
    copy_index = {int(u): len(v) + k for k, u in enumerate(used)}
    v2 = np.vstack([v, v[used]])
    f2[:200] = np.vectorize(copy_index.get)(f[:200])
    # Vertices only used by the first faces are now unused; keep those used by both.
    still_used = np.unique(f2)
    remap = -np.ones(len(v2), dtype=np.int64)
    remap[still_used] = np.arange(len(still_used))
    v2, f2 = v2[still_used], remap[f2]
    a = shared.surface("icosahedron")
    b = VariationalSurface.from_mesh(v2, f2, d=D)
    assert len(b) == len(a)
    q = np.random.default_rng(9).uniform(-1, 1, size=(100, 3))
    np.testing.assert_allclose(b.evaluate(q), a.evaluate(q), atol=1e-9)


def test_from_mesh_merges_duplicates_that_differ_only_in_the_sign_of_zero():
    """-0.0 == 0.0: a seam copy of a vertex whose zero coordinate was written as -0.0 (as mirroring
    or some exporters produce) is the same position and must be merged like any other copy."""
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2, radius=0.8)
    v, f = np.array(m.vertices), np.array(m.faces)
    i = int(np.flatnonzero((v == 0).any(axis=1))[0])  # a vertex with a zero coordinate
    copy = np.where(v[i] == 0, -0.0, v[i])
    assert np.array_equal(copy, v[i]) and np.signbit(copy).any()
    v2 = np.vstack([v, copy])
    f2 = f.copy()
    uses = np.flatnonzero((f == i).any(axis=1))
    for k in uses[: len(uses) // 2]:
        f2[k][f2[k] == i] = len(v)
    welded = VariationalSurface.from_mesh(v, f)
    seamed = VariationalSurface.from_mesh(v2, f2)
    assert len(seamed) == len(welded)
    q = np.random.default_rng(6).uniform(-1, 1, size=(50, 3))
    np.testing.assert_allclose(seamed.evaluate(q), welded.evaluate(q), atol=1e-9)
