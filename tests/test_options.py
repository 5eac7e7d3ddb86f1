"""One call shape: per-method options objects give the meshes of the flat keywords they mirror,
array for array; a wrong or doubled option is refused naming ``options``; PartitionOptions gives
the fit a dict of partition_options does."""

from __future__ import annotations

import numpy as np
import pytest

import implicitmesh as im

BOX = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]


@pytest.fixture(scope="module")
def blobs():
    rng = np.random.default_rng(3)
    return im.BlobField(rng.uniform(-0.5, 0.5, (30, 3)), 0.3)


def same_arrays(a: im.Mesh, b: im.Mesh) -> bool:
    return all(
        x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y)
        for x, y in ((a.vertices, b.vertices), (a.faces, b.faces), (a.normals, b.normals))
    )


def test_octree_options_equal_the_flat_keywords(blobs):
    flat = im.polygonize(blobs, bounds=BOX, resolution=32, method="octree", start_level=2, safety=3.0, corner_test=False)
    boxed = im.polygonize(
        blobs, bounds=BOX, resolution=32, method="octree", options=im.OctreeOptions(start_level=2, safety=3.0, corner_test=False)
    )
    assert len(flat.faces) > 0 and same_arrays(flat, boxed)
    assert flat.stats["evaluations"] == boxed.stats["evaluations"]
    # Options left at None are the defaults.
    assert same_arrays(im.polygonize(blobs, bounds=BOX, resolution=32, method="octree", options=im.OctreeOptions()),
                       im.polygonize(blobs, bounds=BOX, resolution=32, method="octree"))


def test_tracking_options_equal_the_flat_keywords():
    sphere = lambda p: np.linalg.norm(p, axis=1) - 0.6  # noqa: E731
    seeds = [[0.0, 0.0, 0.0]]
    flat = im.polygonize(sphere, bounds=BOX, resolution=24, method="tracking", seeds=seeds)
    boxed = im.polygonize(sphere, bounds=BOX, resolution=24, method="tracking", options=im.TrackingOptions(seeds=seeds))
    assert len(flat.faces) > 0 and same_arrays(flat, boxed)


@pytest.mark.parametrize(
    "method, options",
    [
        ("dense", im.OctreeOptions(safety=2.0)),
        ("tracking", im.OctreeOptions()),
        ("octree", im.TrackingOptions()),
        ("octree", {"safety": 2.0}),
    ],
    ids=repr,
)
def test_options_of_another_method_are_refused(blobs, method, options):
    with pytest.raises(ValueError, match="options"):
        im.polygonize(blobs, bounds=BOX, resolution=8, method=method, options=options)


def test_options_and_their_keywords_are_not_given_together(blobs):
    with pytest.raises(ValueError, match="options.*safety"):
        im.polygonize(blobs, bounds=BOX, resolution=8, method="octree", safety=2.0, options=im.OctreeOptions())
    with pytest.raises(ValueError, match="start_level"):
        im.polygonize(blobs, bounds=BOX, resolution=8, method="octree", options=im.OctreeOptions(start_level=-1))


def test_partition_options_give_the_dict_fit():
    v, f = im.shapes.load_model("knot")
    options = im.PartitionOptions(max_patch=128, overlap=1.2)
    assert options.max_patch == 128 and options.overlap == 1.2 and options.min_points is None
    assert dict(options) == {"max_patch": 128, "overlap": 1.2}
    typed = im.VariationalSurface.from_mesh(v, f, method="partition", partition_options=options)
    plain = im.VariationalSurface.from_mesh(v, f, method="partition", partition_options={"max_patch": 128, "overlap": 1.2})
    default = im.VariationalSurface.from_mesh(v, f, method="partition")
    points = np.random.default_rng(1).uniform(-1, 1, (200, 3))
    assert np.array_equal(typed(points).view(np.uint64), plain(points).view(np.uint64))
    assert len(typed.patches["radii"]) != len(default.patches["radii"])
    for bad in ({"max_patch": 2.5}, {"min_points": True}, {"overlap": "wide"}):
        name = next(iter(bad))
        with pytest.raises(ValueError, match=name):
            im.PartitionOptions(**bad)
    with pytest.raises(TypeError):
        im.PartitionOptions(patch=3)
