"""Blob fields in single precision (``precision="single"``): values in float32 everywhere, sparse ==
dense bit for bit, the same faces as double precision away from the threshold."""

import pickle

import numpy as np
import pytest

import implicitmesh as im
from test_particles import closed_and_oriented, jittered_block, same_mesh

KERNELS = ("triquet", "cubic_spline", "wendland")


def slab_and_sphere(n, spacing, seed):
    """A jittered slab n × n × n/2 of particles and a sphere of particles falling onto it."""
    slab = jittered_block(n, spacing, seed)
    slab = slab[slab[:, 2] < n * spacing / 2]
    ball = jittered_block(n // 2, spacing, seed + 1)
    c = ball.mean(axis=0)
    ball = ball[np.linalg.norm(ball - c, axis=1) < n * spacing / 5] - c
    return np.vstack([slab, ball + [n * spacing / 2, n * spacing / 2, 1.1 * n * spacing]])


def lattice_points(bounds, cells):
    """Lattice point ``[i, j, k]`` as the core computes it (``origin + index * cell``)."""
    _, origin, cell = im._core.lattice(bounds, cells)
    axes = [origin[a] + np.arange(cells + 1) * cell[a] for a in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


@pytest.mark.parametrize("kernel", KERNELS)
def test_values_are_float32_everywhere(kernel):
    rng = np.random.default_rng(1)
    c = rng.uniform(-0.6, 0.6, (200, 3))
    r = rng.uniform(0.15, 0.3, 200)
    d = im.BlobField(c, r, 1.0, 0.4, kernel=kernel)
    s = im.BlobField(c, r, 1.0, 0.4, kernel=kernel, precision="single")
    assert (d.precision, s.precision) == ("double", "single")
    p = rng.uniform(-0.8, 0.8, (5000, 3))
    v, w = s.evaluate(p), d.evaluate(p)
    assert np.array_equal(v, v.astype(np.float32).astype(np.float64))
    assert not np.array_equal(v, w)
    # Each term's error is a few float32 roundings of values at most 1.
    assert np.abs(v - w).max() < 1e-5
    assert np.array_equal(s.potential(p), s.potential(p).astype(np.float32))
    # Gradients stay float64, the same as in double precision.
    assert np.array_equal(s.gradient(p), d.gradient(p))


@pytest.mark.parametrize("kernel", KERNELS)
def test_sparse_equals_dense_bit_for_bit(kernel):
    """A thick slab (blocks inside it ruled out), empty blocks around, a sphere above."""
    x = slab_and_sphere(16, 0.1, 2)
    if kernel == "triquet":
        f, g = (im.BlobField(x, 0.2, 1.0, 1.0, precision=p) for p in ("single", "double"))
    else:
        f, g = (im.BlobField.from_particles(x, 0.05, kernel=kernel, precision=p) for p in ("single", "double"))
    lo, hi = f.bounds
    cells = int(np.ceil((hi - lo).max() / 0.025))
    dense = im.polygonize(f, resolution=cells, method="dense")
    sparse = im.polygonize(f, resolution=cells, method="sparse")
    assert len(dense.faces) > 20000
    assert same_mesh(dense, sparse)
    # Blocks were ruled out (empty ones and ones inside the slab), about as many as in double
    # precision (the bounds' margin widened by the float32 rounding).
    evaluations = sparse.stats["evaluations"]
    assert evaluations < 0.6 * sparse.stats["lattice_points"]
    assert evaluations <= 1.02 * im.polygonize(g, resolution=cells, method="sparse").stats["evaluations"]
    # The dense values are the point values (float32, widened).
    p = lattice_points(dense.stats["bounds"], cells)[::97]
    assert np.array_equal(f.evaluate(p), f.evaluate(p).astype(np.float32))


@pytest.mark.parametrize("kernel", KERNELS)
def test_same_faces_as_double_away_from_the_threshold(kernel):
    """Where every lattice value is at least 1e-4 from the threshold (checked in float64 first),
    single and double precision give the same faces, and vertices within float32 rounding."""
    rng = np.random.default_rng(3)
    c = rng.uniform(-0.6, 0.6, (150, 3))
    r = rng.uniform(0.2, 0.35, 150)
    cells = 30
    bounds = np.array([[-1.0] * 3, [1.0] * 3])
    potential = np.sort(im.BlobField(c, r, 1.0, 0.5, kernel=kernel).potential(lattice_points(bounds, cells)))
    # The threshold in the middle of the widest gap between lattice potentials in [0.2, 0.8].
    mid = (potential > 0.2) & (potential < 0.8)
    gaps = np.diff(potential)[mid[:-1]]
    k = np.argmax(gaps)
    t = float(potential[mid][k] + gaps[k] / 2)
    d = im.BlobField(c, r, 1.0, t, kernel=kernel)
    values = d.evaluate(lattice_points(bounds, cells))
    assert np.abs(values).min() >= 1e-4
    s = im.BlobField(c, r, 1.0, t, kernel=kernel, precision="single")
    for method in ("dense", "sparse"):
        a = im.polygonize(d, bounds=bounds, resolution=cells, method=method)
        b = im.polygonize(s, bounds=bounds, resolution=cells, method=method)
        assert len(a.faces) > 1000
        assert np.array_equal(a.faces, b.faces), method
        assert np.abs(a.vertices - b.vertices).max() < 1e-3 * 2.0 / cells
        assert np.abs(a.normals - b.normals).max() < 1e-3


def test_precision_survives_pickle_and_save(tmp_path):
    rng = np.random.default_rng(4)
    b = im.BlobField(rng.uniform(-0.5, 0.5, (40, 3)), 0.3, 1.0, 0.45, kernel="wendland", precision="single")
    p = rng.uniform(-0.8, 0.8, (400, 3))
    im.save(tmp_path / "b.npz", b)
    for c in (pickle.loads(pickle.dumps(b)), im.load(tmp_path / "b.npz")):
        assert (c.precision, c.kernel) == ("single", "wendland")
        assert np.array_equal(c.evaluate(p), b.evaluate(p))
    assert "precision='single'" in repr(b) or 'precision="single"' in repr(b)
    f = im.BlobField.from_particles(jittered_block(6, 0.1, 5), 0.05, precision="single")
    g = pickle.loads(pickle.dumps(f))
    assert g.precision == "single" and np.array_equal(g.evaluate(p), f.evaluate(p))


def test_colour_field_densities_stay_double():
    x = jittered_block(8, 0.1, 6)
    d = im.BlobField.from_particles(x, 0.05)
    s = im.BlobField.from_particles(x, 0.05, precision="single")
    assert np.array_equal(d.strengths, s.strengths)


def test_bad_precision_refused():
    c = np.zeros((3, 3))
    for bad in ("float", "f32", "Single", ""):
        with pytest.raises(ValueError, match="precision"):
            im.BlobField(c, 0.3, precision=bad)
        with pytest.raises(ValueError, match="precision"):
            im.BlobField.from_particles(c, 0.3, precision=bad)


def test_slab_and_sphere_watertight_and_outward():
    x = slab_and_sphere(12, 0.1, 7)
    for f in (
        im.BlobField(x, 0.2, 1.0, 1.0, precision="single"),
        im.BlobField.from_particles(x, 0.05, precision="single"),
    ):
        lo, hi = f.bounds
        mesh = im.polygonize(f, resolution=int(np.ceil((hi - lo).max() / 0.025)), method="sparse")
        assert closed_and_oriented(mesh.faces)
        assert mesh.volume > 0
        assert mesh.euler_number == 4  # two spheres
        # Normals point outward: along the field's gradient of threshold − potential.
        c = mesh.vertices.mean(axis=0)
        assert np.mean(np.einsum("ij,ij->i", mesh.normals, mesh.vertices - c) > 0) > 0.9
