"""Blob fields and the tracking polygonizer (Triquet et al.)."""

import numpy as np
import pytest

import implicitmesh as im

BOX = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]


def brute_potential(centers, radii, strengths, p):
    d2 = ((p[:, None, :] - centers[None, :, :]) ** 2).sum(axis=2)
    t = np.clip(1.0 - d2 / radii[None, :] ** 2, 0.0, None)
    return (strengths[None, :] * t * t).sum(axis=1)


@pytest.mark.parametrize("n, seed", [(1, 0), (25, 1), (400, 2)])
def test_voxel_evaluation_equals_brute_force(n, seed):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-0.8, 0.8, (n, 3))
    r = rng.uniform(0.05, 0.3, n)
    a = rng.uniform(0.5, 2.0, n)
    b = im.BlobField(c, r, a, threshold=0.7)
    p = rng.uniform(-1.2, 1.2, (5000, 3))
    ref = brute_potential(c, r, a, p)
    np.testing.assert_allclose(b.potential(p), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.evaluate(p), 0.7 - ref, rtol=0, atol=1e-12)


def test_gradient_matches_central_differences():
    rng = np.random.default_rng(4)
    b = im.BlobField(rng.uniform(-0.5, 0.5, (30, 3)), 0.3)
    p = rng.uniform(-0.8, 0.8, (500, 3))
    h = 1e-6
    fd = np.stack(
        [(b.evaluate(p + h * e) - b.evaluate(p - h * e)) / (2 * h) for e in np.eye(3)], axis=1
    )
    np.testing.assert_allclose(b.gradient(p), fd, rtol=0, atol=1e-6)


@pytest.mark.parametrize("n, r, res, seed", [(1, 0.3, 24, 0), (40, 0.2, 48, 1), (150, 0.12, 64, 2), (3, 0.04, 40, 3)])
@pytest.mark.parametrize("ambiguity", ["separate", "join"])
def test_tracking_equals_dense(n, r, res, seed, ambiguity):
    rng = np.random.default_rng(seed)
    b = im.BlobField(rng.uniform(-0.7, 0.7, (n, 3)), r)
    d = im.polygonize(b, bounds=BOX, resolution=res, ambiguity=ambiguity)
    t = im.polygonize(b, bounds=BOX, resolution=res, method="tracking", ambiguity=ambiguity)
    assert im.compare(d, t) == {"missing": 0, "extra": 0, "common": len(d.faces)}
    if len(t.faces):
        assert t.to_trimesh().is_watertight
        assert t.stats["evaluations"] < d.stats["evaluations"]


def test_tracking_a_variational_surface_equals_dense():
    v, f = im.shapes.load_model("spot")
    s = im.VariationalSurface.from_mesh(v, f)
    d = im.polygonize(s, resolution=64, normals=False)
    t = im.polygonize(s, resolution=64, method="tracking", normals=False)
    assert im.compare(d, t)["missing"] == 0 and im.compare(d, t)["extra"] == 0
    assert t.stats["evaluation_percent"] < 0.5 * d.stats["evaluation_percent"]


def test_tracking_callable_needs_seeds():
    sphere = im.shapes.Sphere(radius=0.5)
    with pytest.raises(ValueError, match="seeds"):
        im.polygonize(sphere, resolution=32, method="tracking")
    t = im.polygonize(sphere, resolution=32, method="tracking", seeds=[[0.0, 0.0, 0.0]])
    d = im.polygonize(sphere, resolution=32)
    assert im.compare(d, t)["missing"] == 0
    with pytest.raises(ValueError, match="seeds"):
        im.polygonize(sphere, resolution=32, seeds=[[0.0, 0.0, 0.0]])


def test_tessellator_blocks_must_be_a_bool():
    b = im.BlobField(np.zeros((1, 3)), 0.5)
    with pytest.raises(ValueError, match="blocks"):
        im.Tessellator().polygonize(b, resolution=16, blocks="yes")


def test_tessellator_walks_other_fields_cell_by_cell():
    # blocks=True is ignored for a callable: the same mesh and evaluations as blocks=False.
    def sphere(p):
        return np.linalg.norm(p, axis=1) - 0.5

    kw = dict(bounds=[[-1, -1, -1], [1, 1, 1]], resolution=24, seeds=[[0.0, 0.0, 0.0]])
    a = im.Tessellator().polygonize(sphere, blocks=True, **kw)
    c = im.Tessellator().polygonize(sphere, blocks=False, **kw)
    assert a.stats["evaluations"] == c.stats["evaluations"] < 25**3
    assert im.compare(a, c) == {"missing": 0, "extra": 0, "common": len(c.faces)} and len(c.faces) > 0


def test_tessellator_output_does_not_depend_on_earlier_calls():
    # Block by block the Tessellator evaluates the blocks of its previous call first; its
    # output is still in block order: after frames of other blobs on the same lattice (their
    # blocks evaluated ahead, some where the new blobs are, most not), the same arrays as a
    # fresh Tessellator's. Finding every component, both evaluate every block the bounds cannot
    # rule out, and only those (a block evaluated ahead that the bounds rule out costs no
    # evaluation): the points sparse evaluates.
    rng = np.random.default_rng(11)
    kw = dict(bounds=[[-1, -1, -1], [1, 1, 1]], resolution=48)
    frames = [im.BlobField(rng.uniform(-0.7, 0.7, (n, 3)), 0.2) for n in (60, 30, 90)]
    tess = im.Tessellator()
    for k, field in enumerate(frames):
        kept = tess.polygonize(field, **kw)
        fresh = im.Tessellator().polygonize(field, **kw)
        assert len(fresh.faces) > 0
        assert np.array_equal(kept.faces, fresh.faces)
        assert np.array_equal(kept.vertices, fresh.vertices)
        assert np.array_equal(kept.normals, fresh.normals)
        sp = im.polygonize(field, method="sparse", **kw)
        assert kept.stats["evaluations"] == fresh.stats["evaluations"] == sp.stats["evaluations"]


def slab_and_ball(seed, side, ball, radius, center):
    """Particles 0.1 apart, jittered by ±0.01: a slab of ``side`` × ``side`` × 4 from the origin
    and a ball of ``radius`` (at most ``ball``/10) at ``center``; and which particles are the
    ball's."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(*[np.arange(side) * 0.1] * 2, np.arange(4) * 0.1, indexing="ij"), -1).reshape(-1, 3)
    b = np.stack(np.meshgrid(*[np.arange(-ball, ball + 1) * 0.1] * 3, indexing="ij"), -1).reshape(-1, 3)
    b = b[np.linalg.norm(b, axis=1) <= radius] + center
    p = np.vstack([g, b]) + rng.uniform(-0.01, 0.01, (len(g) + len(b), 3))
    return p, np.arange(len(p)) >= len(g)


def assert_meshes_of_a_new_field(field, tess, p, kw, k):
    """Sparse and ``tess`` on ``field`` (updated in place to ``p``) give the arrays sparse gives
    on a new field of ``p``, bit for bit (frame ``k``); returns that mesh."""
    want = im.polygonize(im.BlobField(p, 0.2, 1.0, 0.9, precision=field.precision), method="sparse", **kw)
    assert len(want.faces) > 0
    for got in (im.polygonize(field, method="sparse", **kw), tess.polygonize(field, **kw)):
        assert np.array_equal(got.faces, want.faces), k
        assert np.array_equal(got.vertices, want.vertices), k
        assert np.array_equal(got.normals, want.normals), k
    return want


@pytest.mark.parametrize("precision", ["double", "single"])
def test_frames_of_a_field_updated_in_place_are_those_of_a_new_field(precision):
    # From its second polygonization on one lattice, a field keeps its lists of primitives per
    # block and remakes, after an update, only the layers of blocks that primitives moved far
    # reach: a slab of jittered particles swaying a little (kept lists) and a ball of them
    # falling through several layers of blocks (remade ones), then fewer particles (all
    # remade). Every frame, sparse and a Tessellator on the field updated in place give the
    # arrays sparse gives on a new field of the frame's particles, bit for bit.
    p0, ball = slab_and_ball(3, 14, 3, 0.3, [0.65, 0.65, 1.0])
    kw = dict(bounds=[[-0.3, -0.3, -0.3], [1.6, 1.6, 1.5]], resolution=[64, 64, 60])
    field = im.BlobField(p0, 0.2, 1.0, 0.9, precision=precision)
    tess = im.Tessellator()
    for k in range(7):
        p = p0 + 0.004 * np.sin(7 * p0[:, [1, 2, 0]] + 0.4 * k)
        p[ball, 2] -= 0.03 * k * k
        if k >= 5:
            p = p[:-4]
            field.update(p, radii=0.2, strengths=1.0)
        else:
            field.update(p)
        assert_meshes_of_a_new_field(field, tess, p, kw, k)


@pytest.mark.parametrize("precision", ["double", "single"])
def test_frames_moved_none_few_many_and_out_are_those_of_a_new_field(precision):
    # After updates in place (kept block lists relisted block by block or layer by layer, signs
    # first tried with last frame's proofs): frames where no particle moves, a few jump across
    # the lattice, some leave it and come back, and all move by half a block. Every frame,
    # sparse and a Tessellator on the field updated in place give the arrays sparse gives on a
    # new field, bit for bit, and dense's triangles and vertices.
    p, _ = slab_and_ball(5, 12, 2, 0.25, [0.55, 0.55, 0.9])
    few = np.random.default_rng(5).choice(len(p), 12, replace=False)
    kw = dict(bounds=[[-0.3, -0.3, -0.3], [1.4, 1.4, 1.4]], resolution=[51, 51, 51])
    moves = [
        lambda q: q,  # none
        lambda q: q,  # none again (every hint from the last frame)
        lambda q: q + np.where(np.isin(np.arange(len(q)), few)[:, None], [0.5, -0.3, 0.2], 0.0),  # a few jump
        lambda q: q + np.where(np.isin(np.arange(len(q)), few)[:, None], [0.0, 0.0, 5.0], 0.0),  # they leave
        lambda q: q - np.where(np.isin(np.arange(len(q)), few)[:, None], [0.0, 0.0, 5.2], 0.0),  # and come back
        lambda q: q + [0.04, -0.05, 0.06],  # all, by half a block and more
    ]
    field = im.BlobField(p, 0.2, 1.0, 0.9, precision=precision)
    tess = im.Tessellator()
    for k, move in enumerate(moves):
        p = move(p)
        field.update(p)
        want = assert_meshes_of_a_new_field(field, tess, p, kw, k)
        dense = im.polygonize(field, method="dense", **kw)
        assert im.compare(dense, want) == {"missing": 0, "extra": 0, "common": len(dense.faces)}, k
        order = lambda v: v[np.lexsort(v.T)]
        assert np.array_equal(order(dense.vertices), order(want.vertices)), k


def test_animation_memory_stays_flat():
    rng = np.random.default_rng(7)
    c0 = rng.uniform(-0.7, 0.7, (200, 3))
    b = im.BlobField(c0, 0.25)
    tess = im.Tessellator()
    sizes = []
    for k in range(100):
        b.update(c0 + 0.05 * np.sin(0.1 * k + np.arange(200))[:, None])
        m = tess.polygonize(b, resolution=48)
        assert len(m.faces) > 0
        sizes.append(tess.capacity_bytes)
    # Stale cache entries are dropped when they outnumber the live ones, so after warming up
    # the capacity stops growing.
    assert max(sizes[50:]) <= sizes[30] * 1.1, sizes[::10]


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(centers=np.zeros((3, 2)), radii=0.2), "centers"),
        (dict(centers=[[0, 0, np.nan]], radii=0.2), "centers"),
        (dict(centers=np.zeros((3, 3)), radii=-0.2), "radii"),
        (dict(centers=np.zeros((3, 3)), radii=[0.1, 0.2]), "radii"),
        (dict(centers=np.zeros((3, 3)), radii=0.2, threshold=0.0), "threshold"),
        (dict(centers=np.zeros((3, 3)), radii=0.2, strengths=[1.0, np.inf, 1.0]), "strengths"),
        (dict(centers=np.zeros((3, 3)), radii=0.2, voxel_size=0.0), "voxel_size"),
    ],
)
def test_bad_blob_input(kwargs, name):
    with pytest.raises(ValueError, match=name):
        im.BlobField(**kwargs)


def test_update_checks_counts():
    b = im.BlobField(np.zeros((3, 3)), 0.2)
    with pytest.raises(ValueError, match="radii"):
        b.update(np.zeros((4, 3)))
    b.update(np.zeros((4, 3)), radii=0.3, strengths=1.0)
    assert len(b) == 4
