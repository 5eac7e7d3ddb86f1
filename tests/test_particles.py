"""Blob fields of SPH particles: the kernels, splashsurf's colour field, input without copies."""

import pickle
import tracemalloc

import numpy as np
import pytest

import implicitmesh as im

KERNELS = ("triquet", "cubic_spline", "wendland")


def profile(kernel, q):
    """w(q) by the textbook formulas (1 at q = 0, 0 from q = 1 on)."""
    q = np.asarray(q, dtype=float)
    inside = q < 1.0
    if kernel == "triquet":
        w = (1.0 - q * q) ** 2
    elif kernel == "cubic_spline":
        w = np.where(q <= 0.5, 6.0 * (q**3 - q**2) + 1.0, 2.0 * (1.0 - q) ** 3)
    else:
        w = (1.0 - q) ** 4 * (1.0 + 4.0 * q)
    return np.where(inside, w, 0.0)


def brute_potential(kernel, centers, radii, strengths, p):
    d = np.linalg.norm(p[:, None, :] - centers[None, :, :], axis=2)
    return (strengths[None, :] * profile(kernel, d / radii[None, :])).sum(axis=1)


def jittered_block(n, spacing, seed, jitter=0.1):
    rng = np.random.default_rng(seed)
    i = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    return i * spacing + rng.uniform(-jitter, jitter, (len(i), 3)) * spacing


def same_mesh(a, b):
    """The same triangles at the same float64 coordinates, and the same normals per vertex."""
    c = im.compare(a, b)
    normals = [{v.tobytes(): n.tobytes() for v, n in zip(m.vertices, m.normals)} for m in (a, b)]
    return c["missing"] == 0 and c["extra"] == 0 and c["common"] == len(a.faces) and normals[0] == normals[1]


def closed_and_oriented(faces):
    """Every directed edge once, and its reverse once: a closed, consistently oriented mesh."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    directed = {tuple(x) for x in e.tolist()}
    return len(directed) == len(e) and all((b, a) in directed for a, b in directed)


@pytest.mark.parametrize("kernel", KERNELS)
def test_kernel_values_equal_brute_force(kernel):
    rng = np.random.default_rng(1)
    c = rng.uniform(-0.8, 0.8, (300, 3))
    r = rng.uniform(0.1, 0.3, 300)
    a = rng.uniform(0.5, 2.0, 300)
    b = im.BlobField(c, r, a, threshold=0.4, kernel=kernel)
    assert b.kernel == kernel
    p = rng.uniform(-1.0, 1.0, (3000, 3))
    ref = brute_potential(kernel, c, r, a, p)
    np.testing.assert_allclose(b.potential(p), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.evaluate(p), 0.4 - ref, rtol=0, atol=1e-12)
    h = 1e-6
    fd = np.stack([(b.evaluate(p + h * e) - b.evaluate(p - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(b.gradient(p), fd, rtol=0, atol=1e-5)


def test_default_kernel_is_triquet():
    rng = np.random.default_rng(2)
    c = rng.uniform(-0.5, 0.5, (50, 3))
    p = rng.uniform(-0.8, 0.8, (500, 3))
    a, b = im.BlobField(c, 0.3), im.BlobField(c, 0.3, kernel="triquet")
    assert a.kernel == "triquet"
    assert np.array_equal(a.evaluate(p), b.evaluate(p))
    with pytest.raises(ValueError, match="kernel"):
        im.BlobField(c, 0.3, kernel="gaussian")


@pytest.mark.parametrize("kernel", KERNELS)
def test_kernel_survives_pickle_and_save(kernel, tmp_path):
    rng = np.random.default_rng(3)
    b = im.BlobField(rng.uniform(-0.5, 0.5, (40, 3)), 0.3, rng.uniform(0.5, 1.5, 40), 0.45, kernel=kernel)
    p = rng.uniform(-0.8, 0.8, (400, 3))
    im.save(tmp_path / "b.npz", b)
    for c in (pickle.loads(pickle.dumps(b)), im.load(tmp_path / "b.npz")):
        assert c.kernel == kernel
        assert np.array_equal(c.evaluate(p), b.evaluate(p))
        assert np.array_equal(c.gradient(p), b.gradient(p))


@pytest.mark.parametrize("kernel", ["cubic_spline", "wendland"])
def test_sph_kernels_sparse_equals_dense(kernel):
    rng = np.random.default_rng(4)
    b = im.BlobField(rng.uniform(-0.6, 0.6, (200, 3)), 0.25, threshold=0.3, kernel=kernel)
    dense = im.polygonize(b, resolution=45, method="dense")
    sparse = im.polygonize(b, resolution=45, method="sparse")
    assert len(dense.faces) > 1000
    assert same_mesh(dense, sparse)


@pytest.mark.parametrize("kernel", ["cubic_spline", "wendland"])
def test_sph_kernels_octree_and_tracking_equal_dense(kernel):
    """The octree's safety comes from the kernel's gradient bound: no crossed block is lost."""
    rng = np.random.default_rng(14)
    b = im.BlobField(rng.uniform(-0.6, 0.6, (150, 3)), rng.uniform(0.1, 0.3, 150), threshold=0.35, kernel=kernel)
    dense = im.polygonize(b, resolution=64, method="dense", normals=False)
    assert len(dense.faces) > 1000
    for method in ("octree", "tracking"):
        m = im.polygonize(b, resolution=64, method=method, normals=False)
        c = im.compare(dense, m)
        assert (c["missing"], c["extra"]) == (0, 0), (method, c)


def test_colour_field_equals_numpy_sum():
    """splashsurf's formula with its normalised cubic spline, mass (2r)³ρ₀ and densities."""
    rng = np.random.default_rng(5)
    r, ell = 0.05, 2.0
    x = rng.uniform(-0.3, 0.3, (400, 3))
    f = im.BlobField.from_particles(x, r, smoothing_length=ell)
    h = 2.0 * ell * r
    sigma = 8.0 / (np.pi * h**3)
    mass = 1000.0 * (2.0 * r) ** 3
    rho = mass * (sigma * profile("cubic_spline", np.linalg.norm(x[:, None] - x[None], axis=2) / h)).sum(axis=1)
    p = rng.uniform(-0.4, 0.4, (2000, 3))
    w = sigma * profile("cubic_spline", np.linalg.norm(p[:, None] - x[None], axis=2) / h)
    ref = (w * (mass / rho)[None, :]).sum(axis=1)
    np.testing.assert_allclose(f.potential(p), ref, rtol=0, atol=1e-12)
    assert f.threshold == 0.6 and f.kernel == "cubic_spline"
    np.testing.assert_array_equal(f.radii, np.full(400, h))


@pytest.mark.parametrize("kernel", ["cubic_spline", "wendland"])
def test_colour_field_about_one_inside_a_block(kernel):
    x = jittered_block(14, 1.0, 6, jitter=0.0)
    f = im.BlobField.from_particles(x, 0.5, kernel=kernel)
    inner = x[np.all((x >= 4) & (x <= 9), axis=1)]
    np.testing.assert_allclose(f.potential(inner), 1.0, atol=1e-12)
    mid = inner[:50] + 0.5
    np.testing.assert_allclose(f.potential(mid), 1.0, atol=0.06)
    # Far outside the block the field is 0; on its faces about a half.
    assert f.potential(np.array([[-3.0, 6.0, 6.0]]))[0] == 0.0


def test_colour_field_mesh_closed_and_sparse_equals_dense():
    x = jittered_block(10, 0.1, 7)
    # A falling sphere of particles above the slab.
    s = jittered_block(5, 0.1, 8)
    s = s[np.linalg.norm(s - 0.2, axis=1) < 0.25] + [0.25, 0.25, 1.3]
    f = im.BlobField.from_particles(np.vstack([x, s]), 0.05)
    lo, hi = f.bounds
    cells = int(np.ceil((hi - lo).max() / 0.025))
    dense = im.polygonize(f, resolution=cells, method="dense")
    mesh = im.polygonize(f, resolution=cells, method="sparse")
    assert same_mesh(dense, mesh)
    assert closed_and_oriented(mesh.faces) and mesh.volume > 0
    assert mesh.euler_number == 4  # two spheres


def test_colour_field_bad_input_named():
    x = jittered_block(3, 0.1, 9)
    for kwargs, name in [
        ({"particle_radius": 0.0}, "particle_radius"),
        ({"particle_radius": -1.0}, "particle_radius"),
        ({"particle_radius": 0.05, "smoothing_length": 0.0}, "smoothing_length"),
        ({"particle_radius": 0.05, "iso_surface_threshold": 0.0}, "iso_surface_threshold"),
        ({"particle_radius": 0.05, "kernel": "poly6"}, "kernel"),
    ]:
        with pytest.raises(ValueError, match=name):
            im.BlobField.from_particles(x, **kwargs)
    bad = x.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="particles"):
        im.BlobField.from_particles(bad, 0.05)
    with pytest.raises(ValueError, match="particles"):
        im.BlobField.from_particles(x[:, :2], 0.05)
    with pytest.raises(ValueError, match="particles"):
        im.BlobField.from_particles(np.array([["a", "b", "c"]]), 0.05)


def test_colour_field_reports_progress():
    x = jittered_block(8, 0.1, 10)
    seen = []
    im.BlobField.from_particles(x, 0.05, progress=seen.append)
    assert seen and seen[-1] == len(x)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("order", ["C", "F"])
def test_float32_and_fortran_input_give_the_same_field(dtype, order):
    rng = np.random.default_rng(11)
    x32 = rng.uniform(-0.5, 0.5, (500, 3)).astype(np.float32)
    ref = im.BlobField.from_particles(x32.astype(np.float64), 0.04)
    x = np.asarray(x32, dtype=dtype, order=order)
    assert x.flags.f_contiguous == (order == "F")
    f = im.BlobField.from_particles(x, 0.04)
    b = im.BlobField(x, 0.15, kernel="wendland")
    b_ref = im.BlobField(x32.astype(np.float64), 0.15, kernel="wendland")
    p = rng.uniform(-0.6, 0.6, (1000, 3))
    assert np.array_equal(f.centers, ref.centers) and np.array_equal(f.strengths, ref.strengths)
    assert np.array_equal(f.evaluate(p), ref.evaluate(p))
    assert np.array_equal(b.evaluate(p), b_ref.evaluate(p))
    # A strided view (every other row) is read in place too.
    assert np.array_equal(im.BlobField(x[::2], 0.15).centers, x32[::2].astype(np.float64))


def test_float32_input_is_not_copied_in_python():
    x = np.random.default_rng(12).uniform(-1, 1, (200_000, 3)).astype(np.float32, order="F")
    tracemalloc.start()
    try:
        im.BlobField(x, 0.05)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # A float64 copy would be 4.8 MB of numpy memory.
    assert peak < 1_000_000, peak


def test_same_surface_as_pysplashsurf():
    import pysplashsurf  # in the test extra
    s = 0.1
    x = jittered_block(16, s, 13)
    r = s / 2
    mesh = pysplashsurf.reconstruct_surface(
        x, particle_radius=r, smoothing_length=2.0, cube_size=0.5, iso_surface_threshold=0.6
    )
    theirs = _splashsurf_mesh(mesh)
    f = im.BlobField.from_particles(x, r)
    lo, hi = f.bounds
    ours = im.polygonize(f, resolution=int(round((hi - lo).max() / (r / 2))), method="sparse")
    assert abs(ours.area / theirs.area - 1) < 0.01, (ours.area, theirs.area)
    assert abs(ours.volume / theirs.volume - 1) < 0.01, (ours.volume, theirs.volume)


def _splashsurf_mesh(result):
    """(vertices, faces) of what pysplashsurf.reconstruct_surface returns, as a Mesh."""
    m = result.mesh if hasattr(result, "mesh") else result
    if hasattr(m, "vertices"):
        v, t = m.vertices, m.triangles
    else:
        v, t = m
    return im.Mesh(np.asarray(v, dtype=float), np.asarray(t, dtype=np.int64))
