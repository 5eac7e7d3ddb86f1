"""Anisotropic particle kernels (``BlobField.from_particles(..., anisotropic=...)``, Yu & Turk
2013) and stray fragments (``polygonize(..., min_particles=k)``): sparse == dense bit for bit in
f64 and f32, flat water flat, a lone particle round, tiles, state, bad input."""

import pickle

import numpy as np
import pytest

import implicitmesh as im
from test_particles import closed_and_oriented, jittered_block, same_mesh

R = 0.05  # particle radius: spacing 0.1


def slab_and_drop():
    x = jittered_block(10, 0.1, 7)
    s = jittered_block(5, 0.1, 8)
    s = s[np.linalg.norm(s - 0.2, axis=1) < 0.25] + [0.25, 0.25, 1.3]
    return np.vstack([x, s, [[0.5, 0.5, 2.2]]])  # a slab, a sphere and a lone particle


def mesh_of(field, **kw):
    lo, hi = field.bounds
    cells = int(np.ceil((hi - lo).max() / (0.5 * R)))
    return im.polygonize(field, bounds=(lo, lo + cells * 0.5 * R), resolution=cells, **kw)


@pytest.mark.parametrize("precision", ["double", "single"])
def test_sparse_equals_dense_bit_for_bit(precision):
    f = im.BlobField.from_particles(slab_and_drop(), R, anisotropic=True, precision=precision)
    assert f.shapes is not None and f.shapes.shape == (len(f), 3, 3)
    dense = mesh_of(f, method="dense")
    sparse = mesh_of(f, method="sparse")
    assert len(dense.faces) > 5000
    assert same_mesh(dense, sparse)
    assert closed_and_oriented(sparse.faces)
    assert sparse.euler_number == 6  # slab, sphere and the lone particle: three spheres
    # The lattice values are the point values, bit for bit.
    p = sparse.vertices[:2000]
    assert np.array_equal(f.evaluate(p), f.evaluate(p[::-1])[::-1])


def test_octree_and_tracking_equal_dense():
    f = im.BlobField.from_particles(slab_and_drop(), R, anisotropic=True)
    dense = mesh_of(f, method="dense", normals=False)
    for method in ("octree", "tracking"):
        m = mesh_of(f, method=method, normals=False)
        c = im.compare(dense, m)
        assert (c["missing"], c["extra"]) == (0, 0), (method, c)
    tess = im.Tessellator()
    for _ in range(2):
        t = mesh_of(f, method="sparse", normals=False)
        lo, hi = f.bounds
        cells = int(np.ceil((hi - lo).max() / (0.5 * R)))
        m = tess.polygonize(f, bounds=(lo, lo + cells * 0.5 * R), resolution=cells, normals=False)
        c = im.compare(t, m)
        assert (c["missing"], c["extra"]) == (0, 0)


def test_gradient_matches_differences():
    f = im.BlobField.from_particles(jittered_block(6, 0.1, 3), R, anisotropic=True, kernel="wendland")
    p = np.random.default_rng(2).uniform(0.0, 0.5, (200, 3))
    h = 1e-6
    fd = np.stack([(f.evaluate(p + e * h) - f.evaluate(p - e * h)) / (2 * h) for e in np.eye(3)], axis=1)
    g = f.gradient(p)
    assert np.abs(g - fd).max() < 1e-5 * max(1.0, np.abs(g).max())


def flat_top(mesh, top):
    """Vertices of the top face away from the slab's edges: (x, y) within the middle, z above
    the last layer's centres."""
    v = mesh.vertices
    return v[(np.abs(v[:, 0] - 1.0) < 0.5) & (np.abs(v[:, 1] - 1.0) < 0.5) & (v[:, 2] > top - 0.25)]


def test_flat_slab_gives_a_flat_surface():
    """A 21 × 21 × 6 slab of particles jittered by ±0.1 spacing: the middle of the top face lies
    within 0.05 r RMS (0.1 r at most) of its fitted plane with anisotropic kernels (measured:
    RMS 0.019 r, at most 0.053 r); with round ones RMS 0.072 r, at most 0.22 r."""
    rng = np.random.default_rng(11)
    i = np.stack(np.meshgrid(np.arange(21), np.arange(21), np.arange(6), indexing="ij"), axis=-1).reshape(-1, 3)
    x = i * 0.1 + rng.uniform(-0.01, 0.01, i.shape)
    top = x[:, 2].max()
    worst, rms = {}, {}
    for aniso in (False, True):
        m = mesh_of(im.BlobField.from_particles(x, R, anisotropic=aniso), method="sparse", normals=False)
        pts = flat_top(m, top)
        assert len(pts) > 300
        a = np.c_[pts[:, :2], np.ones(len(pts))]
        coef, *_ = np.linalg.lstsq(a, pts[:, 2], rcond=None)
        d = (pts[:, 2] - a @ coef) / np.sqrt(1 + coef[0] ** 2 + coef[1] ** 2)
        worst[aniso], rms[aniso] = np.abs(d).max(), np.sqrt((d * d).mean())
    assert rms[True] < 0.05 * R and worst[True] < 0.1 * R, (rms, worst)
    assert rms[False] > 2 * rms[True] and worst[False] > 2 * worst[True], (rms, worst)


def test_lone_particle_is_a_round_closed_body():
    f = im.BlobField.from_particles(np.array([[0.3, -0.2, 0.1]]), R, anisotropic=True)
    np.testing.assert_array_equal(f.shapes[0], 2.0 * np.eye(3))  # round, of radius k_n·H
    m = mesh_of(f, method="sparse")
    assert closed_and_oriented(m.faces) and m.euler_number == 2  # one sphere, genus 0
    d = np.linalg.norm(m.vertices - [0.3, -0.2, 0.1], axis=1)
    assert d.max() - d.min() < 0.1 * d.mean()
    assert d.max() < 0.5 * 4 * R  # inside the round kernel's support k_n·H


def test_volume_and_smoothing_options():
    """The default centre smoothing moves surfaces inwards; smoothing=0 keeps the centres."""
    x = jittered_block(8, 0.1, 4)
    f0 = im.BlobField.from_particles(x, R, anisotropic=im.AnisotropyOptions(smoothing=0.0))
    np.testing.assert_array_equal(f0.centers, x)
    f = im.BlobField.from_particles(x, R, anisotropic=True)
    assert not np.array_equal(f.centers, x)
    # Every kernel's integral is the round one's: strengths times det S (a round kernel's
    # strength is 1/Σ w over its neighbours).
    iso = im.BlobField.from_particles(x, R)
    np.testing.assert_allclose(f.strengths, iso.strengths * np.linalg.det(f.shapes), rtol=1e-12)
    np.testing.assert_array_equal(f.radii, iso.radii)
    assert np.all(f.reaches >= f.radii / np.sqrt(np.linalg.eigvalsh(np.einsum("nki,nkj->nij", f.shapes, f.shapes))[:, :1].ravel()) * (1 - 1e-12))


def test_pickle_and_save_keep_the_shapes(tmp_path):
    f = im.BlobField.from_particles(slab_and_drop(), R, anisotropic=True, precision="single")
    p = np.random.default_rng(3).uniform(-0.1, 1.1, (3000, 3))
    for g in (pickle.loads(pickle.dumps(f)), None):
        if g is None:
            im.save(tmp_path / "f.npz", f)
            g = im.load(tmp_path / "f.npz")
        assert np.array_equal(g.shapes, f.shapes) and g.precision == "single"
        assert np.array_equal(g.evaluate(p), f.evaluate(p))


def test_tiled_equals_one_machine():
    distributed = pytest.importorskip("distributed")
    from implicitmesh import distributed as imd

    from test_distributed import WORKER_MEMORY, assert_same_mesh

    f = im.BlobField.from_particles(jittered_block(7, 0.1, 5) - 0.3, R, anisotropic=True)
    box = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]
    whole = im.polygonize(f, bounds=box, resolution=40, method="sparse")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, memory_limit=WORKER_MEMORY, dashboard_address=":0")
    with distributed.Client(cluster) as client:
        tiled = imd.polygonize(f, bounds=box, resolution=40, method="sparse", client=client, tile=16)
    cluster.close()
    assert_same_mesh(tiled, whole)
    assert tiled.stats["tiles"] > 1


@pytest.mark.parametrize(
    "options, name",
    [
        (im.AnisotropyOptions(k_r=-1.0), "k_r"),
        (im.AnisotropyOptions(k_s=0.0), "k_s"),
        (im.AnisotropyOptions(k_n=float("nan")), "k_n"),
        (im.AnisotropyOptions(smoothing=1.5), "smoothing"),
        (im.AnisotropyOptions(neighbour_radius=-2.0), "neighbour_radius"),
        (im.AnisotropyOptions(min_neighbours=-1), "min_neighbours"),
        ("yes", "anisotropic"),
    ],
)
def test_bad_options_refused_by_name(options, name):
    with pytest.raises(ValueError, match=name):
        im.BlobField.from_particles(jittered_block(3, 0.1, 1), R, anisotropic=options)


def test_bad_shapes_refused_by_name():
    c = np.zeros((2, 3))
    for shapes in (np.zeros((2, 3)), np.zeros((2, 3, 3)), np.full((2, 3, 3), np.nan), np.stack([np.eye(3), np.diag([1.0, 1.0, 1e-6])])):
        with pytest.raises(ValueError, match="shapes"):
            im.BlobField(c, 0.5, shapes=shapes)
    with pytest.raises(ValueError, match="centers"):
        im.BlobField(c, 0.5, shapes=np.stack([np.eye(3)] * 2)).update(np.zeros((3, 3)), radii=0.5)


def test_identity_shapes_give_the_round_field():
    rng = np.random.default_rng(9)
    c = rng.uniform(-0.5, 0.5, (80, 3))
    round_ = im.BlobField(c, 0.3, kernel="cubic_spline")
    shaped = im.BlobField(c, 0.3, kernel="cubic_spline", shapes=np.broadcast_to(np.eye(3), (80, 3, 3)))
    p = rng.uniform(-0.8, 0.8, (2000, 3))
    np.testing.assert_allclose(shaped.evaluate(p), round_.evaluate(p), rtol=0, atol=1e-12)
    a = im.polygonize(round_, resolution=40, method="sparse", normals=False)
    b = im.polygonize(shaped, bounds=round_.bounds, resolution=40, method="sparse", normals=False)
    assert abs(a.volume - b.volume) < 1e-9 * a.volume


def test_min_particles_drops_small_bodies():
    x = jittered_block(8, 0.1, 7)
    drop = jittered_block(2, 0.1, 9) + 2.0  # a droplet of 8 particles
    f = im.BlobField.from_particles(np.vstack([x, drop]), R)
    whole = mesh_of(f, method="sparse")
    kept = mesh_of(f, method="sparse", min_particles=10)
    assert whole.euler_number == 4 and kept.euler_number == 2
    assert kept.stats["fragments_dropped"] == 1 and kept.stats["fragment_particles"] == 8
    assert closed_and_oriented(kept.faces) and np.all(kept.vertices[:, 2] < 1.5)
    same = mesh_of(f, method="sparse", min_particles=8)
    assert same.stats["fragments_dropped"] == 0 and len(same.faces) == len(whole.faces)
    with pytest.raises(ValueError, match="min_particles"):
        mesh_of(f, method="sparse", min_particles=-1)
    with pytest.raises(ValueError, match="min_particles"):
        im.polygonize(lambda p: np.linalg.norm(p, axis=1) - 0.5, bounds=[[-1] * 3, [1] * 3], resolution=8, min_particles=3)
