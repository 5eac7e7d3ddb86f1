"""The octree's mesh is the dense mesh on fits whose field breaks the rejection's premise.

Fits of thin shapes (legs a few normal offsets thick) and of random vertex subsets with normals
from several estimators grow |f| faster than the distance to the surface near it, so the levels
drop blocks the surface crosses; the octree then walks on from its crossed leaves into them.
Everything here is made by the package: no shared files.
"""

from __future__ import annotations

import numpy as np
import pytest

import implicitmesh as im

BOX = [[-1, -1, -1], [1, 1, 1]]


@pytest.fixture(scope="module")
def table_mesh():
    m = im.polygonize(im.shapes.Table(), bounds=BOX, resolution=128, normals=False)
    return m.vertices, m.faces


CASES = [(seed, normals, noise) for seed in range(3) for normals, noise in (("area", 0.0), ("angle", 0.0), ("area", 3.0))]


@pytest.mark.parametrize("resolution", [64, 96])
def test_octree_equals_dense_on_thin_fits(table_mesh, resolution):
    repaired = 0
    for seed, normals, noise in CASES:
        p, n = im.shapes.sample_vertices(*table_mesh, 800, normals=normals, noise_degrees=noise, seed=seed)
        surface = im.VariationalSurface.fit(p, n, exact=True)
        dense = im.polygonize(surface, bounds=BOX, resolution=resolution, method="dense", normals=False)
        octree = im.polygonize(surface, bounds=BOX, resolution=resolution, method="octree", normals=False)
        case = (seed, normals, noise)
        assert im.compare(dense, octree) == {"missing": 0, "extra": 0, "common": len(dense.faces)}, case
        assert len(octree.vertices) == len(dense.vertices), case
        assert octree.to_trimesh().is_watertight == dense.to_trimesh().is_watertight, case
        repaired += octree.stats["cells_repaired"]
    # These fits break the premise: the repair did the work (otherwise the test tests nothing).
    assert repaired > 0


@pytest.mark.parametrize("corner_test", [True, False])
def test_repair_closes_what_an_overestimating_field_loses(corner_test):
    # Three times the signed distance: the levels drop blocks the surface crosses and balls
    # infer wrong signs; the repair recovers the dense mesh.
    field = lambda p: 3.0 * (np.linalg.norm(p - [0.01, 0.02, 0.03], axis=1) - 0.6)  # noqa: E731
    dense = im.polygonize(field, bounds=BOX, resolution=48, method="dense")
    octree = im.polygonize(field, bounds=BOX, resolution=48, method="octree", corner_test=corner_test)
    assert octree.stats["cells_repaired"] > 0
    assert im.compare(dense, octree)["missing"] == 0
    assert im.compare(dense, octree)["extra"] == 0
    assert octree.to_trimesh().is_watertight
    np.testing.assert_array_equal(np.sort(dense.vertices, axis=0), np.sort(octree.vertices, axis=0))


def test_nothing_to_repair_when_the_premise_holds():
    sphere = im.shapes.Sphere()
    octree = im.polygonize(sphere, resolution=64, method="octree")
    assert octree.stats["cells_repaired"] == 0
    assert im.compare(im.polygonize(sphere, resolution=64), octree)["missing"] == 0


def test_sample_vertices_estimators(table_mesh):
    v, f = table_mesh
    for normals in ("area", "angle"):
        p, n = im.shapes.sample_vertices(v, f, 500, normals=normals, seed=1)
        assert p.shape == n.shape == (500, 3)
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0)
        # Outward: a step along the normal leaves the table.
        assert (im.shapes.Table()(p + 0.01 * n) > 0).mean() > 0.95
    p2, n2 = im.shapes.sample_vertices(v, f, 500, normals="area", noise_degrees=5.0, seed=1)
    p1, n1 = im.shapes.sample_vertices(v, f, 500, normals="area", seed=1)
    np.testing.assert_array_equal(p1, p2)
    angle = np.degrees(np.arccos(np.clip((n1 * n2).sum(axis=1), -1, 1)))
    assert 2.0 < np.median(angle) < 15.0
    with pytest.raises(ValueError, match="normals"):
        im.shapes.sample_vertices(v, f, 10, normals="bogus")
    with pytest.raises(ValueError, match="count"):
        im.shapes.sample_vertices(v, f, len(v) + 1)


@pytest.mark.parametrize("name", ["knot", "spot", "star", "fandisk", "torus2", "icosahedron"])
def test_octree_equals_dense_on_random_samplings_of_the_development_meshes(name):
    import trimesh

    from conftest import MESH_DIR

    m = trimesh.load(MESH_DIR / f"{name}_hires.ply", process=False)
    v, f = np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int64)
    for seed, (normals, noise) in enumerate((("area", 0.0), ("angle", 0.0), ("area", 4.0))):
        p, n = im.shapes.sample_vertices(v, f, 800, normals=normals, noise_degrees=noise, seed=seed)
        surface = im.VariationalSurface.fit(p, n, exact=True)
        dense = im.polygonize(surface, bounds=BOX, resolution=64, method="dense", normals=False)
        octree = im.polygonize(surface, bounds=BOX, resolution=64, method="octree", normals=False)
        c = im.compare(dense, octree)
        assert (c["missing"], c["extra"]) == (0, 0), (name, normals, noise, c)
