"""VariationalSurface with method="partition": a partition of unity of variational patches.
Exact interpolation, agreement with the global fit, polygonization (octree equals dense, closed,
right genus) at a few thousand and at 5·10⁴ points, and the errors of the `method` argument."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy.spatial import cKDTree

import implicitmesh as im
from implicitmesh import VariationalSurface, shapes

from conftest import MESH_DIR, genus_of

RES = 128


def load(name: str):
    import trimesh

    m = trimesh.load(MESH_DIR / f"{name}_hires.ply", process=False)
    return m, np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def closed_with_genus(mesh, genus: int) -> None:
    tm = mesh.to_trimesh()
    assert len(mesh.faces) > 0
    assert tm.is_watertight and tm.is_winding_consistent
    assert tm.body_count == 1
    assert mesh.volume > 0
    assert genus_of(mesh.euler_number) == genus


@pytest.fixture(scope="module")
def knot_fits():
    """3,000 vertices of knot_hires with vertex normals, fitted both ways."""
    _, v, f = load("knot")
    p, n = shapes.sample_vertices(v, f, 3000, seed=3)
    return p, n, VariationalSurface.fit(p, n, method="global", exact=True), VariationalSurface.fit(p, n, method="partition", exact=True)


def test_both_fits_interpolate(knot_fits):
    p, _, g, s = knot_fits
    assert (g.method, s.method) == ("global", "partition")
    for surface in (g, s):
        assert np.max(np.abs(surface.evaluate(p))) <= 1e-6
        c = surface.constraints
        assert np.max(np.abs(surface.evaluate(c["points"]) - c["values"])) <= 1e-9
        assert surface.residual <= 1e-9
    # Same constraints, same bounds, same sizes.
    np.testing.assert_array_equal(g.constraints["points"], s.constraints["points"])
    np.testing.assert_array_equal(g.bounds, s.bounds)
    assert len(g) == len(s) == 6000
    np.testing.assert_array_equal(s.centers, s.constraints["points"])


def test_zero_sets_agree(knot_fits):
    _, _, g, s = knot_fits
    bounds = g.bounds
    cell = float(np.max(bounds[1] - bounds[0])) / RES
    a = im.polygonize(g, bounds=bounds, resolution=RES, normals=False)
    b = im.polygonize(s, bounds=bounds, resolution=RES, normals=False)
    d_ab, _ = cKDTree(b.vertices).query(a.vertices)
    d_ba, _ = cKDTree(a.vertices).query(b.vertices)
    d = np.concatenate([d_ab, d_ba]) / cell
    assert d.mean() < 0.25 and d.max() < 1.0, (d.mean(), d.max())
    closed_with_genus(b, 1)


def test_partition_octree_equals_dense_and_is_closed(knot_fits):
    _, _, _, s = knot_fits
    dense = im.polygonize(s, resolution=RES, method="dense")
    octree = im.polygonize(s, resolution=RES, method="octree")
    c = im.compare(dense, octree)
    assert (c["missing"], c["extra"]) == (0, 0), c
    closed_with_genus(octree, 1)
    # The normals are the normalised gradients.
    g = s.gradient(octree.vertices)
    np.testing.assert_allclose(octree.normals, g / np.linalg.norm(g, axis=1)[:, None], atol=1e-12)


def test_tracking_and_subdivision_on_a_partition_fit(knot_fits):
    _, _, _, s = knot_fits
    dense = im.polygonize(s, resolution=64, method="dense")
    tracking = im.polygonize(s, resolution=64, method="tracking")
    c = im.compare(dense, tracking)
    assert (c["missing"], c["extra"]) == (0, 0), c
    with pytest.raises(ValueError, match="method"):
        im.polygonize(s, resolution=16, method="sparse")
    control = im.polygonize(s, resolution=16)
    levels = im.subdivide(control.vertices, control.faces, levels=1, field=s)
    vertices = levels[-1].vertices
    assert len(levels) == 2 and len(vertices) > len(control.vertices)
    # The new vertices are on the zero set.
    assert np.max(np.abs(s.evaluate(vertices[len(control.vertices):]))) < 1e-6


def test_gradient_matches_differences(knot_fits):
    _, _, _, s = knot_fits
    rng = np.random.default_rng(4)
    q = rng.uniform(-0.9, 0.9, size=(200, 3))
    h = 1e-6
    fd = np.stack(
        [(s.evaluate(q + h * e) - s.evaluate(q - h * e)) / (2 * h) for e in np.eye(3)], axis=1
    )
    g = s.gradient(q)
    assert np.max(np.linalg.norm(g - fd, axis=1) / np.maximum(np.linalg.norm(g, axis=1), 1.0)) < 1e-5


def test_patches_describe_the_partition(knot_fits):
    _, _, g, s = knot_fits
    patches = s.patches
    m = len(patches["radii"])
    assert patches["centers"].shape == (m, 3) and patches["sizes"].dtype == np.int64
    assert m > 10 and np.all(patches["radii"] > 0)
    # At most 3/2 of the default max_patch constraints each; the constraints inside first.
    assert np.all(patches["sizes"] >= patches["inside"]) and np.all(patches["sizes"] <= 600)
    assert np.any(patches["sizes"] > patches["inside"])
    c = s.constraints["points"]
    tree = cKDTree(c)
    for k in range(0, m, max(1, m // 25)):
        inside = tree.query_ball_point(patches["centers"][k], patches["radii"][k])
        assert len(inside) == patches["inside"][k]
    for name in ("weights", "polynomial"):
        with pytest.raises(ValueError, match=name):
            getattr(s, name)
    with pytest.raises(ValueError, match="patches"):
        g.patches
    assert "partition" in repr(s) and "global" in repr(g)


def test_fifty_thousand_scan_points():
    """5·10⁴ points sampled on the knot's surface with face normals."""
    import trimesh

    m, _, _ = load("knot")
    p, face = trimesh.sample.sample_surface(m, 50_000, seed=5)
    n = np.asarray(m.face_normals)[face]
    s = VariationalSurface.fit(p, n, exact=True)
    assert s.method == "partition"
    assert np.max(np.abs(s.evaluate(p))) <= 1e-6
    mesh = im.polygonize(s, resolution=RES, method="octree", normals=False)
    closed_with_genus(mesh, 1)
    dense = im.polygonize(s, resolution=RES, method="dense", normals=False)
    c = im.compare(dense, mesh)
    assert c["missing"] == 0 and c["extra"] == 0
    back = pickle.loads(pickle.dumps(s))
    assert np.array_equal(back.evaluate(p[:2000]), s.evaluate(p[:2000]))
    # Subdivision of a control mesh of 10⁵ vertices: the new vertices lie on the zero set.
    control = im.polygonize(s, resolution=232, method="octree", normals=False)
    assert len(control.vertices) >= 100_000
    fine = im.subdivide(control.vertices, control.faces, levels=1, field=s)[-1]
    assert len(fine.faces) == 4 * len(control.faces)
    assert np.max(np.abs(s.evaluate(fine.vertices[len(control.vertices):]))) < 1e-6
    closed_with_genus(fine, 1)


def test_interpolate_and_from_mesh_partition():
    rng = np.random.default_rng(8)
    p = rng.uniform(-1.0, 1.0, size=(3000, 3))
    v = np.sin(3 * p[:, 0]) + p[:, 1] * p[:, 2]
    s = VariationalSurface.interpolate(p, v, method="partition")
    assert s.method == "partition"
    np.testing.assert_allclose(s.evaluate(p), v, rtol=0, atol=1e-9)
    _, vv, f = load("torus2")
    t = VariationalSurface.from_mesh(vv, f, method="partition")
    assert np.max(np.abs(t.evaluate(vv))) <= 1e-6
    closed_with_genus(im.polygonize(t, resolution=64, method="octree"), 2)


def test_auto_chooses_by_size():
    # Global below 2000 constraints: 1000 points with normals, 2000 interpolated values.
    p, n = shapes.fibonacci_sphere(999)
    assert VariationalSurface.fit(p, n, exact=True).method == "global"
    p, n = shapes.fibonacci_sphere(1000)
    assert VariationalSurface.fit(p, n, exact=True).method == "partition"
    assert VariationalSurface.fit(p, n, method="global", exact=True).method == "global"
    rng = np.random.default_rng(2)
    q = rng.uniform(-1, 1, size=(2000, 3))
    assert VariationalSurface.interpolate(q[:1999], q[:1999, 0]).method == "global"
    assert VariationalSurface.interpolate(q, q[:, 0]).method == "partition"


def test_method_and_bad_input_errors():
    p, n = shapes.fibonacci_sphere(200)
    for call in (
        lambda: VariationalSurface.fit(p, n, method="dense", exact=True),
        lambda: VariationalSurface.from_mesh(*shapes.load_model("knot"), method="kdtree"),
        lambda: VariationalSurface.interpolate(p, p[:, 0], method=""),
    ):
        with pytest.raises(ValueError, match="method"):
            call()
    bad = p.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="points"):
        VariationalSurface.fit(bad, n, method="partition", exact=True)
    with pytest.raises(ValueError, match="normals"):
        VariationalSurface.fit(p, n[:-1], method="partition", exact=True)
    with pytest.warns(UserWarning, match="1 data point"):
        s = VariationalSurface.fit(np.vstack([p, p[:1]]), np.vstack([n, n[:1]]), method="partition", exact=True)
    assert s.merged_points == 1
    with pytest.raises(ValueError, match="merge_distance"):
        VariationalSurface.fit(p, n, method="partition", merge_distance=-0.1, exact=True)
    with pytest.raises(ValueError, match="memory_limit"):
        VariationalSurface.fit(p, n, method="partition", memory_limit=1000, exact=True)
    with pytest.raises(ValueError, match="values"):
        VariationalSurface.interpolate(p, p[:-1, 0], method="partition")


def test_partition_options_change_the_patches_and_are_checked():
    p, n = im.shapes.fibonacci_sphere(3000)
    a = im.VariationalSurface.fit(p, n, method="partition", exact=True)
    b = im.VariationalSurface.fit(p, n, method="partition", partition_options={"max_per_leaf": 200, "max_patch": 600}, exact=True)
    assert len(b.patches["sizes"]) < len(a.patches["sizes"])
    assert np.abs(b.evaluate(p)).max() < 1e-6
    with pytest.raises(ValueError, match="partition_options"):
        im.VariationalSurface.fit(p, n, partition_options={"patch": 3}, exact=True)
    with pytest.raises(ValueError, match="partition_options"):
        im.VariationalSurface.fit(p, n, partition_options={"overlap": "big"}, exact=True)
    with pytest.raises(ValueError, match="overlap"):
        im.VariationalSurface.fit(p, n, method="partition", partition_options={"overlap": 0.5}, exact=True)


def test_near_duplicates_from_overlapping_scans_are_merged():
    # A second scan repeats 5 % of the points a ten-millionth of the data's size away: without
    # the merge the partition fit is refused as ill-conditioned.
    rng = np.random.default_rng(7)
    p, n = im.shapes.fibonacci_sphere(10_000)
    again = rng.choice(len(p), 500, replace=False)
    q = np.vstack([p, p[again] + 1e-7 * rng.normal(size=(500, 3))])
    m = np.vstack([n, n[again]])
    with pytest.warns(UserWarning, match="500 data points"):
        s = VariationalSurface.fit(q, m, method="partition", exact=True)
    assert s.merged_points == 500
    assert np.abs(s.evaluate(p)).max() < 1e-9
    assert np.abs(s.evaluate(q[len(p):])).max() < 1e-5
    t = VariationalSurface.from_state(s.to_state())
    assert t.merged_points == 500
    with pytest.raises(ValueError, match="ill-conditioned"):
        VariationalSurface.fit(q, m, method="partition", merge_distance=0.0, exact=True)


def test_every_patch_sees_a_normal_constraint():
    # Normal constraints 0.2 outside a sphere of radius 0.8 lie beyond the supports of the
    # patches just inside it: a patch fitted to its data points alone, all of value 0, would be
    # zero over its whole support, and so would the field deep inside the solid. Such patches
    # are completed with constraints from a ball that reaches the normal constraints.
    p, n = im.shapes.fibonacci_sphere(20_000)
    s = VariationalSurface.fit(p, n, d=0.2, method="partition", exact=True)
    state = s.to_state()
    weights, start = np.abs(state["patch_normalized_weights"]), state["patch_start"]
    polynomial = np.abs(state["patch_normalized_polynomial"]).reshape(-1, 4).max(axis=1)
    largest = np.array([weights[a:b].max(initial=0.0) for a, b in zip(start[:-1], start[1:])])
    assert np.all((largest > 0) | (polynomial > 0))
    assert np.abs(s.evaluate(p)).max() < 1e-9
    rng = np.random.default_rng(0)
    u = rng.normal(size=(100_000, 3))
    inside = 0.8 * rng.uniform(0.3, 0.98, (len(u), 1)) * u / np.linalg.norm(u, axis=1, keepdims=True)
    assert s.evaluate(inside).max() < 0


def test_smoothing_partition_fit_approximates_noisy_points():
    rng = np.random.default_rng(3)
    p, n = im.shapes.fibonacci_sphere(8_000)
    radius = 0.8 * np.linalg.norm(p[0])
    noisy = 0.8 * p + 0.003 * rng.normal(size=p.shape)
    exact = VariationalSurface.fit(noisy, n, method="partition", exact=True)
    smooth = VariationalSurface.fit(noisy, n, method="partition", smoothing=1e-3, exact=True)
    assert np.abs(exact.evaluate(noisy)).max() < 1e-9
    # The smoothed surface leaves the noisy points and lies closer to the sphere they came from.
    assert np.abs(smooth.evaluate(noisy)).max() > 1e-3
    meshes = [im.polygonize(s, resolution=96) for s in (exact, smooth)]
    deviation = [np.abs(np.linalg.norm(m.vertices, axis=1) - radius).max() for m in meshes]
    assert deviation[1] < 0.7 * deviation[0], deviation
    assert meshes[1].euler_number == 2 and meshes[1].to_trimesh().is_watertight
