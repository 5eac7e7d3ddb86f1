"""polygonize (dense marching cubes): analytic shapes, shared meshes, ambiguity choices, batching
and statistics, Mesh conversions and compare()."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import implicitmesh
from implicitmesh import Ambiguity, Mesh, compare, polygonize, shapes

from conftest import (
    MESH_NAMES,
    CountingField,
    count_ambiguous_faces,
    genus_of,
    lattice_points,
    surface_samples,
)

BOX = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])


def closed_outward(mesh: Mesh):
    """trimesh view of `mesh` (process=False) after checking it is a closed, consistently and
    outward oriented surface."""
    tm = mesh.to_trimesh()
    assert len(mesh.faces) > 0
    assert tm.is_watertight
    assert tm.is_winding_consistent
    assert mesh.volume > 0
    return tm


def on_lattice_edges(mesh: Mesh, bounds, resolution) -> bool:
    """Every vertex lies on a lattice edge: at least two coordinates are exactly lattice
    coordinates (origin + i × cell)."""
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    cell = (hi - lo) / np.asarray(resolution, dtype=float)
    k = np.round((mesh.vertices - lo) / cell)
    exact = (lo + k * cell) == mesh.vertices
    return bool(np.all(exact.sum(axis=1) >= 2))


# --------------------------------------------------------------------------- analytic shapes

ANALYTIC = {
    "sphere": shapes.Sphere(),
    "torus": shapes.Torus(),
    "sphere_offcentre": shapes.Sphere(center=(0.013, -0.021, 0.007), radius=0.7),
    "torus_offcentre": shapes.Torus(center=(0.011, 0.02, -0.013), major=0.55, minor=0.2),
}


def exact_volume(shape) -> float:
    if isinstance(shape, shapes.Sphere):
        return 4.0 / 3.0 * math.pi * shape.radius**3
    return 2.0 * math.pi**2 * shape.major * shape.minor**2


@pytest.fixture(scope="module", params=sorted(ANALYTIC))
def analytic_128(request):
    shape = ANALYTIC[request.param]
    counter = CountingField(shape)
    mesh = polygonize(counter, bounds=shape.bounds, resolution=128)
    return shape, counter, mesh


def test_analytic_closed_with_exact_topology_and_area(analytic_128):
    shape, _, mesh = analytic_128
    tm = closed_outward(mesh)
    # (Mesh.euler_number is checked against trimesh on the smaller meshes below.)
    assert tm.euler_number == 2 - 2 * shape.genus
    assert tm.body_count == 1
    assert abs(mesh.area - shape.area) <= 0.01 * shape.area
    assert abs(mesh.volume - exact_volume(shape)) <= 0.01 * exact_volume(shape)
    assert mesh.area == pytest.approx(tm.area, rel=1e-9)


def test_analytic_vertices_on_the_surface(analytic_128):
    shape, _, mesh = analytic_128
    b = shape.bounds
    cell = ((b[1] - b[0]) / 128).min()
    assert np.max(np.abs(shape(mesh.vertices))) < 0.1 * cell
    assert on_lattice_edges(mesh, b, 128)
    assert np.all(mesh.vertices >= b[0]) and np.all(mesh.vertices <= b[1])


def test_analytic_normals_follow_the_gradient(analytic_128):
    shape, _, mesh = analytic_128
    n = mesh.normals
    assert n.shape == mesh.vertices.shape
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)
    # Exact outward normals of the signed distance.
    h = 1e-6
    g = np.stack([(shape(mesh.vertices + h * e) - shape(mesh.vertices - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    assert np.min(np.einsum("ij,ij->i", n, g)) > 0.999


def test_analytic_stats_and_batched_calls(analytic_128):
    _, counter, mesh = analytic_128
    st = mesh.stats
    assert st["evaluations"] == 129**3
    assert st["lattice_points"] == 129**3
    assert st["evaluation_percent"] == pytest.approx(100.0)
    assert tuple(st["resolution"]) == (128, 128, 128)
    assert st["method"] == "dense"
    assert st["triangles"] == len(mesh.faces) and st["vertices"] == len(mesh.vertices)
    assert st["cells_visited"] == 128**3
    assert 0 < st["cells_crossed"] <= len(mesh.faces)
    assert st["normal_evaluations"] > 0
    # Every point the callable saw is counted, and it was called in batches, never point by point.
    assert counter.bad_inputs == []
    assert counter.points == st["evaluations"] + st["normal_evaluations"]
    assert counter.calls * 1000 < counter.points
    assert max(counter.sizes) <= 262144


def test_batch_size_is_respected_and_does_not_change_the_result():
    shape = shapes.Sphere(center=(0.05, 0.0, -0.02), radius=0.6)
    reference = polygonize(shape, bounds=BOX, resolution=24)
    counter = CountingField(shape)
    small = polygonize(counter, bounds=BOX, resolution=24, batch_size=1000)
    assert max(counter.sizes) <= 1000
    assert counter.calls >= math.ceil(25**3 / 1000)
    assert counter.points == small.stats["evaluations"] + small.stats["normal_evaluations"]
    np.testing.assert_array_equal(small.vertices, reference.vertices)
    np.testing.assert_array_equal(small.faces, reference.faces)


def test_callable_called_from_the_calling_thread_only():
    import threading

    threads = set()

    def field(p):
        threads.add(threading.get_ident())
        return shapes.Torus()(p)

    mesh = polygonize(field, bounds=BOX, resolution=40, batch_size=2000)
    assert threads == {threading.get_ident()}
    closed_outward(mesh)


def test_without_normals():
    counter = CountingField(shapes.Sphere())
    mesh = polygonize(counter, bounds=BOX, resolution=20, normals=False)
    assert mesh.normals.shape == (0, 3)
    assert mesh.stats["normal_evaluations"] == 0
    assert counter.points == mesh.stats["evaluations"] == 21**3
    closed_outward(mesh)


def test_anisotropic_resolution_and_box():
    shape = shapes.Sphere(center=(0.01, 0.02, -0.03), radius=0.5)
    bounds = [[-1.0, -0.7, -0.6], [0.9, 0.8, 0.6]]
    mesh = polygonize(shape, bounds=bounds, resolution=(37, 23, 19))
    assert mesh.stats["evaluations"] == 38 * 24 * 20
    assert tuple(mesh.stats["resolution"]) == (37, 23, 19)
    closed_outward(mesh)
    assert mesh.euler_number == 2
    assert on_lattice_edges(mesh, bounds, (37, 23, 19))


def test_surface_leaving_the_box_gives_an_open_mesh():
    mesh = polygonize(shapes.Sphere(radius=1.2), bounds=BOX, resolution=16)
    assert len(mesh.faces) > 0
    assert not mesh.to_trimesh().is_watertight


def test_field_without_a_surface_gives_an_empty_mesh():
    mesh = polygonize(lambda p: np.ones(len(p)), bounds=BOX, resolution=8)
    assert mesh.vertices.shape == (0, 3) and mesh.faces.shape == (0, 3)
    assert mesh.stats["evaluations"] == 9**3


# --------------------------------------------------------------------------- shared meshes


@pytest.mark.parametrize("name", MESH_NAMES)
def test_shared_mesh_polygonized_closed_with_input_genus(shared, name):
    src = shared.trimesh(name)
    assert src.is_watertight and src.body_count == 1
    mesh = shared.polygonized(name)
    tm = closed_outward(mesh)
    assert tm.body_count == 1
    assert mesh.euler_number == tm.euler_number
    assert genus_of(mesh.euler_number) == genus_of(src.euler_number)
    assert mesh.volume == pytest.approx(tm.volume, rel=1e-9)
    assert mesh.stats["evaluations"] == 65**3
    assert tuple(mesh.stats["resolution"]) == (64, 64, 64)


@pytest.mark.parametrize("name", MESH_NAMES)
def test_shared_mesh_vertex_normals_agree_with_faces(shared, name):
    mesh = shared.polygonized(name)
    n = mesh.normals
    assert n.shape == mesh.vertices.shape
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)
    fn = mesh.to_trimesh().face_normals
    dots = np.einsum("fkj,fj->fk", n[mesh.faces], fn)
    assert dots.mean() > 0.9
    # Normals are the field's normalised gradient.
    g = shared.surface(name).gradient(mesh.vertices)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    np.testing.assert_allclose(n, g, atol=1e-9)


@pytest.mark.parametrize("name", MESH_NAMES)
def test_shared_mesh_polygonized_near_the_input(shared, name):
    s = shared.surface(name)
    mesh = shared.polygonized(name)
    bounds = s.bounds
    cell = ((bounds[1] - bounds[0]) / 64).min()
    # Default bounds are the surface's, vertices on lattice edges, on the zero set.
    assert on_lattice_edges(mesh, bounds, 64)
    assert np.max(np.abs(s.evaluate(mesh.vertices))) < 0.5 * cell
    v, f = shared.arrays(name)
    dist, _ = cKDTree(surface_samples(v, f, 0.005)).query(mesh.vertices)
    assert dist.mean() < 0.02


def test_default_bounds_are_the_surface_bounds(shared):
    s = shared.surface("knot")
    a = polygonize(s, resolution=16)
    b = polygonize(s, bounds=s.bounds, resolution=16)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)


def test_variational_surface_same_as_its_callable(sphere_surfaces):
    """The Rust-side field and the same surface passed as a Python callable (a lambda) give the
    same triangles."""
    s = sphere_surfaces["triharmonic"]
    a = polygonize(s, resolution=20)
    b = polygonize(lambda p: s.evaluate(p), bounds=s.bounds, resolution=20)
    assert compare(a, b) == {"missing": 0, "extra": 0, "common": len(a.faces)}


# --------------------------------------------------------------------------- ambiguity


def lattice_field(values: np.ndarray, bounds=BOX):
    """A callable whose value at each lattice point of a dense polygonization with
    resolution len(values) - 1 is the given value (nearest lattice point elsewhere)."""
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    n = values.shape[0] - 1
    cell = (hi - lo) / n

    def f(p):
        idx = np.clip(np.rint((np.asarray(p) - lo) / cell).astype(int), 0, n)
        return values[idx[:, 0], idx[:, 1], idx[:, 2]]

    return f


AMBIGUITY_VALUES = {
    "separate": ["separate", Ambiguity.SEPARATE, "SEPARATE"],
    "join": ["join", Ambiguity.JOIN, "Join"],
}


def test_ambiguity_choices_on_one_ambiguous_face():
    """Two inside lattice points diagonally opposite on one cube face: SEPARATE cuts them off as
    two closed pieces, JOIN connects them through the face into one."""
    values = np.ones((5, 5, 5))
    values[2, 2, 2] = values[3, 3, 2] = -1.0
    field = lattice_field(values)
    assert count_ambiguous_faces(values < 0) == 1
    results = {}
    for choice, spellings in AMBIGUITY_VALUES.items():
        meshes = [polygonize(field, bounds=BOX, resolution=4, ambiguity=a) for a in spellings]
        for m in meshes[1:]:
            np.testing.assert_array_equal(m.vertices, meshes[0].vertices)
            np.testing.assert_array_equal(m.faces, meshes[0].faces)
        results[choice] = meshes[0]
    sep, join = results["separate"], results["join"]
    tm_sep, tm_join = closed_outward(sep), closed_outward(join)
    assert tm_sep.body_count == 2 and sep.euler_number == 4
    assert tm_join.body_count == 1 and join.euler_number == 2
    # The default is SEPARATE.
    default = polygonize(field, bounds=BOX, resolution=4)
    assert compare(default, sep)["missing"] == 0 and compare(default, sep)["extra"] == 0


CUBE_CORNERS = np.array([[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)])


def components(inside_corners: np.ndarray, max_manhattan: int) -> int:
    """Connected groups of the given cube corners, two corners being adjacent when they differ in
    at most `max_manhattan` coordinates (1: along a cube edge; 2: also across a face diagonal)."""
    from scipy.sparse.csgraph import connected_components

    c = CUBE_CORNERS[inside_corners]
    adjacent = np.abs(c[:, None, :] - c[None, :, :]).sum(axis=2) <= max_manhattan
    return connected_components(adjacent, directed=False)[0]


def test_every_cube_configuration_both_choices():
    """All 254 non-trivial inside/outside patterns of one cube (the cube in the middle of a 3³-cell
    lattice, every other lattice point outside): both choices give closed outward surfaces;
    SEPARATE gives one piece per group of inside corners connected along cube edges, JOIN one per
    group connected along edges or face diagonals."""
    for case in range(1, 255):
        inside = np.array([(case >> c) & 1 for c in range(8)], dtype=bool)
        values = np.ones((4, 4, 4))
        for c in np.flatnonzero(inside):
            values[tuple(1 + CUBE_CORNERS[c])] = -1.0
        field = lattice_field(values)
        for ambiguity, reach in ((Ambiguity.SEPARATE, 1), (Ambiguity.JOIN, 2)):
            mesh = polygonize(field, bounds=BOX, resolution=3, ambiguity=ambiguity, normals=False)
            tm = mesh.to_trimesh()
            assert tm.is_watertight and tm.is_winding_consistent and mesh.volume > 0, (case, ambiguity)
            assert tm.body_count == components(inside, reach), (case, ambiguity)


def random_sign_lattice(n=12, seed=3):
    rng = np.random.default_rng(seed)
    values = rng.choice([-1.0, 1.0], size=(n + 1,) * 3) * rng.uniform(0.5, 1.5, size=(n + 1,) * 3)
    for axis in range(3):  # outside on the box, so every piece is closed
        idx = [slice(None)] * 3
        idx[axis] = [0, -1]
        values[tuple(idx)] = 1.0
    return values


def metaballs(p):
    rng = np.random.default_rng(1)
    centres = rng.uniform(-0.5, 0.5, size=(8, 3))
    s = sum(np.exp(-np.sum((p - c) ** 2, axis=1) / (2 * 0.15**2)) for c in centres)
    return 0.5 - s


@pytest.fixture(scope="module")
def ambiguous_fields():
    values = random_sign_lattice()
    n_meta = 32
    meta_inside = metaballs(lattice_points(BOX, n_meta).reshape(-1, 3)).reshape((n_meta + 1,) * 3) < 0
    return {
        "random_lattice": (lattice_field(values), 12, count_ambiguous_faces(values < 0)),
        "metaballs": (metaballs, n_meta, count_ambiguous_faces(meta_inside)),
    }


@pytest.mark.parametrize("field_name", ["random_lattice", "metaballs"])
@pytest.mark.parametrize("ambiguity", [Ambiguity.SEPARATE, Ambiguity.JOIN, "separate", "join"])
def test_both_ambiguity_choices_watertight(ambiguous_fields, field_name, ambiguity):
    field, n, ambiguous = ambiguous_fields[field_name]
    assert ambiguous > 0, "the test field must have ambiguous faces"
    mesh = polygonize(field, bounds=BOX, resolution=n, ambiguity=ambiguity)
    closed_outward(mesh)
    assert on_lattice_edges(mesh, BOX, n)


@pytest.mark.parametrize("field_name", ["random_lattice", "metaballs"])
def test_ambiguity_choices_differ(ambiguous_fields, field_name):
    field, n, _ = ambiguous_fields[field_name]
    sep = polygonize(field, bounds=BOX, resolution=n, ambiguity=Ambiguity.SEPARATE)
    join = polygonize(field, bounds=BOX, resolution=n, ambiguity=Ambiguity.JOIN)
    c = compare(sep, join)
    assert c["missing"] > 0 and c["extra"] > 0
    # Same lattice, same crossings: the two choices share every edge vertex.
    assert {tuple(v) for v in sep.vertices} == {tuple(v) for v in join.vertices}
    # JOIN connects what SEPARATE cuts apart: never more pieces.
    assert join.to_trimesh().body_count <= sep.to_trimesh().body_count


# --------------------------------------------------------------------------- compare


@pytest.fixture(scope="module")
def sphere_32():
    return polygonize(shapes.Sphere(center=(0.01, 0.02, 0.03), radius=0.7), bounds=BOX, resolution=32)


def test_compare_with_itself(sphere_32):
    assert compare(sphere_32, sphere_32) == {"missing": 0, "extra": 0, "common": len(sphere_32.faces)}


def test_compare_ignores_numbering_and_order_but_not_orientation(sphere_32):
    a = sphere_32
    rng = np.random.default_rng(0)
    perm = rng.permutation(len(a.vertices))  # new index of old vertex i is inv[i]
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    faces = inv[a.faces][rng.permutation(len(a.faces))]
    faces = np.roll(faces, 1, axis=1)  # same cyclic order, other starting corner
    b = Mesh(a.vertices[perm], faces)
    assert compare(a, b) == {"missing": 0, "extra": 0, "common": len(a.faces)}
    flipped = Mesh(a.vertices, a.faces[:, ::-1])
    assert compare(a, flipped) == {"missing": len(a.faces), "extra": len(a.faces), "common": 0}
    # Dropping triangles shows up as missing, not extra.
    holed = Mesh(a.vertices, a.faces[10:])
    assert compare(a, holed) == {"missing": 10, "extra": 0, "common": len(a.faces) - 10}


def _compare_by_sets(a: Mesh, b: Mesh) -> dict:
    """compare's counts from Python sets of triangles as tuples of corner bit patterns."""

    def triangles(m):
        out = set()
        for f in m.faces:
            c = [tuple(m.vertices[i].view(np.uint64)) for i in f]
            k = min(range(3), key=lambda i: c[i])
            out.add(tuple(c[k:] + c[:k]))
        return out

    ta, tb = triangles(a), triangles(b)
    return {"missing": len(ta - tb), "extra": len(tb - ta), "common": len(ta & tb)}


@pytest.mark.parametrize("seed", range(6))
def test_compare_counts_what_sets_of_triangles_count(seed):
    """Random meshes over a few positions (repeated vertices, repeated and degenerate
    triangles, -0.0 against 0.0): compare's counts are those of sets of triangles."""
    rng = np.random.default_rng(seed)
    pool = rng.integers(-2, 3, (12, 3)).astype(np.float64) * 0.5
    pool[0] = [-0.0, 0.0, 0.5]
    pool[1] = [0.0, 0.0, 0.5]

    def mesh():
        v = pool[rng.integers(0, len(pool), 20)]
        f = rng.integers(0, len(v), (rng.integers(0, 40), 3))
        return Mesh(v, f)

    for _ in range(5):
        a, b = mesh(), mesh()
        assert compare(a, b) == _compare_by_sets(a, b)
        assert compare(a, a) == _compare_by_sets(a, a)


def test_triangle_keys_name_rotated_rows_with_one_key_or_two():
    from implicitmesh.mesh import _triangle_keys

    rng = np.random.default_rng(1)
    ids = rng.integers(0, 6, (400, 3))
    rotated = [tuple(np.roll(r, -int(np.argmin(r)))) for r in ids]
    for n in (6, (1 << 21) + 1):
        keys = _triangle_keys(ids, n)
        assert keys.shape == (len(ids), 1 if n <= 1 << 21 else 2)
        for i in range(0, len(ids), 7):
            for j in range(len(ids)):
                assert (keys[i] == keys[j]).all() == (rotated[i] == rotated[j])


def test_edge_and_index_counts_are_those_of_unique():
    from implicitmesh.mesh import count_distinct, count_edges

    rng = np.random.default_rng(2)
    for _ in range(100):
        f = rng.integers(0, rng.integers(1, 30), (rng.integers(1, 40), 3))
        e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        assert count_edges(f) == len(np.unique(e, axis=0))
        assert count_distinct(f.ravel()) == len(np.unique(f))
    assert count_distinct(np.zeros(0, dtype=np.int64)) == 0


def test_compare_different_resolutions(sphere_32):
    other = polygonize(shapes.Sphere(center=(0.01, 0.02, 0.03), radius=0.7), bounds=BOX, resolution=33)
    c = compare(sphere_32, other)
    assert c["missing"] > 0 and c["extra"] > 0
    assert c["missing"] + c["common"] == len(sphere_32.faces)
    assert c["extra"] + c["common"] == len(other.faces)


# --------------------------------------------------------------------------- conversions


def test_mesh_arrays(sphere_32):
    m = sphere_32
    assert m.vertices.dtype == np.float64 and m.vertices.flags["C_CONTIGUOUS"]
    assert m.faces.dtype == np.int64 and m.faces.shape[1] == 3
    assert m.faces.min() >= 0 and m.faces.max() < len(m.vertices)
    # Every vertex is used, and no triangle repeats a vertex.
    assert len(np.unique(m.faces)) == len(m.vertices)
    assert np.all((m.faces[:, 0] != m.faces[:, 1]) & (m.faces[:, 1] != m.faces[:, 2]) & (m.faces[:, 0] != m.faces[:, 2]))
    assert repr(m) == f"Mesh(vertices={len(m.vertices)}, faces={len(m.faces)})"


def test_to_trimesh(sphere_32):
    tm = sphere_32.to_trimesh()
    assert isinstance(tm, trimesh.Trimesh)
    np.testing.assert_array_equal(tm.vertices, sphere_32.vertices)
    np.testing.assert_array_equal(tm.faces, sphere_32.faces)
    np.testing.assert_allclose(tm.vertex_normals, sphere_32.normals, atol=1e-12)
    assert tm.euler_number == sphere_32.euler_number


def test_to_pyvista(sphere_32):
    pv = pytest.importorskip("pyvista", reason="pyvista is not installed (the viz extra)")
    poly = sphere_32.to_pyvista()
    assert isinstance(poly, pv.PolyData)
    assert poly.n_points == len(sphere_32.vertices)
    assert poly.n_cells == len(sphere_32.faces)
    np.testing.assert_array_equal(np.asarray(poly.points), sphere_32.vertices)
    np.testing.assert_array_equal(np.asarray(poly.faces).reshape(-1, 4)[:, 1:], sphere_32.faces)
    np.testing.assert_array_equal(np.asarray(poly.point_data["Normals"]), sphere_32.normals)


@pytest.mark.parametrize("suffix", [".ply", ".off"])
def test_save_and_reload(sphere_32, tmp_path, suffix):
    path = tmp_path / f"sphere{suffix}"
    sphere_32.save(path)
    assert path.stat().st_size > 0
    back = trimesh.load(path, process=False)
    assert len(back.vertices) == len(sphere_32.vertices)
    assert len(back.faces) == len(sphere_32.faces)
    np.testing.assert_array_equal(back.faces, sphere_32.faces)
    np.testing.assert_allclose(back.vertices, sphere_32.vertices, atol=1e-6)
    assert back.is_watertight


def test_quality(sphere_32):
    q = sphere_32.quality()
    assert q["min_angle"].shape == (len(sphere_32.faces),)
    assert np.all(q["min_angle"] >= 0) and np.all(q["min_angle"] <= 60 + 1e-9)
    finite = np.isfinite(q["aspect_ratio"])
    assert np.all(q["aspect_ratio"][finite] >= 1 - 1e-9)
    assert q["min_angle_mean"] == pytest.approx(q["min_angle"].mean())


@pytest.mark.parametrize("method", implicitmesh.METHODS)
def test_every_method_reproduces_dense(sphere_32, method):
    """Every polygonizer listed in METHODS works on the same lattice as the dense one and finds
    the same triangles on a simple closed surface (method names are case-insensitive)."""
    assert "dense" in implicitmesh.METHODS
    if method == "sparse":
        # Sparse bounds the field over blocks: blob fields only; a blob is a sphere too.
        with pytest.raises(ValueError, match="method.*BlobField"):
            polygonize(shapes.Sphere(radius=0.7), bounds=BOX, resolution=32, method="SPARSE")
        blob = implicitmesh.BlobField([[0.01, 0.02, 0.03]], 1.3)
        ref = polygonize(blob, bounds=BOX, resolution=32)
        mesh = polygonize(blob, bounds=BOX, resolution=32, method="SPARSE")
        assert mesh.stats["method"] == method
        assert compare(ref, mesh) == {"missing": 0, "extra": 0, "common": len(ref.faces)}
        assert len(ref.faces) > 1000
        return
    # Tracking needs seeds for a callable: the sphere's centre.
    extra = {"seeds": [[0.01, 0.02, 0.03]]} if method == "tracking" else {}
    mesh = polygonize(
        shapes.Sphere(center=(0.01, 0.02, 0.03), radius=0.7), bounds=BOX, resolution=32, method=method.upper(), **extra
    )
    assert mesh.stats["method"] == method
    assert compare(sphere_32, mesh) == {"missing": 0, "extra": 0, "common": len(sphere_32.faces)}


# --------------------------------------------------------------------------- projection


class Quartic:
    """A sphere of radius 0.6 whose field is far from a distance, f = |x|⁴ − 0.6⁴: linear
    interpolation along lattice edges misplaces vertices by a visible fraction of a cell."""

    bounds = BOX

    def __call__(self, p):
        return (np.asarray(p) ** 2).sum(axis=1) ** 2 - 0.6**4


def _fields_for(method):
    if method == "sparse":
        return implicitmesh.BlobField([[0.01, 0.02, 0.03], [0.3, 0.1, 0.0]], 0.9), {}
    extra = {"seeds": [[0.0, 0.0, 0.0]]} if method == "tracking" else {}
    return Quartic(), extra


@pytest.mark.parametrize("method", implicitmesh.METHODS)
def test_projection_moves_vertices_onto_the_surface(method):
    """project=True keeps the faces, brings every vertex closer to the zero set, and gives the
    same mesh whichever polygonizer found the triangles."""
    field, extra = _fields_for(method)
    ref = polygonize(field, bounds=BOX, resolution=24, project=True)
    plain = polygonize(field, bounds=BOX, resolution=24, method=method, **extra)
    moved = polygonize(field, bounds=BOX, resolution=24, method=method, project=True, **extra)
    assert compare(ref, moved) == {"missing": 0, "extra": 0, "common": len(ref.faces)}
    assert np.array_equal(plain.faces, moved.faces)
    before, after = np.abs(field(plain.vertices)), np.abs(field(moved.vertices))
    assert after.max() < before.max() / 10
    if isinstance(field, Quartic):  # distance to the exact sphere
        radial = [np.abs(np.linalg.norm(m.vertices, axis=1) - 0.6).max() for m in (plain, moved)]
        assert radial[0] > 1e-3 and radial[1] < radial[0] / 10
    assert moved.stats["projection_evaluations"] > 0 and plain.stats["projection_evaluations"] == 0
    # Normals are the gradient's direction at the moved vertices (central differences for a
    # callable, the field's own gradient for a blob field).
    g = field.gradient(moved.vertices) if method == "sparse" else 4 * moved.vertices
    g /= np.linalg.norm(g, axis=1)[:, None]
    assert np.abs((g * moved.normals).sum(axis=1) - 1).max() < 1e-6
    closed_outward(moved)


def test_projection_on_a_fitted_surface(shared):
    """On a fitted shared mesh the octree's projected mesh is the dense one's, with |f| at the
    vertices ten times smaller than without projection."""
    surface = shared.surface("knot")
    plain = polygonize(surface, resolution=64, method="octree")
    moved = polygonize(surface, resolution=64, method="octree", project=True)
    dense = polygonize(surface, resolution=64, method="dense", project=True)
    assert compare(dense, moved) == {"missing": 0, "extra": 0, "common": len(dense.faces)}
    assert compare(plain, moved)["common"] == 0 and np.array_equal(plain.faces, moved.faces)
    err = [np.abs(surface(m.vertices)).mean() for m in (plain, moved)]
    assert err[1] < err[0] / 10


def test_projection_must_be_a_bool():
    with pytest.raises(ValueError, match="project"):
        polygonize(shapes.Sphere(), bounds=BOX, resolution=8, project="yes")
